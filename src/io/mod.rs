//! File formats at the edge of the pipeline: images in, disparity maps out.
//!
//! Every file jem writes goes through [`write_atomic`]: the bytes go to a hidden temporary file in the same folder,
//! which is flushed and then renamed over the destination, so an interrupted run never leaves a truncated output.

pub mod calib;
pub mod exr;
pub mod pfm;
pub mod png;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::image::DisparityMap;

/// Output formats for a disparity map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DisparityFormat {
    /// Portable float map, Middlebury convention (little-endian, rows bottom-to-top, inf = invalid).
    Pfm,
    /// OpenEXR, one 32-bit float channel `Y`.
    Exr,
    /// 16-bit grey PNG, disparity × 256, 0 = invalid (the KITTI convention).
    Png16,
}

impl DisparityFormat {
    /// The format implied by a file name's extension (`.pfm`, `.exr`, `.png`).
    ///
    /// # Errors
    /// [`Error::Input`] for any other extension.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("pfm") => Ok(DisparityFormat::Pfm),
            Some("exr") => Ok(DisparityFormat::Exr),
            Some("png") => Ok(DisparityFormat::Png16),
            _ => Err(Error::Input(format!(
                "{}: unknown output format (use a .pfm, .exr or .png file name)",
                path.display()
            ))),
        }
    }
}

/// Writes a disparity map in the format given by the file's extension, atomically.
///
/// # Errors
/// An unknown extension, or any I/O or encoder error (naming the path).
pub fn write_disparity(path: &Path, map: &DisparityMap) -> Result<()> {
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Pfm => pfm::write_pfm(path, map),
        DisparityFormat::Exr => exr::write_exr(path, map),
        DisparityFormat::Png16 => png::write_disparity_png16(path, map),
    }
}

/// Reads a disparity map from a `.pfm`, `.exr` or 16-bit `.png` (×256, 0 = invalid) file.
///
/// # Errors
/// A missing or malformed file, naming the path.
pub fn read_disparity(path: &Path) -> Result<DisparityMap> {
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Pfm => pfm::read_pfm(path),
        DisparityFormat::Exr => exr::read_exr(path),
        DisparityFormat::Png16 => png::read_disparity_png16(path),
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, flushed, then renamed.
///
/// # Errors
/// [`Error::Io`] naming `path` (the temporary file is removed on failure).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |file| file.write_all(bytes).map_err(|e| Error::io(path, e)))
}

/// Like [`write_atomic`], with a closure that writes into the temporary file.
///
/// # Errors
/// Whatever `write` returns, or [`Error::Io`] naming `path`.
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&mut std::fs::File) -> Result<()>) -> Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut file = std::fs::File::create(&tmp).map_err(|e| Error::io(path, e))?;
        write(&mut file)?;
        file.sync_all().map_err(|e| Error::io(path, e))?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// `dir/.name.jem-tmp-<pid>`: hidden, in the destination's folder (so the rename stays on one file system), and
/// unique per process.
fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    path.with_file_name(format!(".{name}.jem-tmp-{}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_extension() {
        assert_eq!(DisparityFormat::from_path(Path::new("a/b.PFM")).unwrap(), DisparityFormat::Pfm);
        assert_eq!(DisparityFormat::from_path(Path::new("b.exr")).unwrap(), DisparityFormat::Exr);
        assert_eq!(DisparityFormat::from_path(Path::new("b.png")).unwrap(), DisparityFormat::Png16);
        assert!(DisparityFormat::from_path(Path::new("b.jpg")).is_err());
        assert!(DisparityFormat::from_path(Path::new("b")).is_err());
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.txt");
        let r = write_atomic_with(&p, |_| Err(Error::Input("boom".into())));
        assert!(r.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
