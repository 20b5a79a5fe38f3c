//! The crate's one error type.
//!
//! Every variant carries enough context (a path, a key, a size) to print a one-line message that tells the user
//! what went wrong and where; the binary prints it as `error: ...` followed by each `source()`.

use std::fmt;
use std::path::PathBuf;

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
    /// A `calib.txt` file is malformed or lacks a key.
    Calib {
        /// The file concerned.
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
    /// Any other invalid input, with a message.
    Input(String),
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
            Error::Input(msg) => f.write_str(msg),
            Error::Frame { stem, .. } => write!(f, "frame {stem}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
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
