//! `jem batch`: runs the pipeline on every scene folder under DIR... with [`jem::batch::run_batch`], shows
//! progress while scenes run ([`BatchDisplay`]) and prints a summary table at the end.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use jem::batch::one_line;
use jem::{Error, Result};

use super::config::ConfigArgs;
use super::{GlobalArgs, MemoryArg, ThreadsArg};

/// Arguments of `jem batch` (the help text is on [`Command::Batch`](super::Command::Batch)).
#[derive(Args, Debug, Clone)]
pub(super) struct BatchArgs {
    /// Folders to search, recursively, for data sets: MiddEval3 scene folders, KITTI 2012/2015 trees (image_2/ +
    /// image_3/, colored_0/ + colored_1/, image_0/ + image_1/), ETH3D two_view_* trees.
    #[arg(required = true, value_name = "DIR")]
    dirs: Vec<PathBuf>,
    /// Algorithm name (letters, digits, _ and - only): MiddEval3 results are disp0NAME.pfm and timeNAME.txt in
    /// each scene; KITTI and ETH3D results go to RESULTS/NAME/SPLIT/, SPLIT the data set's folder name (KITTI
    /// disp_0/FRAME.png, ETH3D low_res_two_view/SCENE.pfm + SCENE.txt).
    #[arg(long, value_name = "NAME")]
    alg: String,
    /// Where KITTI and ETH3D results go: RESULTS/NAME/SPLIT/ (default: the folder results/ beside each data set,
    /// e.g. kitti/results/ for kitti/training/). Never inside a data set.
    #[arg(long, value_name = "RESULTS")]
    results: Option<PathBuf>,
    /// Read the scenes as this layout (middlebury, eth3d, kitti2012, kitti2015) instead of recognising it; only
    /// needed to tell an ETH3D tree from MiddEval3 scenes when its folder is not named two_view_*.
    #[arg(long, value_name = "LAYOUT")]
    layout: Option<jem::dataset::Layout>,
    /// Search range 0..N-1 for every pair, instead of calib.txt (or KITTI's 192, or one measured on the pair).
    #[arg(long, value_name = "N")]
    ndisp: Option<usize>,
    #[command(flatten)]
    config: ConfigArgs,
    /// Scenes processed at the same time (each run is multi-threaded already; more jobs need more memory).
    #[arg(long, short = 'j', value_name = "N", default_value_t = 1)]
    jobs: usize,
    /// Process only part I of N (1-based) of the sorted scene list: scene k (0-based) belongs to part
    /// k mod N + 1. Over I = 1..N every scene is processed exactly once, e.g. one part per job of a job array.
    #[arg(long, value_name = "I/N")]
    shard: Option<jem::batch::Shard>,
    /// Skip pairs whose result is already there and complete (to resume an interrupted run).
    #[arg(long)]
    skip_existing: bool,
    /// Also write where the left-right check rejected each pixel, before fill, weighted median and planes changed
    /// its value (8-bit grey PNG, 255 = rejected, 0 = passed; the disparity map is the same without it): MiddEval3
    /// lrmask0NAME.png beside disp0NAME.pfm (what `jem eval --regions` reads), KITTI RESULTS/NAME/SPLIT/lrmask_0/,
    /// ETH3D RESULTS/NAME/SPLIT/lrmask/.
    #[arg(long)]
    lr_mask: bool,
    /// Also write each pair's confidence map (0..1, PFM; ranks the errors, see `jem eval`): MiddEval3
    /// conf0NAME.pfm beside disp0NAME.pfm, KITTI RESULTS/NAME/SPLIT/conf_0/FRAME.pfm, ETH3D .../confidence/SCENE.pfm.
    #[arg(long)]
    confidence: bool,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
    #[command(flatten)]
    memory: MemoryArg,
}

/// What the batch display shows while scenes run.
struct BatchDisplay {
    /// The run's parameters, for the warnings about values too large for a scene's image.
    params: jem::Params,
    bar: Option<indicatif::ProgressBar>,
    quiet: bool,
    total: usize,
    /// Scenes run at once, for the time left.
    jobs: usize,
    done: std::sync::atomic::AtomicUsize,
    eta: std::sync::Mutex<jem::batch::Eta>,
    active: std::sync::Mutex<std::collections::BTreeMap<usize, (String, String)>>,
}

