//! The report's page: plain HTML written here (no template engine), its style and its sorting script inlined
//! (`page.css`, `page.js`), so that it opens from the disk with nothing else but its pictures folder.
//!
//! The results table's body rows have the same cells in the same order (no `colspan`), so that a header's
//! `data-col` is the index of its cells; a sortable cell carries its value in `data-v` (empty: none, sorted
//! last).

use std::fmt::Write as _;

use super::{AlgCell, Column, Model, Picture, Row, columns};
use crate::dataset::Layout;
use crate::eval::Metrics;

const STYLE: &str = include_str!("page.css");
const SCRIPT: &str = include_str!("page.js");

/// Text as HTML (also inside a quoted attribute).
pub(super) fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A path segment as a relative URL's: bytes other than ASCII letters, digits and `-._~` percent-encoded.
pub(super) fn url_segment(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for b in text.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~') {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// A number with `digits` decimals, `–` for none.
fn number(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.digits$}"),
        _ => "–".into(),
    }
}

/// A sortable cell: its value in `data-v`, `class` added (the best of a row, say), a tooltip when given.
fn value_cell(v: Option<f64>, digits: usize, class: &str, title: Option<&str>) -> String {
    let data = v.filter(|v| v.is_finite()).map_or(String::new(), |v| format!("{v}"));
    let title = title.map_or(String::new(), |t| format!(" title=\"{}\"", escape(t)));
    let class = if class.is_empty() { "num".to_string() } else { format!("num {class}") };
    format!("<td class=\"{class}\" data-v=\"{data}\"{title}>{}</td>", number(v, digits))
}

/// A thumbnail linking to its picture at full size.
fn picture(folder: &str, p: &Picture, alt: &str) -> String {
    let (w, h) = p.thumb_size;
    format!(
        "<a href=\"{folder}/{full}\" title=\"{alt}: full size\"><img src=\"{folder}/{thumb}\" width=\"{w}\" \
         height=\"{h}\" alt=\"{alt}\"></a>",
        folder = url_segment(folder),
        full = url_segment(&p.full),
        thumb = url_segment(&p.thumb),
        alt = escape(alt)
    )
}

/// The cell text where an algorithm has no picture.
fn missing(why: Option<&str>) -> String {
    match why {
        None => "<td class=\"none\">no result</td>".into(),
        Some(e) => format!("<td class=\"none\" title=\"{}\">not drawn</td>", escape(e)),
    }
}

/// The page.
pub(super) fn page(m: &Model, folder: &str) -> String {
    let name = m.dir.file_name().map_or_else(|| m.dir.display().to_string(), |n| n.to_string_lossy().into_owned());
    let mut h = String::with_capacity(64 << 10);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <meta name=\"generator\" content=\"jem {version}\">\n<title>jem report: {title}</title>\n\
         <style>\n{STYLE}</style>\n</head>\n<body>\n",
        version = env!("CARGO_PKG_VERSION"),
        title = escape(&name)
    );
    header(&mut h, m);
    summary_table(&mut h, m);
    legend(&mut h);
    table(&mut h, m, folder);
    footer(&mut h, m);
    let _ = write!(h, "<script>\n{SCRIPT}</script>\n</body>\n</html>\n");
    h
}

/// The title and what the table shows.
fn header(h: &mut String, m: &Model) {
    let layout = match m.layout {
        Layout::Middlebury => "MiddEval3",
        Layout::Kitti2015 => "KITTI 2015",
        Layout::Kitti2012 => "KITTI 2012",
        Layout::Eth3d => "ETH3D two-view",
    };
    let _ = writeln!(h, "<header>\n<h1>jem report: <code>{}</code></h1>", escape(&m.dir.display().to_string()));
    let mut facts = vec![layout.to_string(), format!("{} rows", m.rows.len())];
    facts.push(match m.rule {
        Some(rule) => format!("error maps and scores: {}", rule.describe()),
        None => "no ground truth: pictures only".into(),
    });
    if m.rule.is_some() {
        facts.push(format!("{} pixels", m.mask.name()));
    }
    let _ = writeln!(h, "<p class=\"facts\">{}</p>", escape(&facts.join(" · ")));
    if let Some(note) = m.evals.iter().flatten().find_map(|e| e.scale_inferred.as_ref()) {
        let _ = writeln!(h, "<p class=\"note\">Resolution: {}</p>", escape(note));
    }
    for w in m.evals.iter().flatten().flat_map(|e| &e.writers) {
        let _ = writeln!(h, "<p class=\"note\">Still being written: {} (scored as they were)</p>", escape(w));
    }
    h.push_str("</header>\n");
}

