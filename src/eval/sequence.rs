//! Scoring a sequence's results ([`evaluate_sequence`]): each frame as a pair, and how the answer changes from
//! frame to frame against how the truth changes.
//!
//! # Per frame
//! Frame t's map (`RESULTS/<stem>.pfm`, or the format `jem sequence` recorded) against its ground truth
//! (`gt/<stem>.pfm`, mask `mask/<stem>.png` when there is one) by [`evaluate`]: the rules of the module doc
//! ([`crate::eval`]), so avgErr and bad-2 are in full-resolution pixels (× `scale`), results clipped to
//! `[0, ndisp]` with the sequence's `calib.txt` range (no upper clip without one).
//!
//! # From frame to frame
//! For t = 2…N, the pixels scored are those where the ground truth is finite in frames t − 1 and t, the mask
//! selects both (when the sequence has masks: 255 in both for `nonocc`, > 0 in both for `all`), and both results
//! are valid (finite; clipped as above). With d the results, g the truth, Δd = d_t − d_{t−1}, Δg = g_t − g_{t−1}:
//!
//! | figure | pixels | definition |
//! |---|---|---|
//! | `flicker` (frame-to-frame change) | \|Δg\| < 0.5 (native px: the truth did not move) | s · mean \|Δd\| |
//! | `change_err` (error of the change) | \|Δg\| ≥ 0.5 | s · mean \|Δd − Δg\| |
//!
//! s is the scale to full-resolution pixels (4 for a sequence made from trainingQ: `--scale 4`). The sequence's
//! figures are the plain means of the frames' values over the frames that have such pixels (a frame without any
//! contributes nothing). A frame without ground truth or result is listed with the reason, and the change into
//! and out of it is not scored.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::format::{csv_field, csv_num};
use super::metrics::{MaskMode, Metrics, check_size, evaluate};
use super::text::{fixed, json_num, json_str};
use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane};
use crate::sequence::Sequence;
use crate::table::Table;

/// How much the truth may change at a pixel for it to count as static, in the ground truth's own pixels.
pub const STATIC_CHANGE_PX: f32 = 0.5;

/// The change from the previous frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Change {
    /// Pixels whose truth did not move (|Δg| < [`STATIC_CHANGE_PX`]).
    pub static_pixels: u64,
    /// s · mean |Δd| over them (NaN when there are none).
    pub flicker: f64,
    /// Pixels whose truth moved.
    pub moving_pixels: u64,
    /// s · mean |Δd − Δg| over them (NaN when there are none).
    pub change_err: f64,
}

/// One frame's scores.
#[derive(Clone, Debug)]
pub struct FrameScore {
    /// The frame's stem.
    pub stem: String,
    /// Its scores as a pair, or why it has none.
    pub metrics: std::result::Result<Metrics, Arc<Error>>,
    /// The change from the previous frame (`None` for the first frame, or when either frame has no scores).
    pub change: Option<Change>,
    /// Its run time from the results' times file.
    pub seconds: Option<f64>,
}

/// A sequence's scores.
#[derive(Clone, Debug)]
pub struct SequenceReport {
    /// The results folder.
    pub results: PathBuf,
    /// The sequence folder holding the truth.
    pub sequence: PathBuf,
    /// The pixels scored.
    pub mask: MaskMode,
    /// Factor to full-resolution pixels.
    pub scale: u32,
    /// Every frame of the sequence, in order.
    pub frames: Vec<FrameScore>,
}

impl SequenceReport {
    /// The plain mean of the scored frames' metrics among `frames` (a range of positions; `None` if none).
    pub fn mean_of(&self, frames: std::ops::Range<usize>) -> Option<Metrics> {
        let ok: Vec<&Metrics> = self.frames.get(frames)?.iter().filter_map(|f| f.metrics.as_ref().ok()).collect();
        if ok.is_empty() {
            return None;
        }
        let mut sums = [0.0f64; 9];
        for m in &ok {
            sums.iter_mut().zip(m.values()).for_each(|(s, v)| *s += v);
        }
        Some(Metrics::from_values(sums.map(|s| s / ok.len() as f64), ok.iter().map(|m| m.pixels).sum()))
    }

    /// The plain mean over all scored frames.
    pub fn mean(&self) -> Option<Metrics> {
        self.mean_of(0..self.frames.len())
    }

