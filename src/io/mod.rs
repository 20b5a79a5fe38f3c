//! File formats at the edge of the pipeline: images in, disparity maps out.
//!
//! Every file jem writes goes through [`write_atomic`]: the bytes go to a hidden temporary file in the same folder,
//! which is flushed and then renamed over the destination, so an interrupted run never leaves a truncated output.
//! Only a regular file (or no file) is ever replaced: a rename would put a plain file in the place of a device, a
//! FIFO or a socket (as root, of `/dev/null` itself), so those are refused ([`check_replaceable`]).

pub mod calib;
pub(crate) mod exr;
pub mod pfm;
pub(crate) mod png;
mod write;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::image::{DisparityMap, RgbImage};

pub use png::{IMAGE_FORMATS, ImageHeader, PNG16_MAX_DISPARITY};
pub(crate) use write::file_kind;
#[cfg(feature = "toolkit")]
pub(crate) use write::sweep_stale_temps;
pub use write::{AllOrNone, check_replaceable, write_all_or_none, write_atomic, write_atomic_with};

/// An image file (any of [`IMAGE_FORMATS`]; 8 or 16 bit; grey, RGB or RGBA) as an [`RgbImage`]: samples on the 8-bit
/// scale (16-bit values divided by 257), grey as three equal channels, alpha dropped.
///
/// # Errors
/// [`Error::Io`] naming the file when it cannot be read, [`Error::Image`] when it cannot be decoded.
pub fn read_image(path: &Path) -> Result<RgbImage> {
    png::load_rgb(path)
}

/// An image file decoded as it is, its bit depth and channels kept (what [`read_image`] converts), for a caller
/// that wants the file's own samples.
///
/// # Errors
/// As [`read_image`].
pub fn decode_image(path: &Path) -> Result<image::DynamicImage> {
    png::decode(path)
}

/// [`decode_image`] within a memory limit of `max_bytes`: the header is read first, and an image whose decoding
/// (the file, its samples and a converted copy of them) would not fit is refused before anything is decoded.
///
/// # Errors
/// As [`read_image`]; [`Error::OutOfMemory`] naming the file when its decoding does not fit.
pub fn decode_image_within(path: &Path, max_bytes: u64) -> Result<image::DynamicImage> {
    png::decode_bounded(path, max_bytes)
}

/// Both views of a pair ([`read_image`]), decoded in parallel.
///
/// # Errors
/// As [`read_image`], for either file.
pub fn read_image_pair(left: &Path, right: &Path) -> Result<(RgbImage, RgbImage)> {
    png::load_rgb_pair(left, right)
}

/// An image file's size and the memory its decoding takes, from its header (the image is not decoded).
///
/// # Errors
/// As [`read_image`], for the header.
pub fn read_image_header(path: &Path) -> Result<ImageHeader> {
    png::read_header(path)
}

/// Both views' headers ([`read_image_header`]), checked as a pair: the same size, at least 2 pixels wide.
///
/// # Errors
/// As [`read_image_header`]; [`Error::SizeMismatch`] for unequal sizes, [`Error::InputImage`] for a pair too narrow.
pub fn read_pair_header(left: &Path, right: &Path) -> Result<ImageHeader> {
    png::read_pair_header(left, right)
}

/// An 8-bit grey image file (a MiddEval3 mask, say) as its samples, 0..=255; a colour file is converted to grey.
///
/// # Errors
/// As [`read_image`].
pub fn read_grey8(path: &Path) -> Result<crate::image::Plane<u8>> {
    png::load_grey8(path)
}

