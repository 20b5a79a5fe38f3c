//! Middlebury `calib.txt`: `key=value` lines (`cam0=[...]`, `ndisp=290`, `vmin=..`, `vmax=..`, ...), parsed by key.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The keys of a `calib.txt` file, with typed access to the ones jem uses.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Calib {
    entries: BTreeMap<String, String>,
    /// The file it was read from (empty when parsed from text): its errors name it.
    path: PathBuf,
}

impl Calib {
    /// Parses `key=value` lines; blank lines and `#` comments are skipped, surrounding whitespace is trimmed.
    ///
    /// # Errors
    /// [`Error::Calib`] (without a path) for a non-empty line without `=` or with an empty key.
    pub fn parse(text: &str) -> Result<Calib> {
        let entries = parse_entries(text).map_err(|msg| Error::Calib { path: PathBuf::new(), msg })?;
        Ok(Calib { entries, path: PathBuf::new() })
    }

    /// An [`Error::Calib`] naming the file the keys were read from.
    fn error(&self, msg: impl Into<String>) -> Error {
        Error::Calib { path: self.path.clone(), msg: msg.into() }
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
        let entries = parse_entries(text).map_err(|msg| Error::Calib { path: path.to_path_buf(), msg })?;
        Ok(Calib { entries, path: path.to_path_buf() })
    }

    /// The raw value of `key`.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries.get(key).map(String::as_str)
    }

    /// `ndisp` as a positive integer, if present and valid.
    ///
    /// # Errors
    /// [`Error::Calib`] naming the file (when it was read from one) when the key is missing or not a positive
    /// integer.
    pub fn ndisp(&self) -> Result<usize> {
        let v = self.get("ndisp").ok_or_else(|| self.error("no ndisp key"))?;
        match v.parse::<usize>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(self.error(format!("ndisp = {:?} is not a positive integer", truncate(v)))),
        }
    }

    /// `ndisp` if the file states one: `None` without the key (a calib.txt of geometry only, as `jem rectify`
    /// writes: the range is then measured), a positive integer when present.
    ///
    /// # Errors
    /// As [`Calib::ndisp`] when the key is present but not a positive integer.
    pub fn stated_ndisp(&self) -> Result<Option<usize>> {
        match self.get("ndisp") {
            None => Ok(None),
            Some(_) => self.ndisp().map(Some),
        }
    }

    /// The search `jem --min-disp calib` takes from the file: the smallest disparity, `vmin` rounded down, and,
    /// when the file states `ndisp` (the range 0..ndisp−1), the number of disparities that keeps its top:
    /// `ndisp − min_disp` (`None`: no ndisp, the range is measured from `min_disp` up).
    ///
    /// Safe as a lower bound: MiddEval3's `vmin` lies below every true disparity of its scenes (by 1–5 px on
    /// trainingQ), and the top stays the file's conservative `ndisp`, so the range only narrows from below. Only on
    /// request: MiddEval3 states `vmin` for colour maps and bars algorithms from using it, so a benchmark run (and
    /// every default) ignores it.
    ///
    /// # Errors
    /// [`Error::Calib`] as [`Calib::ndisp`] when `vmin` is missing, not a number of 0 or more, or not below `ndisp`.
    pub fn vmin_search(&self) -> Result<(usize, Option<usize>)> {
        let raw = self.get("vmin");
        let raw =
            raw.ok_or_else(|| self.error("states no vmin (--min-disp calib takes the smallest disparity from it)"))?;
        let vmin = raw.parse::<f64>().ok().filter(|v| v.is_finite() && *v >= 0.0 && *v < 1e9);
        let vmin =
            vmin.ok_or_else(|| self.error(format!("vmin = {:?} is not a disparity of 0 or more", truncate(raw))))?;
        let min_disp = vmin.floor() as usize;
        match self.stated_ndisp()? {
            Some(n) if min_disp >= n => {
                Err(self.error(format!("vmin = {raw} is not below ndisp = {n}: no range is left")))
            }
            Some(n) => Ok((min_disp, Some(n - min_disp))),
            None => Ok((min_disp, None)),
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
    Calib::load(path)?.ndisp()
}

/// The `key=value` entries of the text.
fn parse_entries(text: &str) -> std::result::Result<BTreeMap<String, String>, String> {
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
    Ok(entries)
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
        assert_eq!(c.ndisp().unwrap(), 64);
        assert_eq!(c.float("vmin"), Some(13.0));
        assert_eq!(c.float("baseline"), Some(178.089));
        assert_eq!(c.get("cam0"), Some("[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]"));
    }

    /// `--min-disp calib`: vmin rounded down, the top of the range kept at ndisp − 1.
    #[test]
    fn the_search_from_vmin_keeps_the_top_of_the_range() {
        assert_eq!(Calib::parse(TEDDY).unwrap().vmin_search().ok(), Some((13, Some(51))));
        assert_eq!(Calib::parse("vmin=7.9\nndisp=70").unwrap().vmin_search().ok(), Some((7, Some(63))));
        assert_eq!(Calib::parse("vmin=0\nwidth=3").unwrap().vmin_search().ok(), Some((0, None)));
        for (bad, why) in [
            ("ndisp=64", "states no vmin"),
            ("vmin=-2\nndisp=64", "not a disparity"),
            ("vmin=nan\nndisp=64", "not a disparity"),
            ("vmin=64\nndisp=64", "not below ndisp"),
            ("vmin=3\nndisp=x", "not a positive integer"),
        ] {
            let e = Calib::parse(bad).unwrap().vmin_search().unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn order_whitespace_and_crlf_do_not_matter() {
        let c = Calib::parse("\r\n  vmax = 9 \r\n# note\nndisp= 32\r\n").unwrap();
        assert_eq!(c.ndisp().unwrap(), 32);
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
        assert_eq!(Calib::parse("width=3").unwrap().stated_ndisp().ok(), Some(None));
        assert_eq!(Calib::parse("ndisp=64").unwrap().stated_ndisp().ok(), Some(Some(64)));
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
