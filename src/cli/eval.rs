//! `jem eval`: scores `disp0NAME.pfm` results against the ground truth of every scene under DIR
//! ([`jem::eval::evaluate_dir`]), optionally beside the paper's numbers, and prints the reports
//! ([`jem::eval::render`]).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use jem::{Error, Result};

use super::ThreadsArg;

/// `auto`, 1, 2 or 4.
#[derive(Clone, Copy, Debug)]
pub(super) struct ScaleArg(pub(super) Option<u32>);

impl std::str::FromStr for ScaleArg {
    type Err = Error;
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        match s {
            "auto" => Ok(ScaleArg(None)),
            "1" => Ok(ScaleArg(Some(1))),
            "2" => Ok(ScaleArg(Some(2))),
            "4" => Ok(ScaleArg(Some(4))),
            _ => Err(Error::argument(format!("invalid scale {s:?} (expected auto, 1, 2 or 4)"))),
        }
    }
}

/// Arguments of `jem eval` (the help text is on [`Command::Eval`](super::Command::Eval)).
#[derive(Args, Debug, Clone)]
pub(super) struct EvalArgs {
    /// Folder searched recursively for pairs with ground truth (e.g. MiddEval3/trainingQ or one scene, a KITTI
    /// training/ tree, an ETH3D two_view_training/ tree); or the output folder of `jem sequence`.
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// Result to score, as `jem batch --alg NAME` wrote it (repeatable; required except for a sequence).
    #[arg(long = "alg", value_name = "NAME")]
    algs: Vec<String>,
    /// Where KITTI and ETH3D results are: RESULTS/NAME/SPLIT/ (default: results/ beside the data set, as batch).
    #[arg(long, value_name = "RESULTS")]
    results: Option<PathBuf>,
    /// ETH3D ground truth: the tree with SCENE/disp0GT.pfm and mask0nocc.png (default: DIR's sibling DIR_gt/).
    /// For a sequence's results: the sequence folder (or its gt/ folder; default: the sequence the results were
    /// made from, as DIR/sequence.txt records it).
    #[arg(long, value_name = "DIR")]
    gt: Option<PathBuf>,
    /// Read the scenes as this layout (middlebury, eth3d, kitti2012, kitti2015) instead of recognising it.
    #[arg(long, value_name = "LAYOUT")]
    layout: Option<jem::dataset::Layout>,
    /// Pixels to evaluate: nonocc (mask0nocc.png == 255) or all (mask > 0).
    #[arg(long, value_name = "nonocc|all", default_value = "nonocc")]
    mask: jem::eval::MaskMode,
    /// Factor to full-resolution pixels; auto reads it from the path (trainingQ/testQ = 4, *H = 2, *F = 1), else
    /// from the scenes' names and image sizes (MiddEval3's are known).
    #[arg(long, value_name = "auto|1|2|4", default_value = "auto")]
    scale: ScaleArg,
    /// Also show where the error is (MiddEval3 trees, nonocc): each scene's avgErr split by region — rejected by
    /// the left-right check (from lrmask0NAME.png, which `jem batch --lr-mask` writes; "-" without it, and its
    /// pixels fall into the others), within 3 px of a ground-truth depth edge (a jump over 1 px between
    /// 4-neighbours, at the evaluated resolution), the least-textured 15 % (5×5 mean Sobel magnitude of the left
    /// grey), within 3 px of an occluded pixel (mask 128), the rest; each pixel in the first that holds — and by
    /// error size (≤1, 1–2, 2–4, 4–8, >8 full-resolution px), per scene and weighted. A region's value is its error
    /// sum divided by the number of all scored pixels (valid results, as avgErr), so the regions add up to avgErr;
    /// likewise the gross (> 8 px) table. Text, markdown or json (a "regions" member per --alg).
    #[arg(long)]
    regions: bool,
    /// Output format: table, csv, json or markdown.
    #[arg(long, value_name = "FORMAT", default_value = "table")]
    format: jem::eval::Format,
    /// Print the paper's avgErr from this column of paper-results.tsv beside ours (LCM, FCM, JEM_LRC, JEM_SPS,
    /// JEM_ALL, ...). Give it once for all --alg, or once per --alg in the same order.
    #[arg(long, value_name = "COLUMN")]
    paper: Vec<String>,
    /// The paper's numbers (default: $JEM_DATA/paper-results.tsv, else ../shared/middlebury/paper-results.tsv).
    #[arg(long, value_name = "PATH")]
    paper_file: Option<PathBuf>,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
}

