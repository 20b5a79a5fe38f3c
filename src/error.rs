//! The crate's one error type.
//!
//! Every variant carries enough context (a path, a key, a size) to print a one-line message that tells the user
//! what went wrong and where; the binary prints it as `error: ...` followed by each `source()` ([`Error::chain`]).

use std::fmt;
use std::path::{Path, PathBuf};

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in jem.
#[non_exhaustive]
#[derive(Debug)]
pub enum Error {
    /// A file could not be opened, read, written or renamed.
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// An image file could not be decoded or encoded.
    Image {
        /// The file concerned.
        path: PathBuf,
        /// The codec's error.
        source: image::ImageError,
    },
    /// An OpenEXR file could not be written or read.
    Exr {
        /// The file concerned.
        path: PathBuf,
        /// The codec's error.
        source: exr::error::Error,
    },
    /// A PFM file is malformed.
    Pfm {
        /// The file concerned (empty when decoding from memory).
        path: PathBuf,
        /// What is wrong with it.
        msg: String,
    },
    /// A calibration (`calib.txt`, or a camera file for rectification) is malformed, lacks a key, or states a
    /// camera no depth can be computed from.
    Calib {
        /// The file concerned (empty when parsing text, and then the message is shown alone).
        path: PathBuf,
        /// What is wrong with it.
        msg: String,
    },
    /// A TOML config file could not be parsed or does not match the schema.
    Toml {
        /// The file concerned (`<--set>` for command-line overrides).
        path: PathBuf,
        /// The parser's message.
        msg: String,
    },
    /// A parameter has a value outside its valid range.
    InvalidParam {
        /// Dotted key, e.g. `meanfield.iterations`.
        name: String,
        /// The offending value, as given.
        value: String,
        /// What would have been accepted.
        expected: String,
    },
    /// Left and right images have different sizes.
    SizeMismatch {
        /// Left image (width, height).
        left: (usize, usize),
        /// Right image (width, height).
        right: (usize, usize),
    },
    /// A run would need more memory than allowed.
    OutOfMemory {
        /// Bytes the run is estimated to need.
        needed: u64,
        /// Bytes allowed (`--max-memory`).
        limit: u64,
        /// What the user can do about it.
        hint: String,
    },
    /// An input image (or an image-sized array, or a disparity map read back) jem cannot use: an unsupported
    /// format, samples out of range, empty or too narrow for a pair, or of another size than it must be.
    InputImage {
        /// The file concerned, when there is one; the message follows it and `: `.
        path: Option<PathBuf>,
        /// What is wrong with it.
        msg: String,
    },
    /// An input file jem will not read: not a regular file, too large for what it should hold, or not text.
    InputFile {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong with it.
        msg: String,
    },
    /// A configuration jem cannot use: a config file that is not text, a preset, or settings of the command
    /// line that contradict the file.
    Config {
        /// The config file, when one is concerned; the message follows it and `: `.
        path: Option<PathBuf>,
        /// What is wrong with it.
        msg: String,
    },
    /// A data set, scene, sequence or results folder is not laid out as jem expects: files missing, a folder of
    /// another data set or run, or nothing to work on.
    Dataset {
        /// The folder or file concerned, when the message starts with it; the message follows it and `: `.
        path: Option<PathBuf>,
        /// What is wrong.
        msg: String,
    },
    /// Another run is writing into a results folder (its lock names it), or a lock cannot be read.
    Locked {
        /// The folder or lock file the message starts with; the message follows it and `: `.
        path: PathBuf,
        /// Who holds it, or why the lock cannot be read, and what to do.
        msg: String,
    },
    /// An output jem will not write: a destination that is a folder or not a regular file, that would replace
    /// an input or a folder of another run, above the file-size limit, or a value the format cannot hold.
    Output {
        /// The destination; the message follows it and `: `.
        path: PathBuf,
        /// Why it is refused.
        msg: String,
    },
    /// Arguments (command-line options or a call's arguments) that are missing, contradict each other, or do
    /// not parse.
    Argument {
        /// What is wrong and what to give instead.
        msg: String,
    },
    /// A frame of a sequence failed (its error is the source).
    Frame {
        /// The frame's stem.
        stem: String,
        /// What went wrong.
        source: Box<Error>,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, source } => write!(f, "{}: {}", path.display(), io_reason(source)),
            Error::Image { path, .. } => write!(f, "{}: image codec error", path.display()),
            Error::Exr { path, .. } => write!(f, "{}: OpenEXR error", path.display()),
            Error::Pfm { path, msg } => write!(f, "{}: invalid PFM: {msg}", path.display()),
            Error::Calib { path, msg } if path.as_os_str().is_empty() => f.write_str(msg),
            Error::Calib { path, msg } => write!(f, "{}: {msg}", path.display()),
            Error::Toml { path, msg } => write!(f, "{}: {}", path.display(), msg.trim_end()),
            Error::InvalidParam { name, value, expected } => {
                write!(f, "invalid {name} = {value} (expected {expected})")
            }
            Error::SizeMismatch { left, right } => write!(
                f,
                "left image is {}x{} but right image is {}x{}; a rectified pair must have equal sizes",
                left.0, left.1, right.0, right.1
            ),
            Error::OutOfMemory { needed, limit, hint } => write!(
                f,
                "this run needs about {} but the memory limit is {}; {hint}",
                human_bytes(*needed),
                human_bytes(*limit)
            ),
            Error::InputImage { path, msg } | Error::Config { path, msg } | Error::Dataset { path, msg } => {
                match path {
                    Some(path) => write!(f, "{}: {msg}", path.display()),
                    None => f.write_str(msg),
                }
            }
            Error::InputFile { path, msg } | Error::Locked { path, msg } | Error::Output { path, msg } => {
                write!(f, "{}: {msg}", path.display())
            }
            Error::Argument { msg } => f.write_str(msg),
            Error::Frame { stem, .. } => write!(f, "frame {stem}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            Error::Image { source, .. } => Some(source),
            Error::Exr { source, .. } => Some(source),
            Error::Frame { source, .. } => Some(source.as_ref()),
            _ => None,
        }
    }
}

