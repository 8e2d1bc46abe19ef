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

use std::borrow::Cow;

use rayon::prelude::*;

use crate::csr::CsrView;
use crate::error::{CoreError, Result};

const NONE: u32 = u32::MAX;
const DUMMY: u32 = u32::MAX - 1;
const NO_ARC: usize = usize::MAX;
/// Bound on `range * (n + 1) * (n + 2)`: prices stay within a small multiple of it.
const RANGE_LIMIT: u128 = 1 << 60;
/// Prices never legitimately come near this; it guards the value-minus-price arithmetic.
const PRICE_CAP: i64 = 1 << 62;
/// epsilon shrinks by this factor between scaling phases.
const EPS_FACTOR: i64 = 4;
/// The first phase's epsilon is the scaled median gap between best and second best over this,
const EPS_GAP_DIV: i64 = 4;
/// or, when every person has a tie at the top, the scaled value range over this,
const EPS_START_DIV: i64 = 64;
/// and never less than the scaled value range over `EPS_START_DIV * EPS_FLOOR_DIV`
/// (the default `floor_div` of [`auction_assignment_int_with`]).
const EPS_FLOOR_DIV: i64 = 16;
pub const DEFAULT_FLOOR_DIV: i64 = EPS_START_DIV * EPS_FLOOR_DIV;
/// Candidate arcs kept per person.
const K: usize = 12;
/// Rows per rayon task in the parallel passes.
const PAR_ROWS: usize = 512;

fn invalid<T>(msg: String) -> Result<T> {
    Err(CoreError::InvalidInput(msg))
}

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

