//! The trajectory table: named f64 columns, one row per controller cycle, and
//! its CSV form (`trajectory.csv`).
//!
//! Numbers are written with Rust's shortest round-trip formatting (`{:?}` of
//! `f64`: the shortest decimal string that parses back to the same bits), so a
//! CSV read back with [`Trajectory::read_csv`] is bit-identical to the table
//! that was written.

use crate::ReportError;
use std::fmt::Write as _;
use std::path::Path;

/// Checks column names: at least one, unique, none empty or containing a
/// comma, quote or newline (they are written unquoted in the CSV header).
pub(crate) fn validate_columns(columns: &[String]) -> Result<(), ReportError> {
    if columns.is_empty() {
        return Err(ReportError::Table(
            "a trajectory needs at least one column".into(),
        ));
    }
    for (i, c) in columns.iter().enumerate() {
        if c.is_empty() || c.contains([',', '\n', '\r', '"']) {
            return Err(ReportError::Table(format!(
                "column {i} has an invalid name {c:?} (empty or containing a comma, quote or newline)"
            )));
        }
        if columns[..i].contains(c) {
            return Err(ReportError::Table(format!(
                "column name {c:?} appears twice"
            )));
        }
    }
    Ok(())
}

/// Appends one CSV line (values separated by commas, then a newline) to `s`:
/// the one formatting of a row, shared by [`Trajectory::to_csv_string`] and the
/// streaming [`crate::stream::CsvWriter`] so both write the same bytes.
pub(crate) fn push_csv_row(s: &mut String, row: &[f64]) {
    for (j, v) in row.iter().enumerate() {
        if j > 0 {
            s.push(',');
        }
        // `{:?}` is the shortest representation that round-trips
        // (and uses an exponent for very small/large magnitudes).
        let _ = write!(s, "{v:?}");
    }
    s.push('\n');
}

/// A CSV table as written by [`Trajectory::to_csv_string`], parsed one line at
/// a time (so a long `trajectory.csv` can be read without holding it whole).
pub struct CsvLines<'a, S, I> {
    lines: std::iter::Enumerate<I>,
    origin: &'a str,
    columns: Vec<String>,
    _line: std::marker::PhantomData<S>,
}

impl<'a, S: AsRef<str>, I: Iterator<Item = Result<S, ReportError>>> CsvLines<'a, S, I> {
    /// A parser of `lines`; `origin` names the source in error messages.
    pub fn new(lines: I, origin: &'a str) -> Self {
        CsvLines {
            lines: lines.enumerate(),
            origin,
            columns: Vec::new(),
            _line: std::marker::PhantomData,
        }
    }

    fn error(&self, line: usize, message: String) -> ReportError {
        ReportError::Parse {
            origin: self.origin.to_string(),
            line,
            message,
        }
    }

    /// The column names of the header (the first non-blank line), validated.
    pub fn header(&mut self) -> Result<Vec<String>, ReportError> {
        let header = loop {
            match self.lines.next() {
                Some((_, l)) => {
                    let l = l?;
                    if !l.as_ref().trim().is_empty() {
                        break l;
                    }
                }
                None => return Err(self.error(1, "empty file, expected a header line".into())),
            }
        };
        let columns: Vec<String> = header
            .as_ref()
            .split(',')
            .map(|c| c.trim().to_string())
            .collect();
        validate_columns(&columns).map_err(|e| self.error(1, e.to_string()))?;
        self.columns = columns.clone();
        Ok(columns)
    }

    /// Parses the next row into `row`; `false` at the end of the table.
    pub fn next_row(&mut self, row: &mut Vec<f64>) -> Result<bool, ReportError> {
        let (i, line) = loop {
            match self.lines.next() {
                Some((i, l)) => {
                    let l = l?;
                    if !l.as_ref().trim().is_empty() {
                        break (i, l);
                    }
                }
                None => return Ok(false),
            }
        };
        row.clear();
        for (j, field) in line.as_ref().split(',').enumerate() {
            let v: f64 = field.trim().parse().map_err(|_| {
                let column = self.columns.get(j).map(String::as_str).unwrap_or("<extra>");
                self.error(
                    i + 1,
                    format!("column {column:?}: {field:?} is not a number"),
                )
            })?;
            row.push(v);
        }
        let n = self.columns.len();
        if row.len() != n {
            return Err(self.error(
                i + 1,
                format!("{} values, the header has {n} columns", row.len()),
            ));
        }
        Ok(true)
    }
}

/// Column-named table of f64 values, stored row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    columns: Vec<String>,
    data: Vec<f64>,
}

impl Trajectory {
    /// An empty table with the given column names (must be unique and non-empty).
    pub fn new(columns: Vec<String>) -> Result<Trajectory, ReportError> {
        Self::with_capacity(columns, 0)
    }

    /// Like [`Trajectory::new`], reserving room for `rows` rows.
    pub fn with_capacity(columns: Vec<String>, rows: usize) -> Result<Trajectory, ReportError> {
        validate_columns(&columns)?;
        let n = columns.len();
        Ok(Trajectory {
            columns,
            data: Vec::with_capacity(rows * n),
        })
    }