/// Writes 8-bit RGB samples (`width × height × 3`, row-major, interleaved) as a PNG, atomically.
///
/// # Errors
/// [`Error::Image`] or [`Error::Io`] naming the path.
pub fn write_png_rgb8(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<()> {
    png::write_rgb8_png(path, width, height, rgb)
}

/// An image as an 8-bit RGB PNG file's bytes (samples rounded and held to 0..=255); nothing is written, `path`
/// names the file in an error. With [`write_all_or_none`], several files are written as one.
///
/// # Errors
/// [`Error::Image`] naming the path.
pub fn encode_png(path: &Path, image: &RgbImage) -> Result<Vec<u8>> {
    let (w, h) = image.dims();
    let rgb: Vec<u8> = (0..w * h).flat_map(|i| image.rgb(i).map(|v| v.round().clamp(0.0, 255.0) as u8)).collect();
    png::encode_rgb8_png(path, w, h, &rgb)
}

/// An image as an 8-bit grey PNG file's bytes: its first channel (of a grey image, all three are equal), rounded
/// and held to 0..=255; nothing is written, `path` names the file in an error.
///
/// # Errors
/// [`Error::Image`] naming the path.
pub fn encode_grey_png(path: &Path, image: &RgbImage) -> Result<Vec<u8>> {
    let (w, h) = image.dims();
    let grey: Vec<u8> = image.channel(0).iter().map(|v| v.round().clamp(0.0, 255.0) as u8).collect();
    png::encode_grey8_png(path, w, h, &grey)
}

/// Whether an image file holds grey samples (grey or grey + alpha, 8 or 16 bit), from its header (the image is
/// not decoded).
///
/// # Errors
/// As [`read_image_header`].
pub fn image_is_grey(path: &Path) -> Result<bool> {
    png::is_grey(path)
}

/// The value [`encode_lr_mask`] writes where the left-right check rejected a pixel (0 where it passed).
pub const LR_REJECTED: u8 = 255;

/// Where the left-right check rejected a pixel, as an 8-bit grey PNG file's bytes: [`LR_REJECTED`] (255) where
/// `consistent` is false, 0 where it is true (`jem match --lr-mask`, `jem batch --lr-mask`; read back with
/// [`read_grey8`]). Nothing is written; `path` names the file in an error.
///
/// # Errors
/// [`Error::Output`] if `path` is not a `.png`; [`Error::Image`] naming the path.
pub fn encode_lr_mask(path: &Path, consistent: &crate::image::Plane<bool>) -> Result<Vec<u8>> {
    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        return Err(Error::output_at(path, "the left-right mask is written as .png"));
    }
    let (w, h) = consistent.dims();
    let grey: Vec<u8> = consistent.data().iter().map(|&ok| if ok { 0 } else { LR_REJECTED }).collect();
    png::encode_grey8_png(path, w, h, &grey)
}

/// A decoded image (from the `image` crate) as an [`RgbImage`], exactly as [`read_image`] converts a file's
/// pixels.
pub fn image_from_dynamic(img: &image::DynamicImage) -> RgbImage {
    png::to_rgb(img)
}

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
    /// [`Error::Output`] for any other extension.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("pfm") => Ok(DisparityFormat::Pfm),
            Some("exr") => Ok(DisparityFormat::Exr),
            Some("png") => Ok(DisparityFormat::Png16),
            _ => Err(Error::output_at(path, "unknown output format (use a .pfm, .exr or .png file name)")),
        }
    }
}

/// Writes a disparity map in the format given by the file's extension, atomically.
///
/// # Errors
/// An unknown extension, or any I/O or encoder error (naming the path).
pub fn write_disparity(path: &Path, map: &DisparityMap) -> Result<()> {
    write_atomic(path, &encode_disparity(path, map)?)
}

/// A disparity map encoded in the format given by `path`'s extension (nothing is written).
///
/// # Errors
/// An unknown extension, or an encoder error (naming the path), e.g. a disparity a 16-bit PNG cannot hold.
pub fn encode_disparity(path: &Path, map: &DisparityMap) -> Result<Vec<u8>> {
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Pfm => Ok(pfm::encode_pfm(map)),
        DisparityFormat::Exr => exr::encode_exr(path, map),
        DisparityFormat::Png16 => png::encode_disparity_png16(path, map),
    }
}

