//! The end-of-run report of a batch: one row per scene, the counts, and the failures.

use super::{SceneReport, SceneRun, SceneStatus};
use crate::table::Table;

/// A scene name (or path, or message holding one) on one line: control characters (a newline in a folder name)
/// are shown escaped (`\n`), so they cannot break the progress lines or the table.
pub fn one_line(text: &str) -> String {
    if text.chars().any(char::is_control) {
        text.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect()
    } else {
        text.to_string()
    }
}

/// The end-of-run table: scene, size, ndisp, seconds (and per-stage seconds with -v), status; then counts, with -v
/// what was measured on each pair (as `jem -v` prints it), and the failures.
pub fn summary(reports: &[SceneReport], verbose: bool) -> String {
    // Every stage any scene ran, in the order first run.
    let mut all = crate::pipeline::Timings::default();
    for r in reports.iter().filter(|_| verbose) {
        if let SceneStatus::Done(run) = &r.status {
            all.add_summed(&run.timings);
        }
    }
    let stages: Vec<&'static str> = all.stages.iter().map(|&(name, _)| name).collect();
    let mut header: Vec<String> = ["scene", "size", "ndisp", "seconds"].map(String::from).to_vec();
    header.extend(stages.iter().map(|s| s.to_string()));
    header.push("status".into());
    let mut rows = vec![header];
    let (mut done, mut skipped, mut failed, mut total_s) = (0, 0, 0, 0.0);
    for r in reports {
        let mut row = vec![one_line(&r.name)];
        match &r.status {
            SceneStatus::Done(run) => {
                done += 1;
                total_s += run.seconds;
                row.extend([
                    format!("{}x{}", run.size.0, run.size.1),
                    run.ndisp.to_string(),
                    format!("{:.3}", run.seconds),
                ]);
                let per_stage = run.timings.per_stage();
                for s in &stages {
                    let t = per_stage.stages.iter().find(|(n, _)| n == s).map_or(0.0, |(_, d)| d.as_secs_f64());
                    row.push(format!("{t:.3}"));
                }
                row.push("ok".into());
            }
            other => {
                row.extend(std::iter::repeat_n("-".to_string(), 3 + stages.len()));
                if matches!(other, SceneStatus::Skipped) {
                    skipped += 1;
                    row.push("skipped".into());
                } else {
                    failed += 1;
                    row.push("FAILED".into());
                }
            }
        }
        rows.push(row);
    }
    let ncol = rows.iter().map(Vec::len).max().unwrap_or(0);
    // The scene name and the status are text; the columns between them are numbers.
    let right_aligned = (0..ncol).map(|c| c >= 1 && c + 1 != ncol).collect();
    let mut out = Table { rows, right_aligned }.text();
    let mean = if done > 0 { format!(", mean {:.3} s per pair", total_s / done as f64) } else { String::new() };
    out.push_str(&format!(
        "{} scene(s): {done} done, {skipped} skipped, {failed} failed; pipeline time {total_s:.3} s{mean}\n",
        reports.len()
    ));
    if verbose {
        for r in reports {
            if let SceneStatus::Done(SceneRun { measured: Some(m), .. }) = &r.status {
                out.push_str(&format!("{}: {}\n", one_line(&r.name), m));
            }
        }
    }
    if failed > 0 {
        out.push_str("failures:\n");
        for r in reports {
            if let SceneStatus::Failed(e) = &r.status {
                let dir = one_line(&r.dir.display().to_string());
                out.push_str(&format!("  {} ({dir}): {}\n", one_line(&r.name), one_line(&e.to_string())));
            }
        }
    }
    out
}
