//! Self-describing records: every value a process logs is put with its column (name, CSV
//! format, rerun path) in the same call, so that a column's name and value cannot drift apart,
//! and a controller part adds its columns by putting them. A CSV's header is the columns of a
//! record ([`Record::columns`]); readers go by name.

/// How a column's value is printed in the CSV.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Fixed-point with this many decimals.
    Fixed(usize),
    /// Scientific with this many decimals.
    Sci(usize),
    /// As the shortest exact decimal (counts and flags: `1`, `0`, `17`).
    Plain,
}

/// One logged value: its CSV column and, when plotted, its rerun entity under `controller/`.
#[derive(Debug, PartialEq, Eq)]
pub struct Column {
    pub name: &'static str,
    pub format: Format,
    pub plot: Option<&'static str>,
}

impl Column {
    pub const fn fixed(name: &'static str, decimals: usize) -> Self {
        Self {
            name,
            format: Format::Fixed(decimals),
            plot: None,
        }
    }
    pub const fn sci(name: &'static str, decimals: usize) -> Self {
        Self {
            name,
            format: Format::Sci(decimals),
            plot: None,
        }
    }
    pub const fn plain(name: &'static str) -> Self {
        Self {
            name,
            format: Format::Plain,
            plot: None,
        }
    }
    /// Also a rerun scalar at `controller/<path>`.
    pub const fn plot(mut self, path: &'static str) -> Self {
        self.plot = Some(path);
        self
    }

    /// The value as the CSV prints it.
    pub fn write(&self, w: &mut impl std::io::Write, v: f64) -> std::io::Result<()> {
        match self.format {
            Format::Fixed(d) => write!(w, "{v:.d$}"),
            Format::Sci(d) => write!(w, "{v:.d$e}"),
            Format::Plain => write!(w, "{v}"),
        }
    }
}

/// A column as a `&'static` item, for [`Record::put`]: `col!(fixed("com_x", 5).plot("com/x"))`.
#[macro_export]
macro_rules! col {
    ($($c:tt)*) => {{
        const C: &$crate::record::Column = &$crate::record::Column::$($c)*;
        C
    }};
}

/// The most columns a record holds (a part's columns past it are counted, not kept).
pub const MAX_COLUMNS: usize = 128;

/// One tick's values with their columns: fixed size, copied through the logger's queue
/// without allocating.
#[derive(Clone, Copy)]
pub struct Record {
    columns: [Option<&'static Column>; MAX_COLUMNS],
    values: [f64; MAX_COLUMNS],
    len: usize,
    /// Values put past [`MAX_COLUMNS`] (0 unless the parts outgrew it).
    pub overflow: usize,
}

impl Default for Record {
    fn default() -> Self {
        Self {
            columns: [None; MAX_COLUMNS],
            values: [0.0; MAX_COLUMNS],
            len: 0,
            overflow: 0,
        }
    }
}

impl std::fmt::Debug for Record {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map()
            .entries(self.iter().map(|(c, v)| (c.name, v)))
            .finish()
    }
}

impl Record {
    pub fn put(&mut self, column: &'static Column, value: f64) {
        if self.len < MAX_COLUMNS {
            self.columns[self.len] = Some(column);
            self.values[self.len] = value;
            self.len += 1;
        } else {
            self.overflow += 1;
        }
    }

    /// Put a flag as 1 or 0.
    pub fn flag(&mut self, column: &'static Column, value: bool) {
        self.put(column, f64::from(u8::from(value)));
    }

    pub fn iter(&self) -> impl Iterator<Item = (&'static Column, f64)> + '_ {
        self.columns[..self.len]
            .iter()
            .zip(&self.values[..self.len])
            .filter_map(|(c, v)| c.map(|c| (c, *v)))
    }

    /// The columns, in order: the CSV's header.
    pub fn columns(&self) -> Vec<&'static Column> {
        self.iter().map(|(c, _)| c).collect()
    }

    /// The CSV header these columns make: their names, comma-separated, and a newline.
    pub fn write_csv_header(&self, w: &mut impl std::io::Write) -> std::io::Result<()> {
        for (k, (c, _)) in self.iter().enumerate() {
            if k > 0 {
                w.write_all(b",")?;
            }
            w.write_all(c.name.as_bytes())?;
        }
        writeln!(w)
    }

    /// The CSV row of these values: each in its column's format, comma-separated, and a newline.
    pub fn write_csv_row(&self, w: &mut impl std::io::Write) -> std::io::Result<()> {
        for (k, (c, v)) in self.iter().enumerate() {
            if k > 0 {
                w.write_all(b",")?;
            }
            c.write(w, v)?;
        }
        writeln!(w)
    }

    /// The value of the column named `name` (tests, summaries).
    pub fn get(&self, name: &str) -> Option<f64> {
        self.iter().find(|(c, _)| c.name == name).map(|(_, v)| v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_keeps_each_value_with_its_column_and_prints_it_in_its_format() {
        let mut r = Record::default();
        r.put(col!(fixed("a", 3)), 1.23456);
        r.put(col!(sci("b", 2).plot("x/b")), 12345.0);
        r.flag(col!(plain("c")), true);
        let names: Vec<_> = r.columns().iter().map(|c| c.name).collect();
        assert_eq!(names, ["a", "b", "c"]);
        let mut out = Vec::new();
        for (c, v) in r.iter() {
            c.write(&mut out, v).unwrap();
            out.push(b',');
        }
        assert_eq!(String::from_utf8(out).unwrap(), "1.235,1.23e4,1,");
        assert_eq!(r.get("b"), Some(12345.0));
        assert_eq!(r.columns()[1].plot, Some("x/b"));
    }

    #[test]
    fn a_record_past_its_capacity_counts_what_it_drops() {
        let mut r = Record::default();
        for _ in 0..MAX_COLUMNS + 3 {
            r.put(col!(plain("n")), 1.0);
        }
        assert_eq!((r.columns().len(), r.overflow), (MAX_COLUMNS, 3));
    }
}
