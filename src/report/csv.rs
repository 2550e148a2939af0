//! The one reader of the runs' CSV logs (`controller.csv`, `sim.csv`): numeric columns by the
//! header's names. Two readings: strict for the report, which plots what it reads and refuses a
//! bad file naming file and line; lenient for the after-run analysis, which compares whatever a
//! run left (a run stopped mid-write leaves a short last row).

use std::collections::HashMap;
use std::path::Path;

use super::ReportError;

/// How a cell or a row that is not as the header says is read.
#[derive(Debug, Clone, Copy)]
pub enum Reading<'a> {
    /// Every row has the header's number of fields and every field is a number, else an error
    /// naming the line; the header must name the `required` columns and at least one row follow.
    Strict { required: &'a [&'a str] },
    /// A cell that is not a number is NaN; a short row adds to its first columns only (the
    /// columns then differ in length); never an error.
    Lenient,
}

/// Numeric columns by name.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Columns {
    by_name: HashMap<String, Vec<f64>>,
}

impl Columns {
    /// Read `path`; every error names the file (and the line for a bad row).
    pub fn read(path: &Path, reading: Reading) -> Result<Columns, ReportError> {
        let text = std::fs::read_to_string(path).map_err(|source| ReportError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path, reading)
    }

    /// Parse `text`, read from `path` (which errors name). Blank lines are skipped.
    pub fn parse(text: &str, path: &Path, reading: Reading) -> Result<Columns, ReportError> {
        let bad = |line: usize, message: String| ReportError::Csv {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut lines = text.lines().enumerate();
        let header: Vec<&str> = match (lines.next(), reading) {
            (Some((_, h)), _) => h.split(',').map(str::trim).collect(),
            (None, Reading::Strict { .. }) => {
                return Err(bad(1, "the file is empty (no header)".into()));
            }
            (None, Reading::Lenient) => Vec::new(),
        };
        if let Reading::Strict { required } = reading
            && let Some(name) = required.iter().find(|n| !header.contains(n))
        {
            return Err(bad(1, format!("no `{name}` column in the header")));
        }
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
        for (i, line) in lines {
            if line.trim().is_empty() {
                continue;
            }
            match reading {
                Reading::Strict { .. } => {
                    strict_row(line, &header, &mut cols).map_err(|message| bad(i + 1, message))?
                }
                Reading::Lenient => lenient_row(line, &mut cols),
            }
        }
        if matches!(reading, Reading::Strict { .. }) && cols.first().is_none_or(Vec::is_empty) {
            return Err(bad(2, "no data rows after the header".into()));
        }
        Ok(Columns {
            by_name: header.iter().map(|h| h.to_string()).zip(cols).collect(),
        })
    }

    /// A column by its header name.
    pub fn get(&self, name: &str) -> Option<&Vec<f64>> {
        self.by_name.get(name)
    }
}

/// Columns given by name (a log built in a test).
impl<'a> FromIterator<(&'a str, Vec<f64>)> for Columns {
    fn from_iter<I: IntoIterator<Item = (&'a str, Vec<f64>)>>(iter: I) -> Self {
        Columns {
            by_name: iter.into_iter().map(|(n, c)| (n.to_string(), c)).collect(),
        }
    }
}

/// One row, strictly: the header's number of fields, each a number.
fn strict_row(line: &str, header: &[&str], cols: &mut [Vec<f64>]) -> Result<(), String> {
    let fields: Vec<&str> = line.split(',').collect();
    if fields.len() != header.len() {
        return Err(format!(
            "{} fields where the header has {}",
            fields.len(),
            header.len()
        ));
    }
    for (c, f) in fields.iter().enumerate() {
        let v: f64 = f
            .trim()
            .parse()
            .map_err(|_| format!("`{}` in column `{}` is not a number", f.trim(), header[c]))?;
        cols[c].push(v);
    }
    Ok(())
}

/// One row, leniently: NaN for a cell that is not a number, the first columns of a short row.
fn lenient_row(line: &str, cols: &mut [Vec<f64>]) {
    for (col, cell) in cols.iter_mut().zip(line.split(',')) {
        col.push(cell.trim().parse().unwrap_or(f64::NAN));
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A log's text, read as the after-run analysis reads it.
    pub(in crate::report) fn lenient(text: &str) -> Columns {
        Columns::parse(text, Path::new("log.csv"), Reading::Lenient).unwrap()
    }

    fn strict(text: &str) -> Result<Columns, ReportError> {
        Columns::parse(
            text,
            Path::new("x.csv"),
            Reading::Strict { required: &["t"] },
        )
    }

    /// The lenient reading: NaN for a bad cell, a short row fills its first columns.
    #[test]
    fn lenient_reads_what_is_there() {
        let c = lenient("t, a,b\n0.1,x,2\n0.2,3\n");
        assert_eq!(c.get("t"), Some(&vec![0.1, 0.2]));
        let a = c.get("a").unwrap();
        assert!(a[0].is_nan() && a[1] == 3.0);
        assert_eq!(c.get("b"), Some(&vec![2.0]));
        assert_eq!(lenient(""), Columns::default());
    }

    /// The strict reading names the line and the problem.
    #[test]
    fn strict_names_line_and_problem() {
        let err = |text: &str| strict(text).unwrap_err().to_string();
        assert_eq!(err(""), "x.csv, line 1: the file is empty (no header)");
        assert_eq!(err("a\n1\n"), "x.csv, line 1: no `t` column in the header");
        assert_eq!(
            err("t,a\n1,2\n\n1\n"),
            "x.csv, line 4: 1 fields where the header has 2"
        );
        assert_eq!(
            err("t,a\n1,z\n"),
            "x.csv, line 2: `z` in column `a` is not a number"
        );
        assert_eq!(err("t,a\n"), "x.csv, line 2: no data rows after the header");
        assert_eq!(strict("t,a\n1,2\n").unwrap().get("a"), Some(&vec![2.0]));
    }
}