/// What a path will name once written: the file itself when it exists (through symbolic links), else its
/// folder's canonical path joined with its name; `None` when neither can be resolved.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Some(p);
    }
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(std::fs::canonicalize(parent).ok()?.join(path.file_name()?))
}

/// Whether two paths name the same file: equal once resolved, or (both existing) the same inode.
fn same_file(a: &Path, b: &Path) -> bool {
    if let (Some(ra), Some(rb)) = (resolved(a), resolved(b))
        && ra == rb
    {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    false
}

/// Checks, before any work, that no output of a command is an existing folder or special file
/// ([`check_replaceable`]), one of its inputs or another of its outputs (also through symbolic or hard links).
///
/// # Errors
/// [`Error::Output`] naming the path (and the other path).
pub fn check_outputs(inputs: &[&Path], outputs: &[&Path]) -> Result<()> {
    for (k, out) in outputs.iter().enumerate() {
        check_replaceable(out)?;
        if let Some(input) = inputs.iter().find(|i| same_file(out, i)) {
            return Err(Error::output_at(
                out,
                format!(
                    "this output would overwrite an input of the same command ({}); choose another name",
                    input.display()
                ),
            ));
        }
        if let Some(other) = outputs[..k].iter().find(|o| same_file(out, o)) {
            return Err(Error::output_at(
                out,
                format!("the same file is given for two outputs ({}); choose another name", other.display()),
            ));
        }
    }
    Ok(())
}

/// Checks, before any work, that each output's folder exists (jem makes no folder for a file it is told to write;
/// the commands that write into a folder of their own make it).
///
/// # Errors
/// [`Error::Io`] (not found, or not a folder) naming the output and the folder that is missing, or the file in its
/// place.
pub fn check_output_folders(outputs: &[&Path]) -> Result<()> {
    outputs.iter().find_map(|out| missing_folder(out)).map_or(Ok(()), Err)
}

/// The error for an output whose folder is missing or is not a folder (`None` when it is there).
fn missing_folder(path: &Path) -> Option<Error> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty())?;
    if parent.is_dir() {
        return None;
    }
    let (kind, why) = if parent.exists() {
        (std::io::ErrorKind::NotADirectory, "is not a folder")
    } else {
        (std::io::ErrorKind::NotFound, "does not exist (make it first)")
    };
    let reason = format!("cannot write it: the folder {} {why}", parent.display());
    Some(Error::io(path, std::io::Error::new(kind, reason)))
}

/// A depth map encoded in the format given by `path`'s extension: `.pfm` and `.exr` as floats (as
/// [`encode_disparity`]), `.png` as 16 bits in the baseline's unit rounded, 0 = invalid (nothing is written).
///
/// # Errors
/// An unknown extension, a depth a 16-bit PNG cannot hold (above 65535, or valid but rounding to 0), or an encoder
/// error, naming the path.
pub fn encode_depth(path: &Path, depth: &crate::image::Plane<f32>) -> Result<Vec<u8>> {
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Png16 => png::encode_depth_png16(path, depth),
        _ => encode_disparity(path, depth),
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

/// Reads a depth map as [`encode_depth`] writes it: a `.pfm` or `.exr` holds the depths themselves, a 16-bit `.png`
/// the depth in the baseline's unit, rounded (0 = invalid → inf; not the disparity PNG's × 256).
///
/// # Errors
/// A missing or malformed file, naming the path.
pub fn read_depth(path: &Path) -> Result<crate::image::Plane<f32>> {
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Png16 => png::read_depth_png16(path),
        _ => read_disparity(path),
    }
}

/// Opens a file for reading when it is a regular file (through symbolic links), and refuses anything else before
/// a read can block or never end: a FIFO waits for a writer forever, `/dev/zero` has no end, a folder has no
/// bytes. The file is opened without blocking and checked again once open (it may have been replaced meanwhile).
///
/// # Errors
/// [`Error::Io`] naming the path when it cannot be opened, [`Error::InputFile`] naming it and what it is when it is not
/// a regular file.
pub fn open_regular(path: &Path) -> Result<std::fs::File> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    check_regular(path, &meta)?;
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(|e| Error::io(path, e))?;
    check_regular(path, &file.metadata().map_err(|e| Error::io(path, e))?)?;
    Ok(file)
}

