//! The file reader of ravel's entry points, the command line and the Python
//! package: the one place that reads what the front end asks for
//! ([`ravel::ReadRequest`]). The library itself does no IO; its callers pass
//! [`read_request`] as its reader.
//!
//! Compressed files: a whole-file request (a spec, a controller, a VNN-LIB
//! property, an instance list, an observation file) for a file whose name
//! ends in `.gz` (any case) is decompressed as gzip (every member, as
//! `gunzip` does), so VNN-COMP's `net.onnx.gz` and `prop.vnnlib.gz` are read
//! as they ship. The request's `max_bytes` limits both the file as stored and
//! what it decompresses to: decompression stops one byte past the limit, so
//! a gzip bomb costs at most the limit in memory and time linear in it, and
//! is refused ([`ReadError::DecompressedTooLarge`]); a stream that is not
//! gzip, truncated or corrupt is [`ReadError::Compressed`], never a panic.
//!
//! Decisions: the name decides, not the content. A file not named `.gz` is
//! read as stored even if it starts with gzip's magic bytes (its parser then
//! reports it: a gzip stream is neither UTF-8 text nor an ONNX protobuf), so
//! what a file is never depends on guessing. External data of an ONNX model
//! (a prefix request, `whole == false`) is always read as stored: its
//! offsets and lengths refer to the file's bytes, and ONNX has no compressed
//! external data. A compressed model's external data therefore stays plain,
//! next to it (`net.onnx.gz` beside `net.onnx.data`), resolved relative to
//! the compressed model's folder as for a plain one.
#![forbid(unsafe_code)]

use ravel::ReadError;

/// Read a file the front end asks for ([`ravel::ReadRequest`]): only a
/// regular file (a FIFO, device or folder is refused without blocking: it is
/// opened non-blocking and inspected before any read), at most
/// `max_bytes` bytes, and, for external data, only if its real path (symbolic
/// links resolved) lies inside the requested folder. A whole file named
/// `.gz` is decompressed under the same limit (see the crate's comment).
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
    if req.whole && gzip_named(&req.path) {
        return gunzip(file.take(req.max_bytes), req.max_bytes);
    }
    let mut buf = Vec::with_capacity(meta.len().min(req.max_bytes).min(1 << 26) as usize);
    file.take(req.max_bytes).read_to_end(&mut buf)?;
    Ok(buf)
}

/// Whether a path's name ends in `.gz` (any case).
pub fn gzip_named(path: &std::path::Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

/// The decompressed content of the gzip stream `compressed` (every member),
/// at most `limit` bytes: reading stops one byte past it, which is an error.
fn gunzip(compressed: impl std::io::Read, limit: u64) -> Result<Vec<u8>, ReadError> {
    use std::io::{ErrorKind, Read};
    let mut buf = Vec::new();
    let decoder = flate2::read::MultiGzDecoder::new(compressed);
    match decoder.take(limit.saturating_add(1)).read_to_end(&mut buf) {
        Ok(_) if buf.len() as u64 > limit => Err(ReadError::DecompressedTooLarge { limit }),
        Ok(_) => Ok(buf),
        Err(e)
            if matches!(
                e.kind(),
                ErrorKind::InvalidData | ErrorKind::InvalidInput | ErrorKind::UnexpectedEof
            ) =>
        {
            Err(ReadError::Compressed(e.to_string()))
        }
        Err(e) => Err(e.into()),
    }
}

#[cfg(test)]
mod tests {
    //! The decompression on its own, on streams made here.
    use super::*;
    use std::io::Write;

    fn gz(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(data).expect("write");
        e.finish().expect("finish")
    }

    #[test]
    fn gunzip_reads_every_member_up_to_the_limit() {
        let mut two = gz(b"hello ");
        two.extend(gz(b"world"));
        assert_eq!(gunzip(&two[..], 11), Ok(b"hello world".to_vec()));
        assert_eq!(
            gunzip(&two[..], 10),
            Err(ReadError::DecompressedTooLarge { limit: 10 })
        );
        assert_eq!(gunzip(&gz(b"")[..], 10), Ok(Vec::new()));
    }

    #[test]
    fn broken_streams_are_errors() {
        let whole = gz(b"some text, some text, some text");
        for bad in [
            &b""[..],
            &b"plain text"[..],
            &b"\x1f\x8b"[..],
            &whole[..whole.len() - 4],
            &whole[..whole.len() / 2],
        ] {
            assert!(
                matches!(gunzip(bad, 1 << 20), Err(ReadError::Compressed(_))),
                "{bad:?}: {:?}",
                gunzip(bad, 1 << 20)
            );
        }
        let mut corrupt = whole.clone();
        let n = corrupt.len();
        corrupt[n - 6] ^= 0xff; // the CRC
        assert!(matches!(
            gunzip(&corrupt[..], 1 << 20),
            Err(ReadError::Compressed(_))
        ));
    }
}
