//! The HOPE overlap cost K[p, q] = #{ witnesses v : v in B(p), f(v) in B(q) }, built sparse.
//!
//! Each row lives in a dense per-thread counter over B's vertices (a sparse accumulator) that is
//! updated from one row to the next, so no n_a x n_b array ever exists.
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

/// Rows of one parallel task: consecutive positions of the walk (see `walk_order`).
const SEGMENT: usize = 256;

/// Sparse overlap-count cost, rows = vertices of A, columns = vertices of B, columns sorted.
///
/// Rows are visited along a walk in which consecutive vertices are neighbours, and each row's
/// counts are obtained from the previous row's by adding the balls of the witnesses that enter
/// B(p) and removing those that leave it. Neighbouring k-balls share most of their vertices, so
/// this does a fraction of the work of accumulating every row from scratch (which it falls back
/// to whenever the difference is larger than the ball itself).
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
    let walk = walk_order(nbrs_a);
    let segments: Vec<Segment> = walk
        .par_chunks(SEGMENT)
        .enumerate()
        .map_init(
            || Accumulator::new(n_a, n_b),
            |acc, (s, rows)| acc.segment(nbrs_a, nbrs_b, f, witnesses, &opts, s * SEGMENT, rows),
        )
        .collect();
    // Rows were produced in walk order: lay them out by row index.
    let mut len = vec![0usize; n_a];
    for (seg, rows) in segments.iter().zip(walk.chunks(SEGMENT)) {
        for (i, &p) in rows.iter().enumerate() {
            len[p as usize] = seg.starts[i + 1] - seg.starts[i];
        }
    }
    let mut indptr = Vec::with_capacity(n_a + 1);
    indptr.push(0usize);
    for l in &len {
        indptr.push(indptr.last().unwrap() + l);
    }
    let nnz = indptr[n_a];
    let mut indices = vec![0u32; nnz];
    let mut data = vec![0u32; nnz];
    for (seg, rows) in segments.into_iter().zip(walk.chunks(SEGMENT)) {
        for (i, &p) in rows.iter().enumerate() {
            let (lo, hi) = (seg.starts[i], seg.starts[i + 1]);
            let at = indptr[p as usize];
            indices[at..at + hi - lo].copy_from_slice(&seg.cols[lo..hi]);
            data[at..at + hi - lo].copy_from_slice(&seg.vals[lo..hi]);
        }
    }
    Ok(Csr {
        n_rows: n_a,
        n_cols: n_b,
        indptr,
        indices,
        data,
    })
}

/// An order of A's vertices in which each vertex is, where possible, the first unvisited member
/// of the previous vertex's neighbourhood (its nearest one, for rows in BFS order).
fn walk_order<A: Rows>(a: &A) -> Vec<u32> {
    let n = a.n_rows();
    let mut visited = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut scan = 0usize;
    let mut current: Option<usize> = None;
    while order.len() < n {
        let next = current
            .and_then(|p| {
                a.row(p)
                    .iter()
                    .map(|&v| v as usize)
                    .find(|&v| v < n && !visited[v])
            })
            .unwrap_or_else(|| {
                while visited[scan] {
                    scan += 1;
                }
                scan
            });
        visited[next] = true;
        order.push(next as u32);
        current = Some(next);
    }
    order
}

/// The rows of one segment, in walk order.
struct Segment {
    starts: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<u32>,
}

/// Per-thread state: the counts of the current row, kept up to date as the walk moves.
struct Accumulator {
    count: Vec<i32>,
    /// `listed[q]`: q is in `support`, the columns whose count may be nonzero.
    listed: Vec<bool>,
    support: Vec<u32>,
    /// `member[v]` = 1 + walk position of the last row that contained v.
    member: Vec<u32>,
    entering: Vec<u32>,
    leaving: Vec<u32>,
    selected: Vec<u32>,
    bits: Vec<u64>,
}

impl Accumulator {
    fn new(n_a: usize, n_b: usize) -> Self {
        Accumulator {
            count: vec![0; n_b],
            listed: vec![false; n_b],
            support: Vec::new(),
            member: vec![0; n_a],
            entering: Vec::new(),
            leaving: Vec::new(),
            selected: Vec::new(),
            bits: vec![0; n_b.div_ceil(64)],
        }
    }

    #[inline]
    fn add(&mut self, ball: &[u32]) {
        // Branch-free: whether a column is new is data-dependent and mispredicts often, so every
        // column is written past the end of the list and the length advances only for new ones.
        let mut len = self.support.len();
        self.support.resize(len + ball.len() + 1, 0);
        let buf = &mut self.support[..];
        for &q in ball {
            let qi = q as usize;
            self.count[qi] += 1;
            buf[len] = q;
            len += !self.listed[qi] as usize;
            self.listed[qi] = true;
        }
        self.support.truncate(len);
    }