/// Refuses a file that is not a regular one ([`open_regular`]).
fn check_regular(path: &Path, meta: &std::fs::Metadata) -> Result<()> {
    if meta.is_file() {
        return Ok(());
    }
    let what = if meta.is_dir() { "a folder" } else { file_kind(meta) };
    Err(Error::input_file_at(path, format!("is {what}, not a regular file; jem reads only regular files")))
}

/// A regular file's bytes ([`open_regular`]), all of them.
///
/// # Errors
/// As [`open_regular`], and [`Error::Io`] naming the path when it cannot be read.
pub fn read_regular(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let mut file = open_regular(path)?;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// A regular file's text ([`read_regular`]), at most `max` bytes of it ([`read_capped`]); `None` when it is
/// missing, not a regular file, too large or not UTF-8: for the small files jem writes beside its results and
/// reads back when they are there.
#[cfg(feature = "toolkit")]
pub(crate) fn read_small_text(path: &Path, max: u64) -> Option<String> {
    String::from_utf8(read_capped(path, max, "file").ok()?).ok()
}

/// Reads a whole file of at most `max` bytes (a config, a calib.txt, a PFM header): a device, a pipe or a huge
/// file given by mistake is refused ([`open_regular`]), and a file larger than `max` is refused after `max` + 1
/// bytes instead of filling the memory.
///
/// # Errors
/// [`Error::Io`] naming the path, or [`Error::InputFile`] when it is not a regular file or is larger than `max`.
pub fn read_capped(path: &Path, max: u64, what: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let file = open_regular(path)?;
    let mut bytes = Vec::new();
    file.take(max + 1).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(Error::input_file_at(path, format!("larger than {max} bytes, too large for a {what}")));
    }
    Ok(bytes)
}

/// Creates the folder `dir` and the folders above it that are missing, for outputs. A name that is taken by a file
/// is refused with what to do, instead of the system's "File exists" or "Not a directory".
///
/// # Errors
/// [`Error::Output`] naming `dir`, or the file above it that is in the way; [`Error::Io`] when it cannot be made.
pub fn create_folder(dir: &Path) -> Result<()> {
    check_folder_name(dir)?;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))
}

/// Checks that the folder `dir` exists or can be made: neither it nor a folder above it is a file
/// ([`create_folder`]'s refusals, without making anything).
///
/// # Errors
/// As [`create_folder`].
pub fn check_folder_name(dir: &Path) -> Result<()> {
    if dir.is_dir() {
        return Ok(());
    }
    if std::fs::symlink_metadata(dir).is_ok() {
        return Err(Error::output_at(dir, "exists and is not a folder; give the name of a folder (a new one is made)"));
    }
    if let Some(file) = dir.ancestors().skip(1).find(|a| !a.as_os_str().is_empty() && a.exists() && !a.is_dir()) {
        return Err(Error::output_at(
            file,
            format!("is a file, so the folder {} cannot be made in it; give another name", dir.display()),
        ));
    }
    Ok(())
}

/// The largest config file read.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// The largest calib.txt read.
pub const MAX_CALIB_BYTES: u64 = 64 << 10;