impl Error {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }

    /// An [`Error::InvalidParam`] from displayable parts.
    pub fn param(name: &str, value: impl fmt::Display, expected: impl Into<String>) -> Self {
        Error::InvalidParam { name: name.to_string(), value: value.to_string(), expected: expected.into() }
    }

    /// The message and each cause's, joined by `: ` (what the binary prints after `error: `). The causes of an
    /// [`Error::Io`] are left out: its message already states the operating system's reason.
    pub fn chain(&self) -> String {
        let mut msg = self.to_string();
        let mut cause: &(dyn std::error::Error + 'static) = self;
        while !matches!(cause.downcast_ref::<Error>(), Some(Error::Io { .. }))
            && let Some(next) = cause.source()
        {
            msg.push_str(": ");
            msg.push_str(&next.to_string());
            cause = next;
        }
        msg
    }

    /// An [`Error::InputImage`] without a file.
    pub fn bad_image(msg: impl Into<String>) -> Self {
        Error::InputImage { path: None, msg: msg.into() }
    }

    /// An [`Error::InputImage`] naming `path`.
    pub fn bad_image_at(path: &Path, msg: impl Into<String>) -> Self {
        Error::InputImage { path: Some(path.to_path_buf()), msg: msg.into() }
    }

    /// An [`Error::InputFile`].
    pub fn input_file_at(path: &Path, msg: impl Into<String>) -> Self {
        Error::InputFile { path: path.to_path_buf(), msg: msg.into() }
    }

    /// An [`Error::Config`] naming `path`.
    pub fn config_at(path: &Path, msg: impl Into<String>) -> Self {
        Error::Config { path: Some(path.to_path_buf()), msg: msg.into() }
    }

    /// An [`Error::Dataset`] whose message names its paths itself.
    pub fn dataset(msg: impl Into<String>) -> Self {
        Error::Dataset { path: None, msg: msg.into() }
    }

    /// An [`Error::Dataset`] naming `path`.
    pub fn dataset_at(path: &Path, msg: impl Into<String>) -> Self {
        Error::Dataset { path: Some(path.to_path_buf()), msg: msg.into() }
    }

    /// An [`Error::Locked`].
    pub fn locked_at(path: &Path, msg: impl Into<String>) -> Self {
        Error::Locked { path: path.to_path_buf(), msg: msg.into() }
    }

    /// An [`Error::Output`].
    pub fn output_at(path: &Path, msg: impl Into<String>) -> Self {
        Error::Output { path: path.to_path_buf(), msg: msg.into() }
    }

    /// An [`Error::Argument`].
    pub fn argument(msg: impl Into<String>) -> Self {
        Error::Argument { msg: msg.into() }
    }
}

