//! Batch runs over data sets (what `jem batch` does).
//!
//! The pairs come from [`crate::dataset::discover`]: MiddEval3 scene folders (`im0.png`, `im1.png`,
//! `calib.txt`), KITTI 2012/2015 frames and ETH3D scenes, each with its layout. [`run_pair`] runs the pipeline on
//! one pair, with `ndisp` from `--ndisp`, else its `calib.txt`, else the layout's default (KITTI: 192), and a
//! range measured on the pair when none is given or the stated one is not a real bound (`crate::range`); it
//! writes, all or none, the disparity map and the run time (the seconds spent in the pipeline for that pair —
//! image loading and file writing are not counted) where the layout's submission form puts them
//! ([`crate::dataset::Pair::result_files`]: MiddEval3 `disp0<ALG>.pfm` and `time<ALG>.txt` in the scene folder;
//! KITTI and ETH3D in a results folder beside the data set), the configuration it ran with ([`config_record`]:
//! every parameter, the command and jem's version; [`crate::dataset::ResultFiles::config`]), so a result says how
//! it was made, and with [`BatchOptions::lr_mask`] where the left-right check rejected each pixel
//! ([`crate::dataset::Pair::lr_mask_file`], [`crate::io::encode_lr_mask`]).
//!
//! [`run_batch`] runs a list of pairs, `jobs` at a time (each pipeline is itself multi-threaded on the global
//! rayon pool). A failing pair — unreadable image, malformed calib, unequal sizes, or even a panic inside the
//! pipeline (caught with `catch_unwind`) — is reported in its [`SceneReport`] and the others still run.
//!
//! [`Shard`] splits a sorted list into N deterministic parts (item k goes to part `k mod N`), so a job array
//! (Slurm, GNU parallel) can process a data set with no coordination; `--skip-existing` makes reruns resume.
//! [`Eta`] estimates the time a batch has left from the pairs finished so far.

mod eta;
mod summary;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use crate::dataset::Pair;
use crate::error::{Error, Result};
use crate::io::calib;
use crate::matcher::{Matcher, Progress};
use crate::params::Params;
use crate::pipeline::Timings;
use crate::setup::NdispSource;
use crate::setup::memory::MemoryBudget;
pub use eta::{Eta, format_duration};
pub use summary::{one_line, summary};

/// Checks an algorithm name: 1–64 ASCII letters, digits, `_` or `-` (it becomes part of file names), and not
/// `GT` in any case: `disp0GT.pfm` is the dataset's ground truth, which a result must never overwrite (on a
/// case-insensitive file system `disp0gt.pfm` is the same file).
///
/// # Errors
/// [`Error::InvalidParam`] naming `--alg`.
pub fn validate_alg_name(name: &str) -> Result<()> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if !ok {
        return Err(Error::param("--alg", format!("{name:?}"), "1 to 64 letters, digits, _ or -"));
    }
    if name.eq_ignore_ascii_case("GT") {
        return Err(Error::param("--alg", format!("{name:?}"), "any name but GT (disp0GT.pfm is the ground truth)"));
    }
    Ok(())
}

/// Part `index` (1-based) of `count` of a list: the items whose 0-based position k has `k mod count ==
/// index − 1`. Over `index = 1..=count` every item lands in exactly one part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 1-based part number, 1 ≤ index ≤ count.
    pub index: usize,
    /// Number of parts, ≥ 1.
    pub count: usize,
}

impl Shard {
    /// The items of this part, in order.
    pub fn select<T: Clone>(&self, items: &[T]) -> Vec<T> {
        items.iter().skip(self.index - 1).step_by(self.count).cloned().collect()
    }
}

impl FromStr for Shard {
    type Err = Error;
    /// Parses `I/N` with 1 ≤ I ≤ N.
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        let bad = || Error::argument(format!("invalid shard {s:?} (expected I/N with 1 <= I <= N, e.g. 3/8)"));
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) =
            (i.trim().parse::<usize>().map_err(|_| bad())?, n.trim().parse::<usize>().map_err(|_| bad())?);
        if index == 0 || count == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

/// What one successful scene run measured.
#[derive(Clone, Debug)]
pub struct SceneRun {
    /// Image size (width, height).
    pub size: (usize, usize),
    /// Disparity search range used.
    pub ndisp: usize,
    /// Seconds spent in the pipeline (what `time<ALG>.txt` holds).
    pub seconds: f64,
    /// Per-stage times.
    pub timings: Timings,
    /// What the adaptive front end measured on the pair (`None` when conditioning is off).
    pub measured: Option<crate::pipeline::Measured>,
}

/// How a scene ended.
#[derive(Clone, Debug)]
pub enum SceneStatus {
    /// The pipeline ran and both files were written.
    Done(SceneRun),
    /// `--skip-existing` and a complete result was already there.
    Skipped,
    /// The error (or panic message), on one line.
    Failed(String),
}