#[cfg(test)]
mod tests {
    use super::write::temp_path;
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
    fn outputs_must_not_be_inputs_or_each_other() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.png");
        std::fs::write(&input, b"x").unwrap();
        let link = dir.path().join("link.png");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let hard = dir.path().join("hard.png");
        std::fs::hard_link(&input, &hard).unwrap();
        let other = dir.path().join("out.pfm");
        assert!(check_outputs(&[&input], &[&other]).is_ok());
        let dotted = dir.path().join(".").join("in.png");
        for bad in [&input, &link, &hard, &dotted] {
            let e = check_outputs(&[&input], &[bad]).unwrap_err().to_string();
            assert!(e.contains("overwrite an input"), "{e}");
        }
        std::fs::create_dir(dir.path().join("x")).unwrap();
        let e = check_outputs(&[&input], &[&other, &dir.path().join("x/../out.pfm")]);
        assert!(e.is_err_and(|e| e.to_string().contains("two outputs")));
    }

    #[test]
    fn all_or_none_writes_nothing_when_one_fails() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.txt");
        std::fs::write(&a, b"old").unwrap();
        let blocked = dir.path().join("sub");
        std::fs::create_dir(&blocked).unwrap();
        let bad = blocked.join("missing").join("b.txt");
        assert!(write_all_or_none(&[(&a, b"new"), (&bad, b"b")]).is_err());
        assert_eq!(std::fs::read(&a).unwrap(), b"old", "the first file is untouched");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "no temporary file left: {names:?}");
        let b = dir.path().join("b.txt");
        write_all_or_none(&[(&a, b"new"), (&b, b"b")]).unwrap();
        assert_eq!((std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap()), (b"new".to_vec(), b"b".to_vec()));
    }

    /// A rename that fails (the last destination is a folder) undoes the ones before it: a new
    /// file is removed, a replaced one gets its old content back, and no hidden file is left.
    #[test]
    fn all_or_none_undoes_the_renames_when_one_fails() {
        let dir = tempfile::tempdir().unwrap();
        let (old, new, folder) = (dir.path().join("old.txt"), dir.path().join("new.txt"), dir.path().join("k.pfm"));
        std::fs::write(&old, b"old").unwrap();
        std::fs::create_dir(&folder).unwrap();
        let e = write_all_or_none(&[(&old, b"replaced"), (&new, b"n"), (&folder, b"k")]).unwrap_err();
        assert!(e.to_string().contains("k.pfm"), "{e}");
        assert_eq!(std::fs::read(&old).unwrap(), b"old", "the replaced file is restored");
        assert_eq!(files(dir.path()), ["k.pfm", "old.txt"], "the new file is removed, nothing hidden is left");
        assert!(check_outputs(&[], &[&new, &folder]).unwrap_err().to_string().contains("is a folder"));
    }

    /// A FIFO, a character device (a symbolic link to `/dev/null`, and a device node made with `mknod` where this
    /// process may) are refused by every writer and left as they are; no temporary file is left, and the other
    /// file of an all-or-none pair is not written.
    #[test]
    fn writing_refuses_a_device_node_or_a_fifo() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo.pfm");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let null = dir.path().join("null.pfm");
        std::os::unix::fs::symlink("/dev/null", &null).unwrap();
        let mut specials = vec![fifo, null];
        let node = dir.path().join("mynull.pfm");
        let made = std::process::Command::new("mknod").arg(&node).args(["c", "1", "3"]).output();
        if made.is_ok_and(|o| o.status.success()) {
            specials.push(node);
        }
        let regular = dir.path().join("ok.pfm");
        for special in &specials {
            for result in [
                write_atomic(special, b"x"),
                write_all_or_none(&[(&regular, b"r"), (special, b"x")]),
                check_outputs(&[], &[special]),
            ] {
                let e = result.unwrap_err().to_string();
                assert!(e.contains(&*special.to_string_lossy()) && e.contains("not a regular file"), "{e}");
            }
            let t = std::fs::metadata(special).unwrap().file_type();
            assert!(t.is_fifo() || t.is_char_device(), "{} left as it was", special.display());
        }
        assert!(std::fs::symlink_metadata(dir.path().join("null.pfm")).unwrap().file_type().is_symlink());
        let mut names = files(dir.path());
        names.retain(|n| n.starts_with('.') || n == "ok.pfm");
        assert!(names.is_empty(), "no temporary file, and the other file of the pair not written: {names:?}");
    }

    /// Every reader refuses what is not a regular file before reading: a FIFO (which would wait for a writer), a
    /// device without end (`/dev/zero`), a folder; through a symbolic link too.
    #[test]
    fn readers_refuse_fifos_devices_and_folders() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f.pfm");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let zero = dir.path().join("zero.png");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        for (path, kind) in [(&fifo, "a FIFO"), (&zero, "a character device"), (&dir.path().to_path_buf(), "a folder")]
        {
            let results = [
                read_capped(path, 100, "test").map(drop),
                read_regular(path).map(drop),
                pfm::read_pfm(path).map(drop),
                read_image(path).map(drop),
                read_image_header(path).map(drop),
            ];
            for r in results {
                let e = r.unwrap_err().to_string();
                assert!(e.contains(kind) && e.contains("not a regular file"), "{}: {e}", path.display());
            }
        }
    }

    /// A temporary file of a run of this machine that is gone (`kill -9`) is removed by the next sweep; a live
    /// run's, another machine's and other files are left.
    #[test]
    fn stale_temporary_files_of_dead_runs_are_swept() {
        let dir = tempfile::tempdir().unwrap();
        let host = crate::process::host_name();
        let dead = format!(".page.html.jem-tmp-{host}-4000000000-1-0");
        let live = format!(".page.html.jem-tmp-{host}-{}-1-0", std::process::id());
        let other = ".page.html.jem-tmp-elsewhere-4000000000-1-0".to_string();
        for name in [&dead, &live, &other, &"page.html".to_string()] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let ours = temp_path(&dir.path().join("page.html"));
        let name = ours.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.starts_with(&format!(".page.html.jem-tmp-{host}-{}-", std::process::id())), "{name}");
        sweep_stale_temps(dir.path());
        let mut want = vec![live, other, "page.html".to_string()];
        if !crate::process::proc_available() {
            want.push(dead);
        }
        want.sort();
        assert_eq!(files(dir.path()), want);
    }

    /// A folder name taken by a file, or under one, is refused with what to do (not the system's "File exists" or
    /// "Not a directory"); an existing folder is fine and a missing one is made.
    #[test]
    fn a_folder_is_made_unless_a_file_is_in_the_way() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f");
        std::fs::write(&file, b"x").unwrap();
        let e = create_folder(&file).unwrap_err().to_string();
        assert!(e.ends_with("f: exists and is not a folder; give the name of a folder (a new one is made)"), "{e}");
        let e = create_folder(&file.join("a/b")).unwrap_err().to_string();
        assert!(e.contains("f: is a file, so the folder") && e.contains("f/a/b cannot be made"), "{e}");
        create_folder(&dir.path().join("new/deep")).unwrap();
        create_folder(&dir.path().join("new/deep")).unwrap();
        assert!(dir.path().join("new/deep").is_dir() && check_folder_name(&dir.path().join("x/y")).is_ok());
    }

    /// The names in a folder, sorted.
    fn files(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        names
    }

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.txt");
        let r = write_atomic_with(&p, |_| Err(Error::argument("boom")));
        assert!(r.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    /// An output into a folder that is not there names that folder, before any work and when written.
    #[test]
    fn an_output_in_a_missing_folder_names_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("nodir").join("disp.pfm");
        let expected = format!("the folder {} does not exist", dir.path().join("nodir").display());
        let early = check_output_folders(&[&dir.path().join("fine.pfm"), &out]).unwrap_err();
        // An I/O error of its kind: Python raises FileNotFoundError for it.
        assert!(
            matches!(&early, Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound),
            "{early:?}"
        );
        let early = early.to_string();
        assert!(early.contains(&expected), "{early}");
        let late = write_atomic(&out, b"x").unwrap_err().to_string();
        assert!(late.contains(&expected), "{late}");
        std::fs::write(dir.path().join("file"), b"").unwrap();
        let under_a_file = check_output_folders(&[&dir.path().join("file").join("d.pfm")]).unwrap_err().to_string();
        assert!(under_a_file.contains("is not a folder"), "{under_a_file}");
        assert!(check_output_folders(&[Path::new("d.pfm"), &dir.path().join("d.pfm")]).is_ok());
    }
}