/// Where the paper's TSV is: --paper-file, else $JEM_DATA/paper-results.tsv, else ../shared/middlebury/.
pub(super) fn paper_file(flag: Option<&Path>) -> PathBuf {
    if let Some(p) = flag {
        return p.to_path_buf();
    }
    match std::env::var_os("JEM_DATA") {
        Some(d) if !d.is_empty() => PathBuf::from(d).join("paper-results.tsv"),
        _ => PathBuf::from("../shared/middlebury/paper-results.tsv"),
    }
}

/// Scores every --alg over the folder and prints the reports (or a sequence's results).
pub(super) fn run(args: &EvalArgs, global: &super::GlobalArgs) -> Result<ExitCode> {
    use jem::eval::{PaperResults, evaluate_dir};
    if let Some(seq) = sequence_truth(&args.dir, args.gt.as_deref())? {
        return run_sequence(args, global, &seq);
    }
    if args.algs.is_empty() {
        return Err(Error::argument(format!(
            "{}: give the results to score with --alg NAME (a folder `jem sequence` wrote needs none)",
            args.dir.display()
        )));
    }
    for a in &args.algs {
        jem::batch::validate_alg_name(a)?;
    }
    if args.regions && args.format == jem::eval::Format::Csv {
        return Err(Error::argument("--regions prints a table, markdown or json, not csv"));
    }
    let papers = if args.paper.is_empty() {
        Vec::new()
    } else {
        if args.paper.len() != 1 && args.paper.len() != args.algs.len() {
            return Err(Error::argument(format!(
                "{} --paper columns for {} --alg: give one for all, or one per --alg",
                args.paper.len(),
                args.algs.len()
            )));
        }
        let path = paper_file(args.paper_file.as_deref());
        if !path.is_file() {
            return Err(Error::dataset(format!(
                "--paper needs the paper's numbers, but {} does not exist (use --paper-file or set JEM_DATA)",
                path.display()
            )));
        }
        let table = PaperResults::load(&path)?;
        let columns = args.algs.iter().enumerate().map(|(i, _)| &args.paper[if args.paper.len() == 1 { 0 } else { i }]);
        columns.map(|c| table.column(c).map(Some)).collect::<Result<Vec<_>>>()?
    };
    // An ETH3D ground-truth tree given as DIR: score its image tree (the sibling without `_gt`) against it.
    let (dir, gt) = match (&args.gt, eth3d_image_tree(&args.dir)) {
        (None, Some(images)) => (images, Some(args.dir.clone())),
        _ => (args.dir.clone(), args.gt.clone()),
    };
    let sources = jem::eval::Sources { layout: args.layout, gt, results: args.results.clone() };
    let reports = args
        .algs
        .iter()
        .map(|alg| evaluate_dir(&dir, alg, args.mask, args.scale.0, &sources))
        .collect::<Result<Vec<_>>>()?;
    if !global.quiet {
        // Results a batch is still writing (its lock is held): scored as they are now.
        for line in reports.iter().flat_map(|r| &r.writers) {
            note!("warning: {line}; scored as it is now, the scores may change when it ends");
        }
        // Every --alg scores the same scenes: one line says how their resolution was found.
        if let Some(line) = reports.iter().find_map(|r| r.scale_inferred.as_ref()) {
            note!("note: {line}");
        }
    }
    let regions = if args.regions {
        reports.iter().map(jem::eval::split_report).collect::<Result<Vec<_>>>()?
    } else {
        Vec::new()
    };
    out!("{}", jem::eval::render_with_regions(&reports, &papers, &regions, args.format));
    let excluded = reports.iter().any(|r| r.excluded().next().is_some());
    if !global.quiet {
        note!("{}", scored_line(&reports));
    }
    Ok(if excluded { ExitCode::from(2) } else { ExitCode::SUCCESS })
}

