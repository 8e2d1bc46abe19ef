//! Exact sparse linear assignment: Hopcroft–Karp for feasibility, then Bertsekas' auction with
//! epsilon-scaling in integer arithmetic.
//!
//! The side with fewer vertices always plays the "persons" (transposing when needed) and every
//! person's values are shifted so that its best entry is 0: each person is assigned exactly once,
//! so the shift does not change which assignment is optimal, and it shrinks the value range that
//! bounds the prices. In the rectangular case columns that no person can use are dropped.
//!
//! Rectangular problems (fewer persons than objects) are made square by adding implicit,
//! identical dummy persons that value every object at 0. A dummy's best object is simply the
//! cheapest one, so dummies bid through a min/second-min segment tree over the prices instead of
//! scanning; the tree only exists in the rectangular case, so square problems pay nothing for it.
//! The padded problem is an ordinary square, feasible assignment problem, so plain
//! epsilon-scaling is correct on it, and its optimum restricted to the real persons is optimal
//! for the original problem (the dummies add 0 whatever they take). This is what keeps the
//! objects left unassigned at the lowest prices, which the asymmetric problem requires.
//!
//! Speed: each person keeps its `K` best arcs by reduced value (value - price) and the largest
//! reduced value among the others. Prices only rise, so that bound stays valid, and a bid only
//! rescans the whole row when the candidates can no longer certify the best and second best.
//!
//! Files: `checks` (input checks), `person_csr` (the person-major view), `hopcroft_karp`
//! (feasibility), `bidding` (the epsilon-scaling auction), `warm` (repairing a previous optimum
//! by shortest augmenting paths), `tests`, `warm_tests`.

mod bidding;
mod checks;
mod hopcroft_karp;
mod person_csr;
#[cfg(test)]
mod tests;
mod warm;
#[cfg(test)]
mod warm_tests;

use rayon::prelude::*;

use crate::csr::CsrView;
use crate::error::{invalid, Result};

use bidding::{scan_row, solve, Direct, Stored, TopK};
pub use bidding::{IntValue, DEFAULT_FLOOR_DIV};
use checks::{
    check_duplicates, check_header, check_range, duplicate_error, duplicate_in, is_full_matching,
};
use hopcroft_karp::hopcroft_karp;
use person_csr::{compact_columns, PersonCsr};
pub use warm::{warm_assignment, WarmSolution};

/// Sentinels: no person or object; an object held by a dummy person; no arc.
const NONE: u32 = u32::MAX;
const DUMMY: u32 = u32::MAX - 1;
const NO_ARC: usize = usize::MAX;
/// Bound on `range * (n + 1) * (n + 2)`: prices stay within a small multiple of it.
const RANGE_LIMIT: u128 = 1 << 60;
/// Rows per rayon task in the parallel passes.
const PAR_ROWS: usize = 512;

/// Optimal one-to-one assignment on a sparse cost. Returns, for each row, its column or -1.
/// Missing entries are forbidden pairs; an explicit stored 0 is an allowed pair.
///
/// Every vertex of the smaller side is matched (when `n_rows > n_cols`, `n_rows - n_cols` rows get
/// -1). The result is exactly optimal. Errors: malformed input, duplicate entries, a pattern with
/// no full assignment (`Infeasible`), or a per-row (per-column when `n_rows > n_cols`) spread of
/// the costs so large that `spread * (n + 1) * (n + 2)` exceeds 2^60, where `n` is the number of
/// usable vertices of the larger side (200k x 200k with costs within ±1e6 is far inside).
pub fn auction_assignment_int(cost: &CsrView<i64>, maximize: bool) -> Result<Vec<i64>> {
    auction_assignment_int_with(cost, maximize, DEFAULT_FLOOR_DIV)
}

/// [`auction_assignment_int`] whose first epsilon is at least the scaled value range over
/// `floor_div`. No choice suits every cost: HOPE's top-k overlap costs, where crowding pushes
/// some persons far down their rows, solve faster with a coarse floor (16) than with the
/// default 1024, while small banded integer costs solve slower with it (see
/// docs/decisions.md#auction).
pub fn auction_assignment_int_with(
    cost: &CsrView<i64>,
    maximize: bool,
    floor_div: i64,
) -> Result<Vec<i64>> {
    auction_assignment_int_hinted(cost, maximize, floor_div, None)
}