    /// Same columns and every value the same bit pattern (NaN = NaN: a column a
    /// run cannot know is NaN in every run). `==` follows f64, where NaN ≠ NaN.
    pub fn bit_identical(&self, other: &Trajectory) -> bool {
        self.columns == other.columns
            && self.data.len() == other.data.len()
            && self
                .data
                .iter()
                .zip(&other.data)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }

    /// Column names in order.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// Number of rows.
    pub fn n_rows(&self) -> usize {
        self.data.len() / self.columns.len()
    }

    /// Appends one row; its length must equal the number of columns.
    pub fn push_row(&mut self, row: &[f64]) -> Result<(), ReportError> {
        ReportError::check_row(self.n_rows(), row, self.columns.len())?;
        self.data.extend_from_slice(row);
        Ok(())
    }

    /// Row `i` (panics if out of range, like slice indexing).
    pub fn row(&self, i: usize) -> &[f64] {
        let n = self.columns.len();
        &self.data[i * n..(i + 1) * n]
    }

    /// Iterator over the rows.
    pub fn rows(&self) -> impl Iterator<Item = &[f64]> {
        self.data.chunks_exact(self.columns.len())
    }

    /// Index of a column by name.
    pub fn column_index(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// Copy of a column by name.
    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let j = self.column_index(name)?;
        Some(self.rows().map(|r| r[j]).collect())
    }

    /// Copy of a column, or an error naming the missing column.
    pub fn require(&self, name: &str) -> Result<Vec<f64>, ReportError> {
        self.column(name)
            .ok_or_else(|| ReportError::Table(format!("the trajectory has no column {name:?}")))
    }

    /// The table as CSV text: a header line, then one line per row.
    pub fn to_csv_string(&self) -> String {
        let mut s = String::with_capacity(self.data.len() * 20 + 64);
        s.push_str(&self.columns.join(","));
        s.push('\n');
        for row in self.rows() {
            push_csv_row(&mut s, row);
        }
        s
    }

    /// Writes the table as CSV to `path`.
    pub fn write_csv(&self, path: &Path) -> Result<(), ReportError> {
        std::fs::write(path, self.to_csv_string()).map_err(|e| ReportError::Io {
            path: path.to_path_buf(),
            error: e,
        })
    }

    /// Parses CSV text as written by [`Trajectory::to_csv_string`]. `origin` names the
    /// source in error messages.
    pub fn from_csv_str(text: &str, origin: &str) -> Result<Trajectory, ReportError> {
        let mut csv = CsvLines::new(text.lines().map(Ok), origin);
        let mut t = Trajectory::new(csv.header()?)?;
        let mut row = Vec::with_capacity(t.columns.len());
        while csv.next_row(&mut row)? {
            t.data.extend_from_slice(&row);
        }
        Ok(t)
    }

    /// Reads a CSV file written by [`Trajectory::write_csv`].
    pub fn read_csv(path: &Path) -> Result<Trajectory, ReportError> {
        let text = std::fs::read_to_string(path).map_err(|e| ReportError::Io {
            path: path.to_path_buf(),
            error: e,
        })?;
        Self::from_csv_str(&text, &path.display().to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trip_is_bit_exact() {
        let mut t = Trajectory::new(vec!["t".into(), "q1".into(), "P_mu".into()]).unwrap();
        let vals = [
            0.1 + 0.2,
            -std::f64::consts::FRAC_PI_2,
            1e-300,
            -2.2250738585072014e-308,
            1.7976931348623157e308,
            0.0,
            -0.0,
            123_456_789.123_456_79,
            f64::NAN,
        ];
        for chunk in vals.chunks(3) {
            t.push_row(chunk).unwrap();
        }
        let text = t.to_csv_string();
        let back = Trajectory::from_csv_str(&text, "test").unwrap();
        assert_eq!(back.columns(), t.columns());
        assert_eq!(back.n_rows(), 3);
        for (a, b) in t.rows().zip(back.rows()) {
            for (x, y) in a.iter().zip(b) {
                assert!(x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()));
            }
        }
    }

    #[test]
    fn bad_rows_and_columns_are_rejected() {
        assert!(Trajectory::new(vec![]).is_err());
        assert!(Trajectory::new(vec!["a".into(), "a".into()]).is_err());
        assert!(Trajectory::new(vec!["a,b".into()]).is_err());
        let mut t = Trajectory::new(vec!["a".into(), "b".into()]).unwrap();
        let e = t.push_row(&[1.0]).unwrap_err().to_string();
        assert!(e.contains("2 columns"), "{e}");
        let e = Trajectory::from_csv_str("t,q1\n0,1\n0.001,x\n", "f.csv")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.csv") && e.contains("line 3") && e.contains("q1"),
            "{e}"
        );
        let e = Trajectory::from_csv_str("t,q1\n0,1,2\n", "f.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn column_access() {
        let mut t = Trajectory::new(vec!["t".into(), "x".into()]).unwrap();
        t.push_row(&[0.0, 1.0]).unwrap();
        t.push_row(&[0.5, 2.0]).unwrap();
        assert_eq!(t.column("x").unwrap(), vec![1.0, 2.0]);
        assert!(t.column("y").is_none());
        assert!(t.require("y").unwrap_err().to_string().contains("\"y\""));
        assert_eq!(t.row(1), &[0.5, 2.0]);
    }
}
