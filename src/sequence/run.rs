//! Matching a sequence frame by frame into an output folder ([`run`]).
//!
//! Each frame is matched alone, the way `jem match` matches a pair: the range from [`Sequence::ndisp_source`]
//! ([`RangeRule::PerFrame`]: settled on each frame as `jem match` settles it, so every frame's map is byte for byte
//! `jem match`'s on that pair with `--ndisp` or the sequence's `calib.txt` beside it), matched by a
//! [`Matcher`].
//!
//! # The output folder
//! - `<stem>.<ext>`: each frame's disparity map (`pfm`, `exr` or `png` as [`crate::io::DisparityFormat`]);
//! - [`TIMES_FILE`]: one line per frame written, `<stem> <seconds>`, in frame order (the seconds from the decoded
//!   pair to its disparity map: the range measurement when there is one, and the run; loading and writing are
//!   left out);
//! - [`RUN_FILE`]: what made the folder (the sequence, the mode, the output format, a fingerprint of the
//!   configuration, and of the rectification with `--rectify`), and [`CONFIG_FILE`], the effective configuration;
//!   both written with the first frame, so a run that writes no frame leaves no record (nor a folder it made);
//! - `.jem-lock` while a run writes into it ([`crate::dataset::lock_folder`]): a second run is refused.
//!
//! Each frame's map and the times file are written together, all or none ([`crate::io::write_all_or_none`]), so an
//! interrupted run leaves only whole frames. A rerun into the same folder with the same sequence, mode, format,
//! configuration and rectification skips the frames already there (a map that decodes at the frame's size, with
//! its time) and runs the rest; a folder written by another run is refused rather than mixed. A file where an
//! output goes that is not a regular file (a FIFO) is refused before anything is read from it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{FOLDERS, KITTI_RAW, Sequence, SequenceLayout};
use crate::error::{Error, Result};
use crate::io::DisparityFormat;
use crate::matcher::Matcher;
use crate::setup::NdispSource;

/// The times file of an output folder.
pub const TIMES_FILE: &str = "times.txt";
/// The record of what made an output folder.
pub const RUN_FILE: &str = "sequence.txt";
/// The effective configuration of the run that made an output folder.
pub const CONFIG_FILE: &str = "config.toml";

/// The largest record or times file read back (a line per frame: a million frames fit).
const MAX_RECORD_BYTES: u64 = 64 << 20;

/// How the search range is settled over a sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RangeRule {
    /// On each frame, as `jem match` does on that pair.
    PerFrame,
    /// Once, on the first frame, then held (a range measured on the first frame is used as given for the
    /// others; a new near object later in the sequence is not looked for).
    FirstFrame,
}

/// What [`run`] does besides matching (how each frame is matched is the [`Matcher`]'s: its parameters, range,
/// memory limit, smallest disparity, rectification and temporal model).
#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    /// The output format.
    pub format: DisparityFormat,
    /// How the range is settled (a temporal matcher, [`Matcher::with_temporal`], holds the first frame's range
    /// whatever this says).
    pub range: RangeRule,
}

/// One frame matched.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRun {
    /// The frame's stem.
    pub stem: String,
    /// Its size.
    pub size: (usize, usize),
    /// The range it ran with.
    pub ndisp: usize,
    /// Whether that range was measured on it.
    pub ndisp_measured: bool,
    /// Seconds from the decoded pair to the disparity map (see the module doc).
    pub seconds: f64,
    /// The share of its pixels with a disparity (0–1).
    pub valid: f64,
    /// How the temporal model matched it (`None` without the model).
    pub kind: Option<crate::temporal::FrameKind>,
    /// The exposure change the temporal model compensated in it (`None`: none, or without the model).
    pub exposure: Option<crate::temporal::Exposure>,
    /// The pipeline's stages and their seconds, in order (a stage run more than once, summed).
    pub stages: Vec<(&'static str, f64)>,
}

