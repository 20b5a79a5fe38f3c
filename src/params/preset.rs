//! The shipped configs (`configs/*.toml`) built into the library as presets, so that a crate or a Python wheel,
//! which has no checkout beside it, can run them by name. Each is the file's text, parsed by the code that parses a
//! config file: a preset gives exactly the parameters that loading its file gives.

use std::path::Path;

use super::Params;
use crate::error::{Error, Result};

/// Each preset's name (its file's stem) and its file's text, in name order.
const PRESETS: [(&str, &str); 8] = [
    ("balanced", include_str!("../../configs/balanced.toml")),
    ("default", include_str!("../../configs/default.toml")),
    ("fast", include_str!("../../configs/fast.toml")),
    ("fcm-lrc", include_str!("../../configs/fcm-lrc.toml")),
    ("jem-all", include_str!("../../configs/jem-all.toml")),
    ("jem-lrc", include_str!("../../configs/jem-lrc.toml")),
    ("jem-sps", include_str!("../../configs/jem-sps.toml")),
    ("lcm-lrc", include_str!("../../configs/lcm-lrc.toml")),
];

impl Params {
    /// The names [`Params::preset`] takes: the stems of the shipped `configs/*.toml` (`"fast"`, `"balanced"`, ...),
    /// in name order.
    pub fn preset_names() -> Vec<&'static str> {
        PRESETS.iter().map(|&(name, _)| name).collect()
    }

    /// A shipped config by name, built in: `Params::preset("fast")` is what `Params::load` gives for
    /// `configs/fast.toml`, with no file read.
    ///
    /// ```
    /// let fast = jem::Params::preset("fast")?;
    /// assert_eq!(fast.downscale, 2);
    /// # Ok::<(), jem::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::InvalidParam`] for a name that is no preset, listing the valid names.
    pub fn preset(name: &str) -> Result<Params> {
        Self::preset_with(name, &[])
    }

    /// A preset with `key=value` overrides applied on top, as [`Params::load`] applies them to a file (as
    /// `--set` items).
    ///
    /// # Errors
    /// As [`Params::preset`], and as [`Params::load`] for a malformed override.
    pub fn preset_with(name: &str, overrides: &[String]) -> Result<Params> {
        let text = Self::preset_text(name).ok_or_else(|| {
            Error::param("preset", format!("{name:?}"), format!("one of {}", Self::preset_names().join(", ")))
        })?;
        // An error names the preset where a file's would name its path.
        Self::merged(Some((text, Path::new(&format!("preset {name}")))), overrides)
    }

    /// The TOML text of the preset `name` (its shipped file's), or `None` for a name that is no preset.
    fn preset_text(name: &str) -> Option<&'static str> {
        PRESETS.iter().find(|&&(n, _)| n == name).map(|&(_, text)| text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn configs_dir() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("configs")
    }

    /// Every file in configs/ is a preset and nothing else is: a config added there is reachable by name.
    #[test]
    fn the_presets_are_the_shipped_configs() {
        let mut stems: Vec<String> = std::fs::read_dir(configs_dir())
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
            .collect();
        stems.sort();
        assert_eq!(Params::preset_names(), stems);
    }

    /// A preset gives the parameters its file gives, with and without overrides.
    #[test]
    fn a_preset_is_its_file() {
        let set = ["model=lcm".to_string(), "post.fill=false".to_string()];
        for name in Params::preset_names() {
            let path = configs_dir().join(format!("{name}.toml"));
            let (file, preset) = (Params::load(Some(&path), &[]).unwrap(), Params::preset(name).unwrap());
            assert_eq!(file, preset, "{name}");
            assert_eq!(file.to_toml(), preset.to_toml(), "{name}");
            assert_eq!(Params::load(Some(&path), &set).unwrap(), Params::preset_with(name, &set).unwrap(), "{name}");
        }
    }

    #[test]
    fn an_unknown_preset_lists_the_names() {
        let msg = Params::preset("fastest").unwrap_err().to_string();
        assert!(msg.contains("\"fastest\"") && msg.contains("balanced, default, fast, fcm-lrc"), "{msg}");
        let msg = Params::preset_with("fast", &["meanfield.iterations=x".into()]).unwrap_err().to_string();
        assert!(msg.starts_with("preset fast + --set"), "{msg}");
    }
}
