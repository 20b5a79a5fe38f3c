//! `jem rectify CALIB LEFT RIGHT -o DIR`: rectify a raw pair with its stereo calibration (OpenCV FileStorage
//! YAML/XML, KITTI calib_cam_to_cam.txt), writing `DIR/im0.png`, `DIR/im1.png` and the Middlebury `DIR/calib.txt`
//! of the rectified pair, all or none.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use jem::rectify::{Rectification, StereoCalibration, View};
use jem::{Error, Result};

use super::{GlobalArgs, MemoryArg, ThreadsArg};
use jem::dataset::{CALIB_FILE, LEFT_FILE, RIGHT_FILE};

/// Arguments of `jem rectify` (the help text is on [`Command::Rectify`](super::Command::Rectify)).
#[derive(Args, Debug, Clone)]
pub(super) struct RectifyArgs {
    /// The stereo calibration: OpenCV FileStorage (.yml/.yaml/.xml) or KITTI's calib_cam_to_cam.txt.
    #[arg(value_name = "CALIB")]
    calib: PathBuf,
    /// The left camera's image.
    left: PathBuf,
    /// The right camera's image, the same size.
    right: PathBuf,
    /// Output folder (created if missing; one that holds a scene already is refused): im0.png, im1.png, calib.txt,
    /// rectify.yml.
    #[arg(long, short, value_name = "DIR")]
    output: PathBuf,
    /// Also write the maps (for each rectified pixel, where in the original image it comes from) as
    /// DIR/map0x.pfm, map0y.pfm (left) and map1x.pfm, map1y.pfm (right).
    #[arg(long)]
    maps: bool,
    /// OpenCV's free scaling (stereoRectify's alpha), 0..1: 0 crops the views to valid pixels only (the default),
    /// 1 keeps every pixel of the raw views (black corners come in), values between interpolate. rectify.yml gives
    /// each view's rectangle of valid pixels (validPixROI1, validPixROI2).
    #[arg(long, value_name = "A", allow_negative_numbers = true)]
    alpha: Option<f64>,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
    #[command(flatten)]
    memory: MemoryArg,
}

/// Reads a calibration and the pair's headers, and makes the rectification for the pair's size (with OpenCV's
/// `alpha` when given), before any image is decoded; refuses a pair whose rectification would need more than
/// `max_memory` bytes.
pub(super) fn plan(
    calib: &Path,
    (left, right): (&Path, &Path),
    alpha: Option<f64>,
    max_memory: u64,
) -> Result<Rectification> {
    let calibration = StereoCalibration::load(calib)?;
    let header = jem::io::read_pair_header(left, right)?;
    let rectification = calibration.rectification_with_alpha((header.width, header.height), alpha)?;
    let need = header
        .load_bytes
        .saturating_add(jem::rectify::RECTIFY_BYTES_PER_PX.saturating_mul((header.width * header.height) as u64));
    if need > max_memory {
        return Err(Error::OutOfMemory {
            needed: need,
            limit: max_memory,
            hint: "raise --max-memory or rectify smaller images".into(),
        });
    }
    Ok(rectification)
}

/// Prints (unless `quiet`) a line per rectified view that would come out mostly black
/// ([`Rectification::warnings`]).
pub(super) fn warn(rectification: &Rectification, calib: &Path, quiet: bool) {
    for warning in rectification.warnings().iter().filter(|_| !quiet) {
        note!("warning: {}: {warning}", calib.display());
    }
}

/// Rectifies one pair.
pub(super) fn run(args: &RectifyArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let names = [LEFT_FILE, RIGHT_FILE, CALIB_FILE, "rectify.yml"];
    let mut outputs: Vec<PathBuf> = names.iter().map(|n| args.output.join(n)).collect();
    if args.maps {
        outputs.extend(["map0x.pfm", "map0y.pfm", "map1x.pfm", "map1y.pfm"].map(|n| args.output.join(n)));
    }
    if args.output.exists() && !args.output.is_dir() {
        return Err(Error::output_at(&args.output, "exists and is not a folder; give -o the name of a new folder"));
    }
    // A folder holding a scene (im0.png, im1.png, calib.txt, ground truth, results) would get a new pair beside
    // results and ground truth of the old one, as `jem synth` refuses.
    jem::synth::check_scene_folder(&args.output)?;
    let pair = (args.left.as_path(), args.right.as_path());
    let rectification = plan(&args.calib, pair, args.alpha, args.memory.memory_limit())?;
    warn(&rectification, &args.calib, global.quiet);
    let output_refs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    jem::io::check_outputs(&[&args.calib, &args.left, &args.right], &output_refs)?;
    let (left, right) = jem::io::read_image_pair(&args.left, &args.right)?;
    let (left, right) = rectification.rectify_pair(&left, &right)?;
    // Grey views stay grey: a grey file's three channels are equal, and so are those of its rectified view.
    let grey = jem::io::image_is_grey(&args.left)? && jem::io::image_is_grey(&args.right)?;
    let encode = if grey { jem::io::encode_grey_png } else { jem::io::encode_png };
    let mut files = vec![
        encode(&outputs[0], &left)?,
        encode(&outputs[1], &right)?,
        rectification.calib_txt().into_bytes(),
        rectification.rectify_yml().into_bytes(),
    ];
    if args.maps {
        for view in [View::Left, View::Right] {
            let (x, y) = rectification.maps(view);
            files.push(jem::io::pfm::encode_pfm(&x));
            files.push(jem::io::pfm::encode_pfm(&y));
        }
    }
    jem::io::create_folder(&args.output)?;
    let pairs: Vec<(&Path, &[u8])> = output_refs.iter().copied().zip(files.iter().map(Vec::as_slice)).collect();
    jem::io::write_all_or_none(&pairs)?;
    if !global.quiet {
        let (w, h) = rectification.size();
        note!(
            "wrote {} ({w}×{h}; focal length {:.2} px, baseline {:.6}, doffs {:.2})",
            outputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
            rectification.focal_px(),
            rectification.baseline(),
            rectification.doffs()
        );
    }
    Ok(ExitCode::SUCCESS)
}