/// One pair's outcome.
#[derive(Clone, Debug)]
pub struct SceneReport {
    /// Where the pair is: its scene folder, or a KITTI frame's left image.
    pub dir: PathBuf,
    /// Display name: the scene folder's name or the frame.
    pub name: String,
    /// What happened.
    pub status: SceneStatus,
}

/// Progress events from [`run_batch`]; `index` is the position in the scene list.
#[derive(Debug)]
pub enum Event<'a> {
    /// A scene is starting.
    Started {
        /// Position in the list.
        index: usize,
        /// Display name.
        name: &'a str,
    },
    /// A pipeline stage of that scene is starting.
    Stage {
        /// Position in the list.
        index: usize,
        /// Stage name (as `crate::run_observed` reports it).
        stage: &'a str,
    },
    /// A scene has finished (in any way).
    Finished {
        /// Position in the list.
        index: usize,
        /// Its outcome.
        report: &'a SceneReport,
    },
}

/// Options of [`run_batch`].
#[derive(Clone, Debug)]
pub struct BatchOptions {
    /// Algorithm name: it names the outputs ([`crate::dataset::Pair::result_files`]).
    pub alg: String,
    /// The results base of KITTI and ETH3D data sets (`None`: `results/` beside each data set).
    pub results: Option<PathBuf>,
    /// The search range for every pair, instead of its calib.txt, the layout's default or a measured one.
    pub ndisp: Option<usize>,
    /// Scenes processed at the same time (≥ 1).
    pub jobs: usize,
    /// Skip pairs whose result exists and is complete.
    pub skip_existing: bool,
    /// Also write where the left-right check rejected each pixel ([`crate::dataset::Pair::lr_mask_file`]).
    pub lr_mask: bool,
    /// Also write each pair's confidence map ([`crate::dataset::ResultFiles::confidence`]), which `jem eval` scores.
    pub confidence: bool,
    /// Memory limit of the whole batch (see `crate::check_memory`): concurrent scenes share it, a scene
    /// waits while the ones running hold too much of it, and one that needs more than all of it fails.
    pub max_memory_bytes: u64,
    /// The command that ran the batch, recorded with the configuration beside each result ([`config_record`]).
    pub command: String,
}

/// The configuration recorded beside each result: jem's version and the command as comments, then every
/// parameter (defaults included) as TOML, which `jem --config` reads back to run the same again.
pub fn config_record(params: &Params, command: &str) -> String {
    format!(
        "# The configuration this result was made with (jem --config reads it back).\n# jem {}\n# command: {}\n{}",
        env!("CARGO_PKG_VERSION"),
        one_line(command),
        params.to_toml()
    )
}

/// The display name of a scene folder.
pub fn scene_name(dir: &Path) -> String {
    dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// Runs the pipeline on one pair and writes its result and run time (see the module doc).
///
/// # Errors
/// Unreadable images, a missing or malformed `calib.txt`, unequal sizes, invalid parameters, a result the
/// output format cannot hold, or a failed write. (A panic is not caught here; [`run_batch`] catches it.)
pub fn run_pair(pair: &Pair, params: &Params, opts: &BatchOptions, on_stage: &dyn Fn(&str)) -> Result<SceneRun> {
    let budget = Arc::new(MemoryBudget::new(opts.max_memory_bytes));
    run_pair_with(pair, &Matcher::new(params.clone())?.with_budget(budget), opts, on_stage)
}

/// [`run_pair`] with `matcher` (its range source is set here, per pair), whose memory budget the pairs running
/// beside it share.
fn run_pair_with(pair: &Pair, matcher: &Matcher, opts: &BatchOptions, on_stage: &dyn Fn(&str)) -> Result<SceneRun> {
    on_stage("loading");
    let files = pair.result_files(&opts.alg, opts.results.as_deref());
    let inputs: Vec<&Path> =
        [Some(pair.left.as_path()), Some(pair.right.as_path()), pair.calib.as_deref()].into_iter().flatten().collect();
    let lr_mask = opts.lr_mask.then(|| pair.lr_mask_file(&opts.alg, opts.results.as_deref()));
    let confidence_file = opts.confidence.then_some(files.confidence.as_path());
    let (disparity, time, config) = (files.disparity.as_path(), files.time.as_path(), files.config.as_path());
    let outputs: Vec<&Path> = [Some(disparity), Some(time), Some(config), lr_mask.as_deref(), confidence_file]
        .into_iter()
        .flatten()
        .collect();
    crate::io::check_outputs(&inputs, &outputs)?;
    let stated = match &pair.calib {
        Some(c) => Some(calib::read_ndisp(c)?),
        None => pair.default_ndisp(),
    };
    let mut matcher =
        matcher.clone().with_ndisp(NdispSource::resolve(opts.ndisp, stated)).with_confidence(opts.confidence);
    let out = matcher.match_files(&pair.left, &pair.right, &|progress| {
        if let Progress::Stage(stage) = progress {
            on_stage(stage);
        }
    })?;
    on_stage("writing");
    let disparity = crate::io::encode_disparity(&files.disparity, &out.disparity)?;
    let mask = match &lr_mask {
        Some(path) => Some((path.as_path(), crate::io::encode_lr_mask(path, &out.consistent)?)),
        None => None,
    };
    let confidence =
        opts.confidence.then(|| crate::io::encode_disparity(&files.confidence, out.confidence_map()?)).transpose()?;
    let mut written: Vec<(&Path, &[u8])> = vec![(&files.disparity, &disparity)];
    let time = pair.time_text(out.seconds);
    written.push((&files.time, time.as_bytes()));
    let config = config_record(matcher.params(), &opts.command);
    written.push((&files.config, config.as_bytes()));
    if let Some((path, bytes)) = &mask {
        written.push((path, bytes));
    }
    if let Some(c) = &confidence {
        written.push((files.confidence.as_path(), c.as_slice()));
    }
    for dir in written.iter().filter_map(|(p, _)| p.parent()) {
        if !dir.as_os_str().is_empty() {
            crate::io::create_folder(dir)?;
        }
    }
    crate::io::write_all_or_none(&written)?;
    let size = out.disparity.dims();
    Ok(SceneRun { size, ndisp: out.plan.ndisp, seconds: out.seconds, timings: out.timings, measured: out.measured })
}

/// The text of a panic payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".into()
    }
}

