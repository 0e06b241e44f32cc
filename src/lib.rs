//! ravel: a Reach-Avoid Verification Language and its compiler.
#![deny(unsafe_code)]

pub mod analysis;
pub mod check;
pub mod cli;
pub mod diag;
pub mod execute;
pub mod expm;
pub mod lower;
pub mod lp;
pub mod nn;
pub mod num;
pub mod onnx;
pub mod report;
pub mod rng;
pub mod sets;
pub mod syntax;

use std::path::Path;

use check::{Checked, ControllerFile};
use diag::Diagnostic;

/// The front end: parse and check a spec, reading its controller (and any
/// external-data files) through `read`, relative to `spec_dir`.
///
/// The library performs no IO of its own: `read` is the caller's. The CLI
/// passes a file-system reader; tests may pass anything.
pub fn front_end(
    source: &str,
    spec_dir: &Path,
    read: &dyn Fn(&Path) -> Result<Vec<u8>, String>,
) -> Result<Checked, Vec<Diagnostic>> {
    let spec = syntax::parse(source)?;
    let controller = check::controller_path(&spec).map(|p| {
        let path = spec_dir.join(&p.node);
        let bytes = read(&path);
        let mut external = onnx::ExternalFiles::new();
        if let Ok(b) = &bytes {
            let dir = path.parent().unwrap_or(spec_dir);
            for loc in onnx::external_locations(b) {
                let data = read(&dir.join(&loc));
                external.insert(loc, data);
            }
        }
        ControllerFile { bytes, external }
    });
    check::check(&spec, controller.as_ref())
}
