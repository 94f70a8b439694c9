//! Writing result files.

use crate::Error;
use std::io::Write;
use std::path::Path;

/// Writes `text` to `path` atomically (a temporary file in the same directory, then a
/// rename), so that a reader never sees half a file and a failure leaves the old one.
pub fn write_atomic(path: &Path, text: &[u8]) -> Result<(), Error> {
    write_atomic_inner(path, text).map_err(Error::Io)
}

fn write_atomic_inner(path: &Path, text: &[u8]) -> Result<(), String> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let err = |e: std::io::Error| format!("{}: cannot write: {e}", path.display());
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(err)?;
    tmp.write_all(text).map_err(err)?;
    tmp.as_file().sync_all().map_err(err)?;
    tmp.persist(path).map_err(|e| err(e.error))?;
    Ok(())
}
