//! The one table writer of the results pages: a header, an alignment per column, rows of
//! cells, written as a Markdown table.

/// How a column's cells line up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// Text (the Markdown default).
    Left,
    /// Figures.
    Right,
}

/// A Markdown table built row by row.
#[derive(Debug, Clone)]
pub struct Table {
    head: Vec<(String, Align)>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// `align` has a letter per column: `l` for text, `r` for figures.
    pub fn new<S: Into<String>>(columns: impl IntoIterator<Item = S>, align: &str) -> Self {
        let head: Vec<(String, Align)> = columns
            .into_iter()
            .zip(align.chars())
            .map(|(h, a)| (h.into(), if a == 'r' { Align::Right } else { Align::Left }))
            .collect();
        debug_assert_eq!(head.len(), align.len(), "a letter per column");
        Self {
            head,
            rows: Vec::new(),
        }
    }

    /// Every column text (left-aligned).
    pub fn text<S: Into<String>>(columns: impl IntoIterator<Item = S>) -> Self {
        let columns: Vec<String> = columns.into_iter().map(Into::into).collect();
        let align = "l".repeat(columns.len());
        Self::new(columns, &align)
    }

    /// One row; it must have a cell per column.
    pub fn row(&mut self, cells: impl IntoIterator<Item = String>) {
        let cells: Vec<String> = cells.into_iter().collect();
        debug_assert_eq!(cells.len(), self.head.len(), "a cell per column");
        self.rows.push(cells);
    }

    /// The table as Markdown, ending in a newline.
    pub fn markdown(&self) -> String {
        // `| a | b |`; an empty cell is `| |`.
        let line = |cells: &mut dyn Iterator<Item = &str>| {
            let mut out = String::from("|");
            for c in cells {
                out += &match c.is_empty() {
                    true => " |".to_owned(),
                    false => format!(" {c} |"),
                };
            }
            out + "\n"
        };
        let mut out = line(&mut self.head.iter().map(|(h, _)| h.as_str()));
        out.push('|');
        for (_, a) in &self.head {
            out.push_str(match a {
                Align::Left => "---|",
                Align::Right => "---:|",
            });
        }
        out.push('\n');
        for r in &self.rows {
            out.push_str(&line(&mut r.iter().map(String::as_str)));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_is_a_header_an_alignment_line_and_a_line_per_row() {
        let mut t = Table::new(["case", "error (m)"], "lr");
        t.row(["no fault".into(), "0.12".into()]);
        t.row(["".into(), "–".into()]);
        assert_eq!(
            t.markdown(),
            "| case | error (m) |\n|---|---:|\n| no fault | 0.12 |\n| | – |\n"
        );
    }
}