/// [`auction_assignment_int_with`] given `hint`, a full assignment (row -> column or -1) the
/// caller knows to lie in the pattern, such as HOPE's current map. A hint that checks out
/// (every entry stored, columns distinct, min(n_rows, n_cols) rows covered) proves feasibility,
/// so the Hopcroft–Karp search, a sizeable share of a solve, is skipped. Any other hint is
/// ignored. The result does not depend on the hint.
pub fn auction_assignment_int_hinted<T: IntValue>(
    cost: &CsrView<T>,
    maximize: bool,
    floor_div: i64,
    hint: Option<&[i64]>,
) -> Result<Vec<i64>> {
    check_header(cost)?;
    if floor_div < 1 {
        return invalid(format!("floor_div must be at least 1, got {floor_div}"));
    }
    if cost.n_rows == 0 || cost.n_cols == 0 {
        return Ok(vec![-1; cost.n_rows]);
    }
    let transposed = cost.n_rows > cost.n_cols;
    if transposed {
        check_duplicates(cost)?;
    }
    let (pc, data) = PersonCsr::build(cost)?;
    // One parallel pass over the persons checks duplicates (rows only: the transposed view was
    // checked above), finds each person's spread and its initial candidates, so the big arrays
    // are read once before the auction.
    let scans: Vec<RowScan> = (0..pc.m)
        .into_par_iter()
        .with_min_len(PAR_ROWS)
        .map(|i| {
            let (lo, hi) = (pc.ptr[i], pc.ptr[i + 1]);
            let dup = if transposed {
                None
            } else {
                duplicate_in(&cost.indices[lo..hi])
            };
            let (mn, mx, top) = scan_row(&data[lo..hi], lo, maximize);
            RowScan {
                dup,
                refv: if maximize { mx } else { mn },
                spread: if lo == hi { 0 } else { mx as i128 - mn as i128 },
                top,
            }
        })
        .collect();
    if let Some((r, c)) = scans
        .iter()
        .enumerate()
        .find_map(|(r, s)| s.dup.map(|c| (r, c)))
    {
        return duplicate_error(r, c);
    }
    let range = scans.iter().map(|s| s.spread).max().unwrap_or(0);
    match hint.filter(|h| is_full_matching(cost, h)) {
        // Every assignment is optimal when no person's values differ.
        Some(h) if range == 0 => return Ok(h.to_vec()),
        Some(_) => {}
        None => {
            let (size, hk) = pc.matching();
            if size < pc.m {
                return Err(pc.infeasible(size));
            }
            if range == 0 {
                return Ok(pc.to_rows(&pc.arcs_of(&hk)));
            }
        }
    }
    check_range(range as u128, pc.n_obj)?;
    let range = range as i64;
    let refv: Vec<i64> = scans.iter().map(|s| s.refv).collect();
    let tops: Vec<TopK> = scans.into_iter().map(|s| s.top).collect();
    let data: &[T] = &data;
    let assign = if maximize {
        solve(
            &pc,
            &Direct::<true, T> { data, refv },
            range,
            Some(tops),
            floor_div,
        )?
    } else {
        solve(
            &pc,
            &Direct::<false, T> { data, refv },
            range,
            Some(tops),
            floor_div,
        )?
    };
    Ok(pc.to_rows(&assign))
}