    #[inline]
    fn remove(&mut self, ball: &[u32]) {
        for &q in ball {
            self.count[q as usize] -= 1;
        }
    }

    fn clear(&mut self) {
        for &q in &self.support {
            self.count[q as usize] = 0;
            self.listed[q as usize] = false;
        }
        self.support.clear();
    }

    #[allow(clippy::too_many_arguments)]
    fn segment<A: Rows, B: Rows>(
        &mut self,
        nbrs_a: &A,
        nbrs_b: &B,
        f: &[u32],
        witnesses: &[bool],
        opts: &OverlapOptions<'_>,
        first_pos: usize,
        rows: &[u32],
    ) -> Segment {
        let n_a = self.member.len();
        let mut out = Segment {
            starts: Vec::with_capacity(rows.len() + 1),
            cols: Vec::new(),
            vals: Vec::new(),
        };
        out.starts.push(0);
        self.clear();
        let mut prev: Option<(usize, u32)> = None;
        for (i, &p) in rows.iter().enumerate() {
            let p = p as usize;
            let id = (first_pos + i + 1) as u32;
            let row = nbrs_a.row(p);
            self.entering.clear();
            self.leaving.clear();
            let prev_id = prev.map_or(0, |(_, pid)| pid);
            for &v in row {
                if (v as usize) < n_a && self.member[v as usize] != prev_id {
                    self.entering.push(v);
                }
            }
            for &v in row {
                if (v as usize) < n_a {
                    self.member[v as usize] = id;
                }
            }
            if let Some((q, _)) = prev {
                for &v in nbrs_a.row(q) {
                    if (v as usize) < n_a && self.member[v as usize] != id {
                        self.leaving.push(v);
                    }
                }
            }
            let incremental =
                prev.is_some() && self.entering.len() + self.leaving.len() < row.len();
            let entering = std::mem::take(&mut self.entering);
            let leaving = std::mem::take(&mut self.leaving);
            if !incremental {
                self.clear();
            }
            let fresh: &[u32] = if incremental { &entering } else { row };
            for &v in fresh {
                let v = v as usize;
                if v < n_a && witnesses[v] {
                    self.add(nbrs_b.row(f[v] as usize));
                }
            }
            if incremental {
                for &v in &leaving {
                    if witnesses[v as usize] {
                        self.remove(nbrs_b.row(f[v as usize] as usize));
                    }
                }
            }
            self.entering = entering;
            self.leaving = leaving;
            self.emit(p, opts, &mut out);
            prev = Some((p, id));
        }
        out
    }

    /// Appends row p (nonzero counts, plus the kept column) with sorted columns.
    fn emit(&mut self, p: usize, opts: &OverlapOptions<'_>, out: &mut Segment) {
        let (count, listed) = (&self.count, &mut self.listed);
        self.support.retain(|&q| {
            let live = count[q as usize] > 0;
            listed[q as usize] = live;
            live
        });
        let kept = opts.keep.map(|k| k[p]);
        let sel = &mut self.selected;
        sel.clear();
        sel.extend_from_slice(&self.support);
        if let Some(t) = opts.top_k {
            if sel.len() > t {
                sel.select_nth_unstable_by_key(t - 1, |&q| {
                    (std::cmp::Reverse(count[q as usize]), q)
                });
                sel.truncate(t);
            }
        }
        if let Some(q) = kept {
            if count[q as usize] <= 0 || (opts.top_k.is_some() && !sel.contains(&q)) {
                sel.push(q);
            }
        }
        if sel.len() * 8 < self.bits.len() {
            sel.sort_unstable();
            for &q in sel.iter() {
                out.cols.push(q);
                out.vals.push(count[q as usize].max(0) as u32);
            }
        } else {
            // Dense enough that scanning a bitset beats sorting.
            let (mut lo, mut hi) = (usize::MAX, 0usize);
            for &q in sel.iter() {
                let w = q as usize >> 6;
                self.bits[w] |= 1u64 << (q & 63);
                lo = lo.min(w);
                hi = hi.max(w);
            }
            for w in lo..=hi.min(self.bits.len().saturating_sub(1)) {
                let mut word = std::mem::take(&mut self.bits[w]);
                while word != 0 {
                    let q = (w << 6) | word.trailing_zeros() as usize;
                    word &= word - 1;
                    out.cols.push(q as u32);
                    out.vals.push(count[q].max(0) as u32);
                }
            }
        }
        out.starts.push(out.cols.len());
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // tests index several parallel arrays
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
