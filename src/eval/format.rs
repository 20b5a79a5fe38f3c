//! Printing [`AlgReport`]s: [`render`] writes an aligned text table or Markdown tables (two decimals, laid out
//! by [`Table`]), one JSON object per algorithm, or CSV rows (full precision).

use std::fmt::Write as _;
use std::str::FromStr;

use super::metrics::Metrics;
use super::paper::PaperColumn;
use super::regions::RegionReport;
use super::report::AlgReport;
use super::sparsification::Sparsification;
use super::text::{fixed, json_num, json_str};
use crate::error::Error;
use crate::table::Table;

/// How [`render`] prints reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Aligned plain-text table, two decimals.
    Table,
    /// Comma-separated values, full precision, one row per (algorithm, scene) plus `weighted` and `mean` rows.
    Csv,
    /// One JSON object per algorithm (an array when several), full precision; NaN is `null`.
    Json,
    /// GitHub-flavoured Markdown tables, two decimals.
    Markdown,
}

impl FromStr for Format {
    type Err = Error;
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        match s {
            "table" => Ok(Format::Table),
            "csv" => Ok(Format::Csv),
            "json" => Ok(Format::Json),
            "markdown" | "md" => Ok(Format::Markdown),
            _ => Err(Error::argument(format!("unknown format {s:?} (expected table, csv, json or markdown)"))),
        }
    }
}

/// Renders reports; `papers[i]` (if any) is printed beside `reports[i]`'s avgerr.
///
/// JSON: `{"alg", "layout", "mask", "scale", "scenes": {NAME: {metrics}}, "weighted": {metrics}|null, "mean": ...}`
/// with the keys of [`AlgReport::columns`] ([`Metrics::NAMES`], or [`Metrics::KITTI_NAMES`] with `d1`); scenes that could not be evaluated are left out of `scenes`, and then an
/// `"excluded": {NAME: "reason"}` key is added; with a paper column, `"paper": {"column", "scenes", "weighted"}`.
///
/// # Panics
/// If `papers` is non-empty and not as long as `reports`.
pub fn render(reports: &[AlgReport], papers: &[Option<PaperColumn>], format: Format) -> String {
    render_with_regions(reports, papers, &[], format)
}

/// [`render`], and with `regions` (one per report, from [`split_report`](super::split_report); `jem eval
/// --regions`) where the error is: in JSON a `"regions"` member per algorithm (see
/// [`super::RegionReport`]), in text and Markdown the tables of
/// [`render_regions`](super::render_regions) after each report's.
///
/// # Panics
/// As [`render`], or if `regions` is non-empty and not as long as `reports`, or with CSV and regions (the CLI
/// refuses that first).
pub fn render_with_regions(
    reports: &[AlgReport],
    papers: &[Option<PaperColumn>],
    regions: &[RegionReport],
    format: Format,
) -> String {
    assert!(papers.is_empty() || papers.len() == reports.len(), "one paper column per report");
    assert!(regions.is_empty() || regions.len() == reports.len(), "one region split per report");
    assert!(regions.is_empty() || format != Format::Csv, "no region split in CSV");
    let paper: Vec<Option<&PaperColumn>> = (0..reports.len()).map(|i| papers.get(i).and_then(Option::as_ref)).collect();
    let paper = paper.as_slice();
    match format {
        Format::Json => render_json(reports, paper, regions),
        Format::Csv => render_csv(reports, paper),
        Format::Table | Format::Markdown => {
            let md = format == Format::Markdown;
            let mut out = render_text(reports, paper, md);
            out.push_str(&super::render_regions(regions, md));
            out
        }
    }
}

fn json_metrics(m: Option<&Metrics>, columns: &[&str]) -> String {
    match m {
        None => "null".into(),
        Some(m) => {
            let fields: Vec<String> =
                columns.iter().map(|k| format!("{}: {}", json_str(k), json_num(m.get(k)))).collect();
            format!("{{{}}}", fields.join(", "))
        }
    }
}

