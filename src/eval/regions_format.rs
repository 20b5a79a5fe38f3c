//! Printing [`RegionReport`]s (`jem eval --regions`): four text or Markdown tables per algorithm
//! ([`render_regions`]), or a `"regions"` object inside eval's JSON ([`regions_json`]).

use std::fmt::Write as _;

use super::regions::{REGION_KEYS, RegionReport, RegionSplit, SIZE_KEYS};
use super::text::{fixed, json_num, json_str};
use crate::table::Table;

/// Column headings of the regions, in [`REGION_KEYS`] order.
const REGION_LABELS: [&str; 5] = ["rejected", "near edge", "textureless", "near occl.", "rest"];
/// Column headings of the error sizes, in [`SIZE_KEYS`] order.
const SIZE_LABELS: [&str; 5] = ["≤1", "1–2", "2–4", "4–8", ">8"];

/// The rejected region's value, `None` ("-") when the scene had no left-right mask.
fn region_value(s: &RegionSplit, k: usize, v: f64) -> Option<f64> {
    (k > 0 || s.has_lr_mask).then_some(v)
}

/// The tables of each report as aligned text, or Markdown when `markdown`: avgErr by region, gross errors by
/// region, pixels by region, avgErr by error size; a row per scene and the weighted row.
pub fn render_regions(reports: &[RegionReport], markdown: bool) -> String {
    let mut out = String::new();
    for r in reports {
        let heading = |out: &mut String, title: &str| {
            if markdown {
                let _ = writeln!(out, "#### {title}\n");
            } else {
                let _ = writeln!(out, "{title}");
            }
        };
        let units = format!("nonocc, errors ×{}, full-resolution px", r.scale);
        let tables: [(String, &[&str], Row); 4] = [
            (
                format!(
                    "{} — avgErr by region ({units}): a region's error sum / all scored pixels, so a row's regions \
                     add up to its avgErr",
                    r.alg
                ),
                &REGION_LABELS,
                |s| (Some(s.avgerr), (0..5).map(|k| region_value(s, k, s.error[k])).collect()),
            ),
            (
                format!(
                    "{} — gross errors (> 8 px) by region: their sum in the region / all scored pixels (a row's \
                     regions add up to its gross total)",
                    r.alg
                ),
                &REGION_LABELS,
                |s| (Some(s.gross_total()), (0..5).map(|k| region_value(s, k, s.gross[k])).collect()),
            ),
            (format!("{} — scored pixels by region, %", r.alg), &REGION_LABELS, |s| {
                (None, (0..5).map(|k| region_value(s, k, s.pixels[k])).collect())
            }),
            (format!("{} — avgErr by error size (px): the sizes add up to avgErr", r.alg), &SIZE_LABELS, |s| {
                (Some(s.avgerr), s.by_size.iter().map(|&v| Some(v)).collect())
            }),
        ];
        for (title, labels, row) in tables {
            heading(&mut out, &title);
            out.push_str(&table(r, labels, row, markdown));
            out.push('\n');
        }
        let without: Vec<&str> = r
            .scenes
            .iter()
            .filter(|(_, _, s)| s.as_ref().is_ok_and(|s| !s.has_lr_mask))
            .map(|(n, _, _)| n.as_str())
            .collect();
        if !without.is_empty() {
            let _ = writeln!(
                out,
                "No lrmask0{}.png (jem batch --lr-mask writes it) in: {}; there the rejected pixels fall into the \
                 other regions.",
                r.alg,
                without.join(", ")
            );
        }
        let failed: Vec<String> =
            r.scenes.iter().filter_map(|(n, _, s)| s.as_ref().err().map(|e| format!("{n}: {e}"))).collect();
        if !failed.is_empty() {
            let _ = writeln!(out, "Not split (left out of the weighted row): {}", failed.join("; "));
        }
        if !without.is_empty() || !failed.is_empty() {
            out.push('\n');
        }
    }
    out
}

/// What a table's row shows of a split: the total column (if any) and the five values.
type Row = fn(&RegionSplit) -> (Option<f64>, Vec<Option<f64>>);

