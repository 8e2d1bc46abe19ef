//! Compressed sparse row storage shared by every kernel (scipy's CSR layout, u32 column indices).
use crate::error::{invalid, Result};
use rayon::prelude::*;

/// An owned CSR matrix; `data` is empty for a pure sparsity pattern.
#[derive(Debug, Clone, PartialEq)]
pub struct Csr<T> {
    pub n_rows: usize,
    pub n_cols: usize,
    pub indptr: Vec<usize>,
    pub indices: Vec<u32>,
    pub data: Vec<T>,
}

/// A borrowed CSR matrix, as handed over from NumPy buffers.
#[derive(Debug, Clone, Copy)]
pub struct CsrView<'a, T> {
    pub n_rows: usize,
    pub n_cols: usize,
    pub indptr: &'a [usize],
    pub indices: &'a [u32],
    pub data: &'a [T],
}

impl<T> Csr<T> {
    pub fn view(&self) -> CsrView<'_, T> {
        CsrView {
            n_rows: self.n_rows,
            n_cols: self.n_cols,
            indptr: &self.indptr,
            indices: &self.indices,
            data: &self.data,
        }
    }
    pub fn nnz(&self) -> usize {
        self.indices.len()
    }
}

impl<'a, T> CsrView<'a, T> {
    /// Column indices of row `r`.
    #[inline]
    pub fn row(&self, r: usize) -> &'a [u32] {
        &self.indices[self.indptr[r]..self.indptr[r + 1]]
    }
    /// Values of row `r` (empty slice for a pattern).
    #[inline]
    pub fn row_data(&self, r: usize) -> &'a [T] {
        if self.data.is_empty() {
            &[]
        } else {
            &self.data[self.indptr[r]..self.indptr[r + 1]]
        }
    }
    pub fn nnz(&self) -> usize {
        self.indices.len()
    }

    /// Checks the structural invariants every kernel relies on; `what` names the matrix in messages.
    /// `need_data`: the matrix must carry one value per stored entry.
    pub fn validate(&self, what: &str, need_data: bool) -> Result<()> {
        // Checked: n_rows is the caller's number, and usize::MAX + 1 must not wrap to a match.
        if self.indptr.len().checked_sub(1) != Some(self.n_rows) {
            return invalid(format!(
                "{what}: indptr has length {}, expected n_rows + 1 (n_rows = {})",
                self.indptr.len(),
                self.n_rows
            ));
        }
        if self.indptr[0] != 0 || self.indptr[self.n_rows] != self.indices.len() {
            return invalid(format!(
                "{what}: indptr must start at 0 and end at nnz = {}",
                self.indices.len()
            ));
        }
        if self.indptr.windows(2).any(|w| w[0] > w[1]) {
            return invalid(format!("{what}: indptr must be non-decreasing"));
        }
        if need_data && self.data.len() != self.indices.len() {
            return invalid(format!(
                "{what}: {} values for {} stored entries",
                self.data.len(),
                self.indices.len()
            ));
        }
        // Parallel: cost matrices reach tens of millions of entries. (Chunks: rayon's
        // per-item `find_first` made this pass 15 times slower than a sequential scan.)
        let n_cols = self.n_cols;
        let out_of_range = |c: &u32| *c as usize >= n_cols;
        if let Some(&bad) = self
            .indices
            .par_chunks(1 << 16)
            .find_map_first(|ch| ch.iter().find(|c| out_of_range(c)))
        {
            return invalid(format!(
                "{what}: column index {bad} out of range for {} columns",
                self.n_cols
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_absurd_row_count_is_an_error() {
        let indptr = [0usize];
        for n_rows in [usize::MAX, 1] {
            let v = CsrView::<()> {
                n_rows,
                n_cols: 1,
                indptr: &indptr,
                indices: &[],
                data: &[],
            };
            assert!(v.validate("m", false).is_err());
        }
    }
}