/// Runs (or skips) one pair, turning errors and panics into a [`SceneStatus`].
fn process(pair: &Pair, matcher: &Matcher, opts: &BatchOptions, on_stage: &dyn Fn(&str)) -> SceneStatus {
    if opts.skip_existing && has_complete_result(pair, opts) {
        return SceneStatus::Skipped;
    }
    guarded(|| run_pair_with(pair, matcher, opts, on_stage))
}

/// Whether the pair's result is there and finished: a file that parses as a disparity map of the pair's image
/// size (an empty, truncated or foreign file, or a folder of that name, is not a result; the pair runs again), and
/// with `--confidence` its confidence map beside it.
fn has_complete_result(pair: &Pair, opts: &BatchOptions) -> bool {
    let files = pair.result_files(&opts.alg, opts.results.as_deref());
    if opts.confidence && !files.confidence.is_file() {
        return false;
    }
    let Ok(result) = crate::io::read_disparity(&files.disparity) else { return false };
    let size = image::image_dimensions(&pair.left).ok();
    size.is_some_and(|(w, h)| (w as usize, h as usize) == result.dims())
}

/// Runs `f`, turning an error or a panic into [`SceneStatus::Failed`].
fn guarded(f: impl FnOnce() -> Result<SceneRun>) -> SceneStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(run)) => SceneStatus::Done(run),
        Ok(Err(e)) => SceneStatus::Failed(e.chain()),
        Err(payload) => SceneStatus::Failed(format!("panic in the pipeline: {}", panic_message(payload.as_ref()))),
    }
}

