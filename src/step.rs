//! One HOPE refinement step in one call: the overlap cost with the current-match bonus, its
//! optimal assignment, and a partner for every vertex the assignment leaves out.
//!
//! Building the cost here and handing it straight to the solver spares the round trip through
//! NumPy (writing the cost out, adding the bonus there, copying it back in).
use crate::auction::auction_assignment_int_hinted;
use crate::csr::{Csr, CsrView};
use crate::error::{invalid, Result};
use crate::overlap::{overlap_rows, OverlapOptions, Rows};
use rayon::prelude::*;
use std::time::Instant;

/// Each overlap count is worth this much, and the current match 1 on top: a vertex moves only
/// when the overlap gains.
pub const COUNT_WEIGHT: i64 = 4;

/// The assignment cost `COUNT_WEIGHT * K[p, q] + (q == f[p]) * (1 + COUNT_WEIGHT * s[p])` of
/// the overlap `K`, where `s[p]` is `stay` for a witness p and 0 otherwise: the extra counts a
/// witness's current match is worth. Computed in place on the counts: 32-bit values halve
/// what the auction streams through in its rescans (the solver reads any integer type alike).
pub fn bonus_cost(k: Csr<u32>, f: &[u32], witnesses: &[bool], stay: u32) -> Result<Csr<u32>> {
    // A count is at most the number of witnesses (one per vertex of A).
    let largest = COUNT_WEIGHT as u64 * (k.n_rows as u64 + 1 + stay as u64) + 1;
    if largest > u32::MAX as u64 {
        return invalid(format!(
            "{} vertices of A are too many for 32-bit overlap costs",
            k.n_rows
        ));
    }
    let Csr {
        n_rows,
        n_cols,
        indptr,
        indices,
        mut data,
    } = k;
    let mut rows: Vec<(&mut [u32], &[u32])> = Vec::with_capacity(n_rows);
    let mut rest = data.as_mut_slice();
    for r in 0..n_rows {
        let (head, tail) = rest.split_at_mut(indptr[r + 1] - indptr[r]);
        rows.push((head, &indices[indptr[r]..indptr[r + 1]]));
        rest = tail;
    }
    let weight = COUNT_WEIGHT as u32;
    rows.into_par_iter()
        .enumerate()
        .for_each(|(r, (out, cols))| {
            let bonus = 1 + weight * stay * (witnesses[r] as u32);
            for (d, &c) in out.iter_mut().zip(cols) {
                *d = weight * *d + (c == f[r]) as u32 * bonus;
            }
        });
    Ok(Csr {
        n_rows,
        n_cols,
        indptr,
        indices,
        data,
    })
}

/// Column of the largest value of row `r` (ties: the last one), None for an empty row.
pub fn best_in_row(c: &CsrView<u32>, r: usize) -> Option<u32> {
    let (lo, hi) = (c.indptr[r], c.indptr[r + 1]);
    (lo..hi)
        .max_by_key(|&a| (c.data[a], a))
        .map(|a| c.indices[a])
}

/// The tuning of one [`overlap_assignment`] step; its inputs (graphs, map, witnesses, `keep`,
/// `hint`) are the function's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepOptions {
    /// Keep only the `top_k` largest overlap counts of each row (see `OverlapOptions::top_k`);
    /// `None` keeps every overlapping column.
    pub top_k: Option<usize>,
    /// The solver's first epsilon is at least the value range over this (see
    /// `auction_assignment_int_with`).
    pub floor_div: i64,
    /// Extra overlap counts a witness's current match is worth (see [`bonus_cost`]).
    pub stay: u32,
}

/// Wall-clock seconds of the two halves of one [`overlap_assignment_timed`] step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepTimes {
    /// Building the overlap cost with its bonus (parallel).
    pub cost: f64,
    /// Solving the assignment and completing the rows it leaves out (the auction is sequential).
    pub assign: f64,
}

