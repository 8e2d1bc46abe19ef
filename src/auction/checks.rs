//! Input checks of the exact solvers: the CSR header, duplicate entries, the value range the
//! integer auction can take, and whether a caller's hint is a full matching in the pattern.
use rayon::prelude::*;

use super::{PAR_ROWS, RANGE_LIMIT};
use crate::csr::CsrView;
use crate::error::{invalid, CoreError, Result};

/// Whether `h` (row -> column or -1) uses only stored entries, never a column twice, and assigns
/// min(n_rows, n_cols) rows. `cost` has passed `check_header`.
pub(super) fn is_full_matching<T: Sync>(cost: &CsrView<T>, h: &[i64]) -> bool {
    if h.len() != cost.n_rows {
        return false;
    }
    let stored = (0..cost.n_rows)
        .into_par_iter()
        .with_min_len(PAR_ROWS)
        .all(|r| {
            let c = h[r];
            c < 0 || {
                let row = &cost.indices[cost.indptr[r]..cost.indptr[r + 1]];
                c < cost.n_cols as i64 && row.contains(&(c as u32))
            }
        });
    if !stored {
        return false;
    }
    let mut cols: Vec<i64> = h.iter().copied().filter(|&c| c >= 0).collect();
    let count = cols.len();
    // A flag per column when there are about as many columns as rows; otherwise (n_cols is
    // the caller's number and may dwarf the entries, see `compact_columns`) sorted columns.
    if cost.n_cols <= 2 * h.len() + 1024 {
        let mut used = vec![false; cost.n_cols];
        if cols
            .iter()
            .any(|&c| std::mem::replace(&mut used[c as usize], true))
        {
            return false;
        }
    } else {
        cols.par_sort_unstable();
        if cols.windows(2).any(|w| w[0] == w[1]) {
            return false;
        }
    }
    count == cost.n_rows.min(cost.n_cols)
}

pub(super) fn check_range(range: u128, n_obj: usize) -> Result<()> {
    let n = n_obj as u128;
    if range
        .checked_mul(n + 1)
        .and_then(|x| x.checked_mul(n + 2))
        .is_none_or(|x| x > RANGE_LIMIT)
    {
        return invalid(format!(
            "cost range too large for the exact auction: the largest per-row spread ({range}) \
             times (n+1)(n+2) with n = {n_obj} exceeds 2^60; rescale the costs"
        ));
    }
    Ok(())
}

pub(super) fn check_header<T>(cost: &CsrView<T>) -> Result<()> {
    // validate() computes n_rows + 1; keep an absurd n_rows from overflowing there.
    if cost.indptr.len().checked_sub(1) != Some(cost.n_rows) {
        return invalid(format!(
            "cost: indptr has length {}, expected n_rows + 1",
            cost.indptr.len()
        ));
    }
    cost.validate("cost", true)
}

/// A column stored twice in a (sorted or unsorted) row.
#[inline]
pub(super) fn duplicate_in(row: &[u32]) -> Option<u32> {
    if row.windows(2).all(|w| w[0] < w[1]) {
        return None;
    }
    let mut s = row.to_vec();
    s.sort_unstable();
    s.windows(2).find(|w| w[0] == w[1]).map(|w| w[0])
}

pub(super) fn duplicate_error<T>(row: usize, col: u32) -> Result<T> {
    Err(CoreError::Duplicate { row, col })
}

pub(super) fn check_duplicates<T>(cost: &CsrView<T>) -> Result<()> {
    let dup = (0..cost.n_rows)
        .into_par_iter()
        .with_min_len(PAR_ROWS)
        .find_map_first(|r| {
            duplicate_in(&cost.indices[cost.indptr[r]..cost.indptr[r + 1]]).map(|c| (r, c))
        });
    match dup {
        Some((r, c)) => duplicate_error(r, c),
        None => Ok(()),
    }
}