/// What [`run`] reports as it goes (in frame order, from the calling thread).
#[derive(Debug)]
pub enum Event<'a> {
    /// A line to show before the frames (the stale lock of a run that is gone, taken over).
    Note(&'a str),
    /// Frame `index` is in the folder already and is not run again.
    Skipped {
        /// Its position in the sequence.
        index: usize,
        /// Its stem.
        stem: &'a str,
    },
    /// Frame `index` is in the folder already and is matched again without writing, to rebuild the temporal
    /// model's state for the frames after it.
    Replayed {
        /// Its position in the sequence.
        index: usize,
        /// Its stem.
        stem: &'a str,
    },
    /// Frame `index` starts.
    Started {
        /// Its position in the sequence.
        index: usize,
        /// Its stem.
        stem: &'a str,
    },
    /// A stage of the current frame starts.
    Stage {
        /// The frame's position.
        index: usize,
        /// The stage.
        stage: &'a str,
    },
    /// Frame `index` is written.
    Finished {
        /// Its position in the sequence.
        index: usize,
        /// What the run gave.
        run: &'a FrameRun,
    },
}

/// What [`run`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunSummary {
    /// The frames run, in order.
    pub ran: Vec<FrameRun>,
    /// The stems of the frames skipped (written by an earlier run).
    pub skipped: Vec<String>,
    /// The stems of the frames matched again, not written, to rebuild the temporal model's state.
    pub replayed: Vec<String>,
    /// The range every frame ran with under [`RangeRule::FirstFrame`], and whether it was measured.
    pub settled: Option<(usize, bool)>,
}