/// The map maximising the overlap cost one-to-one (see [`bonus_cost`]); rows the assignment
/// leaves out (A larger than B) take their best column. `keep` (one column per row, e.g. an
/// injective completion of `f`) is stored in every row, so a full assignment exists; `hint` is
/// passed to the solver (see `auction_assignment_int_hinted`); `opts`: see [`StepOptions`].
pub fn overlap_assignment<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    keep: &[u32],
    hint: &[i64],
    opts: StepOptions,
) -> Result<Vec<i64>> {
    overlap_assignment_timed(nbrs_a, nbrs_b, f, witnesses, keep, hint, opts).map(|(g, _)| g)
}

/// [`overlap_assignment`] and the time each of its halves took (a per-step profile).
pub fn overlap_assignment_timed<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    keep: &[u32],
    hint: &[i64],
    opts: StepOptions,
) -> Result<(Vec<i64>, StepTimes)> {
    let StepOptions {
        top_k,
        floor_div,
        stay,
    } = opts;
    if hint.len() != nbrs_a.n_rows() {
        return invalid("hint must hold one entry per vertex of A");
    }
    let t0 = Instant::now();
    let cost = step_cost(nbrs_a, nbrs_b, f, witnesses, top_k, keep, stay)?;
    let t1 = Instant::now();
    let view = cost.view();
    let mut g = auction_assignment_int_hinted(&view, true, floor_div, Some(hint))?;
    g.par_iter_mut().enumerate().for_each(|(r, q)| {
        if *q < 0 {
            // Every row holds its `keep` column, so it is never empty.
            *q = best_in_row(&view, r).map_or(-1, |c| c as i64);
        }
    });
    let times = StepTimes {
        cost: (t1 - t0).as_secs_f64(),
        assign: t1.elapsed().as_secs_f64(),
    };
    Ok((g, times))
}

/// Each vertex's best column of the overlap cost (see [`bonus_cost`]), without the one-to-one
/// constraint: ties in the overlap stay at the current match.
pub fn best_overlap<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    top_k: Option<usize>,
) -> Result<Vec<i64>> {
    let cost = step_cost(nbrs_a, nbrs_b, f, witnesses, top_k, f, 0)?;
    let view = cost.view();
    // Every row holds its current match (`keep` = f), so it is never empty.
    Ok((0..view.n_rows)
        .into_par_iter()
        .map(|r| best_in_row(&view, r).map_or(-1, |c| c as i64))
        .collect())
}

