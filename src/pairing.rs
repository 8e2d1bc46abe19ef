//! Greedy pairing from a ranked list of candidate pairs.
use crate::error::{invalid, Result};
use crate::memory::try_filled_vec;

/// Walks `(rows[i], cols[i])` in the given order (best first) and keeps each pair whose column is
/// still unused and whose row has capacity left (row r takes at most `capacity[r]` columns).
/// Returns the kept pairs, in the order they were kept.
pub fn greedy_pairs(
    rows: &[u32],
    cols: &[u32],
    capacity: &[u32],
    n_cols: usize,
) -> Result<(Vec<u32>, Vec<u32>)> {
    if rows.len() != cols.len() {
        return invalid(format!(
            "rows and cols must have the same length, got {} and {}",
            rows.len(),
            cols.len()
        ));
    }
    let n_rows = capacity.len();
    if rows.iter().any(|&r| r as usize >= n_rows) || cols.iter().any(|&c| c as usize >= n_cols) {
        return invalid(format!(
            "pairs must index {n_rows} rows (one capacity each) and {n_cols} columns"
        ));
    }
    let mut left = capacity.to_vec();
    let mut col_done = try_filled_vec(n_cols, false, "the columns' flags")?;
    let (mut out_r, mut out_c) = (Vec::new(), Vec::new());
    for (&r, &c) in rows.iter().zip(cols) {
        if left[r as usize] > 0 && !col_done[c as usize] {
            left[r as usize] -= 1;
            col_done[c as usize] = true;
            out_r.push(r);
            out_c.push(c);
        }
    }
    Ok((out_r, out_c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_ranked_pairs_while_rows_have_capacity_and_columns_are_free() {
        // Row 0 (capacity 1) takes column 1; (1, 1) is then taken, so row 1 (capacity 2) gets
        // columns 0 and 2; row 2 finds every column taken.
        let rows = [0, 1, 1, 2, 2, 0, 1];
        let cols = [1, 1, 0, 0, 1, 2, 2];
        let (r, c) = greedy_pairs(&rows, &cols, &[1, 2, 1], 3).unwrap();
        assert_eq!(r, vec![0, 1, 1]);
        assert_eq!(c, vec![1, 0, 2]);
        assert!(greedy_pairs(&[0], &[3], &[1], 3).is_err());
        assert!(greedy_pairs(&[1], &[0], &[1], 3).is_err());
        assert!(greedy_pairs(&[0, 1], &[0], &[1, 1], 2).is_err());
    }

    #[test]
    fn an_absurd_column_count_is_an_error_not_an_abort() {
        let e = greedy_pairs(&[], &[], &[], usize::MAX / 2).unwrap_err();
        assert!(
            matches!(e, crate::error::CoreError::OutOfMemory { .. }),
            "{e:?}"
        );
    }
}
