//! k-hop neighbourhoods B_k(v): every vertex within k edges of v, v included.
//!
//! One breadth-first search per vertex up to `k_max` serves every k <= k_max: rows are stored in
//! BFS order, so B_k(v) is a prefix of row v and only the prefix lengths differ between k.
use crate::csr::Csr;
use crate::csr::CsrView;
use crate::error::{invalid, Result};
use crate::memory::{bytes_of, check_budget, try_with_capacity};
use rayon::prelude::*;

/// All k-hop neighbourhoods for k = 0..=k_max of one graph.
#[derive(Debug, Clone)]
pub struct HopBalls {
    pub n: usize,
    pub k_max: usize,
    indptr: Vec<usize>,
    /// Row v in order of hop distance from v (v first).
    order: Vec<u32>,
    /// `ends[v * (k_max + 1) + k]` = |B_k(v)|.
    ends: Vec<u32>,
}

const ROWS_PER_TASK: usize = 256;

impl HopBalls {
    /// Breadth-first searches from every vertex of `adj` (a symmetric pattern), in parallel.
    pub fn new(adj: &CsrView<()>, k_max: usize) -> Result<Self> {
        if adj.n_rows != adj.n_cols {
            return invalid("adjacency must be square");
        }
        if k_max > u8::MAX as usize {
            return invalid(format!("k must be at most 255, got {k_max}"));
        }
        let n = adj.n_rows;
        // Sized by the hop radius the caller passed: checked before any search runs.
        let n_ends = n.checked_mul(k_max + 1);
        check_budget(n_ends.and_then(bytes_of::<u32>), "the hop balls' sizes")?;
        let chunks: Vec<(Vec<u32>, Vec<u32>, Vec<usize>)> = (0..n.div_ceil(ROWS_PER_TASK))
            .into_par_iter()
            .map(|c| {
                let lo = c * ROWS_PER_TASK;
                let hi = (lo + ROWS_PER_TASK).min(n);
                let mut seen = vec![u32::MAX; n];
                let mut order = Vec::new();
                let mut ends = Vec::with_capacity((hi - lo) * (k_max + 1));
                let mut lens = Vec::with_capacity(hi - lo);
                for v in lo..hi {
                    let base = order.len();
                    seen[v] = v as u32;
                    order.push(v as u32);
                    let mut frontier = base;
                    ends.push(1);
                    for _ in 0..k_max {
                        let level_end = order.len();
                        for i in frontier..level_end {
                            let u = order[i] as usize;
                            for &w in adj.row(u) {
                                if seen[w as usize] != v as u32 {
                                    seen[w as usize] = v as u32;
                                    order.push(w);
                                }
                            }
                        }
                        frontier = level_end;
                        ends.push((order.len() - base) as u32);
                    }
                    lens.push(order.len() - base);
                }
                (order, ends, lens)
            })
            .collect();
        let total: usize = chunks.iter().map(|c| c.0.len()).sum();
        let mut order = try_with_capacity(total, "the hop balls")?;
        let mut ends = try_with_capacity(n_ends.unwrap_or(usize::MAX), "the hop balls' sizes")?;
        let mut indptr = Vec::with_capacity(n + 1);
        indptr.push(0);
        for (o, e, lens) in chunks {
            order.extend_from_slice(&o);
            ends.extend_from_slice(&e);
            for l in lens {
                indptr.push(indptr.last().unwrap() + l);
            }
        }
        Ok(HopBalls {
            n,
            k_max,
            indptr,
            order,
            ends,
        })
    }

    /// B_k(v) in BFS order (not sorted).
    #[inline]
    pub fn ball(&self, v: usize, k: usize) -> &[u32] {
        let s = self.indptr[v];
        &self.order[s..s + self.ends[v * (self.k_max + 1) + k] as usize]
    }

    /// B_k as a CSR pattern with sorted column indices (scipy's canonical form).
    pub fn to_csr(&self, k: usize) -> Csr<()> {
        let k = k.min(self.k_max);
        let mut indptr = Vec::with_capacity(self.n + 1);
        indptr.push(0usize);
        for v in 0..self.n {
            indptr.push(indptr[v] + self.ball(v, k).len());
        }
        let mut indices = vec![0u32; indptr[self.n]];
        // Split the output into per-row slices so rows can be sorted in parallel.
        let mut slices = Vec::with_capacity(self.n);
        let mut rest = indices.as_mut_slice();
        for v in 0..self.n {
            let (head, tail) = rest.split_at_mut(indptr[v + 1] - indptr[v]);
            slices.push(head);
            rest = tail;
        }
        slices.into_par_iter().enumerate().for_each(|(v, out)| {
            out.copy_from_slice(self.ball(v, k));
            out.sort_unstable();
        });
        Csr {
            n_rows: self.n,
            n_cols: self.n,
            indptr,
            indices,
            data: Vec::new(),
        }
    }
}

