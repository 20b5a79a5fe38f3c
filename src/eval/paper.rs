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
    /// A message naming the line for a missing header, a bad weight, or a row with the wrong number of fields.
    /// Empty fields and `-` are missing values.
    pub fn parse(text: &str) -> std::result::Result<Self, String> {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let (_, header) = lines.next().ok_or("no header line")?;
        let head: Vec<&str> = header.split('\t').map(str::trim).collect();
        if head.len() < 3 || head[0] != "scene" || head[1] != "weight" {
            return Err("the header must be `scene<TAB>weight<TAB>COLUMN...`".into());
        }
        let columns: Vec<String> = head[2..].iter().map(|s| s.to_string()).collect();
        let mut rows = Vec::new();
        for (n, line) in lines {
            let f: Vec<&str> = line.split('\t').map(str::trim).collect();
            if f.len() != head.len() {
                return Err(format!("line {}: {} fields, the header has {}", n + 1, f.len(), head.len()));
            }
            let weight = f[1].parse::<f64>().map_err(|_| format!("line {}: bad weight {:?}", n + 1, f[1]))?;
            let values = f[2..].iter().map(|v| v.parse::<f64>().ok().filter(|v| v.is_finite())).collect();
            rows.push((f[0].to_string(), weight, values));
        }
        Ok(PaperResults { columns, rows })
    }

    /// Reads and parses a TSV file.
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Input`] naming the path.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(&text).map_err(|msg| Error::Input(format!("{}: {msg}", path.display())))
    }

    /// The column names.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// One column by name.
    ///
    /// # Errors
    /// [`Error::Input`] listing the available columns.
    pub fn column(&self, name: &str) -> Result<PaperColumn> {
        let Some(k) = self.columns.iter().position(|c| c == name) else {
            return Err(Error::Input(format!("no paper column {name:?} (available: {})", self.columns.join(", "))));
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
}
