//! The file reader of ravel's entry points, the command line and the Python
//! package: the one place that reads what the front end asks for
//! ([`ravel::ReadRequest`]). The library itself does no IO; its callers pass
//! [`read_request`] as its reader.
#![forbid(unsafe_code)]

use ravel::ReadError;

/// Read a file the front end asks for ([`ravel::ReadRequest`]): only a
/// regular file (a FIFO, device or folder is refused without blocking: it is
/// opened non-blocking and inspected before any read), at most
/// `max_bytes` bytes, and, for external data, only if its real path (symbolic
/// links resolved) lies inside the requested folder.
pub fn read_request(req: &ravel::ReadRequest) -> Result<Vec<u8>, ReadError> {
    use std::io::Read;
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let file = opts.open(&req.path)?;
    let meta = file.metadata()?;
    if meta.is_dir() {
        return Err(ReadError::Folder);
    }
    if !meta.is_file() {
        return Err(ReadError::Special);
    }
    if let Some(dir) = &req.inside {
        let real = std::fs::canonicalize(&req.path)?;
        // a spec named without a folder (`lane.ravel`) has the empty path
        // as its folder: the working folder
        let dir = if dir.as_os_str().is_empty() {
            std::path::Path::new(".")
        } else {
            dir.as_path()
        };
        let root = std::fs::canonicalize(dir)?;
        if !real.starts_with(&root) {
            return Err(ReadError::Outside);
        }
    }
    if req.whole && meta.len() > req.max_bytes {
        return Err(ReadError::TooLarge {
            bytes: meta.len(),
            limit: req.max_bytes,
        });
    }
    let mut buf = Vec::with_capacity(meta.len().min(req.max_bytes).min(1 << 26) as usize);
    file.take(req.max_bytes).read_to_end(&mut buf)?;
    Ok(buf)
}