    /// The mean frame-to-frame change on static pixels over the frames that have some (`None`: none has).
    pub fn flicker(&self) -> Option<f64> {
        mean_finite(self.frames.iter().filter_map(|f| f.change.map(|c| c.flicker)))
    }

    /// The mean error of the change on moving pixels over the frames that have some.
    pub fn change_err(&self) -> Option<f64> {
        mean_finite(self.frames.iter().filter_map(|f| f.change.map(|c| c.change_err)))
    }

    /// The mean number of static and of moving pixels per frame-to-frame change (`None`: no change was scored).
    pub fn mean_pixels(&self) -> [Option<f64>; 2] {
        let changes: Vec<Change> = self.frames.iter().filter_map(|f| f.change).collect();
        let n = changes.len() as f64;
        let mean = |count: fn(&Change) -> u64| (n > 0.0).then(|| changes.iter().map(count).sum::<u64>() as f64 / n);
        [mean(|c| c.static_pixels), mean(|c| c.moving_pixels)]
    }

    /// The mean run time over the frames with one.
    pub fn mean_seconds(&self) -> Option<f64> {
        mean_finite(self.frames.iter().filter_map(|f| f.seconds))
    }

    /// Frames without scores, with the reason ([`Error::chain`]).
    pub fn excluded(&self) -> impl Iterator<Item = (&str, String)> {
        self.frames.iter().filter_map(|f| f.metrics.as_ref().err().map(|e| (f.stem.as_str(), e.chain())))
    }
}

