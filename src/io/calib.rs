//! Middlebury `calib.txt`: `key=value` lines (`cam0=[...]`, `ndisp=290`, `vmin=..`, `vmax=..`, ...), parsed by key.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Error, Result};

/// The keys of a `calib.txt` file, with typed access to the ones jem uses.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Calib {
    entries: BTreeMap<String, String>,
}

impl Calib {
    /// Parses `key=value` lines; blank lines and `#` comments are skipped, surrounding whitespace is trimmed.
    ///
    /// # Errors
    /// A message for a non-empty line without `=` or with an empty key.
    pub fn parse(text: &str) -> std::result::Result<Calib, String> {
        let mut entries = BTreeMap::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let Some((k, v)) = line.split_once('=') else {
                return Err(format!("line {}: expected key=value, found {:?}", n + 1, truncate(line)));
            };
            let k = k.trim();
            if k.is_empty() {
                return Err(format!("line {}: empty key", n + 1));
            }
            entries.insert(k.to_string(), v.trim().to_string());
        }
        Ok(Calib { entries })
    }

    /// Reads and parses a `calib.txt` file.
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Calib`] naming the path.
    pub fn load(path: &Path) -> Result<Calib> {
        let bytes = super::read_capped(path, super::MAX_CALIB_BYTES, "calib.txt")?;
        let text = String::from_utf8(bytes)
            .map_err(|_| Error::Calib { path: path.to_path_buf(), msg: "not a text file".into() })?;
        // A UTF-8 byte-order mark (some Windows editors write one) is not part of the first key.
        let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
        Calib::parse(text).map_err(|msg| Error::Calib { path: path.to_path_buf(), msg })
    }

    /// The raw value of `key`.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries.get(key).map(String::as_str)
    }

    /// `ndisp` as a positive integer, if present and valid.
    ///
    /// # Errors
    /// A message when the key is missing or not a positive integer.
    pub fn ndisp(&self) -> std::result::Result<usize, String> {
        let v = self.get("ndisp").ok_or("no ndisp key")?;
        match v.parse::<usize>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(format!("ndisp = {:?} is not a positive integer", truncate(v))),
        }
    }

    /// `ndisp` if the file states one: `None` without the key (a calib.txt of geometry only, as `jem rectify`
    /// writes: the range is then measured), a positive integer when present.
    ///
    /// # Errors
    /// A message when the key is present but not a positive integer.
    pub fn stated_ndisp(&self) -> std::result::Result<Option<usize>, String> {
        match self.get("ndisp") {
            None => Ok(None),
            Some(_) => self.ndisp().map(Some),
        }
    }

    /// A finite float value of `key`, if present and parseable.
    pub fn float(&self, key: &str) -> Option<f32> {
        self.get(key).and_then(|v| v.parse::<f32>().ok()).filter(|v| v.is_finite())
    }
}

/// Reads `ndisp` from a `calib.txt`.
///
/// # Errors
/// [`Error::Io`] or [`Error::Calib`] naming the path.
pub fn read_ndisp(path: &Path) -> Result<usize> {
    Calib::load(path)?.ndisp().map_err(|msg| Error::Calib { path: path.to_path_buf(), msg })
}

fn truncate(s: &str) -> String {
    s.chars().take(40).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEDDY: &str = "cam0=[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]\ncam1=[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]\n\
                         doffs=0\nbaseline=178.089\nwidth=450\nheight=375\nndisp=64\nisint=0\nvmin=13\nvmax=52\n\
                         dyavg=0\ndymax=0\n";

    #[test]
    fn parses_middlebury_calib_by_key() {
        let c = Calib::parse(TEDDY).unwrap();
        assert_eq!(c.ndisp(), Ok(64));
        assert_eq!(c.float("vmin"), Some(13.0));
        assert_eq!(c.float("baseline"), Some(178.089));
        assert_eq!(c.get("cam0"), Some("[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]"));
    }

    #[test]
    fn order_whitespace_and_crlf_do_not_matter() {
        let c = Calib::parse("\r\n  vmax = 9 \r\n# note\nndisp= 32\r\n").unwrap();
        assert_eq!(c.ndisp(), Ok(32));
        assert_eq!(c.float("vmax"), Some(9.0));
    }

    #[test]
    fn bad_values_and_lines_are_errors() {
        assert!(Calib::parse("ndisp 64").is_err());
        assert!(Calib::parse("=3").is_err());
        for bad in ["ndisp=0", "ndisp=-3", "ndisp=abc", "ndisp=", "width=3"] {
            assert!(Calib::parse(bad).unwrap().ndisp().is_err(), "{bad}");
        }
        for bad in ["ndisp=0", "ndisp=-3", "ndisp=abc", "ndisp="] {
            assert!(Calib::parse(bad).unwrap().stated_ndisp().is_err(), "{bad}");
        }
        assert_eq!(Calib::parse("width=3").unwrap().stated_ndisp(), Ok(None));
        assert_eq!(Calib::parse("ndisp=64").unwrap().stated_ndisp(), Ok(Some(64)));
    }

    #[test]
    fn file_errors_name_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("calib.txt");
        std::fs::write(&p, "width=3\n").unwrap();
        let e = read_ndisp(&p).unwrap_err().to_string();
        assert!(e.contains("calib.txt") && e.contains("ndisp"), "{e}");
        std::fs::write(&p, [0xff, 0xfe, 0x00]).unwrap();
        assert!(read_ndisp(&p).is_err());
    }
}