fn render_json(reports: &[AlgReport], paper: &[Option<&PaperColumn>], regions: &[RegionReport]) -> String {
    let objects: Vec<String> = reports
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let cols = r.columns();
            let scenes: Vec<String> = r
                .scenes
                .iter()
                .filter_map(|s| {
                    s.metrics.as_ref().ok().map(|m| {
                        let mut fields = json_metrics(Some(m), cols);
                        if let Some(sp) = s.sparsification {
                            fields.pop();
                            let _ = write!(
                                fields,
                                ", \"auc\": {}, \"auc_optimum\": {}}}",
                                json_num(sp.auc),
                                json_num(sp.optimum)
                            );
                        }
                        format!("    {}: {}", json_str(&s.name), fields)
                    })
                })
                .collect();
            let mut o = format!(
                "{{\n  \"alg\": {},\n  \"layout\": {},\n  \"mask\": {},\n  \"scale\": {},\n  \"scenes\": {{{}}},\n  \
                 \"weighted\": {},\n  \"mean\": {}",
                json_str(&r.alg),
                json_str(r.layout.name()),
                json_str(r.mask.name()),
                r.scale,
                if scenes.is_empty() { String::new() } else { format!("\n{}\n  ", scenes.join(",\n")) },
                json_metrics(r.weighted().as_ref(), cols),
                json_metrics(r.mean().as_ref(), cols),
            );
            if let Some((sp, n)) = r.mean_sparsification() {
                let _ = write!(
                    o,
                    ",\n  \"sparsification\": {{\"auc\": {}, \"auc_optimum\": {}, \"scenes\": {n}}}",
                    json_num(sp.auc),
                    json_num(sp.optimum)
                );
            }
            let excluded: Vec<String> =
                r.excluded().map(|(n, e)| format!("{}: {}", json_str(n), json_str(&e))).collect();
            if !excluded.is_empty() {
                let _ = write!(o, ",\n  \"excluded\": {{{}}}", excluded.join(", "));
            }
            if let Some(p) = paper[i] {
                let scenes: Vec<String> =
                    p.scenes.iter().map(|(k, v)| format!("{}: {}", json_str(k), json_num(*v))).collect();
                let _ = write!(
                    o,
                    ",\n  \"paper\": {{\"column\": {}, \"scenes\": {{{}}}, \"weighted\": {}}}",
                    json_str(&p.name),
                    scenes.join(", "),
                    p.weighted.map_or("null".into(), json_num)
                );
            }
            if let Some(split) = regions.get(i) {
                let _ = write!(o, ",\n  \"regions\": {}", super::regions_format::regions_json(split));
            }
            o.push_str("\n}");
            o
        })
        .collect();
    if objects.len() == 1 { format!("{}\n", objects[0]) } else { format!("[\n{}\n]\n", objects.join(",\n")) }
}

pub(super) fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

pub(super) fn csv_num(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v}"),
        Some(_) => "nan".into(),
        None => String::new(),
    }
}

fn render_csv(reports: &[AlgReport], paper: &[Option<&PaperColumn>]) -> String {
    // One header for all reports (they come from one data set): the first report's columns.
    let cols = reports.first().map_or(&Metrics::NAMES[..], AlgReport::columns);
    let mut out = format!("alg,mask,scale,scene,weight,{},time_s,paper,error\n", cols.join(","));
    for (i, r) in reports.iter().enumerate() {
        let p = paper[i];
        let prefix = format!("{},{},{}", csv_field(&r.alg), r.mask.name(), r.scale);
        let mut row =
            |scene: &str, weight: Option<f64>, m: Option<&Metrics>, t: Option<f64>, pv: Option<f64>, e: &str| {
                let values: Vec<String> = match m {
                    Some(m) => cols.iter().map(|k| csv_num(Some(m.get(k)))).collect(),
                    None => vec![String::new(); cols.len()],
                };
                let _ = writeln!(
                    out,
                    "{prefix},{},{},{},{},{},{}",
                    csv_field(scene),
                    csv_num(weight),
                    values.join(","),
                    csv_num(t),
                    csv_num(pv),
                    csv_field(e)
                );
            };
        for s in &r.scenes {
            let pv = p.and_then(|p| p.scenes.get(&s.name).copied());
            match &s.metrics {
                Ok(m) => row(&s.name, Some(s.weight), Some(m), s.seconds, pv, ""),
                Err(e) => row(&s.name, Some(s.weight), None, s.seconds, pv, &e.chain()),
            }
        }
        let mean_t = r.mean_seconds().map(|(t, _)| t);
        row("weighted", None, r.weighted().as_ref(), None, p.and_then(|p| p.weighted), "");
        row("mean", None, r.mean().as_ref(), mean_t, None, "");
    }
    out
}

