//! A recorded simulation: named columns sampled at the communication points.

use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// Column names; the first is `time`.
    pub columns: Vec<String>,
    pub rows: Rows,
}

/// The rows of a trace, stored one after the other in one buffer: recording a row is a copy,
/// not an allocation (a 10 s run at 4 kHz has 40 000 of them), and a row reads as a slice.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rows {
    width: usize,
    values: Vec<f64>,
}

impl Rows {
    pub fn new(width: usize) -> Self {
        Self { width, values: Vec::new() }
    }

    /// Append a row; every row has the width of the first.
    pub fn push(&mut self, row: impl AsRef<[f64]>) {
        let row = row.as_ref();
        if self.values.is_empty() && self.width == 0 {
            self.width = row.len();
        }
        assert_eq!(row.len(), self.width, "a trace row has {} values, the trace {} columns", row.len(), self.width);
        self.values.extend_from_slice(row);
    }

    /// Append a row from its values in column order (no intermediate row).
    pub fn push_from(&mut self, row: impl IntoIterator<Item = f64>) {
        let before = self.values.len();
        self.values.extend(row);
        assert_eq!(self.values.len() - before, self.width, "a trace row must have {} values", self.width);
    }

    /// Append the row `values[gather.sources[0]], values[gather.sources[1]], …` (one value per
    /// column): the sources were checked against the buffer's length once, by [`Gather::new`],
    /// not at every value of every row.
    pub fn push_gathered(&mut self, values: &[f64], gather: &Gather) {
        assert_eq!(gather.sources.len(), self.width, "a trace row must have {} values", self.width);
        assert_eq!(values.len(), gather.from, "the row is gathered from {} values, not {}", gather.from, values.len());
        // The columns that take the buffer's first values in order, in one copy.
        self.values.extend_from_slice(&values[..gather.in_place]);
        // SAFETY: every source is below `gather.from` (`Gather::new`), the length of `values`.
        self.values.extend(gather.sources[gather.in_place..].iter().map(|&k| unsafe { *values.get_unchecked(k) }));
        self.prefetch_next_row();
    }

    /// Ask for the cache lines the next row will be written to, while the simulation computes
    /// that row. A long recording writes into memory no cache holds (all 52 outputs of a 10 s
    /// run at 4 kHz are 17 MB): without the hint, each row's stores wait for their lines to
    /// be fetched, and recording all outputs cost about as much as the FMI boundary itself
    /// (`servo bench fmu`). A prefetch is a hint: it never faults and changes no value.
    #[inline]
    fn prefetch_next_row(&self) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            const LINE: usize = 64;
            let spare = self.values.capacity() - self.values.len();
            let bytes = spare.min(self.width) * std::mem::size_of::<f64>();
            let start = self.values.as_ptr().wrapping_add(self.values.len()) as *const i8;
            // Every line the row touches: one per 64 bytes from its start, and its last byte's.
            for offset in (0..bytes).step_by(LINE).chain(bytes.checked_sub(1)) {
                // SAFETY: `offset` stays inside the vector's allocation (its spare capacity);
                // a prefetch neither reads nor writes memory.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(start.add(offset)) };
            }
        }
    }

    /// Append a row of zeros and let `fill` write it (columns in any order).
    pub fn push_with(&mut self, fill: impl FnOnce(&mut [f64])) {
        let start = self.values.len();
        self.values.resize(start + self.width, 0.0);
        fill(&mut self.values[start..]);
    }

    /// Drop every row, keep the buffer.
    pub fn clear(&mut self) {
        self.values.clear();
    }

    pub fn reserve_exact(&mut self, rows: usize) {
        self.values.reserve_exact(rows * self.width);
    }

    pub fn len(&self) -> usize {
        self.values.len().checked_div(self.width).unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    pub fn iter(&self) -> std::slice::ChunksExact<'_, f64> {
        self.values.chunks_exact(self.width.max(1))
    }

    pub fn iter_mut(&mut self) -> std::slice::ChunksExactMut<'_, f64> {
        self.values.chunks_exact_mut(self.width.max(1))
    }

    pub fn first(&self) -> Option<&[f64]> {
        self.iter().next()
    }

    /// The last row (a run looks at it after every step: no iterator, no division; rows are
    /// only ever pushed whole).
    #[inline]
    pub fn last(&self) -> Option<&[f64]> {
        let (n, width) = (self.values.len(), self.width.max(1));
        debug_assert_eq!(n % width, 0, "a trace holds whole rows");
        (n >= width).then(|| &self.values[n - width..])
    }

    pub fn get(&self, k: usize) -> Option<&[f64]> {
        (k < self.len()).then(|| &self[k])
    }
}

