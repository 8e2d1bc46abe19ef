//! The HOPE overlap cost K[p, q] = #{ witnesses v : v in B(p), f(v) in B(q) }, built sparse.
//!
//! Each row is accumulated in a dense per-thread counter over B's vertices (a sparse
//! accumulator), so the cost of row p is sum over witnesses v in B(p) of |B(f(v))| increments
//! and no n_a x n_b array ever exists.
use crate::csr::{Csr, CsrView};
use crate::error::{invalid, Result};
use crate::khop::HopBalls;
use rayon::prelude::*;

/// Anything that can hand out neighbourhood rows: a CSR pattern or the k-prefix of `HopBalls`.
pub trait Rows: Sync {
    fn n_rows(&self) -> usize;
    fn row(&self, r: usize) -> &[u32];
}

impl Rows for CsrView<'_, ()> {
    fn n_rows(&self) -> usize {
        self.n_rows
    }
    fn row(&self, r: usize) -> &[u32] {
        CsrView::row(self, r)
    }
}

/// B_k of every vertex, read from precomputed `HopBalls`.
pub struct BallsAt<'a> {
    pub balls: &'a HopBalls,
    pub k: usize,
}

impl Rows for BallsAt<'_> {
    fn n_rows(&self) -> usize {
        self.balls.n
    }
    fn row(&self, r: usize) -> &[u32] {
        self.balls.ball(r, self.k)
    }
}

/// Options bounding the size of the cost.
#[derive(Debug, Clone, Copy, Default)]
pub struct OverlapOptions<'a> {
    /// Keep only the `top_k` largest counts of each row (ties: smaller column first).
    pub top_k: Option<usize>,
    /// Column that row p always keeps (stored even when its count is 0), e.g. the current match,
    /// so that a full assignment stays available.
    pub keep: Option<&'a [u32]>,
}

const ROWS_PER_TASK: usize = 64;