/// The table as aligned text, or as Markdown when `markdown`.
fn layout(table: &Table, markdown: bool) -> String {
    if markdown { table.markdown() } else { table.text() }
}

fn render_text(reports: &[AlgReport], paper: &[Option<&PaperColumn>], md: bool) -> String {
    let mut out = String::new();
    if reports.len() > 1 {
        out.push_str(&layout(&summary_table(reports, paper), md));
        out.push('\n');
    }
    for (i, r) in reports.iter().enumerate() {
        let p = paper[i];
        let units = if r.layout == crate::dataset::Layout::Middlebury {
            format!("errors ×{} (full-resolution px)", r.scale)
        } else {
            format!("{}, errors in native px", r.layout.name())
        };
        let title = format!(
            "{} — mask {}, {units}{}",
            r.alg,
            r.mask.name(),
            p.map(|p| format!(", paper column {}", p.name)).unwrap_or_default()
        );
        if md {
            let _ = writeln!(out, "#### {title}\n");
        } else {
            let _ = writeln!(out, "{title}");
        }
        // The paper's avgErr goes right after ours.
        let cols = r.columns();
        let mut header: Vec<String> = vec!["scene".into(), "weight".into()];
        for k in cols {
            header.push(label(k).into());
            if p.is_some() && *k == "avgerr" {
                header.push("paper".into());
            }
        }
        // The confidence's AUC and its optimum (in %, as the bad columns) when a scene has a confidence map.
        let sparse = r.mean_sparsification();
        if sparse.is_some() {
            header.extend(["AUC".into(), "AUC opt".into()]);
        }
        header.push("time s".into());
        let ncol = header.len();
        let mut rows = vec![header];
        let mut push = |name: String,
                        weight: String,
                        m: Option<&Metrics>,
                        pv: Option<f64>,
                        sp: Option<Sparsification>,
                        t: Option<f64>| {
            let mut r = vec![name, weight];
            for k in cols {
                r.push(fixed(m.map(|m| m.get(k))));
                if p.is_some() && *k == "avgerr" {
                    r.push(fixed(pv));
                }
            }
            if sparse.is_some() {
                r.push(fixed(sp.map(|s| 100.0 * s.auc)));
                r.push(fixed(sp.map(|s| 100.0 * s.optimum)));
            }
            r.push(t.map_or("-".into(), |t| format!("{t:.3}")));
            rows.push(r);
        };
        for s in &r.scenes {
            let pv = p.and_then(|p| p.scenes.get(&s.name).copied());
            let name = if s.metrics.is_ok() { s.name.clone() } else { format!("{} (excluded)", s.name) };
            push(name, format!("{}", s.weight), s.metrics.as_ref().ok(), pv, s.sparsification, s.seconds);
        }
        let strong = |s: &str| {
            if md { format!("**{s}**") } else { s.to_string() }
        };
        push(strong("weighted"), String::new(), r.weighted().as_ref(), p.and_then(|p| p.weighted), None, None);
        let mean_sparse = sparse.map(|(s, _)| s);
        push("mean".into(), String::new(), r.mean().as_ref(), None, mean_sparse, r.mean_seconds().map(|(t, _)| t));
        let mut right_aligned = vec![true; ncol];
        right_aligned[0] = false;
        out.push_str(&layout(&Table { rows, right_aligned }, md));
        let evaluated = r.scenes.iter().filter(|s| s.metrics.is_ok()).count();
        let mut notes = vec![format!("{evaluated} of {} scenes evaluated", r.scenes.len())];
        if let Some((t, k)) = r.mean_seconds() {
            notes.push(format!("mean time per pair {t:.3} s (over {k})"));
        }
        if let Some((_, k)) = sparse {
            let bad = if r.layout.is_kitti() { "3 px" } else { "1 px at the resolution matched" };
            notes.push(format!(
                "AUC: the confidence map's sparsification AUC in % (bad: off by > {bad}; mean over {k})"
            ));
        }
        if md {
            out.push('\n');
        }
        let _ = writeln!(out, "{}.", notes.join("; "));
        let excluded: Vec<(&str, String)> = r.excluded().collect();
        if !excluded.is_empty() {
            let _ = writeln!(out, "Excluded from the averages:");
            for (n, e) in excluded {
                let _ = writeln!(out, "{}{n}: {e}", if md { "- " } else { "  " });
            }
        }
        out.push('\n');
    }
    out
}