/// The sequence whose truth scores DIR: `--gt` naming a sequence folder (or its `gt/`), else the sequence DIR's
/// record names (`jem sequence` wrote DIR); `None` when DIR is no sequence's results.
fn sequence_truth(dir: &Path, gt: Option<&Path>) -> Result<Option<jem::sequence::Sequence>> {
    use jem::sequence::Sequence;
    let candidate = match gt {
        Some(g) if Sequence::recognise(g).is_some() => Some(g.to_path_buf()),
        Some(g) if g.file_name().is_some_and(|n| n == "gt") => {
            g.parent().filter(|p| Sequence::recognise(p).is_some()).map(Path::to_path_buf)
        }
        Some(_) => None,
        None => jem::sequence::recorded_source(dir),
    };
    let Some(root) = candidate else { return Ok(None) };
    Sequence::open(&root).map(Some).map_err(|e| match gt {
        None => Error::dataset_at(
            &dir.join(jem::sequence::RUN_FILE),
            format!("made from the sequence {}, which does not open ({e}); give its truth with --gt", root.display()),
        ),
        Some(_) => e,
    })
}

/// Scores a sequence's results frame by frame ([`jem::eval::sequence`]) and prints the report.
fn run_sequence(args: &EvalArgs, global: &super::GlobalArgs, seq: &jem::sequence::Sequence) -> Result<ExitCode> {
    use jem::eval::sequence::{evaluate_sequence, render_sequence};
    if !args.algs.is_empty() || !args.paper.is_empty() {
        return Err(Error::argument(format!(
            "{}: a sequence's results are scored without --alg or --paper",
            args.dir.display()
        )));
    }
    let scale = args.scale.0.unwrap_or_else(|| jem::eval::scale_from_path(&seq.root).unwrap_or(1));
    let report = evaluate_sequence(&args.dir, seq, args.mask, scale, None)?;
    out!("{}", render_sequence(&report, args.format));
    let missing = report.excluded().count();
    if !global.quiet {
        let scored = report.frames.len() - missing;
        let note =
            if missing > 0 { format!("; {missing} without a usable result (listed above)") } else { String::new() };
        let scale = if scale == 1 { String::new() } else { format!(", errors ×{scale}") };
        note!(
            "scored {scored} of {} frames of {} ({}{scale}){note}",
            report.frames.len(),
            seq.root.display(),
            args.mask.name()
        );
    }
    Ok(if missing > 0 { ExitCode::from(2) } else { ExitCode::SUCCESS })
}

/// The last line of an eval: `scored 15 scenes of JEM (middlebury, nonocc, errors ×4)`, and how many had no
/// usable result, and how many no usable ground truth, mask or calib.txt.
fn scored_line(reports: &[jem::eval::AlgReport]) -> String {
    let parts: Vec<String> = reports
        .iter()
        .map(|r| {
            let total = r.scenes.len();
            let excluded: Vec<&jem::eval::SceneResult> = r.scenes.iter().filter(|s| s.metrics.is_err()).collect();
            let no_truth = excluded.iter().filter(|s| s.truth_unusable).count();
            let no_result = excluded.len() - no_truth;
            let scale = if r.scale == 1 { String::new() } else { format!(", errors ×{}", r.scale) };
            let mut missing = Vec::new();
            if no_result > 0 {
                missing.push(format!("{no_result} without a usable result"));
            }
            if no_truth > 0 {
                missing.push(format!("{no_truth} without a usable ground truth, mask or calib.txt"));
            }
            let note =
                if missing.is_empty() { String::new() } else { format!("; {} (listed above)", missing.join(", ")) };
            format!(
                "scored {} of {total} scene(s) of {} ({}, {}{scale}){note}",
                total - excluded.len(),
                r.alg,
                r.layout.name(),
                r.mask.name()
            )
        })
        .collect();
    parts.join("; ")
}

/// The image tree of an ETH3D ground-truth tree: `X` for a folder `X_gt` without images of its own, when `X`
/// exists beside it.
fn eth3d_image_tree(dir: &Path) -> Option<PathBuf> {
    let name = dir.file_name()?.to_str()?;
    let images = dir.with_file_name(name.strip_suffix("_gt")?);
    let has_scenes =
        jem::dataset::discover(&[dir.to_path_buf()], jem::dataset::Purpose::Run, &jem::dataset::Discovery::default())
            .is_ok_and(|pairs| !pairs.is_empty());
    (images.is_dir() && !has_scenes).then_some(images)
}
