//! A recorded simulation: named columns sampled at the communication points.

use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// Column names; the first is `time`.
    pub columns: Vec<String>,
    pub rows: Vec<Vec<f64>>,
}

impl Trace {
    pub fn new(columns: Vec<String>) -> Self {
        Self { columns, rows: Vec::new() }
    }

    pub fn index(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let i = self.index(name)?;
        Some(self.rows.iter().map(|r| r[i]).collect())
    }

    /// CSV with shortest round-trip number formatting (reading it back gives the same bits).
    pub fn write_csv(&self, path: &Path) -> Result<()> {
        let mut f = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?,
        );
        writeln!(f, "{}", self.columns.join(","))?;
        for r in &self.rows {
            let line: Vec<String> = r.iter().map(|x| format!("{x:?}")).collect();
            writeln!(f, "{}", line.join(","))?;
        }
        Ok(())
    }

    pub fn read_csv(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut lines = text.lines();
        let header = lines.next().context("empty CSV")?;
        let columns: Vec<String> = header.split(',').map(|s| s.trim().to_string()).collect();
        let mut rows = Vec::new();
        for (n, line) in lines.enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let row: Vec<f64> = line
                .split(',')
                .map(|s| parse_number(s.trim()))
                .collect::<Result<_>>()
                .with_context(|| format!("{} line {}", path.display(), n + 2))?;
            if row.len() != columns.len() {
                bail!("{} line {}: {} values for {} columns", path.display(), n + 2, row.len(), columns.len());
            }
            rows.push(row);
        }
        Ok(Self { columns, rows })
    }
}

fn parse_number(s: &str) -> Result<f64> {
    match s {
        "True" | "true" => Ok(1.0),
        "False" | "false" => Ok(0.0),
        _ => s.parse::<f64>().with_context(|| format!("`{s}` is not a number")),
    }
}

/// First difference between two traces over their common columns, bit for bit.
#[derive(Clone, Debug, PartialEq)]
pub struct Mismatch {
    pub column: String,
    pub row: usize,
    pub left: f64,
    pub right: f64,
}

/// Compare the columns both traces have; `Ok(columns compared)` when every value has the same
/// bits, else the first mismatch (or an error for different shapes).
pub fn compare_exact(a: &Trace, b: &Trace) -> Result<std::result::Result<usize, Mismatch>> {
    if a.rows.len() != b.rows.len() {
        bail!("different lengths: {} vs {} rows", a.rows.len(), b.rows.len());
    }
    let common: Vec<(usize, usize, &String)> =
        a.columns.iter().enumerate().filter_map(|(i, c)| b.index(c).map(|j| (i, j, c))).collect();
    if common.len() < 2 {
        bail!("the traces share fewer than two columns");
    }
    for (row, (ra, rb)) in a.rows.iter().zip(&b.rows).enumerate() {
        for &(i, j, c) in &common {
            if ra[i].to_bits() != rb[j].to_bits() && !(ra[i] == 0.0 && rb[j] == 0.0) {
                return Ok(Err(Mismatch { column: c.clone(), row, left: ra[i], right: rb[j] }));
            }
        }
    }
    Ok(Ok(common.len()))
}