/// The colour bar and the error map's key.
fn legend(h: &mut String) {
    let stops: Vec<String> = (0..=8)
        .map(|k| {
            let t = k as f32 / 8.0;
            let [r, g, b] = crate::viz::colormap(t);
            format!("rgb({r},{g},{b}) {}%", k * 100 / 8)
        })
        .collect();
    let _ = writeln!(
        h,
        "<section class=\"legend\">\n<div class=\"bar\"><span>low disparity (far)</span>\
         <span class=\"ramp\" style=\"background:linear-gradient(to right, {})\"></span>\
         <span>high disparity (near)</span><span class=\"dim\">each row's range is under its name; \
         invalid pixels are black</span></div>",
        stops.join(", ")
    );
    let keys = [
        ("linear-gradient(to right, rgb(255,255,255), rgb(205,205,205))", "good (white: exact)"),
        ("rgb(230,30,30)", "bad"),
        ("rgb(128,140,179)", "occluded, good"),
        ("rgb(140,40,40)", "occluded, bad"),
        ("rgb(0,0,0)", "invalid"),
        ("rgb(48,48,48)", "no ground truth"),
    ];
    h.push_str("<div class=\"keys\">error maps:");
    for (colour, text) in keys {
        let _ = write!(h, " <span class=\"key\"><i style=\"background:{colour}\"></i>{text}</span>");
    }
    h.push_str(
        "</div>\n<p class=\"dim\">Click a picture for its full size, a column's header to sort the rows by it \
         (again to reverse).</p>\n</section>\n",
    );
}

/// What the time columns hold, and why no time is marked best: each run times itself on whatever machine and
/// load it had, so times of different runs are not a ranking.
const TIME_HELP: &str = "seconds in the pipeline per pair, as each run recorded them; not ranked: runs made on \
                         other machines or under other loads are not comparable";

/// The score columns of one algorithm, with the time and the paper's avgErr when it has a column.
fn alg_columns(m: &Model, a: usize) -> (Vec<Column>, bool) {
    let cols = if m.rule.is_some() { columns(m.layout) } else { Vec::new() };
    (cols, m.papers.get(a).is_some_and(Option::is_some))
}

/// The results table.
fn table(h: &mut String, m: &Model, folder: &str) {
    h.push_str("<table class=\"results\">\n<thead>\n<tr><th rowspan=\"2\" class=\"sort\" data-col=\"0\" tabindex=\"0\">scene</th><th rowspan=\"2\">left image</th>");
    let mut second = String::new();
    let mut col = 2;
    for (a, alg) in m.algs.iter().enumerate() {
        let (cols, paper) = alg_columns(m, a);
        let span = 2 + cols.len() + 1 + usize::from(paper);
        let _ = write!(h, "<th colspan=\"{span}\" class=\"alg\">{}</th>", escape(alg));
        second.push_str("<th>disparity</th><th>error</th>");
        col += 2;
        let mut sortable = |title: &str, help: &str| {
            let _ = write!(
                second,
                "<th class=\"sort\" data-col=\"{col}\" data-num=\"1\" tabindex=\"0\" title=\"{}\">{}</th>",
                escape(help),
                escape(title)
            );
            col += 1;
        };
        for c in &cols {
            sortable(c.title, c.help);
        }
        sortable("time (s)", TIME_HELP);
        if let Some(p) = m.papers[a].as_ref() {
            sortable("paper", &format!("the paper's avgErr for this scene ({}, paper-results.tsv)", p.name));
        }
    }
    let _ = writeln!(h, "</tr>\n<tr>{second}</tr>\n</thead>\n<tbody>");
    for row in &m.rows {
        body_row(h, m, row, folder);
    }
    h.push_str("</tbody>\n");
    summary_row(h, m);
    h.push_str("</table>\n");
}