/// The overlap cost with the match bonus, `keep[p]` stored in every row p: the cost one
/// [`overlap_assignment`] step solves.
pub fn step_cost<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    top_k: Option<usize>,
    keep: &[u32],
    stay: u32,
) -> Result<Csr<u32>> {
    let opts = OverlapOptions {
        top_k,
        keep: Some(keep),
    };
    let rows = overlap_rows(nbrs_a, nbrs_b, f, witnesses, opts)?;
    bonus_cost(rows.into_csr(), f, witnesses, stay)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::adjacency_from_faces;
    use crate::khop::HopBalls;
    use crate::overlap::{overlap_cost, BallsAt};

    fn strip(n: u32) -> Vec<[u32; 3]> {
        (0..n - 2).map(|i| [i, i + 1, i + 2]).collect()
    }

    #[test]
    fn matches_the_separate_kernels() {
        let n = 60u32;
        let adj = adjacency_from_faces(&strip(n), n as usize).unwrap();
        let balls = HopBalls::new(&adj.view(), 3).unwrap();
        // Two vertices swapped and left out of the vote, as are a few others.
        let swap = |v: u32| match v {
            20 => 25,
            25 => 20,
            _ => v,
        };
        let f: Vec<u32> = (0..n).map(swap).collect();
        let w: Vec<bool> = (0..n).map(|v| v != 20 && v != 25 && v % 7 != 3).collect();
        let keep = f.clone();
        let hint: Vec<i64> = keep.iter().map(|&q| q as i64).collect();
        for k in 1..=3 {
            let rows = BallsAt { balls: &balls, k };
            let opts = StepOptions {
                top_k: None,
                floor_div: 16,
                stay: 0,
            };
            let g = overlap_assignment(&rows, &rows, &f, &w, &keep, &hint, opts).unwrap();
            let (timed, _) =
                overlap_assignment_timed(&rows, &rows, &f, &w, &keep, &hint, opts).unwrap();
            assert_eq!(g, timed, "k={k}: timing a step changes nothing");
            let opts = OverlapOptions {
                top_k: None,
                keep: Some(&keep),
            };
            let cost =
                bonus_cost(overlap_cost(&rows, &rows, &f, &w, opts).unwrap(), &f, &w, 0).unwrap();
            let reference =
                auction_assignment_int_hinted(&cost.view(), true, 16, Some(&hint)).unwrap();
            assert_eq!(g, reference, "k={k}");
            // The bonus is exactly 1 on the current match and the counts are multiplied.
            for (r, &fr) in f.iter().enumerate() {
                for a in cost.indptr[r]..cost.indptr[r + 1] {
                    assert_eq!(
                        cost.data[a] as i64 % COUNT_WEIGHT,
                        (cost.indices[a] == fr) as i64
                    );
                }
            }
            // The swap is undone: the strip is matched to itself.
            assert!(
                g.iter().enumerate().all(|(v, &q)| q == v as i64),
                "k={k}: {g:?}"
            );
        }
    }

    #[test]
    fn best_overlap_takes_each_rows_largest_value() {
        let n = 40u32;
        let adj = adjacency_from_faces(&strip(n), n as usize).unwrap();
        let balls = HopBalls::new(&adj.view(), 2).unwrap();
        let rows = BallsAt {
            balls: &balls,
            k: 2,
        };
        let f: Vec<u32> = (0..n).map(|v| if v == 10 { 30 } else { v }).collect();
        let w: Vec<bool> = (0..n).map(|v| v != 10).collect();
        let got = best_overlap(&rows, &rows, &f, &w, None).unwrap();
        let opts = OverlapOptions {
            top_k: None,
            keep: Some(&f),
        };
        let cost =
            bonus_cost(overlap_cost(&rows, &rows, &f, &w, opts).unwrap(), &f, &w, 0).unwrap();
        for (r, &q) in got.iter().enumerate() {
            let (lo, hi) = (cost.indptr[r], cost.indptr[r + 1]);
            let best = cost.data[lo..hi].iter().max().unwrap();
            let at = cost.indices[lo..hi]
                .iter()
                .position(|&c| c as i64 == q)
                .unwrap();
            assert_eq!(cost.data[lo + at], *best, "row {r}");
        }
        assert_eq!(got[10], 10, "the moved vertex returns");
    }

    #[test]
    fn stay_keeps_a_match_that_loses_by_one_count() {
        // Row 0 matches column 0 with 3 counts; column 1 (free) has 4. Row 1 holds column 2.
        let k = Csr {
            n_rows: 2,
            n_cols: 3,
            indptr: vec![0, 2, 3],
            indices: vec![0, 1, 2],
            data: vec![3u32, 4, 5],
        };
        let f = [0u32, 2];
        let hint = [0i64, 2];
        let solve = |w: &[bool], stay: u32| {
            let c = bonus_cost(k.clone(), &f, w, stay).unwrap();
            auction_assignment_int_hinted(&c.view(), true, 16, Some(&hint)).unwrap()
        };
        assert_eq!(
            solve(&[false, false], 1),
            vec![1, 2],
            "without stay the larger overlap wins"
        );
        assert_eq!(solve(&[true, false], 0), vec![1, 2]);
        assert_eq!(
            solve(&[true, false], 1),
            vec![0, 2],
            "one extra count keeps the match"
        );
        let c = bonus_cost(k.clone(), &f, &[true, false], 1).unwrap();
        assert_eq!(c.data, vec![4 * 3 + 1 + 4, 4 * 4, 4 * 5 + 1]);
    }

    #[test]
    fn rows_left_out_take_their_best_column() {
        // 3 rows, 2 columns: row 2 loses the assignment and takes its larger entry.
        let c = Csr {
            n_rows: 3,
            n_cols: 2,
            indptr: vec![0, 1, 2, 4],
            indices: vec![0, 1, 0, 1],
            data: vec![5u32, 5, 1, 2],
        };
        assert_eq!(best_in_row(&c.view(), 2), Some(1));
        assert_eq!(best_in_row(&c.view(), 0), Some(0));
    }
}
