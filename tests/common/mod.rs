//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `jem` binary under test.
pub fn jem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jem"))
}

/// Runs `jem` with `args` in `dir`.
pub fn run_in(dir: &Path, args: &[&str]) -> Output {
    jem().current_dir(dir).args(args).output().expect("cannot start the jem binary")
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Middlebury data folder (holding `MiddEval3/`), from `JEM_DATA` or `../shared/middlebury`.
///
/// Returns `None` with a printed notice when it is absent, so a fresh clone without the data still passes;
/// with `JEM_REQUIRE_DATA=1` (set by `.ci/run`) absence is a test failure instead.
pub fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("JEM_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("..").join("shared").join("middlebury"));
    if dir.join("MiddEval3").join("trainingQ").is_dir() {
        return Some(dir);
    }
    if std::env::var_os("JEM_REQUIRE_DATA").is_some_and(|v| v == "1") {
        panic!("Middlebury data not found at {} (JEM_DATA) but JEM_REQUIRE_DATA=1", dir.display());
    }
    eprintln!("note: skipping: Middlebury data not found at {} (set JEM_DATA)", dir.display());
    None
}

/// The trainingQ scene folders, sorted.
pub fn training_scenes(data: &Path) -> Vec<PathBuf> {
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(data.join("MiddEval3").join("trainingQ"))
        .expect("cannot list trainingQ")
        .map(|e| e.expect("cannot read trainingQ entry").path())
        .filter(|p| p.join("im0.png").is_file())
        .collect();
    scenes.sort();
    scenes
}

/// Lists a folder's file names, sorted.
pub fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    names
}

/// stderr as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A pair of views with its search range, matched through the public API.
#[derive(Clone, Debug)]
pub struct Pair {
    pub left: jem::RgbImage,
    pub right: jem::RgbImage,
    pub ndisp: usize,
}

impl Pair {
    pub fn new(left: jem::RgbImage, right: jem::RgbImage, ndisp: usize) -> Pair {
        Pair { left, right, ndisp }
    }

    /// The pair matched with `params` and its own range, as `jem --ndisp N` would.
    pub fn run(&self, params: &jem::Params) -> jem::Output {
        let matcher = jem::Matcher::new(params.clone()).expect("valid parameters");
        let mut matcher = matcher.with_ndisp(jem::NdispSource::Given(self.ndisp));
        matcher.match_pair(&self.left, &self.right).expect("the pair matches")
    }
}