/// One scene's row.
fn body_row(h: &mut String, m: &Model, row: &Row, folder: &str) {
    let range = row.cells.iter().find_map(|c| c.pictures.as_ref().and_then(|p| p.as_ref().ok())).map(|p| p.range);
    let mut under = Vec::new();
    if let Some(w) = row.weight.filter(|&w| w != 1.0) {
        under.push(format!("weight {w}"));
    }
    if let Some((lo, hi)) = range {
        under.push(format!("d {lo:.0}–{hi:.0}"));
    }
    let _ = write!(
        h,
        "<tr><td class=\"scene\" data-v=\"{name}\" title=\"{loc}\"><b>{name}</b><br><span class=\"dim\">{under}</span></td>",
        name = escape(&row.name),
        loc = escape(&row.location.display().to_string()),
        under = escape(&under.join(" · "))
    );
    match &row.left {
        Some(p) => {
            let _ = write!(h, "<td>{}</td>", picture(folder, p, &format!("{}: left image", row.name)));
        }
        None => h.push_str("<td class=\"none\">–</td>"),
    }
    let best = best_values(m, row);
    for (a, (alg, cell)) in m.algs.iter().zip(&row.cells).enumerate() {
        match &cell.pictures {
            Some(Ok(p)) => {
                let what = format!("{}, {alg}", row.name);
                let range = format!("{what}: disparity, colours over {:.1}..{:.1}", p.range.0, p.range.1);
                let _ = write!(h, "<td>{}</td>", picture(folder, &p.colour, &range));
                let _ = write!(h, "<td>{}</td>", picture(folder, &p.error, &format!("{what}: error map")));
            }
            Some(Err(e)) => {
                h.push_str(&missing(Some(e)));
                h.push_str("<td class=\"none\"></td>");
            }
            None => {
                h.push_str(&missing(None));
                h.push_str("<td class=\"none\"></td>");
            }
        }
        score_cells(h, m, a, cell, &best);
    }
    h.push_str("</tr>\n");
}

/// A row's score cells for algorithm `a`: each score (the row's best bold), the time (never bold: [`TIME_HELP`]),
/// the paper's avgErr.
fn score_cells(h: &mut String, m: &Model, a: usize, cell: &AlgCell, best: &[Option<f64>]) {
    let (cols, paper) = alg_columns(m, a);
    let why = match &cell.metrics {
        Some(Err(e)) => Some(e.chain()),
        None if m.rule.is_some() => Some("no ground truth".to_string()),
        _ => None,
    };
    let metrics = cell.metrics.as_ref().and_then(|r| r.as_ref().ok());
    for (k, c) in cols.iter().enumerate() {
        let v = metrics.map(|x| (c.value)(x));
        let class = if v.is_some() && v == best[k] { "best" } else { "" };
        h.push_str(&value_cell(v, c.digits, class, why.as_deref()));
    }
    h.push_str(&value_cell(cell.seconds, 2, "", None));
    if paper {
        h.push_str(&value_cell(cell.paper, 2, "paper", None));
    }
}

/// The lowest value of each score in a row, among the algorithms that have one (`None` with fewer than two, or
/// when two share it: nothing stands out). Times are not compared ([`TIME_HELP`]).
fn best_values(m: &Model, row: &Row) -> Vec<Option<f64>> {
    let cols = if m.rule.is_some() { columns(m.layout) } else { Vec::new() };
    let metrics = |c: &AlgCell| c.metrics.as_ref().and_then(|r| r.as_ref().ok()).copied();
    cols.iter()
        .map(|c| lowest(&row.cells.iter().filter_map(metrics).map(|x| (c.value)(&x)).collect::<Vec<_>>(), c.digits))
        .collect()
}