fn mean_finite(values: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The change between two frames' results against their truths (see the module doc). `mask`: each frame's mask
/// when the sequence has them.
///
/// # Panics
/// If the maps differ in size.
pub fn frame_change(
    prev: (&DisparityMap, &DisparityMap, Option<&Plane<u8>>),
    cur: (&DisparityMap, &DisparityMap, Option<&Plane<u8>>),
    ndisp: usize,
    scale: u32,
    mask_mode: MaskMode,
) -> Change {
    let ((d0, g0, m0), (d1, g1, m1)) = (prev, cur);
    assert!(d0.dims() == g0.dims() && d1.dims() == g1.dims() && d0.dims() == d1.dims(), "frame sizes differ");
    let max_d = ndisp as f64;
    let (mut n_static, mut n_moving, mut sum_static, mut sum_moving) = (0u64, 0u64, 0.0f64, 0.0f64);
    for i in 0..d0.data.len() {
        let (a, b, ga, gb) = (d0.data[i], d1.data[i], g0.data[i], g1.data[i]);
        let selected = |m: Option<&Plane<u8>>| m.is_none_or(|m| mask_mode.selects(m.data[i]));
        if !(ga.is_finite() && gb.is_finite() && a.is_finite() && b.is_finite() && selected(m0) && selected(m1)) {
            continue;
        }
        let dd = f64::from(b).clamp(0.0, max_d) - f64::from(a).clamp(0.0, max_d);
        let dg = f64::from(gb) - f64::from(ga);
        if (gb - ga).abs() < STATIC_CHANGE_PX {
            n_static += 1;
            sum_static += dd.abs();
        } else {
            n_moving += 1;
            sum_moving += (dd - dg).abs();
        }
    }
    let s = f64::from(scale);
    let mean = |sum: f64, n: u64| if n == 0 { f64::NAN } else { s * sum / n as f64 };
    Change {
        static_pixels: n_static,
        flicker: mean(sum_static, n_static),
        moving_pixels: n_moving,
        change_err: mean(sum_moving, n_moving),
    }
}

/// A frame's maps, loaded for scoring.
struct Loaded {
    result: DisparityMap,
    gt: DisparityMap,
    mask: Option<Plane<u8>>,
}

/// Scores the results in `results` (the per-frame maps `jem sequence` wrote) against the truth of `seq`, frame
/// by frame and from frame to frame (see the module doc). `ndisp`: the upper clip of the results (`None`: the
/// sequence's `calib.txt` range, else none).
///
/// # Errors
/// [`Error::Dataset`] when the sequence has no ground truth, or no frame could be scored; a malformed
/// `calib.txt`. Per-frame problems are recorded in the report.
pub fn evaluate_sequence(
    results: &Path,
    seq: &Sequence,
    mask_mode: MaskMode,
    scale: u32,
    ndisp: Option<usize>,
) -> Result<SequenceReport> {
    if !seq.has_ground_truth() {
        return Err(Error::dataset_at(&seq.root, "the sequence has no ground truth (gt/<stem>.pfm)"));
    }
    let ndisp = match (ndisp, &seq.calib) {
        (Some(n), _) => n,
        (None, Some(c)) => crate::io::calib::read_ndisp(c)?,
        (None, None) => usize::MAX,
    };
    let ext = result_extension(results);
    let times = read_times(&results.join(crate::sequence::TIMES_FILE));
    let mut frames = Vec::with_capacity(seq.frames.len());
    let mut prev: Option<Loaded> = None;
    for f in &seq.frames {
        let loaded = load_frame(results, f, &ext);
        let change = match (&prev, &loaded) {
            (Some(p), Ok(c)) if p.gt.dims() == c.gt.dims() => Some(frame_change(
                (&p.result, &p.gt, p.mask.as_ref()),
                (&c.result, &c.gt, c.mask.as_ref()),
                ndisp,
                scale,
                mask_mode,
            )),
            _ => None,
        };
        let metrics = loaded.as_ref().map_err(|e| e.clone()).and_then(|l| {
            let m = evaluate(&l.result, &l.gt, l.mask.as_ref(), ndisp, scale, mask_mode);
            if m.pixels == 0 {
                Err(Arc::new(Error::dataset(format!("no pixel with ground truth under the {} mask", mask_mode.name()))))
            } else {
                Ok(m)
            }
        });
        let seconds = times.iter().find(|(s, _)| *s == f.stem).map(|(_, t)| *t);
        frames.push(FrameScore { stem: f.stem.clone(), metrics, change, seconds });
        prev = loaded.ok();
    }
    let report =
        SequenceReport { results: results.to_path_buf(), sequence: seq.root.clone(), mask: mask_mode, scale, frames };
    if report.mean().is_none() {
        let why = report.excluded().next().map_or(String::new(), |(s, e)| format!(" (frame {s}: {e})"));
        return Err(Error::dataset_at(results, format!("no frame could be scored{why}")));
    }
    Ok(report)
}

/// The extension of the results: the format `jem sequence` recorded, else `pfm`.
fn result_extension(results: &Path) -> String {
    let record = crate::io::read_small_text(&results.join(crate::sequence::RUN_FILE), 1 << 20).unwrap_or_default();
    record.lines().find_map(|l| l.strip_prefix("format=")).unwrap_or("pfm").to_string()
}

/// Loads a frame's result, truth and mask, or says why it cannot be scored.
fn load_frame(results: &Path, f: &crate::sequence::Frame, ext: &str) -> std::result::Result<Loaded, Arc<Error>> {
    let chain = Arc::new;
    let Some(gt_path) = &f.gt else { return Err(Arc::new(Error::dataset("no ground truth"))) };
    let path = results.join(format!("{}.{ext}", f.stem));
    if !path.is_file() {
        return Err(Arc::new(Error::dataset(format!("no result {}", path.display()))));
    }
    let gt = crate::io::pfm::read_pfm(gt_path).map_err(chain)?;
    let result = crate::io::read_disparity(&path).map_err(chain)?;
    check_size(&path, "result", result.dims(), "the ground truth", gt.dims()).map_err(chain)?;
    let mask = match &f.mask {
        Some(m) => {
            let mask = crate::io::png::load_grey8(m).map_err(chain)?;
            check_size(m, "mask", mask.dims(), "the ground truth", gt.dims()).map_err(chain)?;
            Some(mask)
        }
        None => None,
    };
    Ok(Loaded { result, gt, mask })
}

/// The `(stem, seconds)` lines of a times file.
fn read_times(path: &Path) -> Vec<(String, f64)> {
    let text = crate::io::read_small_text(path, 64 << 20).unwrap_or_default();
    text.lines()
        .filter_map(|l| {
            let (stem, seconds) = l.rsplit_once(' ')?;
            Some((stem.to_string(), seconds.trim().parse().ok()?))
        })
        .collect()
}

/// Prints a report: a table per frame with the means (text or Markdown), JSON or CSV (see `jem eval --help`).
pub fn render_sequence(report: &SequenceReport, format: super::Format) -> String {
    let cols = ["avgerr", "bad2", "invalid"];
    match format {
        super::Format::Json => {
            let frames: Vec<String> = report
                .frames
                .iter()
                .filter_map(|f| {
                    let m = f.metrics.as_ref().ok()?;
                    let mut fields: Vec<String> =
                        Metrics::NAMES.iter().map(|k| format!("{}: {}", json_str(k), json_num(m.get(k)))).collect();
                    if let Some(c) = f.change {
                        fields.push(format!(
                            "\"flicker\": {}, \"change_err\": {}",
                            json_num(c.flicker),
                            json_num(c.change_err)
                        ));
                        fields.push(format!(
                            "\"static_pixels\": {}, \"moving_pixels\": {}",
                            c.static_pixels, c.moving_pixels
                        ));
                    }
                    if let Some(t) = f.seconds {
                        fields.push(format!("\"seconds\": {}", json_num(t)));
                    }
                    Some(format!("{}: {{{}}}", json_str(&f.stem), fields.join(", ")))
                })
                .collect();
            let mean = report.mean().map_or("null".into(), |m| {
                let fields: Vec<String> =
                    Metrics::NAMES.iter().map(|k| format!("{}: {}", json_str(k), json_num(m.get(k)))).collect();
                format!("{{{}}}", fields.join(", "))
            });
            let excluded: Vec<String> =
                report.excluded().map(|(s, e)| format!("{}: {}", json_str(s), json_str(&e))).collect();
            let opt = |v: Option<f64>| v.map_or("null".into(), json_num);
            format!(
                "{{\"results\": {}, \"sequence\": {}, \"mask\": \"{}\", \"scale\": {}, \"frames\": {{{}}}, \"mean\": {mean}, \
                 \"flicker\": {}, \"change_err\": {}, \"seconds\": {}, \"excluded\": {{{}}}}}\n",
                json_str(&report.results.display().to_string()),
                json_str(&report.sequence.display().to_string()),
                report.mask.name(),
                report.scale,
                frames.join(", "),
                opt(report.flicker()),
                opt(report.change_err()),
                opt(report.mean_seconds()),
                excluded.join(", ")
            )
        }
        super::Format::Csv => {
            let mut out = format!(
                "frame,{},flicker,change_err,static_pixels,moving_pixels,time_s,error\n",
                Metrics::NAMES.join(",")
            );
            for f in &report.frames {
                let values: Vec<String> = match &f.metrics {
                    Ok(m) => Metrics::NAMES.iter().map(|k| csv_num(Some(m.get(k)))).collect(),
                    Err(_) => vec![String::new(); Metrics::NAMES.len()],
                };
                let c = f.change;
                out.push_str(&format!(
                    "{},{},{},{},{},{},{},{}\n",
                    csv_field(&f.stem),
                    values.join(","),
                    csv_num(c.map(|c| c.flicker)),
                    csv_num(c.map(|c| c.change_err)),
                    c.map_or(String::new(), |c| c.static_pixels.to_string()),
                    c.map_or(String::new(), |c| c.moving_pixels.to_string()),
                    csv_num(f.seconds),
                    csv_field(&f.metrics.as_ref().err().map_or(String::new(), |e| e.chain()))
                ));
            }
            out
        }
        super::Format::Table | super::Format::Markdown => {
            let mut rows = vec![
                ["frame", "avgErr", "bad2", "invalid", "flicker", "static px", "change err", "moving px", "time s"]
                    .map(String::from)
                    .to_vec(),
            ];
            // A figure over no pixels (NaN) reads "-", as in the mean row.
            let shown = |v: Option<f64>| fixed(v.filter(|v| v.is_finite()));
            for f in &report.frames {
                let mut row = vec![f.stem.clone()];
                match &f.metrics {
                    Ok(m) => row.extend(cols.iter().map(|k| fixed(Some(m.get(k))))),
                    Err(e) => {
                        row.extend(["-", "-", "-"].map(String::from));
                        row.push(format!("({})", e.chain()));
                        rows.push(row);
                        continue;
                    }
                }
                let count = |n: Option<u64>| n.map_or("-".to_string(), |n| n.to_string());
                row.push(shown(f.change.map(|c| c.flicker)));
                row.push(count(f.change.map(|c| c.static_pixels)));
                row.push(shown(f.change.map(|c| c.change_err)));
                row.push(count(f.change.map(|c| c.moving_pixels)));
                row.push(fixed(f.seconds));
                rows.push(row);
            }
            let mean = report.mean();
            let mut last = vec!["mean".to_string()];
            last.extend(cols.iter().map(|k| fixed(mean.map(|m| m.get(k)))));
            let [static_px, moving_px] = report.mean_pixels().map(|n| n.map_or("-".to_string(), |n| format!("{n:.0}")));
            last.extend([shown(report.flicker()), static_px, shown(report.change_err()), moving_px]);
            last.push(fixed(report.mean_seconds()));
            rows.push(last);
            let mut right_aligned = vec![true; rows[0].len()];
            right_aligned[0] = false;
            let table = Table { rows, right_aligned };
            let body = if format == super::Format::Markdown { table.markdown() } else { table.text() };
            let units =
                if report.scale == 1 { "px".to_string() } else { format!("full-resolution px (×{})", report.scale) };
            format!(
                "{} against {} ({}, errors in {units}; flicker: mean |d_t − d_t−1| over the static px, where the truth \
                 moved less than {STATIC_CHANGE_PX} px of its own resolution; change err: mean |Δd − Δg| over the \
                 moving px, where it moved more; both over pixels valid in both frames, - where there are none; the \
                 mean row: the means over the frames)\n{body}",
                report.results.display(),
                report.sequence.display(),
                report.mask.name()
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sequence::{SequenceFrame, write_sequence};

    fn map(values: &[f32]) -> DisparityMap {
        Plane::from_parts(values.len(), 1, values.to_vec())
    }

    /// Four pixels: static truth at 0–1 (the answer moves by 1, then not at all, where pixel 2's result is
    /// invalid), moving truth at 3 (2 → 5, the answer 2 → 4: an error of the change of 1).
    #[test]
    fn the_change_is_split_by_whether_the_truth_moved() {
        let inf = f32::INFINITY;
        let (g0, g1) = (map(&[3.0, 7.0, 1.0, 2.0]), map(&[3.2, 7.0, 1.0, 5.0]));
        let (d0, d1) = (map(&[3.0, 6.0, 1.0, 2.0]), map(&[4.0, 6.0, inf, 4.0]));
        let c = frame_change((&d0, &g0, None), (&d1, &g1, None), 64, 4, MaskMode::Nonocc);
        assert_eq!((c.static_pixels, c.moving_pixels), (2, 1));
        assert_eq!((c.flicker, c.change_err), (4.0 * (1.0 + 0.0) / 2.0, 4.0 * 1.0));
        // A mask drops a pixel when either frame's mask does not select it; all (> 0) keeps occluded ones.
        let (m0, m1) = (Plane::from_parts(4, 1, vec![255, 128, 255, 255]), Plane::from_parts(4, 1, vec![255; 4]));
        let c = frame_change((&d0, &g0, Some(&m0)), (&d1, &g1, Some(&m1)), 64, 1, MaskMode::Nonocc);
        assert_eq!((c.static_pixels, c.flicker), (1, 1.0));
        let c = frame_change((&d0, &g0, Some(&m0)), (&d1, &g1, Some(&m1)), 64, 1, MaskMode::All);
        assert_eq!(c.static_pixels, 2);
        // Results are clipped to the range first: 4 → 3 with ndisp 3.
        let c = frame_change((&d0, &g0, None), (&d1, &g1, None), 3, 1, MaskMode::All);
        assert_eq!((c.flicker, c.change_err), (0.0, 2.0));
        let none = frame_change((&d0, &map(&[inf; 4]), None), (&d1, &g1, None), 64, 1, MaskMode::All);
        assert!(none.static_pixels == 0 && none.flicker.is_nan() && none.change_err.is_nan());
    }

    /// A three-frame sequence whose truth is 10 everywhere, then 10 on the left half and 12 on the right; the
    /// results written by hand.
    fn sequence(dir: &Path) -> Sequence {
        let truth = |k: usize| {
            Plane::from_parts(4, 2, (0..8).map(|i| if k == 2 && i % 4 >= 2 { 12.0 } else { 10.0 }).collect())
        };
        let mut frame = |k: usize| {
            let img = crate::image::RgbImage::new(4, 2);
            Ok(SequenceFrame { left: img.clone(), right: img, gt: Some(truth(k)), mask: None })
        };
        write_sequence(&dir.join("seq"), 3, &mut frame, &mut || vec![("calib.txt", "ndisp=16\n".into())]).unwrap();
        Sequence::open(&dir.join("seq")).unwrap()
    }

    #[test]
    fn a_sequence_is_scored_per_frame_and_between_frames() {
        let dir = tempfile::tempdir().unwrap();
        let seq = sequence(dir.path());
        let out = dir.path().join("out");
        std::fs::create_dir(&out).unwrap();
        // Frame 0 exact; frame 1 off by 1 on every pixel; frame 2 exact.
        let results = [[10.0; 8], [11.0; 8], [10.0, 10.0, 12.0, 12.0, 10.0, 10.0, 12.0, 12.0]];
        for (k, r) in results.iter().enumerate() {
            crate::io::pfm::write_pfm(&out.join(format!("{k:06}.pfm")), &Plane::from_parts(4, 2, r.to_vec())).unwrap();
        }
        std::fs::write(out.join(crate::sequence::TIMES_FILE), "000000 1.5\n000001 2.5\n").unwrap();
        let report = evaluate_sequence(&out, &seq, MaskMode::Nonocc, 2, None).unwrap();
        let avg: Vec<f64> = report.frames.iter().map(|f| f.metrics.as_ref().unwrap().avgerr).collect();
        assert_eq!(avg, [0.0, 2.0, 0.0]);
        assert_eq!(report.frames[0].change, None);
        let (c1, c2) = (report.frames[1].change.unwrap(), report.frames[2].change.unwrap());
        assert_eq!((c1.static_pixels, c1.flicker, c1.moving_pixels), (8, 2.0, 0));
        // Into frame 2: the left half static (11 → 10: a change of 1), the right half moved by 2 and so did the
        // answer (11 → 12: a change of 1 against 2).
        assert_eq!((c2.static_pixels, c2.flicker, c2.moving_pixels, c2.change_err), (4, 2.0, 4, 2.0));
        assert_eq!((report.flicker(), report.change_err()), (Some(2.0), Some(2.0)));
        assert_eq!(report.mean().unwrap().avgerr, 2.0 / 3.0);
        assert_eq!(report.mean_of(1..3).unwrap().avgerr, 1.0);
        assert_eq!(report.mean_seconds(), Some(2.0));
        let text = render_sequence(&report, crate::eval::Format::Table);
        assert!(text.contains("errors in full-resolution px (×2)") && text.lines().last().unwrap().starts_with("mean"));
        // The table names the threshold and the pixels each figure covers; a figure over no pixels reads "-" per
        // frame as in the mean row (frame 1 has no moving pixel).
        assert!(text.contains("moved less than 0.5 px") && text.contains("static px") && text.contains("moving px"));
        let cells = |stem: &str| -> Vec<String> {
            let line = text.lines().find(|l| l.starts_with(stem)).unwrap();
            line.split_whitespace().map(String::from).collect()
        };
        assert_eq!(cells("000001")[4..8], ["2.00", "8", "-", "0"], "{text}");
        assert_eq!(cells("000002")[4..8], ["2.00", "4", "2.00", "4"], "{text}");
        assert_eq!(cells("mean")[4..8], ["2.00", "6", "2.00", "2"], "{text}");
        assert!(!text.contains("nan"), "{text}");
        let json = render_sequence(&report, crate::eval::Format::Json);
        assert!(json.contains("\"flicker\": 2, \"change_err\": 2") && json.contains("\"scale\": 2"), "{json}");
        // A missing result is listed, and the changes into and out of it are not scored.
        std::fs::remove_file(out.join("000001.pfm")).unwrap();
        let report = evaluate_sequence(&out, &seq, MaskMode::Nonocc, 1, None).unwrap();
        assert!(report.frames[1].metrics.as_ref().unwrap_err().to_string().contains("no result"));
        assert!(report.frames[1].change.is_none() && report.frames[2].change.is_none());
        assert_eq!(report.excluded().count(), 1);
        assert_eq!(report.flicker(), None);
    }

    #[test]
    fn a_sequence_without_truth_or_results_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let seq = sequence(dir.path());
        let e = evaluate_sequence(dir.path(), &seq, MaskMode::Nonocc, 1, None).unwrap_err().to_string();
        assert!(e.contains("no frame could be scored") && e.contains("no result"), "{e}");
        let bare = Sequence {
            frames: seq.frames.iter().map(|f| crate::sequence::Frame { gt: None, ..f.clone() }).collect(),
            ..seq
        };
        let e = evaluate_sequence(dir.path(), &bare, MaskMode::Nonocc, 1, None).unwrap_err().to_string();
        assert!(e.contains("no ground truth"), "{e}");
    }
}