/// Float version of [`auction_assignment_int`].
///
/// Each row's values are shifted by the row's best value and quantized onto a uniform integer
/// grid of `q = floor(2^60 / ((n + 1) (n + 2))) - 1` steps over the largest per-row spread `R`
/// (per column when `n_rows > n_cols`; `n` = number of usable vertices of the larger side); the
/// integer problem is then solved exactly. With `m = min(n_rows, n_cols)`, the returned
/// assignment's total cost is within `m * R / q` (about `m (n+1) (n+2) R / 2^60`) of the true
/// optimum: e.g. `~4e-5 R` for 28k x 28k, below `1e-11 R` up to 100 x 100.
pub fn auction_assignment_float(cost: &CsrView<f64>, maximize: bool) -> Result<Vec<i64>> {
    check_header(cost)?;
    check_duplicates(cost)?;
    if cost.data.par_iter().any(|x| !x.is_finite()) {
        return invalid(
            "cost contains NaN or infinite values; use a finite cost and leave forbidden pairs \
             out of the sparsity pattern"
                .to_string(),
        );
    }
    if cost.n_rows == 0 || cost.n_cols == 0 {
        return Ok(vec![-1; cost.n_rows]);
    }
    let (pc, data) = PersonCsr::build(cost)?;
    let (size, hk) = pc.matching();
    if size < pc.m {
        return Err(pc.infeasible(size));
    }
    // Halved so that the spread of values near f64::MAX cannot overflow to infinity.
    let value = |k: usize| -> f64 {
        let c = 0.5 * data[k];
        if maximize {
            c
        } else {
            -c
        }
    };
    let refs: Vec<(f64, f64)> = (0..pc.m)
        .into_par_iter()
        .with_min_len(PAR_ROWS)
        .map(|i| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for a in pc.ptr[i]..pc.ptr[i + 1] {
                let v = value(a);
                lo = lo.min(v);
                hi = hi.max(v);
            }
            if lo > hi {
                (0.0, 0.0)
            } else {
                (hi, hi - lo)
            }
        })
        .collect();
    let range = refs.iter().fold(0.0f64, |r, x| r.max(x.1));
    if range <= 0.0 {
        return Ok(pc.to_rows(&pc.arcs_of(&hk)));
    }
    let n = pc.n_obj as u128;
    let q = (RANGE_LIMIT / (n + 1).saturating_mul(n + 2)).saturating_sub(1);
    if q < 1 {
        return invalid(format!(
            "problem too large for the exact auction: (n+1)(n+2) with n = {} exceeds 2^60",
            pc.n_obj
        ));
    }
    let qf = q as f64;
    let quant = |i: usize, a: usize| -> i64 {
        let t = (value(a) - refs[i].0) / range;
        // t is in [-1, 0] up to rounding; the clamp keeps that a guarantee.
        (t * qf).round().clamp(-qf, 0.0) as i64
    };
    let range_q = q as i64;
    let assign = if range_q <= i32::MAX as i64 {
        solve(
            &pc,
            &Stored(pc.arcs_map(|i, a| quant(i, a) as i32)),
            range_q,
            None,
            DEFAULT_FLOOR_DIV,
        )?
    } else {
        solve(
            &pc,
            &Stored(pc.arcs_map(quant)),
            range_q,
            None,
            DEFAULT_FLOOR_DIV,
        )?
    };
    Ok(pc.to_rows(&assign))
}

/// Hopcroft–Karp maximum-cardinality matching on the pattern; returns (size, row->col or -1).
///
/// Malformed input never panics: row ranges are clamped to the index array, out-of-range
/// column indices are ignored, and when `indptr` describes fewer than `n_rows` rows only those
/// rows are returned.
pub fn max_cardinality_matching(
    n_rows: usize,
    n_cols: usize,
    indptr: &[usize],
    indices: &[u32],
) -> (usize, Vec<i64>) {
    let clean = indptr.len() == n_rows.wrapping_add(1)
        && indptr.first() == Some(&0)
        && indptr.last() == Some(&indices.len())
        && indptr.windows(2).all(|w| w[0] <= w[1])
        && indices.iter().all(|&c| (c as usize) < n_cols);
    let mut ptr: Vec<usize> = Vec::new();
    let mut idx: Vec<u32> = Vec::new();
    let (ptr_ref, idx_src): (&[usize], &[u32]) = if clean {
        (indptr, indices)
    } else {
        ptr.push(0);
        for r in 0..n_rows.min(indptr.len().saturating_sub(1)) {
            let lo = indptr[r].min(indices.len());
            let hi = indptr[r + 1].min(indices.len());
            if lo < hi {
                idx.extend(indices[lo..hi].iter().filter(|&&c| (c as usize) < n_cols));
            }
            ptr.push(idx.len());
        }
        (&ptr, &idx)
    };
    // Column arrays are sized by the used columns only when n_cols dwarfs the entries.
    let (n_used, col_of, compact) = if n_cols <= 2 * idx_src.len() + 1024 {
        (n_cols, None, None)
    } else {
        compact_columns(idx_src, n_cols)
    };
    let idx_use: &[u32] = compact.as_deref().unwrap_or(idx_src);
    let (size, rm) = hopcroft_karp(ptr_ref.len() - 1, n_used, ptr_ref, idx_use);
    let out = rm
        .iter()
        .map(|&c| match (c, &col_of) {
            (NONE, _) => -1,
            (c, Some(t)) => t[c as usize] as i64,
            (c, None) => c as i64,
        })
        .collect();
    (size, out)
}

/// One person's row as the single pre-auction pass sees it.
struct RowScan {
    dup: Option<u32>,
    refv: i64,
    spread: i128,
    top: TopK,
}