/// Matches every frame of `seq` into the folder `out` (created if missing), skipping frames an earlier run of
/// the same kind left there (see the module doc), each with `matcher` (the range it is given, else the one the
/// sequence's `calib.txt` states: [`Sequence::ndisp_source`]; no confidence map or pair check is made, as none is
/// written). Frames run one after another; each uses the threads of the current rayon pool. The folder is locked
/// against a second run for the time of this one ([`crate::dataset::lock_folder`]), and its record ([`RUN_FILE`],
/// [`CONFIG_FILE`]) is written with the first frame: a run that writes no frame leaves nothing (a folder it made is
/// removed again).
///
/// # Errors
/// [`Error::Output`] when `out` is the sequence folder or one of its input folders, a file, or holds another run's
/// results, or a file where an output goes is not a regular file; [`Error::Locked`] when another run holds its lock;
/// any error of loading, planning (memory) or running a frame, naming the frame ([`Error::Frame`]). Frames written
/// before the error stay, whole, and a rerun continues from them.
pub fn run(
    seq: &Sequence,
    out: &Path,
    matcher: Matcher,
    opts: &RunOptions,
    on_event: &dyn Fn(Event<'_>),
) -> Result<RunSummary> {
    check_output_folder(seq, out)?;
    let source = seq.ndisp_source(matcher.ndisp())?;
    let matcher = matcher.with_ndisp(source).with_confidence(false).with_checks(false);
    let record = record_text(seq, &matcher, opts, source);
    let created = make_folder(out)?;
    let result = (|| {
        let lock = crate::dataset::lock_folder(out)?;
        for note in lock.taken_over() {
            on_event(Event::Note(note));
        }
        crate::io::sweep_stale_temps(out);
        run_locked(seq, out, matcher, opts, &record, on_event)
    })();
    if result.is_err() && created {
        // Empty unless a frame was written (then it stays, with its record, for a rerun to continue).
        let _ = std::fs::remove_dir(out);
    }
    result
}

/// Creates the output folder `out` if missing; whether it was created.
///
/// # Errors
/// [`Error::Output`] when it exists and is not a folder, [`Error::Io`] when it cannot be made.
fn make_folder(out: &Path) -> Result<bool> {
    let created = !out.is_dir();
    crate::io::create_folder(out)?;
    Ok(created)
}

/// [`run`] in the locked folder.
fn run_locked(
    seq: &Sequence,
    out: &Path,
    mut matcher: Matcher,
    opts: &RunOptions,
    record: &str,
    on_event: &dyn Fn(Event<'_>),
) -> Result<RunSummary> {
    let ext = extension(opts.format);
    let results = seq.frames.iter().map(|f| out.join(format!("{}.{ext}", f.stem)));
    for path in [RUN_FILE, CONFIG_FILE, TIMES_FILE].map(|n| out.join(n)).into_iter().chain(results) {
        crate::io::check_replaceable(&path)?;
    }
    claim_folder(seq, out, ext, record)?;
    let config = matcher.params().to_toml();
    let mut recorded = false;
    let mut times = read_times(&out.join(TIMES_FILE));
    // Each map is decoded once, here, before any frame runs: the frames written after a frame decide whether it is
    // replayed, and asking each frame about every later one would decode n²/2 maps.
    let written = written_frames(seq, out, ext, &times);
    let last_missing = written.iter().rposition(|w| !w);
    let order: std::collections::HashMap<&str, usize> =
        seq.frames.iter().enumerate().map(|(i, f)| (f.stem.as_str(), i)).collect();
    let mut summary = RunSummary::default();
    for (index, frame) in seq.frames.iter().enumerate() {
        let named = |e: Error| Error::Frame { stem: frame.stem.clone(), source: Box::new(e) };
        let result = out.join(format!("{}.{ext}", frame.stem));
        if opts.range == RangeRule::FirstFrame && index == 0 {
            let settled = (|| {
                let (l, r) = matcher.read_pair(&frame.left, &frame.right)?;
                matcher.search_range(&l, &r)
            })()
            .map_err(named)?;
            summary.settled = Some(settled);
            matcher = matcher.with_ndisp(NdispSource::Given(settled.0));
        }
        if written[index] {
            // The temporal model's state after a frame is not in the folder: a written frame before one still to
            // run is matched again to rebuild it (not written again); once every frame is written, none is.
            if matcher.is_temporal() && last_missing.is_some_and(|m| m > index) {
                on_event(Event::Replayed { index, stem: &frame.stem });
                match_frame(&mut matcher, frame, &|_| {}).map_err(named)?;
                summary.replayed.push(frame.stem.clone());
            } else {
                on_event(Event::Skipped { index, stem: &frame.stem });
                summary.skipped.push(frame.stem.clone());
            }
            continue;
        }
        times.retain(|(s, _)| *s != frame.stem);
        on_event(Event::Started { index, stem: &frame.stem });
        let on_stage = |stage: &str| on_event(Event::Stage { index, stage });
        let (map, run) = match_frame(&mut matcher, frame, &on_stage).map_err(named)?;
        on_event(Event::Stage { index, stage: "writing" });
        times.push((frame.stem.clone(), run.seconds));
        times.sort_by_key(|(s, _)| order.get(s.as_str()).copied());
        let bytes = crate::io::encode_disparity(&result, &map).map_err(named)?;
        let times_text: String = times.iter().map(|(s, t)| format!("{s} {t:.6}\n")).collect();
        let (run_file, config_file, times_file) = (out.join(RUN_FILE), out.join(CONFIG_FILE), out.join(TIMES_FILE));
        let mut files: Vec<(&Path, &[u8])> = vec![(&result, &bytes), (&times_file, times_text.as_bytes())];
        if !recorded {
            // With the first frame written, never before: a run that fails before it leaves no record.
            files.extend([(run_file.as_path(), record.as_bytes()), (config_file.as_path(), config.as_bytes())]);
        }
        crate::io::write_all_or_none(&files).map_err(named)?;
        recorded = true;
        on_event(Event::Finished { index, run: &run });
        summary.ran.push(run);
    }
    Ok(summary)
}

/// Matches one frame as `jem match` does: headers and the memory limit before decoding, then the run (the
/// rectification first when the matcher has one).
fn match_frame(
    matcher: &mut Matcher,
    frame: &super::Frame,
    on_stage: &dyn Fn(&str),
) -> Result<(crate::image::DisparityMap, FrameRun)> {
    on_stage("loading");
    let (l, r) = matcher.read_pair(&frame.left, &frame.right)?;
    let stem = &frame.stem;
    let start = Instant::now();
    let out = matcher.match_pair_with(&l, &r, &|progress| {
        if let crate::matcher::Progress::Stage(stage) = progress {
            on_stage(stage);
        }
    })?;
    let seconds = start.elapsed().as_secs_f64();
    let map = out.disparity;
    let valid = map.data.iter().filter(|d| d.is_finite()).count() as f64 / map.data.len().max(1) as f64;
    let run = FrameRun {
        stem: stem.to_string(),
        size: map.dims(),
        ndisp: out.plan.ndisp,
        ndisp_measured: out.plan.ndisp_measured,
        seconds,
        valid,
        kind: out.frame,
        exposure: out.exposure,
        stages: stage_seconds(&out.timings),
    };
    Ok((map, run))
}

/// `timings` as (stage, seconds), each stage once, in the order first run.
fn stage_seconds(timings: &crate::pipeline::Timings) -> Vec<(&'static str, f64)> {
    timings.per_stage().stages.iter().map(|&(name, d)| (name, d.as_secs_f64())).collect()
}

/// The file extension of a format.
pub(crate) fn extension(format: DisparityFormat) -> &'static str {
    match format {
        DisparityFormat::Pfm => "pfm",
        DisparityFormat::Exr => "exr",
        DisparityFormat::Png16 => "png",
    }
}

/// The record of a run ([`RUN_FILE`]): `key=value` lines. A rerun must match it to continue the folder.
fn record_text(seq: &Sequence, matcher: &Matcher, opts: &RunOptions, source: NdispSource) -> String {
    let root = std::fs::canonicalize(&seq.root).unwrap_or_else(|_| seq.root.clone());
    let range = match (opts.range, source) {
        (_, NdispSource::Given(n)) => format!("given {n}"),
        (RangeRule::PerFrame, NdispSource::Stated(n)) => format!("calib.txt {n}, per frame"),
        (RangeRule::FirstFrame, NdispSource::Stated(n)) => format!("calib.txt {n}, first frame"),
        (RangeRule::PerFrame, NdispSource::Unknown) => "measured per frame".into(),
        (RangeRule::FirstFrame, NdispSource::Unknown) => "measured on the first frame".into(),
    };
    // The configuration, and a bound on the confidence when there is one (it changes the maps as a parameter
    // does; without one the fingerprint is that of the configuration alone, as before the bound existed).
    let bound = matcher.min_confidence().map_or(String::new(), |c| format!("\nmin_confidence = {c}\n"));
    let config = matcher.params().to_toml() + &bound;
    let fingerprint = crate::rng::fnv1a(crate::rng::FNV_OFFSET, config.as_bytes());
    // What the rectification does (its cameras, rotations and projections), not only the file it came from: a
    // calibration file changed in place rectifies the frames differently.
    let rectify = matcher.rectification().map_or("none".to_string(), |r| format!("{:016x}", r.fingerprint()));
    // Only when set: the records of runs from 0 (every run before the option existed) stay as they were.
    let range = match matcher.min_disp() {
        0 => range,
        d => format!("{range}, from {d}"),
    };
    format!(
        "source={}\nmode={}\nformat={}\nrange={range}\nconfig={fingerprint:016x}\nrectify={rectify}\njem={}\n",
        root.display(),
        if matcher.is_temporal() { "temporal" } else { "independent" },
        extension(opts.format),
        env!("CARGO_PKG_VERSION")
    )
}

/// Reads the `source=` line of an output folder's [`RUN_FILE`]: the sequence it holds the results of.
pub fn recorded_source(out: &Path) -> Option<PathBuf> {
    let text = crate::io::read_small_text(&out.join(RUN_FILE), MAX_RECORD_BYTES)?;
    text.lines().find_map(|l| l.strip_prefix("source=")).map(PathBuf::from)
}

/// Refuses an output folder that is the sequence folder itself or lies in one of its input folders.
fn check_output_folder(seq: &Sequence, out: &Path) -> Result<()> {
    let real = |p: &Path| std::fs::canonicalize(p).ok();
    let Some(out_real) = real(out).or_else(|| {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        Some(real(parent)?.join(out.file_name()?))
    }) else {
        return Ok(());
    };
    let Some(root) = real(&seq.root) else { return Ok(()) };
    let inputs: &[&str] = match seq.layout {
        SequenceLayout::Folders => &FOLDERS,
        SequenceLayout::KittiRaw => &KITTI_RAW,
    };
    if out_real == root || inputs.iter().any(|f| out_real.starts_with(root.join(f))) {
        return Err(Error::output_at(
            out,
            format!(
                "the output folder must not be the sequence folder {} or one of its frame folders",
                seq.root.display()
            ),
        ));
    }
    Ok(())
}

/// Takes `out` for this run: a folder without a record is new (unless it holds frame results, which another
/// program wrote); one with a record continues only when the record is this run's.
fn claim_folder(seq: &Sequence, out: &Path, ext: &str, record: &str) -> Result<()> {
    let path = out.join(RUN_FILE);
    if !path.exists() {
        let foreign =
            out.join(TIMES_FILE).exists() || seq.frames.iter().any(|f| out.join(format!("{}.{ext}", f.stem)).exists());
        if foreign {
            return Err(Error::output_at(
                out,
                format!(
                    "holds frame results without a {RUN_FILE}; refusing to mix them with this run's (use another \
                 folder)"
                ),
            ));
        }
        return Ok(());
    }
    let old = String::from_utf8(crate::io::read_capped(&path, MAX_RECORD_BYTES, RUN_FILE)?)
        .map_err(|_| Error::output_at(&path, "not a text file; use another folder"))?;
    let keys = ["source", "mode", "format", "range", "config", "rectify"];
    let value = |text: &str, key: &str| {
        text.lines().find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix('='))).map(str::to_owned)
    };
    if let Some(key) = keys.iter().find(|k| value(&old, k) != value(record, k)) {
        let what = match (*key, value(&old, key)) {
            ("config", _) => format!("another configuration (see {CONFIG_FILE})"),
            ("rectify", Some(r)) if r == "none" => "unrectified frames (this run has --rectify)".to_string(),
            ("rectify", Some(_)) if value(record, key).as_deref() == Some("none") => {
                "rectified frames (this run has no --rectify)".to_string()
            }
            ("rectify", Some(_)) => "another rectification (another calibration)".to_string(),
            (_, None) => format!("no {key} recorded (an older jem's run)"),
            (_, Some(v)) => format!("{key} {v}"),
        };
        return Err(Error::output_at(
            &path,
            format!("holds the results of another run, with {what}; use another folder"),
        ));
    }
    Ok(())
}