/// Runs every scene, `opts.jobs` at a time, and returns one report per scene in list order. `on_event` is
/// called from the worker threads (so it must be `Sync`); events of one scene arrive in order.
///
/// Panics inside the pipeline are caught and reported; note that the process's panic hook still runs (the
/// `jem` binary installs a quiet one).
pub fn run_batch(
    scenes: &[Pair],
    params: &Params,
    opts: &BatchOptions,
    on_event: &(dyn Fn(Event<'_>) + Sync),
) -> Vec<SceneReport> {
    let slots: Mutex<Vec<Option<SceneReport>>> = Mutex::new(vec![None; scenes.len()]);
    let next = AtomicUsize::new(0);
    let matcher = match Matcher::new(params.clone()) {
        Ok(m) => m.with_budget(Arc::new(MemoryBudget::new(opts.max_memory_bytes))),
        Err(e) => {
            let failed = |pair: &Pair| SceneReport {
                dir: pair.location(),
                name: pair.name.clone(),
                status: SceneStatus::Failed(e.chain()),
            };
            return scenes.iter().map(failed).collect();
        }
    };
    let worker = || {
        loop {
            let index = next.fetch_add(1, Ordering::Relaxed);
            let Some(pair) = scenes.get(index) else { break };
            let name = pair.name.clone();
            on_event(Event::Started { index, name: &name });
            let status = process(pair, &matcher, opts, &|stage| on_event(Event::Stage { index, stage }));
            let report = SceneReport { dir: pair.location(), name, status };
            on_event(Event::Finished { index, report: &report });
            if let Ok(mut s) = slots.lock() {
                s[index] = Some(report);
            }
        }
    };
    let jobs = opts.jobs.clamp(1, scenes.len().max(1));
    if jobs == 1 {
        worker();
    } else {
        std::thread::scope(|scope| {
            for _ in 0..jobs {
                scope.spawn(worker);
            }
        });
    }
    let slots = slots.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner());
    slots
        .into_iter()
        .zip(scenes)
        .map(|(r, pair)| {
            r.unwrap_or_else(|| SceneReport {
                dir: pair.location(),
                name: pair.name.clone(),
                status: SceneStatus::Failed("not run (a worker thread stopped)".into()),
            })
        })
        .collect()
}

/// [`run_batch`] for the pairs of a batch that holds `lock` on their results: a MiddEval3 scene whose lock could
/// not be taken (it could not be read: [`crate::dataset::ResultsLock::refused`]) fails without running, reported
/// first; the others run. One report per scene, in list order.
pub fn run_batch_locked(
    scenes: &[Pair],
    lock: &crate::dataset::ResultsLock,
    params: &Params,
    opts: &BatchOptions,
    on_event: &(dyn Fn(Event<'_>) + Sync),
) -> Vec<SceneReport> {
    let refused: Vec<Option<&String>> = scenes
        .iter()
        .map(|p| {
            lock.refused().iter().find(|(dir, _)| p.layout == crate::dataset::Layout::Middlebury && *dir == p.root)
        })
        .map(|found| found.map(|(_, e)| e))
        .collect();
    let failed = |pair: &Pair, e: &str| SceneReport {
        dir: pair.location(),
        name: pair.name.clone(),
        status: SceneStatus::Failed(e.to_string()),
    };
    for (index, (pair, e)) in scenes.iter().zip(&refused).enumerate() {
        if let Some(e) = e {
            on_event(Event::Finished { index, report: &failed(pair, e) });
        }
    }
    let (positions, runnable): (Vec<usize>, Vec<Pair>) = scenes
        .iter()
        .zip(&refused)
        .enumerate()
        .filter(|(_, (_, e))| e.is_none())
        .map(|(k, (p, _))| (k, p.clone()))
        .unzip();
    // The events of the pairs that run carry their place in `scenes`.
    let forward = |event: Event<'_>| {
        on_event(match event {
            Event::Started { index, name } => Event::Started { index: positions[index], name },
            Event::Stage { index, stage } => Event::Stage { index: positions[index], stage },
            Event::Finished { index, report } => Event::Finished { index: positions[index], report },
        })
    };
    let mut ran = run_batch(&runnable, params, opts, &forward).into_iter();
    scenes
        .iter()
        .zip(&refused)
        .map(|(pair, e)| match e {
            Some(e) => failed(pair, e),
            None => ran.next().unwrap_or_else(|| failed(pair, "not run")),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parse_and_partition() {
        assert_eq!("2/3".parse::<Shard>().ok(), Some(Shard { index: 2, count: 3 }));
        for bad in ["0/3", "4/3", "1/0", "3", "a/b", "1/2/3", ""] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
        let items: Vec<usize> = (0..10).collect();
        assert_eq!(Shard { index: 2, count: 3 }.select(&items), vec![1, 4, 7]);
        for n in 1..=12 {
            let mut all: Vec<usize> = (1..=n).flat_map(|i| Shard { index: i, count: n }.select(&items)).collect();
            all.sort();
            assert_eq!(all, items, "N = {n}");
        }
    }

    #[test]
    fn alg_names() {
        assert!(validate_alg_name("JEM_lrc-2").is_ok());
        assert!(validate_alg_name("GTx").is_ok());
        for gt in ["GT", "gt", "Gt"] {
            let e = validate_alg_name(gt).unwrap_err().to_string();
            assert!(e.contains("ground truth"), "{e}");
        }
        for bad in ["", "a/b", "a b", "..", "é"] {
            assert!(validate_alg_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn errors_and_panics_become_failures() {
        let p = catch_unwind(|| panic!("boom {}", 3)).unwrap_err();
        assert_eq!(panic_message(p.as_ref()), "boom 3");
        let failed = |s: SceneStatus| match s {
            SceneStatus::Failed(msg) => msg,
            other => panic!("expected a failure, got {other:?}"),
        };
        assert_eq!(failed(guarded(|| panic!("static"))), "panic in the pipeline: static");
        assert_eq!(failed(guarded(|| todo!("mean field"))), "panic in the pipeline: not yet implemented: mean field");
        assert_eq!(failed(guarded(|| Err(Error::argument("bad calib")))), "bad calib");
        let run = SceneRun { size: (2, 1), ndisp: 1, seconds: 0.5, timings: Timings::default(), measured: None };
        assert!(matches!(guarded(|| Ok(run)), SceneStatus::Done(r) if r.seconds == 0.5));
    }
}
