//! `jem report`: an HTML page of results ([`jem::report::write_report`]): per scene the left image, each
//! algorithm's disparity and error map and its scores, sortable, with the paper's numbers beside them when asked.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use jem::{Error, Result};

use super::ThreadsArg;
use super::eval::{ScaleArg, paper_file};

/// Arguments of `jem report` (the help text is on [`Command::Report`](super::Command::Report)).
#[derive(Args, Debug, Clone)]
pub(super) struct ReportArgs {
    /// A data set's folder with results: MiddEval3 scenes (e.g. MiddEval3/trainingQ), a KITTI training/ tree, an
    /// ETH3D two_view_training/ tree.
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// The results to show, side by side in this order, as `jem batch --alg NAME` wrote them (comma-separated or
    /// repeated).
    #[arg(long = "alg", required = true, value_name = "NAME", value_delimiter = ',')]
    algs: Vec<String>,
    /// The page to write (.html); its pictures go into the folder <stem>_files/ beside it.
    #[arg(long, short, value_name = "OUT.html")]
    output: PathBuf,
    /// The paper's avgErr to show beside each --alg: a column of paper-results.tsv (LCM, FCM, JEM_LRC, JEM_SPS,
    /// JEM_ALL, ...) per --alg in the same order, - for none (e.g. --paper -,JEM_ALL); one column alone is shown
    /// beside every --alg.
    #[arg(long, value_name = "COLUMN", value_delimiter = ',', allow_hyphen_values = true)]
    paper: Vec<String>,
    /// The paper's numbers (default: $JEM_DATA/paper-results.tsv, else ../shared/middlebury/paper-results.tsv).
    #[arg(long, value_name = "PATH")]
    paper_file: Option<PathBuf>,
    /// Pixels to score: nonocc (mask0nocc.png == 255) or all (mask > 0).
    #[arg(long, value_name = "nonocc|all", default_value = "nonocc")]
    mask: jem::eval::MaskMode,
    /// MiddEval3: factor to full-resolution pixels; auto reads it from the path (trainingQ = 4, *H = 2, *F = 1),
    /// else from the scenes' names and image sizes.
    #[arg(long, value_name = "auto|1|2|4", default_value = "auto")]
    scale: ScaleArg,
    /// Read the data as this layout (middlebury, eth3d, kitti2015, kitti2012) instead of recognising it.
    #[arg(long, value_name = "LAYOUT")]
    layout: Option<jem::dataset::Layout>,
    /// Where KITTI and ETH3D results are: RESULTS/NAME/SPLIT/ (default: results/ beside the data set, as batch).
    #[arg(long, value_name = "RESULTS")]
    results: Option<PathBuf>,
    /// ETH3D ground truth: the tree with SCENE/disp0GT.pfm and mask0nocc.png (default: DIR's sibling DIR_gt/).
    #[arg(long, value_name = "DIR")]
    gt: Option<PathBuf>,
    /// The largest width of a thumbnail in the table, in pixels (a click opens the full size).
    #[arg(long, value_name = "PX", default_value_t = 120)]
    thumb_width: usize,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
}

/// Writes the report and says what it wrote.
pub(super) fn run(args: &ReportArgs, global: &super::GlobalArgs) -> Result<ExitCode> {
    let papers = if args.paper.is_empty() {
        Vec::new()
    } else {
        if args.paper.len() != 1 && args.paper.len() != args.algs.len() {
            return Err(Error::argument(format!(
                "{} --paper columns for {} --alg: give one per --alg (- for none), or one for all",
                args.paper.len(),
                args.algs.len()
            )));
        }
        let path = paper_file(args.paper_file.as_deref());
        let wanted: Vec<&str> =
            (0..args.algs.len()).map(|i| args.paper[i.min(args.paper.len() - 1)].as_str()).collect();
        if wanted.iter().all(|c| *c == "-") {
            vec![None; args.algs.len()]
        } else {
            if !path.is_file() {
                return Err(Error::dataset(format!(
                    "--paper needs the paper's numbers, but {} does not exist (use --paper-file or set JEM_DATA)",
                    path.display()
                )));
            }
            let table = jem::eval::PaperResults::load(&path)?;
            wanted.iter().map(|c| (*c != "-").then(|| table.column(c)).transpose()).collect::<Result<Vec<_>>>()?
        }
    };
    let opts = jem::report::ReportOptions {
        algs: args.algs.clone(),
        papers,
        mask: args.mask,
        scale: args.scale.0,
        layout: args.layout,
        gt: args.gt.clone(),
        results: args.results.clone(),
        thumb_width: args.thumb_width,
        command: super::command_line(),
    };
    let summary = jem::report::write_report(&args.dir, &args.output, &opts)?;
    for n in &summary.not_drawn {
        note!("warning: {} ({}) not drawn: {}", n.scene, n.alg, n.reason);
    }
    if !global.quiet {
        for line in &summary.writers {
            note!("warning: {line}; reported as it is now");
        }
        if let Some(line) = &summary.scale_inferred {
            note!("note: {line}");
        }
        note!(
            "wrote {} ({} rows, {}) and {} pictures in {}/",
            summary.page.display(),
            summary.scenes,
            args.algs.join(", "),
            summary.pictures,
            summary.files.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}