/// Which value of a buffer each column of a row takes ([`Rows::push_gathered`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Gather {
    sources: Vec<usize>,
    from: usize,
    /// The first columns take the buffer's first values, in order (`sources[c] == c`).
    in_place: usize,
}

impl Gather {
    /// Column `c` takes `values[sources[c]]` of a buffer of `from` values; a source outside
    /// the buffer panics here.
    pub fn new(sources: Vec<usize>, from: usize) -> Self {
        if let Some(k) = sources.iter().find(|&&k| k >= from) {
            panic!("a column takes value {k} of a buffer of {from} values");
        }
        let in_place = sources.iter().enumerate().take_while(|&(c, &k)| c == k).count();
        Self { sources, from, in_place }
    }
}

impl std::ops::Index<usize> for Rows {
    type Output = [f64];
    fn index(&self, k: usize) -> &[f64] {
        &self.values[k * self.width..(k + 1) * self.width]
    }
}

impl std::ops::IndexMut<usize> for Rows {
    fn index_mut(&mut self, k: usize) -> &mut [f64] {
        &mut self.values[k * self.width..(k + 1) * self.width]
    }
}

impl<'a> IntoIterator for &'a Rows {
    type Item = &'a [f64];
    type IntoIter = std::slice::ChunksExact<'a, f64>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl Trace {
    pub fn new(columns: Vec<String>) -> Self {
        let width = columns.len();
        Self { columns, rows: Rows::new(width) }
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
        let mut rows = Rows::new(columns.len());
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gathered_row_takes_each_column_from_its_source() {
        // Columns 0 and 1 in place, then the buffer's values picked out of order.
        let buffer = [10.0, 11.0, 12.0, 13.0, 14.0];
        let gather = Gather::new(vec![0, 1, 4, 2, 2, 3], buffer.len());
        let mut rows = Rows::new(6);
        rows.push_gathered(&buffer, &gather);
        rows.push_gathered(&[0.0, 1.0, 2.0, 3.0, 4.0], &gather);
        assert_eq!(&rows[0], &[10.0, 11.0, 14.0, 12.0, 12.0, 13.0]);
        assert_eq!(&rows[1], &[0.0, 1.0, 4.0, 2.0, 2.0, 3.0]);
        // All in place (a record list whose Float64 outputs come first).
        let mut rows = Rows::new(3);
        rows.push_gathered(&[1.0, 2.0, 3.0], &Gather::new(vec![0, 1, 2], 3));
        assert_eq!(&rows[0], &[1.0, 2.0, 3.0]);
    }

    #[test]
    #[should_panic(expected = "takes value 5 of a buffer of 5 values")]
    fn a_source_outside_the_buffer_is_refused_when_the_gather_is_made() {
        Gather::new(vec![0, 5], 5);
    }

    #[test]
    #[should_panic(expected = "gathered from 5 values, not 4")]
    fn a_buffer_of_another_length_is_refused() {
        let mut rows = Rows::new(2);
        rows.push_gathered(&[0.0; 4], &Gather::new(vec![0, 4], 5));
    }
}