/// B_k of every vertex of `adj` (a symmetric pattern) as a CSR pattern with sorted columns,
/// straight from breadth-first searches that mark visited vertices in a bitset: the columns
/// then come out in order by reading the marked words, with no per-row sort and no rows kept
/// in BFS order (what [`HopBalls`] stores to serve every k at once).
pub fn khop_csr(adj: &CsrView<()>, k: usize) -> Result<Csr<()>> {
    if adj.n_rows != adj.n_cols {
        return invalid("adjacency must be square");
    }
    let n = adj.n_rows;
    let chunks: Vec<(Vec<u32>, Vec<usize>)> = (0..n.div_ceil(ROWS_PER_TASK))
        .into_par_iter()
        .map(|c| {
            let (lo, hi) = (c * ROWS_PER_TASK, ((c + 1) * ROWS_PER_TASK).min(n));
            let mut bits = vec![0u64; n.div_ceil(64)];
            let mut members = Vec::new();
            let mut cols = Vec::new();
            let mut lens = Vec::with_capacity(hi - lo);
            for v in lo..hi {
                members.clear();
                members.push(v as u32);
                bits[v >> 6] |= 1u64 << (v & 63);
                let (mut w_lo, mut w_hi) = (v >> 6, v >> 6);
                let mut level_start = 0usize;
                for _ in 0..k {
                    let frontier_end = members.len();
                    for i in level_start..frontier_end {
                        for &w in adj.row(members[i] as usize) {
                            let (word, bit) = (w as usize >> 6, 1u64 << (w & 63));
                            if bits[word] & bit == 0 {
                                bits[word] |= bit;
                                members.push(w);
                                w_lo = w_lo.min(word);
                                w_hi = w_hi.max(word);
                            }
                        }
                    }
                    if members.len() == frontier_end {
                        break;
                    }
                    level_start = frontier_end;
                }
                let start = cols.len();
                // Reading the words costs their span, sorting the members m log m: take the
                // cheaper (the span is long when vertex numbering is not spatially coherent).
                if w_hi - w_lo < 4 * members.len() {
                    for (word, b) in bits[w_lo..=w_hi].iter_mut().enumerate() {
                        let mut x = std::mem::take(b);
                        while x != 0 {
                            cols.push((((w_lo + word) << 6) | x.trailing_zeros() as usize) as u32);
                            x &= x - 1;
                        }
                    }
                } else {
                    for &w in &members {
                        bits[w as usize >> 6] = 0;
                    }
                    cols.extend_from_slice(&members);
                    cols[start..].sort_unstable();
                }
                lens.push(cols.len() - start);
            }
            (cols, lens)
        })
        .collect();
    let mut indptr = Vec::with_capacity(n + 1);
    indptr.push(0usize);
    for (_, lens) in &chunks {
        for &l in lens {
            indptr.push(indptr.last().unwrap() + l);
        }
    }
    let mut indices = try_with_capacity(*indptr.last().unwrap(), "the k-hop neighbourhoods")?;
    for (cols, _) in chunks {
        indices.extend_from_slice(&cols);
    }
    Ok(Csr {
        n_rows: n,
        n_cols: n,
        indptr,
        indices,
        data: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::adjacency_from_faces;

    /// A strip of triangles along a path 0-1-2-...: hop distances are easy to reason about.
    fn strip(n: u32) -> Vec<[u32; 3]> {
        (0..n - 2).map(|i| [i, i + 1, i + 2]).collect()
    }

    #[test]
    fn strip_balls_match_index_distance() {
        let adj = adjacency_from_faces(&strip(20), 22).unwrap();
        let b = HopBalls::new(&adj.view(), 3).unwrap();
        // In a strip (i, i+1, i+2) two vertices are adjacent iff |i - j| <= 2.
        for v in 0..20usize {
            for k in 0..=3usize {
                let mut got = b.ball(v, k).to_vec();
                got.sort_unstable();
                let want: Vec<u32> = (0..20u32)
                    .filter(|&u| (u as i64 - v as i64).unsigned_abs() as usize <= 2 * k)
                    .collect();
                assert_eq!(got, want, "v={v} k={k}");
            }
        }
        for k in 0..=3usize {
            assert_eq!(khop_csr(&adj.view(), k).unwrap(), b.to_csr(k), "k={k}");
        }
        // The two isolated vertices 20 and 21 are their own balls.
        assert_eq!(b.ball(21, 3), &[21]);
        let csr = b.to_csr(1);
        assert_eq!(&csr.indices[csr.indptr[0]..csr.indptr[1]], &[0, 1, 2]);
    }

    /// A triangulated m x m grid with its vertices numbered in a scrambled order, so that balls
    /// span most of the index range (the sorting path of `khop_csr`).
    fn scrambled_grid(m: u32) -> (Vec<[u32; 3]>, usize) {
        let n = (m * m) as usize;
        let mut label: Vec<u32> = (0..n as u32).collect();
        let mut x = 12345u64;
        for i in (1..n).rev() {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            label.swap(i, (x >> 33) as usize % (i + 1));
        }
        let at = |r: u32, c: u32| label[(r * m + c) as usize];
        let mut faces = Vec::new();
        for r in 0..m - 1 {
            for c in 0..m - 1 {
                faces.push([at(r, c), at(r + 1, c), at(r, c + 1)]);
                faces.push([at(r + 1, c), at(r + 1, c + 1), at(r, c + 1)]);
            }
        }
        (faces, n)
    }

    #[test]
    fn sorted_balls_match_bfs_order_balls() {
        for (faces, n) in [scrambled_grid(40), (strip(300), 300)] {
            let adj = adjacency_from_faces(&faces, n).unwrap();
            let b = HopBalls::new(&adj.view(), 8).unwrap();
            for k in 0..=8usize {
                assert_eq!(
                    khop_csr(&adj.view(), k).unwrap(),
                    b.to_csr(k),
                    "n={n} k={k}"
                );
            }
        }
    }
}
