//! Laying out a table of text cells, as aligned plain-text columns ([`Table::text`]) or as a GitHub-flavoured
//! Markdown table ([`Table::markdown`]). Used by the reports of `jem eval` ([`crate::eval::render`]) and the
//! summary of `jem batch`.

/// Rows of text cells, the first row being the header, and which columns are right-aligned.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Table {
    /// The rows, header first. A row may be shorter than the others: its missing cells are left out.
    pub rows: Vec<Vec<String>>,
    /// `right_aligned[c]`: column `c` is right-aligned (numbers); the others, and columns past the end of this
    /// list, are left-aligned.
    pub right_aligned: Vec<bool>,
}

impl Table {
    /// Whether column `c` is right-aligned.
    fn is_right(&self, c: usize) -> bool {
        self.right_aligned.get(c).copied().unwrap_or(false)
    }

    /// Aligned columns, one line per row: each column is as wide as its widest cell (counted in `char`s),
    /// cells are padded on the left (right-aligned columns) or the right, joined by two spaces, and trailing
    /// spaces are trimmed. An empty table gives an empty string.
    pub(crate) fn text(&self) -> String {
        let ncol = self.rows.iter().map(Vec::len).max().unwrap_or(0);
        let widths: Vec<usize> = (0..ncol)
            .map(|c| self.rows.iter().filter_map(|r| r.get(c)).map(|v| v.chars().count()).max().unwrap_or(0))
            .collect();
        let mut out = String::new();
        for r in &self.rows {
            let cells: Vec<String> = r
                .iter()
                .enumerate()
                .map(|(c, v)| {
                    if self.is_right(c) { format!("{v:>w$}", w = widths[c]) } else { format!("{v:<w$}", w = widths[c]) }
                })
                .collect();
            out.push_str(cells.join("  ").trim_end());
            out.push('\n');
        }
        out
    }

    /// A GitHub-flavoured Markdown table: the header row, a rule (`---:` under the columns of
    /// [`Table::right_aligned`] that are `true`, `---` under the others), then the other rows; `|` in a cell is
    /// escaped. An empty table gives an empty string.
    pub(crate) fn markdown(&self) -> String {
        let Some((header, body)) = self.rows.split_first() else {
            return String::new();
        };
        let line =
            |r: &[String]| format!("| {} |\n", r.iter().map(|c| c.replace('|', "\\|")).collect::<Vec<_>>().join(" | "));
        let mut out = line(header);
        let rule: Vec<&str> = self.right_aligned.iter().map(|&right| if right { "---:" } else { "---" }).collect();
        out.push_str(&format!("|{}|\n", rule.join("|")));
        for r in body {
            out.push_str(&line(r));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_of_text() {
        use crate::table::Table;
        let rows = vec![vec!["scene".into(), "err".into(), "ok".into()], vec!["A".into(), "1.25".into()]];
        let table = Table { rows, right_aligned: vec![false, true] };
        assert_eq!(table.text(), "scene   err  ok\nA      1.25\n");
    }

    #[test]
    fn example_of_markdown() {
        use crate::table::Table;
        let rows = vec![vec!["scene".into(), "err".into()], vec!["a|b".into(), "1.25".into()]];
        let table = Table { rows, right_aligned: vec![false, true] };
        assert_eq!(table.markdown(), "| scene | err |\n|---|---:|\n| a\\|b | 1.25 |\n");
    }

    fn table(rows: &[&[&str]], right_aligned: &[bool]) -> Table {
        Table {
            rows: rows.iter().map(|r| r.iter().map(|c| c.to_string()).collect()).collect(),
            right_aligned: right_aligned.to_vec(),
        }
    }

    #[test]
    fn text_pads_by_chars_and_trims_the_line_end() {
        let t = table(&[&["alg", "×", "note"], &["JemALL", "4.94", ""], &["é", "10.5", "x"]], &[false, true, false]);
        assert_eq!(t.text(), "alg        ×  note\nJemALL  4.94\né       10.5  x\n");
    }

    #[test]
    fn text_of_short_rows_and_empty_tables() {
        let t = table(&[&["a", "bb", "c"], &["long"]], &[false, true]);
        assert_eq!(t.text(), "a     bb  c\nlong\n");
        assert_eq!(Table::default().text(), "");
        assert_eq!(Table::default().markdown(), "");
    }

    #[test]
    fn markdown_rule_follows_the_alignment() {
        let t = table(&[&["scene", "weight", "avgErr"], &["**weighted**", "", "4.94"]], &[false, true, true]);
        assert_eq!(t.markdown(), "| scene | weight | avgErr |\n|---|---:|---:|\n| **weighted** |  | 4.94 |\n");
    }
}