/// A metric's column heading in text tables.
fn label(key: &str) -> &str {
    match key {
        "avgerr" => "avgErr",
        "d1" => "D1",
        k => k,
    }
}

/// One row per algorithm: (mean D1 for KITTI,) weighted and mean avgErr (and the paper's), weighted bad2 and
/// invalid, mean time.
fn summary_table(reports: &[AlgReport], paper: &[Option<&PaperColumn>]) -> Table {
    let has_paper = paper.iter().any(Option::is_some);
    let kitti = reports.iter().any(|r| r.layout.is_kitti());
    let mut header: Vec<String> = vec!["alg".into()];
    if kitti {
        header.push("mean D1".into());
    }
    header.push("weighted avgErr".into());
    if has_paper {
        header.extend(["paper".into(), "paper column".into()]);
    }
    header.extend(["mean avgErr", "weighted bad2", "weighted invalid", "scenes", "mean time s"].map(String::from));
    let mut rows = vec![header];
    for (i, r) in reports.iter().enumerate() {
        let w = r.weighted();
        let mut row = vec![r.alg.clone()];
        if kitti {
            row.push(fixed(r.mean().map(|m| m.d1)));
        }
        row.push(fixed(w.map(|m| m.avgerr)));
        if has_paper {
            let p = paper[i];
            row.push(fixed(p.and_then(|p| p.weighted)));
            row.push(p.map_or("-".into(), |p| p.name.clone()));
        }
        row.push(fixed(r.mean().map(|m| m.avgerr)));
        row.push(fixed(w.map(|m| m.bad2)));
        row.push(fixed(w.map(|m| m.invalid)));
        row.push(format!("{}/{}", r.scenes.iter().filter(|s| s.metrics.is_ok()).count(), r.scenes.len()));
        row.push(r.mean_seconds().map_or("-".into(), |(t, _)| format!("{t:.3}")));
        rows.push(row);
    }
    let ncol = rows[0].len();
    let paper_name_col = 3 + usize::from(kitti);
    let right_aligned = (0..ncol).map(|c| !(c == 0 || (has_paper && c == paper_name_col))).collect();
    Table { rows, right_aligned }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::MaskMode;
    use crate::eval::report::tests::scene;

    #[test]
    fn json_shape_and_nan() {
        let mut r = AlgReport {
            alg: "A\"B".into(),
            layout: crate::dataset::Layout::Middlebury,
            mask: MaskMode::All,
            scale: 2,
            scenes: vec![scene("Teddy", 1.5, true), scene("Pipes", 0.0, false)],
            scale_inferred: None,
            writers: Vec::new(),
        };
        if let Ok(m) = &mut r.scenes[0].metrics {
            m.rms = f64::NAN;
        }
        let json = render(&[r], &[], Format::Json);
        assert!(
            json.starts_with(
                "{\n  \"alg\": \"A\\\"B\",\n  \"layout\": \"middlebury\",\n  \"mask\": \"all\",\n  \"scale\": 2,\n"
            ),
            "{json}"
        );
        assert!(json.contains("\"Teddy\": {\"avgerr\": 1.5, \"rms\": null, \"bad0.5\": 0, \"bad1\": 0, \"bad2\": 10,"));
        assert!(json.contains("\"excluded\": {\"Pipes\": \"no result\"}"));
        assert!(!json.contains("\"paper\""));
    }
}