impl BatchDisplay {
    fn new(total: usize, jobs: usize, quiet: bool, params: jem::Params) -> Self {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let style = indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] [{bar:30}] {pos}/{len} scenes{prefix}  {wide_msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> ");
            let bar = indicatif::ProgressBar::new(total as u64).with_style(style);
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            bar
        });
        BatchDisplay {
            params,
            bar,
            quiet,
            total,
            jobs,
            done: 0.into(),
            eta: Default::default(),
            active: Default::default(),
        }
    }

    fn line(&self, msg: &str) {
        match &self.bar {
            Some(bar) => bar.println(msg),
            None => note!("{msg}"),
        }
    }

    fn refresh(&self) {
        let (Some(bar), Ok(active)) = (&self.bar, self.active.lock()) else {
            return;
        };
        let msg: Vec<String> = active.values().map(|(name, stage)| format!("{name} ({stage})")).collect();
        bar.set_message(msg.join(", "));
    }

    fn on_event(&self, event: jem::batch::Event<'_>) {
        use jem::batch::{Event, SceneStatus};
        match event {
            Event::Started { index, name } => {
                if let Ok(mut a) = self.active.lock() {
                    a.insert(index, (one_line(name), "starting".into()));
                }
                self.refresh();
            }
            Event::Stage { index, stage } => {
                if let Ok(mut a) = self.active.lock()
                    && let Some(entry) = a.get_mut(&index)
                {
                    entry.1 = stage.to_string();
                }
                self.refresh();
            }
            Event::Finished { index, report } => {
                if let Ok(mut a) = self.active.lock() {
                    a.remove(&index);
                }
                let n = self.done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                let head = format!("[{n}/{}] {}", self.total, one_line(&report.name));
                let left = self.time_left(&report.status, self.total - n);
                match &report.status {
                    SceneStatus::Failed(e) => self.line(&format!("{head}: FAILED: {}", one_line(&e.to_string()))),
                    _ if self.quiet || self.bar.is_some() => {}
                    SceneStatus::Skipped => self.line(&format!("{head}: skipped (result exists)")),
                    SceneStatus::Done(r) => self.line(&format!(
                        "{head}: {}x{}, ndisp {}, {:.3} s{left}",
                        r.size.0, r.size.1, r.ndisp, r.seconds
                    )),
                }
                // A value too large for this scene's image (held to its bound); -q silences it.
                if let SceneStatus::Done(r) = &report.status
                    && !self.quiet
                {
                    for warning in self.params.image_warnings(r.size.0, r.size.1) {
                        self.line(&format!("{head}: warning: {warning}"));
                    }
                }
                if let Some(bar) = &self.bar {
                    bar.set_prefix(left);
                    bar.inc(1);
                }
                self.refresh();
            }
        }
    }

    /// `, ETA 1 min 05 s` after a finished scene (its pipeline time counted), while scenes are left and one has
    /// finished; else empty.
    fn time_left(&self, status: &jem::batch::SceneStatus, left: usize) -> String {
        let Ok(mut eta) = self.eta.lock() else {
            return String::new();
        };
        if let jem::batch::SceneStatus::Done(r) = status {
            eta.record(r.seconds);
        }
        match eta.remaining(left, self.jobs) {
            Some(d) if left > 0 => format!(", ETA {}", jem::batch::format_duration(d)),
            _ => String::new(),
        }
    }
}

/// Runs the pipeline on every scene found, then prints the summary.
pub(super) fn run(args: &BatchArgs, global: &GlobalArgs) -> Result<ExitCode> {
    use jem::batch::{BatchOptions, SceneStatus};
    jem::batch::validate_alg_name(&args.alg)?;
    if args.jobs == 0 {
        return Err(Error::param("--jobs", 0, "at least 1"));
    }
    if args.ndisp == Some(0) {
        return Err(Error::param("--ndisp", 0, "at least 1"));
    }
    let params = args.config.params()?;
    let (all, scenes) = find_pairs(args)?;
    let lock = claim_results(args, &all, &scenes, global.quiet)?;
    if !global.quiet {
        announce(args, &all, &scenes);
    }
    let opts = BatchOptions {
        alg: args.alg.clone(),
        results: args.results.clone(),
        ndisp: args.ndisp,
        jobs: args.jobs,
        skip_existing: args.skip_existing,
        lr_mask: args.lr_mask,
        confidence: args.confidence,
        max_memory_bytes: args.memory.memory_limit(),
        command: super::command_line(),
    };
    let display = BatchDisplay::new(scenes.len(), args.jobs, global.quiet, params.clone());
    // Panics inside the pipeline are caught and reported per scene; keep the default hook's message and
    // backtrace note off the terminal unless -v.
    let previous_hook = (!global.verbose).then(|| {
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        prev
    });
    let reports = jem::batch::run_batch_locked(&scenes, &lock, &params, &opts, &|e| display.on_event(e));
    drop(lock);
    if let Some(prev) = previous_hook {
        std::panic::set_hook(prev);
    }
    if let Some(bar) = &display.bar {
        bar.finish_and_clear();
    }
    let failed = reports.iter().filter(|r| matches!(r.status, SceneStatus::Failed(_))).count();
    if !global.quiet {
        out!("{}", jem::batch::summary(&reports, global.verbose));
        note!("{}", results_line(&scenes, &reports, args));
    }
    Ok(if failed > 0 { ExitCode::from(2) } else { ExitCode::SUCCESS })
}