/// The `(stem, seconds)` lines of a times file (none when it is missing or unreadable).
fn read_times(path: &Path) -> Vec<(String, f64)> {
    let text = crate::io::read_small_text(path, MAX_RECORD_BYTES).unwrap_or_default();
    text.lines()
        .filter_map(|l| {
            let (stem, seconds) = l.rsplit_once(' ')?;
            Some((stem.to_string(), seconds.trim().parse().ok()?))
        })
        .collect()
}

/// Which frames an earlier run finished: a line in the times file and a map that decodes at the frame's size.
fn written_frames(seq: &Sequence, out: &Path, ext: &str, times: &[(String, f64)]) -> Vec<bool> {
    let timed: std::collections::HashSet<&str> = times.iter().map(|(s, _)| s.as_str()).collect();
    let map = |f: &super::Frame| out.join(format!("{}.{ext}", f.stem));
    seq.frames.iter().map(|f| timed.contains(f.stem.as_str()) && is_complete(&map(f), &f.left)).collect()
}

#[cfg(test)]
thread_local! {
    /// The maps [`is_complete`] read on this thread (a test counts them: a rerun reads each map once).
    pub(super) static MAPS_READ: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Whether `result` is a finished frame: a disparity map that decodes, at the size of the frame's left image.
fn is_complete(result: &Path, left: &Path) -> bool {
    #[cfg(test)]
    MAPS_READ.with(|n| n.set(n.get() + 1));
    let Ok(map) = crate::io::read_disparity(result) else { return false };
    crate::io::png::read_header(left).is_ok_and(|h| (h.width, h.height) == map.dims())
}
