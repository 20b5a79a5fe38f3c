//! The paper's published numbers: [`PaperResults`] parses `paper-results.tsv` (one row per scene, one column per
//! method), [`PaperColumn`] is one method's column with its weighted mean, which
//! [`render`](crate::eval::render) prints beside ours.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Error, Result};

/// The paper's per-scene numbers (`paper-results.tsv`: `#` comments, a header `scene weight COL...`, then one
/// tab-separated row per scene).
#[derive(Clone, Debug, PartialEq)]
pub struct PaperResults {
    columns: Vec<String>,
    rows: Vec<(String, f64, Vec<Option<f64>>)>,
}

/// One column of [`PaperResults`].
#[derive(Clone, Debug, PartialEq)]
pub struct PaperColumn {
    /// Column name, e.g. `JEM_ALL`.
    pub name: String,
    /// Scene → value.
    pub scenes: BTreeMap<String, f64>,
    /// Weighted mean of the column with the file's weights (the paper's "Avg").
    pub weighted: Option<f64>,
}

impl PaperResults {
    /// Parses the TSV text.
    ///
    /// # Errors
    /// [`Error::Dataset`] naming the line for a missing header, a column or scene given twice, a weight that is not a
    /// positive number, a value that is neither a number ≥ 0 nor missing, or a row with the wrong number of fields.
    /// Empty fields and `-` are missing values.
    pub fn parse(text: &str) -> Result<Self> {
        Self::parse_text(text).map_err(Error::dataset)
    }

    /// [`PaperResults::parse`], with the message alone.
    fn parse_text(text: &str) -> std::result::Result<Self, String> {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let (_, header) = lines.next().ok_or("no header line")?;
        let head: Vec<&str> = header.split('\t').map(str::trim).collect();
        if head.len() < 3 || head[0] != "scene" || head[1] != "weight" {
            return Err("the header must be `scene<TAB>weight<TAB>COLUMN...`".into());
        }
        let columns: Vec<String> = head[2..].iter().map(|s| s.to_string()).collect();
        if let Some((k, c)) = columns.iter().enumerate().find(|(k, c)| columns[..*k].contains(c)) {
            let first = columns.iter().position(|x| x == c).unwrap_or(k);
            return Err(format!("the header names column {c:?} twice (fields {} and {})", first + 3, k + 3));
        }
        let mut rows: Vec<(String, f64, Vec<Option<f64>>)> = Vec::new();
        let mut seen: BTreeMap<String, usize> = BTreeMap::new();
        for (n, line) in lines {
            let f: Vec<&str> = line.split('\t').map(str::trim).collect();
            if f.len() != head.len() {
                return Err(format!("line {}: {} fields, the header has {}", n + 1, f.len(), head.len()));
            }
            if let Some(first) = seen.insert(f[0].to_string(), n + 1) {
                return Err(format!("line {}: scene {} is listed twice (first on line {first})", n + 1, f[0]));
            }
            let weight = f[1].parse::<f64>().ok().filter(|w| w.is_finite() && *w > 0.0);
            let weight =
                weight.ok_or_else(|| format!("line {}: bad weight {:?} (expected a number > 0)", n + 1, f[1]))?;
            let values = f[2..]
                .iter()
                .zip(&columns)
                .map(|(v, column)| value(v).map_err(|why| format!("line {}: {column} {v:?} {why}", n + 1)))
                .collect::<std::result::Result<_, _>>()?;
            rows.push((f[0].to_string(), weight, values));
        }
        Ok(PaperResults { columns, rows })
    }

    /// Reads and parses a TSV file (at most 1 MiB).
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::InputFile`] naming the path, [`Error::Dataset`] naming it for malformed text.
    pub fn load(path: &Path) -> Result<Self> {
        let bytes = crate::io::read_capped(path, 1 << 20, "paper results file")?;
        let text = String::from_utf8(bytes).map_err(|_| Error::input_file_at(path, "not UTF-8 text"))?;
        Self::parse_text(&text).map_err(|msg| Error::dataset_at(path, msg))
    }

    /// The column names.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// One column by name.
    ///
    /// # Errors
    /// [`Error::Argument`] listing the available columns.
    pub fn column(&self, name: &str) -> Result<PaperColumn> {
        let Some(k) = self.columns.iter().position(|c| c == name) else {
            return Err(Error::argument(format!("no paper column {name:?} (available: {})", self.columns.join(", "))));
        };
        let mut scenes = BTreeMap::new();
        let (mut sum, mut total) = (0.0, 0.0);
        for (scene, w, values) in &self.rows {
            if let Some(v) = values[k] {
                scenes.insert(scene.clone(), v);
                sum += w * v;
                total += w;
            }
        }
        Ok(PaperColumn { name: name.to_string(), scenes, weighted: (total > 0.0).then(|| sum / total) })
    }
}

/// One value of the table: a number ≥ 0 (an error is never negative), or missing (empty or `-`).
fn value(field: &str) -> std::result::Result<Option<f64>, &'static str> {
    if field.is_empty() || field == "-" {
        return Ok(None);
    }
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(Some(v)),
        Ok(_) => Err("is not a score (expected a number >= 0)"),
        Err(_) => Err("is not a number (empty or - for a missing value)"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_tsv_parses_and_averages() {
        let text = "# c\nscene\tweight\tA\tB\nTeddy\t1.0\t2.0\t-\nPianoL\t0.5\t5.0\t1.0\n";
        let p = PaperResults::parse(text).unwrap();
        assert_eq!(p.columns(), ["A", "B"]);
        let a = p.column("A").unwrap();
        assert_eq!(a.scenes.get("PianoL"), Some(&5.0));
        assert!((a.weighted.unwrap() - 4.5 / 1.5).abs() < 1e-12);
        assert_eq!(p.column("B").unwrap().scenes.len(), 1);
        assert!(p.column("C").unwrap_err().to_string().contains("A, B"));
        assert!(PaperResults::parse("scene\tweight\tA\nTeddy\t1\n").is_err());
        assert!(PaperResults::parse("scene\tA\n").is_err());
    }

    /// A scene listed twice (which row counts?), a negative score or weight, or a value that is not a number (read
    /// as missing before, silently leaving the scene out of the mean) is refused, naming the line.
    #[test]
    fn duplicate_rows_negative_and_non_numeric_values_are_refused() {
        let head = "scene\tweight\tA\tB\n";
        for (rows, needle) in [
            ("Teddy\t1\t2\t3\nTeddy\t1\t2\t4\n", "line 3: scene Teddy is listed twice (first on line 2)"),
            ("Teddy\t1\t-2\t3\n", "line 2: A \"-2\" is not a score"),
            ("Teddy\t1\t2\tabc\n", "line 2: B \"abc\" is not a number"),
            ("Teddy\t1\tnan\t2\n", "line 2: A \"nan\" is not a score"),
            ("Teddy\t-1\t2\t3\n", "line 2: bad weight \"-1\""),
        ] {
            let e = PaperResults::parse(&format!("{head}{rows}")).unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        }
        assert!(PaperResults::parse("scene\tweight\tA\tA\n").unwrap_err().to_string().contains("column \"A\" twice"));
        let ok = PaperResults::parse(&format!("{head}Teddy\t1\t\t-\n")).unwrap();
        assert!(ok.column("A").unwrap().scenes.is_empty());
    }
}