/// Every pair under the folders given, and this shard's part of them.
fn find_pairs(args: &BatchArgs) -> Result<(Vec<jem::dataset::Pair>, Vec<jem::dataset::Pair>)> {
    let how = jem::dataset::Discovery { layout: args.layout, gt: None };
    let all = jem::dataset::discover(&args.dirs, jem::dataset::Purpose::Run, &how)?;
    if all.is_empty() {
        let dirs: Vec<String> = args.dirs.iter().map(|d| d.display().to_string()).collect();
        return Err(Error::dataset(format!(
            "no scene folder (with im0.png, im1.png and calib.txt) or KITTI frame (image_2/ + image_3/, \
             colored_0/ + colored_1/) under {}",
            dirs.join(", ")
        )));
    }
    if args.results.is_some() && all.iter().all(|p| p.layout == jem::dataset::Layout::Middlebury) {
        return Err(Error::argument(
            "--results is for KITTI and ETH3D data sets; MiddEval3 results go into each scene folder",
        ));
    }
    let scenes = match args.shard {
        Some(shard) => shard.select(&all),
        None => all.clone(),
    };
    Ok((all, scenes))
}

/// Claims the results folders of `scenes` for this run, before any work: each is checked for the whole data set
/// `all` (another shard may claim it), locked against a second batch writing the same results until this one ends,
/// and checked again under the lock (which is when the source files are written).
fn claim_results(
    args: &BatchArgs,
    all: &[jem::dataset::Pair],
    scenes: &[jem::dataset::Pair],
    quiet: bool,
) -> Result<jem::dataset::ResultsLock> {
    jem::dataset::check_results_dirs(all, &args.alg, args.results.as_deref(), false)?;
    let shard = args.shard.map(|s| (s.index, s.count));
    let lock = jem::dataset::lock_results(scenes, &args.alg, args.results.as_deref(), shard)?;
    for line in lock.taken_over().iter().filter(|_| !quiet) {
        note!("note: {line}");
    }
    jem::dataset::check_results_dirs(scenes, &args.alg, args.results.as_deref(), true)?;
    Ok(lock)
}

/// The first lines of a batch: how many pairs, which shard, and where the results of KITTI and ETH3D go.
fn announce(args: &BatchArgs, all: &[jem::dataset::Pair], scenes: &[jem::dataset::Pair]) {
    let shard = args.shard.map(|s| format!(" (shard {}/{} of {})", s.index, s.count, all.len())).unwrap_or_default();
    note!("{} pair(s){shard}, alg {}, {} job(s)", scenes.len(), args.alg, args.jobs);
    let dirs: std::collections::BTreeSet<(&str, PathBuf)> = scenes
        .iter()
        .filter(|p| p.layout != jem::dataset::Layout::Middlebury)
        .filter_map(|p| {
            let files = p.result_files(&args.alg, args.results.as_deref());
            Some((p.layout.name(), files.disparity.parent()?.to_path_buf()))
        })
        .collect();
    for (layout, dir) in dirs {
        note!("{layout} results: {}", dir.display());
    }
}

/// The last line of a batch: how many pairs were written, skipped and failed, and where the results are
/// (MiddEval3: the file names in each scene folder; KITTI, ETH3D: the results folders).
fn results_line(scenes: &[jem::dataset::Pair], reports: &[jem::batch::SceneReport], args: &BatchArgs) -> String {
    use jem::batch::SceneStatus;
    use jem::dataset::Layout;
    let count = |f: fn(&SceneStatus) -> bool| reports.iter().filter(|r| f(&r.status)).count();
    let written = count(|s| matches!(s, SceneStatus::Done(_)));
    let skipped = count(|s| matches!(s, SceneStatus::Skipped));
    let failed = count(|s| matches!(s, SceneStatus::Failed(_)));
    let mut places: Vec<String> = Vec::new();
    let middlebury: std::collections::BTreeSet<PathBuf> = scenes
        .iter()
        .filter(|p| p.layout == Layout::Middlebury)
        .map(|p| p.root.parent().map_or_else(|| PathBuf::from("."), std::path::Path::to_path_buf))
        .collect();
    if !middlebury.is_empty() {
        let under: Vec<String> = middlebury.iter().map(|d| d.display().to_string()).collect();
        places.push(format!(
            "disp0{alg}.pfm and time{alg}.txt in each MiddEval3 scene folder (under {})",
            one_line(&under.join(", ")),
            alg = args.alg
        ));
    }
    let others: std::collections::BTreeSet<PathBuf> = scenes
        .iter()
        .filter(|p| p.layout != Layout::Middlebury)
        .filter_map(|p| p.results_dir(&args.alg, args.results.as_deref()))
        .collect();
    for dir in others {
        places.push(format!("{}/", one_line(&dir.display().to_string())));
    }
    let failed = if failed > 0 { format!("{failed} FAILED (listed above)") } else { "0 failed".into() };
    format!("{} pair(s): {written} written, {skipped} skipped, {failed}; results: {}", reports.len(), places.join("; "))
}