fn table(r: &RegionReport, labels: &[&str], row: Row, markdown: bool) -> String {
    let has_total = r.scenes.iter().find_map(|(_, _, s)| s.as_ref().ok()).is_none_or(|s| row(s).0.is_some());
    let mut header: Vec<String> = vec!["scene".into(), "weight".into()];
    if has_total {
        header.push("total".into());
    }
    header.extend(labels.iter().map(|l| (*l).to_string()));
    let mut rows = vec![header];
    let mut push = |name: String, weight: String, s: Option<&RegionSplit>| {
        let mut cells = vec![name, weight];
        match s {
            Some(s) => {
                let (total, values) = row(s);
                if has_total {
                    cells.push(fixed(total));
                }
                cells.extend(values.into_iter().map(fixed));
            }
            None => cells.extend(std::iter::repeat_n("-".to_string(), labels.len() + usize::from(has_total))),
        }
        rows.push(cells);
    };
    for (name, weight, s) in &r.scenes {
        push(name.clone(), format!("{weight}"), s.as_ref().ok());
    }
    let weighted = if markdown { "**weighted**" } else { "weighted" };
    push(weighted.into(), String::new(), r.weighted().as_ref());
    let ncol = rows[0].len();
    let right_aligned = (0..ncol).map(|c| c > 0).collect();
    let t = Table { rows, right_aligned };
    if markdown { t.markdown() } else { t.text() }
}

/// A split as a JSON object: `{"avgerr", "pixels_valid", "lr_mask", "error": {REGION: v}, "gross": {...,
/// "total"}, "pixels_pct": {...}, "by_size": {SIZE: v}}`; the rejected region is `null` without the mask.
fn split_json(s: &RegionSplit) -> String {
    let regions = |v: &[f64; 5], total: Option<f64>| {
        let mut fields: Vec<String> = REGION_KEYS
            .iter()
            .enumerate()
            .map(|(k, key)| format!("{}: {}", json_str(key), region_value(s, k, v[k]).map_or("null".into(), json_num)))
            .collect();
        if let Some(t) = total {
            fields.push(format!("\"total\": {}", json_num(t)));
        }
        format!("{{{}}}", fields.join(", "))
    };
    let sizes: Vec<String> =
        SIZE_KEYS.iter().zip(&s.by_size).map(|(k, v)| format!("{}: {}", json_str(k), json_num(*v))).collect();
    format!(
        "{{\"avgerr\": {}, \"pixels_valid\": {}, \"lr_mask\": {}, \"error\": {}, \"gross\": {}, \"pixels_pct\": {}, \
         \"by_size\": {{{}}}}}",
        json_num(s.avgerr),
        s.pixels_valid,
        s.has_lr_mask,
        regions(&s.error, None),
        regions(&s.gross, Some(s.gross_total())),
        regions(&s.pixels, None),
        sizes.join(", ")
    )
}

/// The `"regions"` member eval's JSON gets with `--regions`: `{"scenes": {NAME: split}, "weighted": split|null}`,
/// plus `"excluded": {NAME: reason}` when a scene was not split (see [`split_json`] for a split's keys).
pub(super) fn regions_json(r: &RegionReport) -> String {
    let scenes: Vec<String> = r
        .scenes
        .iter()
        .filter_map(|(n, _, s)| s.as_ref().ok().map(|s| format!("    {}: {}", json_str(n), split_json(s))))
        .collect();
    let mut o = format!(
        "{{\"scenes\": {{\n{}\n  }}, \"weighted\": {}",
        scenes.join(",\n"),
        r.weighted().as_ref().map_or("null".into(), split_json)
    );
    let excluded: Vec<String> = r
        .scenes
        .iter()
        .filter_map(|(n, _, s)| s.as_ref().err().map(|e| format!("{}: {}", json_str(n), json_str(&e.chain()))))
        .collect();
    if !excluded.is_empty() {
        let _ = write!(o, ", \"excluded\": {{{}}}", excluded.join(", "));
    }
    o.push('}');
    o
}