/// Whether `h` (row -> column or -1) uses only stored entries, never a column twice, and assigns
/// min(n_rows, n_cols) rows. `cost` has passed `check_header`.
fn is_full_matching<T: Sync>(cost: &CsrView<T>, h: &[i64]) -> bool {
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

fn check_range(range: u128, n_obj: usize) -> Result<()> {
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

// ---------------------------------------------------------------------------------------------
// Input checks and the person-major view
// ---------------------------------------------------------------------------------------------

fn check_header<T>(cost: &CsrView<T>) -> Result<()> {
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
fn duplicate_in(row: &[u32]) -> Option<u32> {
    if row.windows(2).all(|w| w[0] < w[1]) {
        return None;
    }
    let mut s = row.to_vec();
    s.sort_unstable();
    s.windows(2).find(|w| w[0] == w[1]).map(|w| w[0])
}

fn duplicate_error<T>(row: usize, col: u32) -> Result<T> {
    Err(CoreError::Duplicate { row, col })
}

fn check_duplicates<T>(cost: &CsrView<T>) -> Result<()> {
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

struct RowScan {
    dup: Option<u32>,
    refv: i64,
    spread: i128,
    top: TopK,
}

/// Renumbers the used columns 0..n_used in increasing order. Returns (n_used, compact->original
/// table or None when nothing was dropped, remapped indices or None when unchanged).
fn compact_columns(idx: &[u32], n_cols: usize) -> (usize, Option<Vec<u32>>, Option<Vec<u32>>) {
    if n_cols <= 2 * idx.len() + 1024 {
        let mut map = vec![NONE; n_cols];
        for &c in idx {
            map[c as usize] = 0;
        }
        let mut table = Vec::new();
        for (c, m) in map.iter_mut().enumerate() {
            if *m == 0 {
                *m = table.len() as u32;
                table.push(c as u32);
            }
        }
        if table.len() == n_cols {
            return (n_cols, None, None);
        }
        let remapped = idx.par_iter().map(|&c| map[c as usize]).collect();
        (table.len(), Some(table), Some(remapped))
    } else {
        let mut table = idx.to_vec();
        table.par_sort_unstable();
        table.dedup();
        let remapped = idx
            .par_iter()
            .map(|c| table.binary_search(c).unwrap_or(0) as u32)
            .collect();
        (table.len(), Some(table), Some(remapped))
    }
}

/// The problem seen from the smaller side ("persons"), objects renumbered compactly.
struct PersonCsr<'a> {
    m: usize,
    n_obj: usize,
    n_rows: usize,
    transposed: bool,
    ptr: Cow<'a, [usize]>,
    obj: Cow<'a, [u32]>,
    /// Compact object -> original column (or row, when transposed); None: identity.
    obj_orig: Option<Vec<u32>>,
}

impl<'a> PersonCsr<'a> {
    /// The person view and the values in its arc order.
    fn build<T: Copy + Default>(cost: &CsrView<'a, T>) -> Result<(Self, Cow<'a, [T]>)> {
        let (nr, nc) = (cost.n_rows, cost.n_cols);
        if nr.min(nc) >= DUMMY as usize {
            return invalid(format!("cost: {nr} x {nc} is too large for the auction"));
        }
        if nr <= nc {
            // Square: an unused column makes the problem infeasible, which Hopcroft–Karp
            // reports, so there is nothing to compact.
            let (n_obj, obj_orig, remapped) = if nr == nc {
                (nc, None, None)
            } else {
                compact_columns(cost.indices, nc)
            };
            let obj = match remapped {
                Some(v) => Cow::Owned(v),
                None => Cow::Borrowed(cost.indices),
            };
            let pc = PersonCsr {
                m: nr,
                n_obj,
                n_rows: nr,
                transposed: false,
                ptr: Cow::Borrowed(cost.indptr),
                obj,
                obj_orig,
            };
            Ok((pc, Cow::Borrowed(cost.data)))
        } else {
            // Persons are the columns; objects are the non-empty rows, in row order.
            let m = nc;
            let nnz = cost.indices.len();
            let mut ptr = vec![0usize; m + 1];
            for &c in cost.indices {
                ptr[c as usize + 1] += 1;
            }
            for i in 0..m {
                ptr[i + 1] += ptr[i];
            }
            let mut next = ptr.clone();
            let mut obj = vec![0u32; nnz];
            let mut val = vec![T::default(); nnz];
            let mut obj_orig = Vec::new();
            for r in 0..nr {
                let (lo, hi) = (cost.indptr[r], cost.indptr[r + 1]);
                if lo == hi {
                    continue;
                }
                let id = obj_orig.len() as u32;
                obj_orig.push(r as u32);
                for (k, &c) in cost.indices[lo..hi].iter().enumerate() {
                    let p = &mut next[c as usize];
                    obj[*p] = id;
                    val[*p] = cost.data[lo + k];
                    *p += 1;
                }
            }
            if obj_orig.len() >= DUMMY as usize {
                return invalid(format!("cost: {nr} x {nc} is too large for the auction"));
            }
            let pc = PersonCsr {
                m,
                n_obj: obj_orig.len(),
                n_rows: nr,
                transposed: true,
                ptr: Cow::Owned(ptr),
                obj: Cow::Owned(obj),
                obj_orig: Some(obj_orig),
            };
            Ok((pc, Cow::Owned(val)))
        }
    }

    /// Maps every arc through `f(person, arc)`, in arc order.
    fn arcs_map<W: Send, F: Fn(usize, usize) -> W + Sync>(&self, f: F) -> Vec<W> {
        (0..self.m)
            .into_par_iter()
            .with_min_len(PAR_ROWS)
            .flat_map_iter(|i| (self.ptr[i]..self.ptr[i + 1]).map(move |a| (i, a)))
            .map(|(i, a)| f(i, a))
            .collect()
    }

    fn matching(&self) -> (usize, Vec<u32>) {
        hopcroft_karp(self.m, self.n_obj, &self.ptr, &self.obj)
    }

    /// Person -> object into person -> arc.
    fn arcs_of(&self, mates: &[u32]) -> Vec<usize> {
        mates
            .iter()
            .enumerate()
            .map(|(i, &o)| {
                let lo = self.ptr[i];
                self.obj[lo..self.ptr[i + 1]]
                    .iter()
                    .position(|&x| x == o)
                    .map_or(NO_ARC, |k| lo + k)
            })
            .collect()
    }

    fn infeasible(&self, size: usize) -> CoreError {
        CoreError::Infeasible {
            uncovered: self.m - size,
            side: if self.transposed { "columns" } else { "rows" },
        }
    }

    /// Person -> arc (NO_ARC for unassigned) into row -> column.
    fn to_rows(&self, arc_of: &[usize]) -> Vec<i64> {
        let orig = |o: u32| -> i64 {
            self.obj_orig
                .as_ref()
                .map_or(o as i64, |t| t[o as usize] as i64)
        };
        let mut out = vec![-1i64; self.n_rows];
        for (i, &a) in arc_of.iter().enumerate() {
            if a == NO_ARC {
                continue;
            }
            let o = orig(self.obj[a]);
            if self.transposed {
                out[o as usize] = i as i64;
            } else {
                out[i] = o;
            }
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// Hopcroft–Karp
// ---------------------------------------------------------------------------------------------

/// Maximum matching on a valid CSR pattern; returns (size, row mate with NONE = free).
fn hopcroft_karp(nr: usize, nc: usize, ptr: &[usize], idx: &[u32]) -> (usize, Vec<u32>) {
    const INF: u32 = u32::MAX;
    let mut rm = vec![NONE; nr];
    let mut cm = vec![NONE; nc];
    let mut size = 0usize;
    // Greedy start, each row trying first the column proportional to its own index (found by
    // bisection, meaningful when rows are sorted): on near-diagonal patterns that column is
    // almost always still free and the greedy matching is already perfect.
    for (r, mate) in rm.iter_mut().enumerate() {
        let row = &idx[ptr[r]..ptr[r + 1]];
        let target = ((r as u128 * nc as u128) / nr.max(1) as u128) as u32;
        let h = row.partition_point(|&c| c < target);
        if let Some(&c) = row[h..]
            .iter()
            .chain(&row[..h])
            .find(|&&c| cm[c as usize] == NONE)
        {
            *mate = c;
            cm[c as usize] = r as u32;
            size += 1;
        }
    }
    let target = nr.min(nc);
    if size == target {
        return (size, rm);
    }
    let mut dist = vec![INF; nr];
    let mut queue: Vec<u32> = Vec::with_capacity(nr);
    let mut it = vec![0usize; nr];
    let mut stack: Vec<u32> = Vec::new();
    loop {
        queue.clear();
        for r in 0..nr {
            if rm[r] == NONE {
                dist[r] = 0;
                queue.push(r as u32);
            } else {
                dist[r] = INF;
            }
        }
        let mut limit = INF;
        let mut head = 0;
        while head < queue.len() {
            let r = queue[head] as usize;
            head += 1;
            let dr = dist[r];
            if dr >= limit {
                break;
            }
            for &c in &idx[ptr[r]..ptr[r + 1]] {
                let r2 = cm[c as usize];
                if r2 == NONE {
                    if limit == INF {
                        limit = dr + 1;
                    }
                } else if dist[r2 as usize] == INF {
                    dist[r2 as usize] = dr + 1;
                    queue.push(r2);
                }
            }
        }
        if limit == INF {
            break;
        }
        it.copy_from_slice(&ptr[..nr]);
        let mut aug = 0usize;
        for r0 in 0..nr {
            if rm[r0] != NONE || dist[r0] != 0 {
                continue;
            }
            stack.clear();
            stack.push(r0 as u32);
            while let Some(&top) = stack.last() {
                let r = top as usize;
                if it[r] < ptr[r + 1] {
                    let c = idx[it[r]];
                    it[r] += 1;
                    let r2 = cm[c as usize];
                    let d = dist[r] + 1;
                    if r2 == NONE {
                        if d == limit {
                            // Flip the path: each row takes the column its successor held.
                            let mut c = c;
                            for &rr in stack.iter().rev() {
                                let prev = rm[rr as usize];
                                rm[rr as usize] = c;
                                cm[c as usize] = rr;
                                c = prev;
                            }
                            aug += 1;
                            break;
                        }
                    } else if d < limit && dist[r2 as usize] == d {
                        stack.push(r2);
                    }
                } else {
                    dist[r] = INF;
                    stack.pop();
                }
            }
        }
        size += aug;
        if aug == 0 || size == target {
            break;
        }
    }
    (size, rm)
}

// ---------------------------------------------------------------------------------------------
// Auction
// ---------------------------------------------------------------------------------------------

/// Shifted, unscaled person values (all <= 0, >= -range) by (person, arc).
/// Integer value types the exact solver reads in place. Costs whose values fit in 32 bits (every
/// HOPE overlap cost) are best passed as `i32`: half the memory to fault in and to stream through
/// the rescans.
pub trait IntValue: Copy + Default + Send + Sync + Into<i64> {}
impl IntValue for i32 {}
impl IntValue for i64 {}

trait Values: Sync {
    fn get(&self, i: usize, a: usize) -> i64;
    /// The K + 1 best arcs of person `i` (arcs `lo..hi`) by reduced value
    /// `get(i, a) * scale - price[obj[a]]`, among those above `floor` (unused slots: `NO_ARC`).
    fn top_reduced(&self, i: usize, lo: usize, hi: usize, s: &Rescan) -> TopK;
}

/// What a rescan measures arcs against. Every `obj[a]` must be below `price.len()`.
struct Rescan<'a> {
    obj: &'a [u32],
    price: &'a [i64],
    scale: i64,
    floor: i64,
}

/// [`Values::top_reduced`] over one row's values `w` (arcs `lo..lo + w.len()`), each turned
/// into a shifted value by `value`. The auction's hottest loop (a rescan reads the whole row,
/// and on HOPE's k = 8 costs rows hold about 1000 arcs), so it reads prices unchecked and
/// compares a block of reduced values with the threshold at once.
#[inline(always)]
fn top_reduced_of<W: Copy>(w: &[W], value: impl Fn(W) -> i64, lo: usize, s: &Rescan) -> TopK {
    const BLOCK: usize = 8;
    let Rescan {
        obj,
        price,
        scale,
        floor,
    } = *s;
    let obj = &obj[lo..lo + w.len()];
    debug_assert!(obj.iter().all(|&o| (o as usize) < price.len()));
    let reduced = |v: W, o: u32| -> i64 {
        // SAFETY: objects are < n_obj = price.len(): `PersonCsr::build` renumbers them from
        // columns that `check_header` bounded, and the caller promises it.
        value(v) * scale - unsafe { *price.get_unchecked(o as usize) }
    };
    let mut t = TopK {
        vs: [i64::MIN; K + 1],
        ks: [NO_ARC; K + 1],
        len: K + 1,
    };
    let mut thr = floor;
    let (wb, ob) = (w.chunks_exact(BLOCK), obj.chunks_exact(BLOCK));
    let (wr, or) = (wb.remainder(), ob.remainder());
    let mut at = lo;
    for (wc, oc) in wb.zip(ob) {
        let mut r = [0i64; BLOCK];
        for j in 0..BLOCK {
            r[j] = reduced(wc[j], oc[j]);
        }
        if r.iter().any(|&x| x > thr) {
            for (j, &x) in r.iter().enumerate() {
                if x > thr {
                    t.insert(K, x, at + j);
                    thr = thr.max(t.vs[K]);
                }
            }
        }
        at += BLOCK;
    }
    for (j, (&v, &o)) in wr.iter().zip(or).enumerate() {
        let x = reduced(v, o);
        if x > thr {
            t.insert(K, x, at + j);
            thr = thr.max(t.vs[K]);
        }
    }
    t.len = t.ks.iter().take_while(|&&a| a != NO_ARC).count();
    t
}

/// Integer costs read in place: no copy of the values for the common non-transposed case.
struct Direct<'a, const MAXIMIZE: bool, T> {
    data: &'a [T],
    refv: Vec<i64>,
}

impl<const MAXIMIZE: bool, T: IntValue> Values for Direct<'_, MAXIMIZE, T> {
    #[inline(always)]
    fn get(&self, i: usize, a: usize) -> i64 {
        let d: i64 = self.data[a].into();
        if MAXIMIZE {
            d.wrapping_sub(self.refv[i])
        } else {
            self.refv[i].wrapping_sub(d)
        }
    }
    #[inline]
    fn top_reduced(&self, i: usize, lo: usize, hi: usize, s: &Rescan) -> TopK {
        let r = self.refv[i];
        let w = &self.data[lo..hi];
        if MAXIMIZE {
            top_reduced_of(w, |d: T| d.into().wrapping_sub(r), lo, s)
        } else {
            top_reduced_of(w, |d: T| r.wrapping_sub(d.into()), lo, s)
        }
    }
}

/// Precomputed values (transposed or quantized problems); i32 when the range allows.
struct Stored<W>(Vec<W>);

impl<W: Copy + Into<i64> + Sync> Values for Stored<W> {
    #[inline(always)]
    fn get(&self, _i: usize, a: usize) -> i64 {
        self.0[a].into()
    }
    #[inline]
    fn top_reduced(&self, _: usize, lo: usize, hi: usize, s: &Rescan) -> TopK {
        top_reduced_of(&self.0[lo..hi], |v: W| v.into(), lo, s)
    }
}

/// Min and second-min price over all objects, for the dummy persons' bids. Price changes are
/// only recorded and applied when the minimum is asked for: dummies bid rarely while persons
/// raise the same contested prices many times in between, so updating the tree on every raise
/// would cost more than the bids it serves.
struct MinTree {
    size: usize,
    m1: Vec<i64>,
    m2: Vec<i64>,
    arg: Vec<u32>,
    dirty: Vec<u32>,
    is_dirty: Vec<bool>,
}

impl MinTree {
    fn new(n: usize) -> Self {
        let size = n.next_power_of_two().max(2);
        let mut t = MinTree {
            size,
            m1: vec![i64::MAX; 2 * size],
            m2: vec![i64::MAX; 2 * size],
            arg: vec![0; 2 * size],
            dirty: Vec::new(),
            is_dirty: vec![false; n],
        };
        for j in 0..size {
            t.arg[size + j] = j as u32;
            if j < n {
                t.m1[size + j] = 0;
            }
        }
        for v in (1..size).rev() {
            t.pull(v);
        }
        t
    }
    #[inline]
    fn pull(&mut self, v: usize) {
        let (a, b) = (2 * v, 2 * v + 1);
        if self.m1[a] <= self.m1[b] {
            self.m1[v] = self.m1[a];
            self.arg[v] = self.arg[a];
            self.m2[v] = self.m2[a].min(self.m1[b]);
        } else {
            self.m1[v] = self.m1[b];
            self.arg[v] = self.arg[b];
            self.m2[v] = self.m2[b].min(self.m1[a]);
        }
    }
    /// Records that object `j`'s price changed.
    #[inline]
    fn mark(&mut self, j: usize) {
        if !self.is_dirty[j] {
            self.is_dirty[j] = true;
            self.dirty.push(j as u32);
        }
    }
    #[inline]
    fn set(&mut self, j: usize, p: i64) {
        let mut v = self.size + j;
        self.m1[v] = p;
        v /= 2;
        while v >= 1 {
            self.pull(v);
            v /= 2;
        }
    }
    /// (min price, its object, second-smallest price) given the current prices.
    #[inline]
    fn top(&mut self, price: &[i64]) -> (i64, usize, i64) {
        while let Some(j) = self.dirty.pop() {
            self.is_dirty[j as usize] = false;
            self.set(j as usize, price[j as usize]);
        }
        (self.m1[1], self.arg[1] as usize, self.m2[1])
    }
}

/// The K + 1 largest keys of a row with their arcs, largest first.
struct TopK {
    vs: [i64; K + 1],
    ks: [usize; K + 1],
    len: usize,
}

impl TopK {
    #[inline]
    fn of(mut items: impl Iterator<Item = (i64, usize)>) -> TopK {
        let mut t = TopK {
            vs: [i64::MIN; K + 1],
            ks: [NO_ARC; K + 1],
            len: 0,
        };
        while t.len < K + 1 {
            let Some((v, a)) = items.next() else {
                return t;
            };
            t.len += 1;
            t.insert(t.len - 1, v, a);
        }
        // The threshold lives in a register; the arrays are only touched on insertion.
        let mut thr = t.vs[K];
        for (v, a) in items {
            if v > thr {
                t.insert(K, v, a);
                thr = t.vs[K];
            }
        }
        t
    }

    /// Inserts (v, a) in order, dropping what was at position `last`.
    #[inline(always)]
    fn insert(&mut self, last: usize, v: i64, a: usize) {
        let mut p = last;
        while p > 0 && self.vs[p - 1] < v {
            self.vs[p] = self.vs[p - 1];
            self.ks[p] = self.ks[p - 1];
            p -= 1;
        }
        self.vs[p] = v;
        self.ks[p] = a;
    }
}

/// One pass over an integer row: (min, max, top K + 1 arcs by value).
#[inline]
fn scan_row<T: IntValue>(row: &[T], lo: usize, maximize: bool) -> (i64, i64, TopK) {
    if maximize {
        scan_row_key(row, lo, |c| c)
    } else {
        // `!c` orders like `-c` without overflowing at i64::MIN.
        scan_row_key(row, lo, |c| !c)
    }
}

#[inline(always)]
fn scan_row_key<T: IntValue>(row: &[T], lo: usize, key: impl Fn(i64) -> i64) -> (i64, i64, TopK) {
    let head = row.len().min(K + 1);
    let mut t = TopK::of(
        row[..head]
            .iter()
            .enumerate()
            .map(|(k, &c)| (key(c.into()), lo + k)),
    );
    let (mut mn, mut mx) = row[..head].iter().fold((i64::MAX, i64::MIN), |(a, b), &c| {
        (a.min(c.into()), b.max(c.into()))
    });
    let mut thr = t.vs[K];
    for (k, &c) in row[head..].iter().enumerate() {
        let c: i64 = c.into();
        mn = mn.min(c);
        mx = mx.max(c);
        let v = key(c);
        if v > thr {
            t.insert(K, v, lo + head + k);
            thr = t.vs[K];
        }
    }
    (mn, mx, t)
}

fn price_overflow<T>() -> Result<T> {
    invalid(
        "cost range too large for the exact auction: prices exceeded the safe integer range; \
         rescale the costs"
            .to_string(),
    )
}

/// An arc as the bidding loop needs it.
#[derive(Clone, Copy)]
struct Cand {
    arc: usize,
    obj: u32,
    /// value * scale
    val: i64,
}

const NO_CAND: Cand = Cand {
    arc: NO_ARC,
    obj: NONE,
    val: i64::MIN,
};

struct Auction<'p, V> {
    ptr: &'p [usize],
    obj: &'p [u32],
    vals: &'p V,
    scale: i64,
    /// Scaled value range: the increment used when a person has a single candidate.
    range: i64,
    price: Vec<i64>,
    owner: Vec<u32>,
    /// Arc held by each person (NO_ARC: unassigned).
    arc: Vec<usize>,
    /// Lower bound on (own value) - (best other value), valid since the last bid or check: other
    /// prices only rise, so it stays a lower bound and lets a phase skip the person unscanned.
    slack: Vec<i64>,
    /// Each person's K candidate arcs with their objects and scaled values, so that a bid reads
    /// them in one place rather than through the arc in the value and object arrays.
    cand: Vec<Cand>,
    cand_len: Vec<u8>,
    /// Object and scaled value of the arc each person holds (valid while `arc[i] != NO_ARC`).
    held: Vec<Cand>,
    /// Upper bound on the reduced value of every non-candidate arc.
    bound: Vec<i64>,
    stack: Vec<u32>,
    queued: Vec<bool>,
    tree: Option<MinTree>,
    free_dummies: usize,
}

impl<V: Values> Auction<'_, V> {
    #[inline]
    fn push(&mut self, i: usize) {
        if !self.queued[i] {
            self.queued[i] = true;
            self.stack.push(i as u32);
        }
    }

    #[inline]
    fn set_price(&mut self, j: usize, p: i64) {
        self.price[j] = p;
        if let Some(t) = self.tree.as_mut() {
            t.mark(j);
        }
    }

    /// Exact (best, best candidate, second best) of person `i`, from the candidates when they
    /// certify it, otherwise by a full rescan that refreshes them.
    #[inline]
    fn best_two(&mut self, i: usize) -> (i64, Cand, i64) {
        let base = i * K;
        let cnt = self.cand_len[i] as usize;
        let (mut b1, mut c1, mut b2) = (i64::MIN, NO_CAND, i64::MIN);
        let mut low = i64::MAX;
        for c in &self.cand[base..base + cnt] {
            let v = c.val - self.price[c.obj as usize];
            low = low.min(v);
            if v > b2 {
                if v > b1 {
                    b2 = b1;
                    b1 = v;
                    c1 = *c;
                } else {
                    b2 = v;
                }
            }
        }
        if b2 >= self.bound[i] {
            return (b1, c1, b2);
        }
        let (lo, hi) = (self.ptr[i], self.ptr[i + 1]);
        // The K current candidates are K arcs worth at least `low`, so the new K best are all
        // among the arcs worth `low` or more: the scan skips the rest, which on HOPE's costs
        // cut its insertions into the top list, the hot spot, to a few per row. The rest are
        // then bounded by `low - 1` rather than by the exact (K + 1)-th value.
        let floor = if cnt == K { low - 1 } else { i64::MIN };
        let scan = Rescan {
            obj: self.obj,
            price: &self.price,
            scale: self.scale,
            floor,
        };
        let t = self.vals.top_reduced(i, lo, hi, &scan);
        let cnt = t.len.min(K);
        for (slot, (&v, &a)) in self.cand[base..base + cnt]
            .iter_mut()
            .zip(t.vs.iter().zip(&t.ks))
        {
            let o = self.obj[a];
            *slot = Cand {
                arc: a,
                obj: o,
                val: v + self.price[o as usize],
            };
        }
        self.cand_len[i] = cnt as u8;
        self.bound[i] = t.vs[K].max(floor);
        let best = if cnt > 0 { self.cand[base] } else { NO_CAND };
        (t.vs[0], best, t.vs[1])
    }

    /// Re-checks an assigned person's eps-CS (keeping it if it holds) or bids for its best object.
    fn process(&mut self, i: usize, eps: i64) -> Result<()> {
        let (b1, best, b2) = self.best_two(i);
        let best_arc = best.arc;
        if best_arc == NO_ARC {
            // No arcs at all: excluded by the feasibility check.
            return Ok(());
        }
        let cur = self.arc[i];
        if cur != NO_ARC {
            let jc = self.held[i].obj as usize;
            let vc = self.held[i].val - self.price[jc];
            let other = if best_arc == cur { b2 } else { b1 };
            if other == i64::MIN {
                self.slack[i] = i64::MAX;
                return Ok(());
            }
            if vc >= other - eps {
                self.slack[i] = vc - other;
                return Ok(());
            }
            self.owner[jc] = NONE;
            self.arc[i] = NO_ARC;
        }
        let j = best.obj as usize;
        let prev = self.owner[j];
        if prev == NONE {
            // An unowned object is taken at its current price: eps-CS holds with slack b1 - b2
            // >= 0, so the person survives later phases untouched unless outbid. Objects never
            // lose their owner within a phase, so this happens at most n times per phase.
            self.slack[i] = if b2 == i64::MIN { i64::MAX } else { b1 - b2 };
        } else {
            let (gamma, slack) = if b2 == i64::MIN {
                (self.range.saturating_add(eps), i64::MAX)
            } else {
                // Any increment in [eps, b1 - b2 + eps] keeps eps-CS; b1 - b2 + 1 leaves slack -1,
                // which survives every later phase.
                let g = (b1 - b2 + 1).max(eps);
                (g, b1 - g - b2)
            };
            let np = match self.price[j].checked_add(gamma) {
                Some(p) if p <= PRICE_CAP => p,
                _ => return price_overflow(),
            };
            self.set_price(j, np);
            self.slack[i] = slack;
            if prev == DUMMY {
                self.free_dummies += 1;
            } else {
                self.arc[prev as usize] = NO_ARC;
                self.push(prev as usize);
            }
        }
        self.owner[j] = i as u32;
        self.arc[i] = best_arc;
        self.held[i] = best;
        Ok(())
    }

    /// One free dummy bids for the cheapest object.
    fn dummy_bid(&mut self, eps: i64) -> Result<()> {
        let Some(t) = self.tree.as_mut() else {
            self.free_dummies = 0;
            return Ok(());
        };
        let (pmin, j, p2) = t.top(&self.price);
        let prev = self.owner[j];
        if prev != NONE {
            let gamma = p2.saturating_sub(pmin).saturating_add(1).max(eps);
            let np = match pmin.checked_add(gamma) {
                Some(p) if p <= PRICE_CAP => p,
                _ => return price_overflow(),
            };
            self.set_price(j, np);
        }
        match prev {
            NONE => self.free_dummies -= 1,
            DUMMY => {}
            o => {
                self.free_dummies -= 1;
                self.arc[o as usize] = NO_ARC;
                self.push(o as usize);
            }
        }
        self.owner[j] = DUMMY;
        Ok(())
    }

    fn drain(&mut self, eps: i64) -> Result<()> {
        loop {
            while let Some(i) = self.stack.pop() {
                let i = i as usize;
                self.queued[i] = false;
                self.process(i, eps)?;
            }
            if self.free_dummies > 0 {
                self.dummy_bid(eps)?;
            } else {
                return Ok(());
            }
        }
    }
}

/// Epsilon-scaling auction on the person view; returns person -> arc.
/// `tops`: each person's initial candidates, ordered like its values (computed here if None).
fn solve<V: Values>(
    pc: &PersonCsr,
    vals: &V,
    range: i64,
    tops: Option<Vec<TopK>>,
    floor_div: i64,
) -> Result<Vec<usize>> {
    let (m, n) = (pc.m, pc.n_obj);
    let scale = n as i64 + 1;
    // Checked by the callers: range * (n+1) * (n+2) <= 2^60.
    let range_scaled = range * scale;
    let price = vec![0i64; n];
    let mut cand = vec![NO_CAND; m * K];
    let mut cand_len = vec![0u8; m];
    let mut bound = vec![i64::MIN; m];
    let (ptr, obj): (&[usize], &[u32]) = (&pc.ptr, &pc.obj);
    let tops = tops.unwrap_or_else(|| {
        (0..m)
            .into_par_iter()
            .with_min_len(PAR_ROWS)
            .map(|i| TopK::of((ptr[i]..ptr[i + 1]).map(|a| (vals.get(i, a), a))))
            .collect()
    });
    // At zero prices the reduced values are the scaled values, so key order is value order.
    for (i, t) in tops.iter().enumerate() {
        let cnt = t.len.min(K);
        for (c, &a) in cand[i * K..i * K + cnt].iter_mut().zip(&t.ks) {
            *c = Cand {
                arc: a,
                obj: obj[a],
                val: vals.get(i, a) * scale,
            };
        }
        cand_len[i] = cnt as u8;
        if t.len > K {
            bound[i] = vals.get(i, t.ks[K]) * scale;
        }
    }
    let mut a = Auction {
        ptr,
        obj,
        vals,
        scale,
        range: range_scaled,
        price,
        owner: vec![NONE; n],
        arc: vec![NO_ARC; m],
        slack: vec![i64::MIN; m],
        cand,
        cand_len,
        held: vec![NO_CAND; m],
        bound,
        stack: Vec::with_capacity(m),
        queued: vec![false; m],
        tree: if n > m { Some(MinTree::new(n)) } else { None },
        free_dummies: n - m,
    };
    // First epsilon from the data: a quarter of the median positive gap between persons' two
    // best values. Persons whose best object beats the rest by more than that settle with a
    // slack no later phase revisits, while ties still get coarse price steps (starting from a
    // fixed fraction of the range was several times slower on near-tie problems). The floor
    // bounds the price wars of the first phase when a few values dwarf the typical gap.
    let mut gaps: Vec<i64> = tops
        .iter()
        .filter(|t| t.len >= 2)
        .map(|t| t.vs[0].saturating_sub(t.vs[1]))
        .filter(|&g| g > 0)
        .collect();
    let floor = range_scaled / EPS_START_DIV;
    let mut eps = if gaps.is_empty() {
        floor
    } else {
        let mid = gaps.len() / 2;
        let median = *gaps.select_nth_unstable(mid).1;
        (median.saturating_mul(scale) / EPS_GAP_DIV).max(range_scaled / floor_div)
    }
    .clamp(1, range_scaled.max(1));
    let mut first = true;
    loop {
        if first {
            for i in (0..m).rev() {
                a.push(i);
            }
            first = false;
        } else {
            if let Some(t) = a.tree.as_mut() {
                let limit = t.top(&a.price).0.saturating_add(eps);
                for j in 0..n {
                    if a.owner[j] == DUMMY && a.price[j] > limit {
                        a.owner[j] = NONE;
                        a.free_dummies += 1;
                    }
                }
            }
            for i in (0..m).rev() {
                if a.slack[i] < -eps {
                    a.push(i);
                }
            }
        }
        a.drain(eps)?;
        if eps == 1 {
            break;
        }
        eps = (eps / EPS_FACTOR).max(1);
    }
    Ok(a.arc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csr::Csr;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
        fn range(&mut self, lo: i64, hi: i64) -> i64 {
            lo + self.below((hi - lo + 1) as u64) as i64
        }
        fn unit(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    type Dense<T> = Vec<Vec<Option<T>>>;

    /// Dense -> CSR; with `shuffle`, rows are stored in a scrambled column order.
    fn to_csr<T: Copy>(d: &Dense<T>, nc: usize, rng: Option<&mut Rng>) -> Csr<T> {
        let mut indptr = vec![0];
        let mut indices = Vec::new();
        let mut data = Vec::new();
        let mut rng = rng;
        for row in d {
            let mut ent: Vec<(u32, T)> = row
                .iter()
                .enumerate()
                .filter_map(|(c, v)| v.map(|x| (c as u32, x)))
                .collect();
            if let Some(r) = rng.as_deref_mut() {
                for k in (1..ent.len()).rev() {
                    ent.swap(k, r.below(k as u64 + 1) as usize);
                }
            }
            for (c, x) in ent {
                indices.push(c);
                data.push(x);
            }
            indptr.push(indices.len());
        }
        Csr {
            n_rows: d.len(),
            n_cols: nc,
            indptr,
            indices,
            data,
        }
    }

    macro_rules! hungarian {
        ($name:ident, $t:ty, $inf:expr) => {
            /// Min-cost assignment of every row (n <= m) on a dense matrix (e-maxx potentials).
            fn $name(a: &[Vec<$t>], n: usize, m: usize) -> Vec<usize> {
                let inf: $t = $inf;
                let zero = <$t>::default();
                let mut u = vec![zero; n + 1];
                let mut v = vec![zero; m + 1];
                let mut p = vec![0usize; m + 1];
                let mut way = vec![0usize; m + 1];
                for i in 1..=n {
                    p[0] = i;
                    let mut j0 = 0;
                    let mut minv = vec![inf; m + 1];
                    let mut used = vec![false; m + 1];
                    loop {
                        used[j0] = true;
                        let i0 = p[j0];
                        let mut delta = inf;
                        let mut j1 = 0;
                        for j in 1..=m {
                            if !used[j] {
                                let cur = a[i0 - 1][j - 1] - u[i0] - v[j];
                                if cur < minv[j] {
                                    minv[j] = cur;
                                    way[j] = j0;
                                }
                                if minv[j] < delta {
                                    delta = minv[j];
                                    j1 = j;
                                }
                            }
                        }
                        for j in 0..=m {
                            if used[j] {
                                u[p[j]] += delta;
                                v[j] -= delta;
                            } else {
                                minv[j] -= delta;
                            }
                        }
                        j0 = j1;
                        if p[j0] == 0 {
                            break;
                        }
                    }
                    loop {
                        let j1 = way[j0];
                        p[j0] = p[j1];
                        j0 = j1;
                        if j0 == 0 {
                            break;
                        }
                    }
                }
                let mut ans = vec![0; n];
                for j in 1..=m {
                    if p[j] != 0 {
                        ans[p[j] - 1] = j - 1;
                    }
                }
                ans
            }
        };
    }
    hungarian!(hungarian_i, i128, i128::MAX / 4);
    hungarian!(hungarian_f, f64, f64::INFINITY);

    /// (forbidden pairs needed, optimal total) by the reference.
    fn reference_int(d: &Dense<i64>, nc: usize, maximize: bool) -> (usize, i128) {
        let nr = d.len();
        let big: i128 = 1 << 80;
        let get =
            |r: usize, c: usize| d[r][c].map(|x| if maximize { -(x as i128) } else { x as i128 });
        let (n, m, tr) = if nr <= nc {
            (nr, nc, false)
        } else {
            (nc, nr, true)
        };
        let a: Vec<Vec<i128>> = (0..n)
            .map(|i| {
                (0..m)
                    .map(|j| {
                        let x = if tr { get(j, i) } else { get(i, j) };
                        x.unwrap_or(big)
                    })
                    .collect()
            })
            .collect();
        let ans = hungarian_i(&a, n, m);
        let mut forb = 0;
        let mut tot = 0i128;
        for (i, &j) in ans.iter().enumerate() {
            let x = if tr { d[j][i] } else { d[i][j] };
            match x {
                None => forb += 1,
                Some(x) => tot += x as i128,
            }
        }
        (forb, tot)
    }

    fn reference_float(d: &Dense<f64>, nc: usize, maximize: bool) -> (usize, f64) {
        let nr = d.len();
        let cmax = d
            .iter()
            .flatten()
            .flatten()
            .fold(0.0f64, |a, &x| a.max(x.abs()));
        // Large enough to force the fewest forbidden pairs, small enough to keep f64 precision.
        let big = (cmax * 1e4 * (nr + nc + 1) as f64).max(1.0);
        let (n, m, tr) = if nr <= nc {
            (nr, nc, false)
        } else {
            (nc, nr, true)
        };
        let a: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..m)
                    .map(|j| {
                        let x = if tr { d[j][i] } else { d[i][j] };
                        x.map_or(big, |x| if maximize { -x } else { x })
                    })
                    .collect()
            })
            .collect();
        let ans = hungarian_f(&a, n, m);
        let mut forb = 0;
        let mut tot = 0.0;
        for (i, &j) in ans.iter().enumerate() {
            match if tr { d[j][i] } else { d[i][j] } {
                None => forb += 1,
                Some(x) => tot += x,
            }
        }
        (forb, tot)
    }

    /// Checks the result's structure and returns its total.
    fn total<T: Copy>(d: &Dense<T>, nc: usize, res: &[i64], add: impl Fn(T)) {
        let nr = d.len();
        assert_eq!(res.len(), nr);
        let mut used = vec![false; nc];
        let mut count = 0;
        for (r, &c) in res.iter().enumerate() {
            if c < 0 {
                assert_eq!(c, -1);
                continue;
            }
            let c = c as usize;
            assert!(c < nc);
            assert!(!used[c], "column {c} used twice");
            used[c] = true;
            add(d[r][c].expect("assigned a forbidden pair"));
            count += 1;
        }
        assert_eq!(count, nr.min(nc), "smaller side not fully assigned");
    }

    #[test]
    fn coarse_first_epsilon_reaches_the_optimum() {
        // Crowded: every row prefers the same few columns and has one 0-valued escape.
        let n = 60usize;
        let d: Dense<i64> = (0..n)
            .map(|r| {
                (0..n)
                    .map(|c| match c {
                        0..=4 => Some(100 - (r as i64 * 7 + c as i64 * 13) % 37),
                        _ if c == 5 + r % (n - 5) => Some(0),
                        _ => None,
                    })
                    .collect()
            })
            .collect();
        let m = to_csr(&d, n, None);
        let (_, best) = reference_int(&d, n, true);
        for floor_div in [1, 16, DEFAULT_FLOOR_DIV] {
            let g = auction_assignment_int_with(&m.view(), true, floor_div).unwrap();
            let got: i128 = g
                .iter()
                .enumerate()
                .map(|(r, &c)| d[r][c as usize].unwrap() as i128)
                .sum();
            assert_eq!(got, best, "floor_div {floor_div}");
        }
        assert!(auction_assignment_int_with(&m.view(), true, 0).is_err());
    }

    #[test]
    fn hints_skip_the_feasibility_search_without_changing_the_answer() {
        let mut rng = Rng(0x5eed_1234);
        for (nr, nc) in [(40, 40), (30, 45), (45, 30), (1, 3)] {
            for density in [0.15, 0.6] {
                let d = random_dense(&mut rng, nr, nc, density, |r| r.range(-20, 20));
                let m = to_csr(&d, nc, None);
                let Ok(cold) = auction_assignment_int(&m.view(), true) else {
                    continue; // infeasible draw
                };
                let (_, best) = reference_int(&d, nc, true);
                let value = |g: &[i64]| -> i128 {
                    g.iter()
                        .enumerate()
                        .filter(|(_, &c)| c >= 0)
                        .map(|(r, &c)| d[r][c as usize].unwrap() as i128)
                        .sum()
                };
                // Any full assignment in the pattern is a valid hint, e.g. the optimum itself.
                let hinted =
                    auction_assignment_int_hinted(&m.view(), true, DEFAULT_FLOOR_DIV, Some(&cold));
                assert_eq!(value(&hinted.unwrap()), best, "{nr}x{nc}");
                // Broken hints are ignored.
                let mut bad = cold.clone();
                bad.swap(0, nr - 1);
                bad[0] = if nr > 1 { bad[nr - 1] } else { nc as i64 };
                for h in [&bad[..], &cold[1..]] {
                    let g =
                        auction_assignment_int_hinted(&m.view(), true, DEFAULT_FLOOR_DIV, Some(h));
                    assert_eq!(value(&g.unwrap()), best, "{nr}x{nc}");
                }
            }
        }
        // A hint cannot make an infeasible cost look feasible.
        let d: Dense<i64> = vec![vec![Some(1), None], vec![Some(2), None]];
        let m = to_csr(&d, 2, None);
        for h in [[0i64, 0], [0, 1], [0, -1]] {
            let got = auction_assignment_int_hinted(&m.view(), true, DEFAULT_FLOOR_DIV, Some(&h));
            assert!(matches!(got, Err(CoreError::Infeasible { .. })), "{h:?}");
        }
        // All values equal: a valid hint is returned as it is.
        let d: Dense<i64> = vec![vec![Some(3); 3]; 3];
        let m = to_csr(&d, 3, None);
        let h = [2i64, 0, 1];
        let g = auction_assignment_int_hinted(&m.view(), true, DEFAULT_FLOOR_DIV, Some(&h));
        assert_eq!(g.unwrap(), h);
    }

    fn side(nr: usize, nc: usize) -> &'static str {
        if nr <= nc {
            "rows"
        } else {
            "columns"
        }
    }

    fn check_int(d: &Dense<i64>, nc: usize, maximize: bool, rng: &mut Rng) {
        let csr = to_csr(d, nc, Some(rng));
        let res = auction_assignment_int(&csr.view(), maximize);
        let (forb, opt) = reference_int(d, nc, maximize);
        let (size, mm) = max_cardinality_matching(csr.n_rows, nc, &csr.indptr, &csr.indices);
        assert_eq!(size, d.len().min(nc) - forb);
        assert_eq!(mm.iter().filter(|&&c| c >= 0).count(), size);
        if forb > 0 {
            assert_eq!(
                res,
                Err(CoreError::Infeasible {
                    uncovered: forb,
                    side: side(d.len(), nc)
                })
            );
            return;
        }
        let res = res.expect("feasible problem failed");
        let s = std::cell::Cell::new(0i128);
        total(d, nc, &res, |x| s.set(s.get() + x as i128));
        assert_eq!(s.get(), opt, "not optimal (maximize={maximize}) {d:?}");
    }

    fn check_float(d: &Dense<f64>, nc: usize, maximize: bool, rng: &mut Rng) {
        let csr = to_csr(d, nc, Some(rng));
        let res = auction_assignment_float(&csr.view(), maximize);
        let (forb, opt) = reference_float(d, nc, maximize);
        if forb > 0 {
            assert_eq!(
                res,
                Err(CoreError::Infeasible {
                    uncovered: forb,
                    side: side(d.len(), nc)
                })
            );
            return;
        }
        let res = res.expect("feasible problem failed");
        let s = std::cell::Cell::new(0.0f64);
        total(d, nc, &res, |x| s.set(s.get() + x));
        let cmax = d
            .iter()
            .flatten()
            .flatten()
            .fold(0.0f64, |a, &x| a.max(x.abs()));
        let n = d.len().max(nc) as f64;
        assert!(
            (s.get() - opt).abs() <= 1e-9 * cmax * n + 1e-12,
            "float result {} vs optimum {opt}",
            s.get()
        );
    }

    fn random_dense<T>(
        rng: &mut Rng,
        nr: usize,
        nc: usize,
        density: f64,
        mut gen: impl FnMut(&mut Rng) -> T,
    ) -> Dense<T> {
        (0..nr)
            .map(|_| {
                (0..nc)
                    .map(|_| {
                        if rng.unit() < density {
                            Some(gen(rng))
                        } else {
                            None
                        }
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn random_small_int_vs_reference() {
        let mut rng = Rng(0x9e3779b97f4a7c15);
        let mut n_feasible = 0;
        for t in 0..3000 {
            let nr = 1 + rng.below(8) as usize;
            let nc = 1 + rng.below(8) as usize;
            let density = [1.0, 0.8, 0.5, 0.3][t % 4];
            let (lo, hi) = [(0, 2), (-50, 50), (0, 300), (-1_000_000, 1_000_000)][(t / 4) % 4];
            let d = random_dense(&mut rng, nr, nc, density, |r| r.range(lo, hi));
            let maximize = t % 2 == 0;
            check_int(&d, nc, maximize, &mut rng);
            if reference_int(&d, nc, maximize).0 == 0 {
                n_feasible += 1;
            }
        }
        assert!(n_feasible > 1500, "{n_feasible}");
    }

    #[test]
    fn random_medium_sparse_int_vs_reference() {
        let mut rng = Rng(12345);
        for t in 0..300 {
            let nr = 5 + rng.below(60) as usize;
            let nc = match t % 3 {
                0 => nr,
                1 => nr + rng.below(30) as usize,
                _ => (nr / 2).max(1),
            };
            let density = [0.15, 0.3, 0.6, 1.0][t % 4];
            let hi = [2, 10, 300, 1000][(t / 4) % 4];
            let d = random_dense(&mut rng, nr, nc, density, |r| r.range(0, hi));
            check_int(&d, nc, t % 2 == 1, &mut rng);
        }
    }

    #[test]
    fn banded_with_single_candidates() {
        let mut rng = Rng(777);
        for t in 0..200 {
            let n = 3 + rng.below(40) as usize;
            let nc = n + (t % 3) * rng.below(5) as usize;
            let mut d: Dense<i64> = vec![vec![None; nc]; n];
            for (r, row) in d.iter_mut().enumerate() {
                if rng.below(4) == 0 {
                    // Single candidate: the diagonal only.
                    row[r] = Some(rng.range(-5, 5));
                    continue;
                }
                let w = 1 + rng.below(3) as usize;
                for (c, x) in row.iter_mut().enumerate() {
                    if c + w >= r && c <= r + w {
                        *x = Some(if c == r {
                            rng.range(5, 9)
                        } else {
                            rng.range(0, 6)
                        });
                    }
                }
            }
            check_int(&d, nc, t % 2 == 0, &mut rng);
            // Transposed orientation of the same instance.
            let dt: Dense<i64> = (0..nc).map(|c| (0..n).map(|r| d[r][c]).collect()).collect();
            check_int(&dt, n, t % 2 == 1, &mut rng);
        }
    }

    #[test]
    fn rectangular_extremes() {
        let mut rng = Rng(4242);
        for t in 0..60 {
            let (nr, nc) = if t % 2 == 0 { (3, 80) } else { (80, 3) };
            let density = [1.0, 0.2, 0.05][t % 3];
            let d = random_dense(&mut rng, nr, nc, density, |r| r.range(0, 3));
            check_int(&d, nc, t % 4 < 2, &mut rng);
        }
        // One person, many objects; many persons, one object.
        let d: Dense<i64> = vec![(0..50).map(|c| Some((c * 7 % 13) as i64)).collect()];
        check_int(&d, 50, true, &mut rng);
        check_int(&d, 50, false, &mut rng);
        let dt: Dense<i64> = (0..50).map(|c| vec![Some((c * 7 % 13) as i64)]).collect();
        check_int(&dt, 1, true, &mut rng);
        check_int(&dt, 1, false, &mut rng);
    }

    #[test]
    fn random_float_vs_reference() {
        let mut rng = Rng(99);
        for t in 0..1500 {
            let nr = 1 + rng.below(9) as usize;
            let nc = 1 + rng.below(9) as usize;
            let density = [1.0, 0.7, 0.4][t % 3];
            let scale = [1.0, 1e-3, 1e6, 1e300][(t / 3) % 4];
            let d = random_dense(&mut rng, nr, nc, density, |r| {
                if t % 5 == 0 {
                    r.range(0, 2) as f64 * scale
                } else {
                    (r.unit() * 2.0 - 1.0) * scale
                }
            });
            check_float(&d, nc, t % 2 == 0, &mut rng);
        }
        for t in 0..100 {
            let n = 20 + rng.below(40) as usize;
            let nc = n + (t % 2) * 7;
            let d = random_dense(&mut rng, n, nc, 0.3, |r| r.unit() * 100.0 - 30.0);
            check_float(&d, nc, t % 4 < 2, &mut rng);
        }
    }

    #[test]
    fn large_values_exact() {
        let mut rng = Rng(31337);
        let n = 2000;
        let d = random_dense(&mut rng, n, n, 1.0, |r| 1_000_000 - r.range(0, 2000));
        check_int(&d, n, true, &mut rng);
        let d = random_dense(&mut rng, 300, 400, 1.0, |r| r.range(-1_000_000, 1_000_000));
        check_int(&d, 400, false, &mut rng);
        // Extreme i64 values in a tiny problem: range too large must be an error, not a panic.
        let d: Dense<i64> = vec![vec![Some(i64::MIN), Some(i64::MAX)], vec![Some(0), Some(1)]];
        let csr = to_csr(&d, 2, None);
        for maximize in [true, false] {
            assert!(matches!(
                auction_assignment_int(&csr.view(), maximize),
                Err(CoreError::InvalidInput(_))
            ));
        }
        // Large but uniform per row: the shift makes it trivial.
        let d: Dense<i64> = vec![
            vec![Some(i64::MIN), Some(i64::MIN)],
            vec![Some(i64::MAX), None],
        ];
        let csr = to_csr(&d, 2, None);
        assert_eq!(
            auction_assignment_int(&csr.view(), false).unwrap(),
            vec![1, 0]
        );
    }

    #[test]
    fn huge_offsets_small_spread() {
        // Values near the ends of i64 with a small spread per person: the shift makes them
        // solvable, and the wrapping differences must be exact.
        let mut rng = Rng(2718);
        for t in 0..400 {
            let nr = 1 + rng.below(8) as usize;
            let nc = 1 + rng.below(8) as usize;
            let mut d = random_dense(&mut rng, nr, nc, 0.7, |r| r.range(-20, 20));
            let big = [i64::MAX - 40, i64::MIN + 40, 1 << 62, -(1 << 62)];
            if nr <= nc {
                for row in d.iter_mut() {
                    let off = big[rng.below(4) as usize];
                    row.iter_mut()
                        .flatten()
                        .for_each(|x| *x = x.wrapping_add(off));
                }
            } else {
                for c in 0..nc {
                    let off = big[rng.below(4) as usize];
                    d.iter_mut().for_each(|row| {
                        if let Some(x) = row[c].as_mut() {
                            *x = x.wrapping_add(off)
                        }
                    });
                }
            }
            check_int(&d, nc, t % 2 == 0, &mut rng);
        }
    }

    #[test]
    fn dense_ties_rectangular_many_candidates() {
        // Rows much longer than the candidate lists, mostly ties: exercises the list refreshes
        // together with the dummy persons.
        let mut rng = Rng(1618);
        for t in 0..40 {
            let (nr, nc) = [(30, 90), (90, 30), (60, 60), (45, 50)][t % 4];
            let hi = [1, 2, 5][t % 3];
            let d = random_dense(&mut rng, nr, nc, 0.9, |r| r.range(0, hi));
            check_int(&d, nc, t % 2 == 0, &mut rng);
        }
    }

    #[test]
    fn range_at_the_limit() {
        // The largest spread the up-front check accepts must solve without tripping the price
        // guard, on sparse chain-like and dense patterns, square and rectangular.
        let mut rng = Rng(141);
        for t in 0..24 {
            let (nr, nc) = [(60, 60), (40, 70), (70, 40)][t % 3];
            let n = nr.max(nc) as i128;
            let lim = ((1i128 << 60) / ((n + 1) * (n + 2))) as i64;
            let density = [0.08, 0.3, 1.0, 0.05][t % 4];
            let mut d = random_dense(&mut rng, nr, nc, density, |r| {
                if r.below(2) == 0 {
                    r.range(lim - 3, lim)
                } else {
                    r.range(0, 3)
                }
            });
            // A diagonal keeps most instances feasible.
            for (k, row) in d.iter_mut().enumerate().take(nc) {
                row[k] = Some(if k % 2 == 0 { lim } else { 0 });
            }
            check_int(&d, nc, t % 2 == 0, &mut rng);
        }
        let d: Dense<i64> = vec![vec![Some(0), Some(1 << 58)], vec![Some(1 << 58), Some(0)]];
        let csr = to_csr(&d, 2, None);
        assert!(matches!(
            auction_assignment_int(&csr.view(), true),
            Err(CoreError::InvalidInput(m)) if m.contains("cost range too large")
        ));
    }

    #[test]
    fn ties_and_zeros() {
        // Explicit zeros are allowed pairs.
        let d: Dense<i64> = vec![vec![Some(0), None], vec![None, Some(0)]];
        let csr = to_csr(&d, 2, None);
        assert_eq!(
            auction_assignment_int(&csr.view(), true).unwrap(),
            vec![0, 1]
        );
        let mut rng = Rng(5);
        for t in 0..100 {
            let n = 30 + rng.below(30) as usize;
            let d = random_dense(&mut rng, n, n, 0.5, |_| 0);
            check_int(&d, n, t % 2 == 0, &mut rng);
        }
    }

    #[test]
    fn infeasible_patterns() {
        let d: Dense<i64> = vec![vec![Some(1), None], vec![Some(2), None]];
        let csr = to_csr(&d, 2, None);
        assert_eq!(
            auction_assignment_int(&csr.view(), true),
            Err(CoreError::Infeasible {
                uncovered: 1,
                side: "rows"
            })
        );
        let d: Dense<i64> = vec![vec![Some(1), Some(1), Some(1)], vec![None; 3]];
        let csr = to_csr(&d, 3, None);
        assert_eq!(
            auction_assignment_int(&csr.view(), true),
            Err(CoreError::Infeasible {
                uncovered: 1,
                side: "rows"
            })
        );
        // 3 rows, 2 columns: columns are the smaller side; column 1 unreachable.
        let d: Dense<f64> = vec![vec![Some(1.0), None]; 3];
        let csr = to_csr(&d, 2, None);
        assert_eq!(
            auction_assignment_float(&csr.view(), false),
            Err(CoreError::Infeasible {
                uncovered: 1,
                side: "columns"
            })
        );
        // 100k rows all on the same 10 columns, plus a chain: must be instant.
        let n = 100_000;
        let mut indptr = vec![0];
        let mut indices = Vec::new();
        for r in 0..n {
            if r % 2 == 0 {
                indices.extend(0..10u32);
            } else {
                indices.push(r as u32);
                indices.push(r as u32 - 1);
                indices.sort_unstable_by(|_, _| std::cmp::Ordering::Equal);
            }
            let l = indices.len();
            if r % 2 == 1 {
                indices[l - 2..].sort_unstable();
            }
            indptr.push(indices.len());
        }
        let data = vec![1i64; indices.len()];
        let csr = Csr {
            n_rows: n,
            n_cols: n,
            indptr,
            indices,
            data,
        };
        let t0 = std::time::Instant::now();
        let res = auction_assignment_int(&csr.view(), true);
        let dt = t0.elapsed();
        // Odd rows all match (r or r-1); even rows share 10 columns, some of which are odd rows'
        // r-1 ... the exact count comes from HK.
        let (size, _) = max_cardinality_matching(n, n, &csr.indptr, &csr.indices);
        assert!(size < n);
        assert_eq!(
            res,
            Err(CoreError::Infeasible {
                uncovered: n - size,
                side: "rows"
            })
        );
        assert!(dt.as_secs_f64() < 2.0, "infeasible detection took {dt:?}");
        eprintln!("100k-row infeasible case: {dt:?}, matching size {size}");
    }

    #[test]
    fn invalid_inputs() {
        let bad = |indptr: Vec<usize>, indices: Vec<u32>, data: Vec<i64>, nr, nc| {
            let c = Csr {
                n_rows: nr,
                n_cols: nc,
                indptr,
                indices,
                data,
            };
            let r = auction_assignment_int(&c.view(), true);
            let rejected = |r: &Result<Vec<i64>>| {
                matches!(
                    r,
                    Err(CoreError::InvalidInput(_) | CoreError::Duplicate { .. })
                )
            };
            assert!(rejected(&r), "{r:?}");
            let cf = Csr {
                n_rows: nr,
                n_cols: nc,
                indptr: c.indptr.clone(),
                indices: c.indices.clone(),
                data: c.data.iter().map(|&x| x as f64).collect(),
            };
            let r = auction_assignment_float(&cf.view(), true);
            assert!(rejected(&r), "{r:?}");
            // The raw matching never panics either.
            let _ = max_cardinality_matching(nr, nc, &c.indptr, &c.indices);
        };
        bad(vec![0, 2], vec![0, 1], vec![1, 1], 2, 2); // indptr too short
        bad(vec![], vec![], vec![], 0, 2); // no indptr at all
        bad(vec![1, 2], vec![0, 1], vec![1, 1], 1, 2); // does not start at 0
        bad(vec![0, 2, 1], vec![0, 1], vec![1, 1], 2, 2); // decreasing
        bad(vec![0, 1, 5], vec![0, 1], vec![1, 1], 2, 2); // past nnz
        bad(vec![0, 1, 2], vec![0, 2], vec![1, 1], 2, 2); // column out of range
        bad(vec![0, 1, 2], vec![0, 1], vec![1], 2, 2); // data too short
        bad(vec![0, 2], vec![1, 1], vec![1, 2], 1, 2); // duplicate
        bad(vec![0, 3], vec![2, 0, 2], vec![1, 2, 3], 1, 3); // unsorted duplicate
        bad(vec![0, 1], vec![0], vec![1], usize::MAX, 2); // absurd n_rows

        // Columns far beyond the entries, with a hint: nothing is sized by the column count.
        for nc in [usize::MAX, usize::MAX / 64, 1 << 40] {
            let c = Csr {
                n_rows: 2,
                n_cols: nc,
                indptr: vec![0, 2, 3],
                indices: vec![0, 7, 7],
                data: vec![5i64, 1, 1],
            };
            for hint in [[0i64, 7], [7, 0], [7, 7]] {
                let r =
                    auction_assignment_int_hinted(&c.view(), true, DEFAULT_FLOOR_DIV, Some(&hint));
                assert_eq!(r, Ok(vec![0, 7]), "n_cols {nc}, hint {hint:?}");
            }
        }
        let c = Csr {
            n_rows: 1,
            n_cols: 3,
            indptr: vec![0, 3],
            indices: vec![2, 0, 2],
            data: vec![1i64; 3],
        };
        match auction_assignment_int(&c.view(), true) {
            Err(e @ CoreError::Duplicate { row: 0, col: 2 }) => {
                let m = e.to_string();
                assert!(
                    m.contains("row 0") && m.contains("column 2") && m.contains("sum_duplicates"),
                    "{m}"
                )
            }
            r => panic!("{r:?}"),
        }
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let c = Csr {
                n_rows: 1,
                n_cols: 2,
                indptr: vec![0, 2],
                indices: vec![0, 1],
                data: vec![1.0, x],
            };
            match auction_assignment_float(&c.view(), false) {
                Err(CoreError::InvalidInput(m)) => {
                    assert!(m.starts_with("cost contains NaN or infinite values"), "{m}")
                }
                r => panic!("{r:?}"),
            }
        }
        // Garbage given straight to the matching.
        let (s, m) = max_cardinality_matching(3, 2, &[5, 0], &[7, 1, 0]);
        // indptr describes one row only.
        assert_eq!(m.len(), 1);
        assert!(s <= 1);
        let (s, m) = max_cardinality_matching(2, 2, &[0, 2, 9], &[0, 1, 1]);
        assert_eq!((s, m.len()), (2, 2));
        let (s, _) = max_cardinality_matching(2, usize::MAX, &[0, 1, 2], &[4_000_000_000, 7]);
        assert_eq!(s, 2);
    }

    #[test]
    fn empty_problems() {
        let c: Csr<i64> = Csr {
            n_rows: 0,
            n_cols: 0,
            indptr: vec![0],
            indices: vec![],
            data: vec![],
        };
        assert_eq!(
            auction_assignment_int(&c.view(), true).unwrap(),
            Vec::<i64>::new()
        );
        let c: Csr<i64> = Csr {
            n_rows: 3,
            n_cols: 0,
            indptr: vec![0; 4],
            indices: vec![],
            data: vec![],
        };
        assert_eq!(
            auction_assignment_int(&c.view(), true).unwrap(),
            vec![-1; 3]
        );
        let c: Csr<f64> = Csr {
            n_rows: 0,
            n_cols: 5,
            indptr: vec![0],
            indices: vec![],
            data: vec![],
        };
        assert_eq!(
            auction_assignment_float(&c.view(), true).unwrap(),
            Vec::<i64>::new()
        );
        // Columns far more numerous than entries (compaction path).
        let c = Csr {
            n_rows: 2,
            n_cols: 1 << 31,
            indptr: vec![0, 2, 3],
            indices: vec![5, 1 << 30, 5],
            data: vec![1i64, 2, 3],
        };
        assert_eq!(
            auction_assignment_int(&c.view(), true).unwrap(),
            vec![1 << 30, 5]
        );
    }

    /// The real workload's shape: 28k x 28k, ~1000 entries per row in a band, integer costs
    /// 0..300 with a bonus near the diagonal. `cargo test --release -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_banded_28k() {
        let n = 28_000usize;
        let half = 500usize;
        let mut rng = Rng(2024);
        let mut indptr = vec![0usize];
        let mut indices = Vec::new();
        let mut data = Vec::new();
        for r in 0..n {
            let lo = r.saturating_sub(half);
            let hi = (r + half).min(n - 1);
            for c in lo..=hi {
                let d = r.abs_diff(c);
                let w = if d <= 2 {
                    250 + rng.range(0, 50)
                } else {
                    rng.range(0, 200)
                };
                indices.push(c as u32);
                data.push(w);
            }
            indptr.push(indices.len());
        }
        let csr = Csr {
            n_rows: n,
            n_cols: n,
            indptr,
            indices,
            data,
        };
        for _ in 0..3 {
            let t0 = std::time::Instant::now();
            let res = auction_assignment_int(&csr.view(), true).unwrap();
            let dt = t0.elapsed();
            let tot: i64 = (0..n)
                .map(|r| {
                    let c = res[r] as u32;
                    let row = &csr.indices[csr.indptr[r]..csr.indptr[r + 1]];
                    csr.data[csr.indptr[r] + row.iter().position(|&x| x == c).unwrap()]
                })
                .sum();
            eprintln!(
                "28k banded (nnz {}): {dt:?}, total {tot}",
                csr.indices.len()
            );
        }
    }

    fn timed(name: &str, csr: &Csr<i64>, maximize: bool) {
        let t0 = std::time::Instant::now();
        let res = auction_assignment_int(&csr.view(), maximize).unwrap();
        let dt = t0.elapsed();
        let assigned = res.iter().filter(|&&c| c >= 0).count();
        eprintln!("{name}: {dt:?} ({assigned} assigned)");
    }

    fn band(
        nr: usize,
        nc: usize,
        half: usize,
        rng: &mut Rng,
        w: impl Fn(&mut Rng, usize) -> i64,
    ) -> Csr<i64> {
        let mut indptr = vec![0usize];
        let mut indices = Vec::new();
        let mut data = Vec::new();
        for r in 0..nr {
            let center = r * nc / nr;
            for c in center.saturating_sub(half)..=(center + half).min(nc - 1) {
                indices.push(c as u32);
                data.push(w(rng, center.abs_diff(c)));
            }
            indptr.push(indices.len());
        }
        Csr {
            n_rows: nr,
            n_cols: nc,
            indptr,
            indices,
            data,
        }
    }

    /// HOPE-like weights: high near the diagonal (the true match), noise elsewhere.
    fn workload_weight(r: &mut Rng, d: usize) -> i64 {
        if d <= 2 {
            250 + r.range(0, 50)
        } else {
            r.range(0, 200)
        }
    }

    /// Other shapes, to show nothing degenerates. `cargo test --release -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_other_shapes() {
        let mut rng = Rng(77);
        let ties = band(28_000, 28_000, 500, &mut rng, |r, _| r.range(0, 3));
        timed("28k band, costs 0..3, maximize", &ties, true);
        timed("28k band, costs 0..3, minimize", &ties, false);
        let w = band(28_000, 28_000, 500, &mut rng, workload_weight);
        timed("28k band, workload weights, minimize", &w, false);
        let rect = band(14_000, 28_000, 500, &mut rng, workload_weight);
        timed("14k x 28k band, maximize", &rect, true);
        timed("14k x 28k band, minimize", &rect, false);
        let rect_t = band(28_000, 14_000, 250, &mut rng, workload_weight);
        timed("28k x 14k band, maximize", &rect_t, true);
        let few = band(100, 28_000, 2000, &mut rng, |r, _| r.range(0, 1000));
        timed("100 x 28k band, maximize", &few, true);
        let n = 50_000;
        let mut indptr = vec![0usize];
        let mut indices = Vec::new();
        let mut data = Vec::new();
        for r in 0..n {
            let mut cols: Vec<u32> = (0..20).map(|_| rng.below(n as u64) as u32).collect();
            cols.push(r as u32);
            cols.sort_unstable();
            cols.dedup();
            for &c in &cols {
                indices.push(c);
                data.push(rng.range(-1_000_000, 1_000_000));
            }
            indptr.push(indices.len());
        }
        let rnd = Csr {
            n_rows: n,
            n_cols: n,
            indptr,
            indices,
            data,
        };
        timed(
            "50k random sparse (21/row), costs +-1e6, maximize",
            &rnd,
            true,
        );
        timed(
            "50k random sparse (21/row), costs +-1e6, minimize",
            &rnd,
            false,
        );
    }
}