/// Formats a byte count as `12.3 MiB`.
pub(crate) fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 { format!("{bytes} B") } else { format!("{value:.1} {}", UNITS[unit]) }
}

/// The I/O error's message without the "(os error N)" suffix.
fn io_reason(e: &std::io::Error) -> String {
    let s = e.to_string();
    match s.find(" (os error") {
        Some(i) => s[..i].to_string(),
        None => s,
    }
}

#[cfg(test)]
mod tests {
    use std::error::Error as _;

    use super::*;

    fn io_error() -> Error {
        Error::io("a/b.png", std::io::Error::from(std::io::ErrorKind::NotFound))
    }

    #[test]
    fn each_variant_displays_its_message_and_names_its_path() {
        let p = || PathBuf::from("d/f");
        let cases = [
            (io_error(), "a/b.png: entity not found"),
            (Error::Pfm { path: p(), msg: "bad header".into() }, "d/f: invalid PFM: bad header"),
            (Error::Calib { path: p(), msg: "no ndisp key".into() }, "d/f: no ndisp key"),
            (Error::Calib { path: PathBuf::new(), msg: "line 1: empty key".into() }, "line 1: empty key"),
            (Error::Toml { path: p(), msg: "bad\n".into() }, "d/f: bad"),
            (Error::param("x.y", 3, "1 or 2"), "invalid x.y = 3 (expected 1 or 2)"),
            (Error::bad_image("the images are empty"), "the images are empty"),
            (Error::bad_image_at(&p(), "16-bit?"), "d/f: 16-bit?"),
            (Error::input_file_at(&p(), "is a folder"), "d/f: is a folder"),
            (Error::config_at(&p(), "not UTF-8"), "d/f: not UTF-8"),
            (Error::Config { path: None, msg: "preset".into() }, "preset"),
            (Error::dataset("no scene under d"), "no scene under d"),
            (Error::dataset_at(&p(), "no frames"), "d/f: no frames"),
            (Error::locked_at(&p(), "run 12 holds it"), "d/f: run 12 holds it"),
            (Error::output_at(&p(), "is a folder"), "d/f: is a folder"),
            (Error::argument("--a needs --b"), "--a needs --b"),
            (
                Error::SizeMismatch { left: (2, 1), right: (3, 1) },
                "left image is 2x1 but right image is 3x1; a rectified pair must have equal sizes",
            ),
            (
                Error::OutOfMemory { needed: 2048, limit: 1024, hint: "tile".into() },
                "this run needs about 2.0 KiB but the memory limit is 1.0 KiB; tile",
            ),
            (Error::Frame { stem: "0001".into(), source: Box::new(Error::argument("x")) }, "frame 0001"),
        ];
        for (e, want) in cases {
            assert_eq!(e.to_string(), want, "{e:?}");
        }
    }

    #[test]
    fn io_exposes_its_source() {
        let e = io_error();
        let source = e.source().expect("an I/O error has its source");
        let io = source.downcast_ref::<std::io::Error>().expect("the source is the io::Error");
        assert_eq!(io.kind(), std::io::ErrorKind::NotFound);
    }

    #[test]
    fn only_wrapping_variants_have_a_source() {
        let frame = Error::Frame { stem: "7".into(), source: Box::new(Error::argument("inner")) };
        assert_eq!(frame.source().map(|s| s.to_string()).as_deref(), Some("inner"));
        for e in [
            Error::bad_image("m"),
            Error::input_file_at(Path::new("f"), "m"),
            Error::config_at(Path::new("f"), "m"),
            Error::dataset("m"),
            Error::locked_at(Path::new("f"), "m"),
            Error::output_at(Path::new("f"), "m"),
            Error::argument("m"),
            Error::Calib { path: PathBuf::new(), msg: "m".into() },
        ] {
            assert!(e.source().is_none(), "{e:?}");
        }
    }

    #[test]
    fn the_chain_leaves_out_what_an_io_message_states() {
        // The message already holds the reason: printing the source again would repeat it.
        assert_eq!(io_error().chain(), "a/b.png: entity not found");
        let frame = Error::Frame { stem: "7".into(), source: Box::new(io_error()) };
        assert_eq!(frame.chain(), "frame 7: a/b.png: entity not found");
        let nested = Error::Frame { stem: "8".into(), source: Box::new(Error::argument("bad")) };
        assert_eq!(nested.chain(), "frame 8: bad");
    }
}