/// Sparse overlap-count cost, rows = vertices of A, columns = vertices of B, columns sorted.
pub fn overlap_cost<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    opts: OverlapOptions<'_>,
) -> Result<Csr<u32>> {
    let n_a = nbrs_a.n_rows();
    let n_b = nbrs_b.n_rows();
    if f.len() != n_a || witnesses.len() != n_a {
        return invalid(format!(
            "f and witnesses must have one entry per vertex of A ({n_a}), got {} and {}",
            f.len(),
            witnesses.len()
        ));
    }
    if let Some(&bad) = f.iter().find(|&&q| q as usize >= n_b) {
        return invalid(format!(
            "f contains {bad}, out of range for the {n_b} vertices of B"
        ));
    }
    if let Some(keep) = opts.keep {
        if keep.len() != n_a || keep.iter().any(|&q| q as usize >= n_b) {
            return invalid("keep must hold one vertex of B per vertex of A");
        }
    }
    if opts.top_k == Some(0) {
        return invalid("top_k must be at least 1");
    }
    let chunks: Vec<(Vec<usize>, Vec<u32>, Vec<u32>)> = (0..n_a.div_ceil(ROWS_PER_TASK))
        .into_par_iter()
        .map_init(
            || (vec![0u32; n_b], vec![0u32; n_b + 1], Vec::<u32>::new()),
            |(count, first_seen, touched), c| {
                let lo = c * ROWS_PER_TASK;
                let hi = (lo + ROWS_PER_TASK).min(n_a);
                let mut lens = Vec::with_capacity(hi - lo);
                let mut cols = Vec::new();
                let mut vals = Vec::new();
                for p in lo..hi {
                    let mut n_seen = 0usize;
                    for &v in nbrs_a.row(p) {
                        let v = v as usize;
                        if v >= n_a || !witnesses[v] {
                            continue;
                        }
                        // The hot loop: branch-free, since whether a column is new is data-
                        // dependent and unpredictable. Every column is written to the list, and
                        // the length only advances on a first visit.
                        for &q in nbrs_b.row(f[v] as usize) {
                            let slot = &mut count[q as usize];
                            first_seen[n_seen] = q;
                            n_seen += (*slot == 0) as usize;
                            *slot += 1;
                        }
                    }
                    touched.extend_from_slice(&first_seen[..n_seen]);
                    let kept = opts.keep.map(|k| k[p]);
                    if let Some(q) = kept {
                        if count[q as usize] == 0 {
                            touched.push(q);
                        }
                    }
                    if let Some(t) = opts.top_k {
                        if touched.len() > t {
                            let key = |&q: &u32| (std::cmp::Reverse(count[q as usize]), q);
                            touched.select_nth_unstable_by_key(t - 1, key);
                            for &q in &touched[t..] {
                                if Some(q) != kept {
                                    count[q as usize] = 0;
                                }
                            }
                            touched.truncate(t);
                            if let Some(q) = kept {
                                if !touched.contains(&q) {
                                    touched.push(q);
                                }
                            }
                        }
                    }
                    touched.sort_unstable();
                    lens.push(touched.len());
                    for &q in touched.iter() {
                        cols.push(q);
                        vals.push(count[q as usize]);
                        count[q as usize] = 0;
                    }
                    touched.clear();
                }
                (lens, cols, vals)
            },
        )
        .collect();
    let nnz: usize = chunks.iter().map(|c| c.1.len()).sum();
    let mut indptr = Vec::with_capacity(n_a + 1);
    indptr.push(0usize);
    let mut indices = Vec::with_capacity(nnz);
    let mut data = Vec::with_capacity(nnz);
    // Consuming the chunks one by one frees each as it is copied: peak memory stays ~1x the cost.
    for (lens, cols, vals) in chunks {
        for l in lens {
            indptr.push(indptr.last().unwrap() + l);
        }
        indices.extend_from_slice(&cols);
        data.extend_from_slice(&vals);
    }
    Ok(Csr {
        n_rows: n_a,
        n_cols: n_b,
        indptr,
        indices,
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::adjacency_from_faces;

    fn dense_reference(
        a: &HopBalls,
        b: &HopBalls,
        k: usize,
        f: &[u32],
        w: &[bool],
    ) -> Vec<Vec<u32>> {
        let mut out = vec![vec![0u32; b.n]; a.n];
        for (p, row) in out.iter_mut().enumerate() {
            for &v in a.ball(p, k) {
                if w[v as usize] {
                    for &q in b.ball(f[v as usize] as usize, k) {
                        row[q as usize] += 1;
                    }
                }
            }
        }
        out
    }

    fn grid_faces(w: u32, h: u32) -> Vec<[u32; 3]> {
        let mut f = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let v = y * w + x;
                f.push([v, v + 1, v + w]);
                f.push([v + 1, v + w + 1, v + w]);
            }
        }
        f
    }

    #[test]
    fn matches_dense_count_and_top_k_keeps_best() {
        let adj_a = adjacency_from_faces(&grid_faces(7, 6), 42).unwrap();
        let adj_b = adjacency_from_faces(&grid_faces(6, 7), 42).unwrap();
        let a = HopBalls::new(&adj_a.view(), 3).unwrap();
        let b = HopBalls::new(&adj_b.view(), 3).unwrap();
        let f: Vec<u32> = (0..42u32).map(|i| (i * 17 + 5) % 42).collect();
        let w: Vec<bool> = (0..42).map(|i| i % 3 != 0).collect();
        for k in 0..=3 {
            let dense = dense_reference(&a, &b, k, &f, &w);
            let opts = OverlapOptions::default();
            let c = overlap_cost(
                &BallsAt { balls: &a, k },
                &BallsAt { balls: &b, k },
                &f,
                &w,
                opts,
            )
            .unwrap();
            for p in 0..42 {
                let v = c.view();
                let got: Vec<(u32, u32)> = v
                    .row(p)
                    .iter()
                    .copied()
                    .zip(v.row_data(p).iter().copied())
                    .collect();
                let want: Vec<(u32, u32)> = (0..42u32)
                    .filter(|&q| dense[p][q as usize] > 0)
                    .map(|q| (q, dense[p][q as usize]))
                    .collect();
                assert_eq!(got, want);
            }
            let keep: Vec<u32> = (0..42u32).rev().collect();
            let opts = OverlapOptions {
                top_k: Some(3),
                keep: Some(&keep),
            };
            let t = overlap_cost(
                &BallsAt { balls: &a, k },
                &BallsAt { balls: &b, k },
                &f,
                &w,
                opts,
            )
            .unwrap();
            let v = t.view();
            for p in 0..42 {
                let (cols, vals) = (v.row(p), v.row_data(p));
                assert!(cols.contains(&keep[p]) && cols.len() <= 4);
                // Top-k property: nothing dropped beats anything kept (the forced column aside).
                let min_kept = cols
                    .iter()
                    .zip(vals)
                    .filter(|(&q, _)| q != keep[p])
                    .map(|(_, &c)| c)
                    .min()
                    .unwrap_or(u32::MAX);
                let max_dropped = (0..42u32)
                    .filter(|q| !cols.contains(q))
                    .map(|q| dense[p][q as usize])
                    .max()
                    .unwrap_or(0);
                assert!(max_dropped <= min_kept, "row {p}");
                for (&q, &c) in cols.iter().zip(vals) {
                    assert_eq!(c, dense[p][q as usize]);
                }
            }
        }
    }
}