/// The lowest finite value, when there are two or more and no other shows the same to the digits displayed (a tie
/// there, all 0.0 invalid say, marks nothing).
fn lowest(values: &[f64], digits: usize) -> Option<f64> {
    let shown: Vec<String> = values.iter().filter(|v| v.is_finite()).map(|v| format!("{v:.digits$}")).collect();
    let min = values.iter().copied().filter(|v| v.is_finite()).fold(f64::INFINITY, f64::min);
    let ties = shown.iter().filter(|s| **s == format!("{min:.digits$}")).count();
    (shown.len() >= 2 && ties == 1).then_some(min)
}

/// The summary row: MiddEval3's weighted mean, else the plain mean, of each algorithm's scores and times.
fn summary_row(h: &mut String, m: &Model) {
    if m.evals.iter().all(Option::is_none) {
        return;
    }
    let (label, help) = match m.layout {
        Layout::Middlebury => (
            "weighted mean",
            "MiddEval3's weighted mean: PianoL, Playroom, Playtable, Shelves and Vintage count half; times: plain mean",
        ),
        _ => ("mean", "the mean over the scored rows"),
    };
    let _ = write!(h, "<tfoot><tr><th title=\"{}\">{label}</th><td></td>", escape(help));
    let avgs: Vec<Option<Metrics>> = m
        .evals
        .iter()
        .map(|e| e.as_ref().and_then(|e| if m.layout == Layout::Middlebury { e.weighted() } else { e.mean() }))
        .collect();
    let times: Vec<Option<f64>> =
        m.evals.iter().map(|e| e.as_ref().and_then(|e| e.mean_seconds()).map(|(s, _)| s)).collect();
    // The best of each score column bold, as in the rows above; the times are not ranked.
    for (a, avg) in avgs.iter().enumerate() {
        let (cols, paper) = alg_columns(m, a);
        h.push_str("<td></td><td></td>");
        for c in &cols {
            let v = avg.as_ref().map(|x| (c.value)(x));
            let all: Vec<f64> = avgs.iter().flatten().map(|x| (c.value)(x)).collect();
            let class = if v.is_some() && v == lowest(&all, c.digits) { "best" } else { "" };
            h.push_str(&value_cell(v, c.digits, class, None));
        }
        h.push_str(&value_cell(times[a], 2, "", None));
        if paper {
            let w = m.papers[a].as_ref().and_then(|p| p.weighted);
            h.push_str(&value_cell(w, 2, "paper", None));
        }
    }
    h.push_str("</tr></tfoot>\n");
}

/// The headline: each algorithm's summary row (as the table's last row), one line per algorithm.
fn summary_table(h: &mut String, m: &Model) {
    if m.evals.iter().all(Option::is_none) {
        return;
    }
    let cols = columns(m.layout);
    let label = if m.layout == Layout::Middlebury { "weighted mean" } else { "mean" };
    let _ = write!(h, "<table class=\"summary\">\n<thead><tr><th>{label}</th>");
    for c in &cols {
        let _ = write!(h, "<th title=\"{}\">{}</th>", escape(c.help), escape(c.title));
    }
    let _ = write!(h, "<th title=\"{}\">time (s)</th>", escape(TIME_HELP));
    let any_paper = m.papers.iter().any(Option::is_some);
    if any_paper {
        h.push_str("<th title=\"the paper's avgErr (paper-results.tsv)\">paper avgErr</th>");
    }
    h.push_str("<th>scored</th></tr></thead>\n<tbody>\n");
    for ((alg, eval), paper) in m.algs.iter().zip(&m.evals).zip(&m.papers) {
        let _ = write!(h, "<tr><th>{}</th>", escape(alg));
        let avg = eval.as_ref().and_then(|e| if m.layout == Layout::Middlebury { e.weighted() } else { e.mean() });
        for c in &cols {
            h.push_str(&value_cell(avg.as_ref().map(|x| (c.value)(x)), c.digits, "", None));
        }
        let t = eval.as_ref().and_then(|e| e.mean_seconds()).map(|(s, _)| s);
        h.push_str(&value_cell(t, 2, "", None));
        if any_paper {
            let title = paper.as_ref().map(|p| format!("{} of paper-results.tsv", p.name));
            h.push_str(&value_cell(paper.as_ref().and_then(|p| p.weighted), 2, "paper", title.as_deref()));
        }
        let (ok, all) =
            eval.as_ref().map_or((0, 0), |e| (e.scenes.iter().filter(|s| s.metrics.is_ok()).count(), e.scenes.len()));
        let _ = writeln!(h, "<td class=\"num\">{ok} of {all}</td></tr>");
    }
    h.push_str("</tbody>\n</table>\n");
}

/// An algorithm's recorded configurations: each in a fold that says which of its `results` it made (all of them,
/// when there is one), or that none was recorded.
pub(super) fn configurations(configs: &[super::Recorded], results: usize) -> String {
    if configs.is_empty() {
        return "not recorded (no configuration beside these results: they were written by another program, or by a \
                jem batch older than the record)"
            .into();
    }
    let mut out = String::new();
    for c in configs {
        let whose = if c.scenes.len() == results {
            format!("recorded beside all {results} results")
        } else {
            format!("recorded beside {} of {results} results: {}", c.scenes.len(), c.scenes.join(", "))
        };
        let _ = write!(out, "<details><summary>{}</summary><pre>{}</pre></details>", escape(&whose), escape(&c.text));
    }
    out
}

/// How the report was made: the command, the configurations, the machine.
fn footer(h: &mut String, m: &Model) {
    h.push_str("<footer>\n<h2>How this was made</h2>\n<dl>\n");
    let _ = writeln!(h, "<dt>command</dt><dd><code>{}</code></dd>", escape(&m.command));
    for (alg, (configs, results)) in m.algs.iter().zip(&m.configs) {
        let _ = writeln!(h, "<dt>configuration of {}</dt><dd>{}</dd>", escape(alg), configurations(configs, *results));
    }
    for (alg, paper) in m.algs.iter().zip(&m.papers) {
        if let Some(p) = paper {
            let _ = writeln!(
                h,
                "<dt>paper column beside {}</dt><dd>{} of paper-results.tsv (the paper's avgErr)</dd>",
                escape(alg),
                escape(&p.name)
            );
        }
    }
    let _ = writeln!(
        h,
        "<dt>machine</dt><dd>{} (where this report was made; the times are those the runs recorded)</dd>",
        escape(&m.machine)
    );
    h.push_str("</dl>\n</footer>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_urls_are_escaped() {
        assert_eq!(escape("a<b & \"c\" 'd'>"), "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt;");
        assert_eq!(url_segment("my report_files"), "my%20report_files");
        assert_eq!(url_segment("é#?.png"), "%C3%A9%23%3F.png");
    }

    #[test]
    fn the_lowest_stands_out_only_alone_and_among_two_or_more() {
        assert_eq!(lowest(&[4.94, 3.58], 2), Some(3.58));
        assert_eq!(lowest(&[0.0, 0.001], 1), None, "a tie to the digits shown marks nothing");
        assert_eq!(lowest(&[3.58], 2), None, "one algorithm: nothing to compare");
        assert_eq!(lowest(&[f64::NAN, 2.0, 5.0], 2), Some(2.0));
    }

    #[test]
    fn values_sort_by_data_and_missing_ones_are_empty() {
        assert_eq!(value_cell(Some(4.125), 2, "", None), "<td class=\"num\" data-v=\"4.125\">4.12</td>");
        assert_eq!(
            value_cell(Some(f64::NAN), 1, "best", Some("no <result>")),
            "<td class=\"num best\" data-v=\"\" title=\"no &lt;result&gt;\">–</td>"
        );
    }
}
