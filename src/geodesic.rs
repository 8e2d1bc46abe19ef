//! Shortest paths on a mesh's edge graph, searched locally (each search stops early).
use crate::csr::CsrView;
use crate::error::{invalid, Result};
use crate::memory::try_filled_vec;
use rayon::prelude::*;
use std::borrow::Cow;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// A mesh's edge graph with Euclidean edge lengths.
pub struct EdgeGraph<'a> {
    pub vertices: &'a [[f64; 3]],
    pub adj: CsrView<'a, ()>,
    /// The length of each stored edge, in `adj`'s entry order ([`edge_lengths`]): one load
    /// per relaxed edge instead of two vertex loads and a square root is faster, with the same
    /// distances.
    pub lengths: Cow<'a, [f64]>,
}

#[inline]
fn distance(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

/// The Euclidean length of every stored entry of `adj`, in entry order.
pub fn edge_lengths(vertices: &[[f64; 3]], adj: &CsrView<'_, ()>) -> Vec<f64> {
    let mut out = vec![0.0; adj.indices.len()];
    out.par_chunks_mut(4096).enumerate().for_each(|(c, chunk)| {
        let start = c * 4096;
        // The row of entry `start`, then walk rows along the chunk.
        let mut r = adj.indptr.partition_point(|&p| p <= start) - 1;
        for (k, l) in chunk.iter_mut().enumerate() {
            let e = start + k;
            while adj.indptr[r + 1] <= e {
                r += 1;
            }
            *l = distance(vertices[r], vertices[adj.indices[e] as usize]);
        }
    });
    out
}

impl<'a> EdgeGraph<'a> {
    /// The graph with its edge lengths computed here.
    pub fn new(vertices: &'a [[f64; 3]], adj: CsrView<'a, ()>) -> Self {
        let lengths = Cow::Owned(edge_lengths(vertices, &adj));
        EdgeGraph {
            vertices,
            adj,
            lengths,
        }
    }

    /// The straight-line distance between vertices `a` and `b`.
    #[inline]
    pub fn straight_line(&self, a: usize, b: usize) -> f64 {
        distance(self.vertices[a], self.vertices[b])
    }

    /// Mean length of the edges at vertex `v` (0 for an isolated vertex).
    pub fn local_edge_length(&self, v: usize) -> f64 {
        let row = self.adj.row(v);
        if row.is_empty() {
            return 0.0;
        }
        row.iter()
            .map(|&b| self.straight_line(v, b as usize))
            .sum::<f64>()
            / row.len() as f64
    }

    /// Mean length of the graph's edges (0 for a graph without edges).
    pub fn mean_edge_length(&self) -> f64 {
        let (mut sum, mut count) = (0.0, 0usize);
        for a in 0..self.adj.n_rows {
            for &b in self.adj.row(a) {
                if (b as usize) > a {
                    sum += self.straight_line(a, b as usize);
                    count += 1;
                }
            }
        }
        if count == 0 {
            0.0
        } else {
            sum / count as f64
        }
    }
}

/// Reusable Dijkstra state: `dist[v]` is valid only where `stamp[v] == current`, and
/// `pending[v] == current` marks a target not yet settled.
pub struct Dijkstra {
    dist: Vec<f64>,
    stamp: Vec<u32>,
    pending: Vec<u32>,
    current: u32,
    heap: BinaryHeap<Reverse<(u64, u32)>>,
}

/// How many times the size a caller needs a kept thread workspace may be (16 bytes a vertex).
const LOCAL_SLACK: usize = 4;

thread_local! {
    /// Each thread's workspace for [`Dijkstra::with_local`].
    static WORKSPACE: std::cell::Cell<Option<Dijkstra>> = const { std::cell::Cell::new(None) };
}

impl Dijkstra {
    /// Runs `work` with this thread's workspace for graphs of at most `n` vertices, kept for
    /// the thread's next call. Many short searches spread over rayon's tasks would otherwise
    /// allocate (and the kernel zero, page by page as the searches touch them) a workspace
    /// of the graph's size per task, again on every call. A nested call gets a fresh one.
    /// A kept workspace more than [`LOCAL_SLACK`] times the size asked for is replaced, so a
    /// large mesh's workspace does not stay with every thread through later small ones.
    pub fn with_local<R>(n: usize, work: impl FnOnce(&mut Dijkstra) -> R) -> R {
        let mut dj = match WORKSPACE.take() {
            Some(dj) if dj.dist.len() >= n && dj.dist.len() <= n.saturating_mul(LOCAL_SLACK) => dj,
            _ => Dijkstra::new(n),
        };
        let out = work(&mut dj);
        WORKSPACE.set(Some(dj));
        out
    }

    pub fn new(n: usize) -> Self {
        Dijkstra {
            dist: vec![0.0; n],
            stamp: vec![0; n],
            pending: vec![0; n],
            current: 0,
            heap: BinaryHeap::new(),
        }
    }

    /// Offers every neighbour of the settled vertex `u` a path through it.
    #[inline]
    fn relax(&mut self, g: &EdgeGraph, u: usize, du: f64, cur: u32) {
        let (lo, hi) = (g.adj.indptr[u], g.adj.indptr[u + 1]);
        for (&w, &l) in g.adj.indices[lo..hi].iter().zip(&g.lengths[lo..hi]) {
            let w = w as usize;
            let nd = du + l;
            if self.stamp[w] != cur || nd < self.dist[w] {
                self.stamp[w] = cur;
                self.dist[w] = nd;
                self.heap.push(Reverse((nd.to_bits(), w as u32)));
            }
        }
    }

    /// A stamp no entry carries yet: every distance and mark becomes stale at once.
    fn next_stamp(&mut self) -> u32 {
        self.current = self.current.wrapping_add(1);
        if self.current == 0 {
            self.stamp.fill(0);
            self.pending.fill(0);
            self.current = 1;
        }
        self.current
    }

    /// Distances from `src` to `targets` (infinite where farther than `cutoff`); stops as soon as
    /// every target is settled, so the search stays local.
    pub fn run(
        &mut self,
        g: &EdgeGraph,
        src: usize,
        targets: &[u32],
        cutoff: f64,
        out: &mut Vec<f64>,
    ) {
        let cur = self.next_stamp();
        let mut remaining = 0usize;
        for &t in targets {
            if self.pending[t as usize] != cur {
                self.pending[t as usize] = cur;
                remaining += 1;
            }
        }
        self.heap.clear();
        self.stamp[src] = cur;
        self.dist[src] = 0.0;
        // Non-negative f64s order like their bit patterns, so the heap can hold integers.
        self.heap.push(Reverse((0f64.to_bits(), src as u32)));
        while remaining > 0 {
            let Some(Reverse((bits, u))) = self.heap.pop() else {
                break;
            };
            let (du, u) = (f64::from_bits(bits), u as usize);
            if du > cutoff {
                break;
            }
            if du > self.dist[u] {
                continue;
            }
            if self.pending[u] == cur {
                self.pending[u] = 0;
                remaining -= 1;
            }
            self.relax(g, u, du, cur);
        }
        out.clear();
        out.extend(targets.iter().map(|&t| {
            let t = t as usize;
            if self.stamp[t] == cur && self.pending[t] != cur && self.dist[t] <= cutoff {
                self.dist[t]
            } else {
                f64::INFINITY
            }
        }));
    }

    /// Every vertex within `cutoff` of `src`, in the order settled (nondecreasing distance), but
    /// at most `cap` of them. Returns the radius below which the list is complete: `cutoff` when
    /// the ball fits, else just under the distance of the first vertex left out.
    pub fn ball(
        &mut self,
        g: &EdgeGraph,
        src: usize,
        cutoff: f64,
        cap: usize,
        ids: &mut Vec<u32>,
        dists: &mut Vec<f64>,
    ) -> f64 {
        let cur = self.next_stamp();
        ids.clear();
        dists.clear();
        self.heap.clear();
        self.stamp[src] = cur;
        self.dist[src] = 0.0;
        self.heap.push(Reverse((0f64.to_bits(), src as u32)));
        while let Some(Reverse((bits, u))) = self.heap.pop() {
            let (du, u) = (f64::from_bits(bits), u as usize);
            if du > cutoff {
                break;
            }
            // `pending` marks settled vertices here (a popped stale entry of one is skipped).
            if du > self.dist[u] || self.pending[u] == cur {
                continue;
            }
            if ids.len() == cap {
                // Everything nearer than du is already listed; du itself may tie with a vertex
                // left out, hence the largest float below it.
                return f64::from_bits(bits.saturating_sub(1)).max(0.0);
            }
            self.pending[u] = cur;
            ids.push(u as u32);
            dists.push(du);
            self.relax(g, u, du, cur);
        }
        cutoff
    }
    /// Lowers `bound` to the distance from `src` wherever that is smaller, leaving every other
    /// entry as it is: a search that never enters a vertex it cannot improve. When `bound` is
    /// the minimum of earlier [`Dijkstra::ball`] fields, the result is exactly the minimum with
    /// this source's full field (a vertex improved lies on a path of improved vertices only),
    /// at the cost of searching only the region the source takes over.
    pub fn lower(&mut self, g: &EdgeGraph, src: usize, bound: &mut [f64]) {
        self.heap.clear();
        // Nothing to lower at a sample already (or a NaN bound).
        if bound[src].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return;
        }
        bound[src] = 0.0;
        self.heap.push(Reverse((0f64.to_bits(), src as u32)));
        while let Some(Reverse((bits, u))) = self.heap.pop() {
            let (du, u) = (f64::from_bits(bits), u as usize);
            if du > bound[u] {
                continue;
            }
            let (lo, hi) = (g.adj.indptr[u], g.adj.indptr[u + 1]);
            for (&w, &l) in g.adj.indices[lo..hi].iter().zip(&g.lengths[lo..hi]) {
                let nd = du + l;
                if nd < bound[w as usize] {
                    bound[w as usize] = nd;
                    self.heap.push(Reverse((nd.to_bits(), w)));
                }
            }
        }
    }
}

/// Edge-graph distance between each pair `(sources[i], targets[i])` (infinite when not
/// connected). Each search stops once its target is settled, so nearby pairs are cheap.
pub fn pair_distances(g: &EdgeGraph, sources: &[u32], targets: &[u32]) -> Result<Vec<f64>> {
    let n = g.adj.n_rows;
    if sources.len() != targets.len() {
        return invalid("sources and targets must have the same length");
    }
    if sources.iter().chain(targets).any(|&v| v as usize >= n) {
        return invalid(format!("vertex index out of range for {n} vertices"));
    }
    Ok(sources
        .par_iter()
        .zip(targets.par_iter())
        .map_init(
            || (Dijkstra::new(n), Vec::new()),
            |(dj, out), (&s, &t)| {
                dj.run(g, s as usize, &[t], f64::INFINITY, out);
                out[0]
            },
        )
        .collect())
}

/// Edge-graph distances from each source to every vertex (infinite where unreachable): row i
/// of the returned `sources.len() x n` row-major array belongs to `sources[i]`. Sources are
/// searched in parallel.
pub fn distance_fields(g: &EdgeGraph, sources: &[u32]) -> Result<Vec<f64>> {
    let n = g.adj.n_rows;
    if let Some(&s) = sources.iter().find(|&&s| s as usize >= n) {
        return invalid(format!("source {s} out of range for {n} vertices"));
    }
    let size = sources.len().saturating_mul(n);
    let mut out = try_filled_vec(size, f64::INFINITY, "the distance fields")?;
    fill_fields(g, sources, &mut out);
    Ok(out)
}

/// Writes the distance field of `sources[i]` into row i of `out` (`sources.len() x n`
/// row-major, every entry infinite on entry; sources in range), searching in parallel.
fn fill_fields(g: &EdgeGraph, sources: &[u32], out: &mut [f64]) {
    let n = g.adj.n_rows;
    if n == 0 {
        return;
    }
    // A full search is a ball without limits; its distances are the ones `run` settles.
    out.par_chunks_mut(n).zip(sources.par_iter()).for_each_init(
        || (Dijkstra::new(n), Vec::new(), Vec::new()),
        |(dj, ids, dists), (row, &s)| {
            dj.ball(g, s as usize, f64::INFINITY, n, ids, dists);
            for (&v, &d) in ids.iter().zip(dists.iter()) {
                row[v as usize] = d;
            }
        },
    );
}

/// Farthest-point samples of `candidates` and their distance fields: `start` first, then
/// repeatedly the candidate farthest from every sample so far (distances divided by `scale`,
/// the first of equal ones; candidates unreachable from all samples count as -1), until `n`
/// samples or until the farthest candidate is a sample. Returns the samples and their fields
/// (unscaled, `samples.len() x n_vertices` row-major, as [`distance_fields`] gives them).
///
/// The nearest-sample distance is kept up to date by [`Dijkstra::lower`], which searches only
/// the region each new sample takes over; the full fields of the samples are then searched in
/// parallel.
pub fn farthest_point_fields(
    g: &EdgeGraph,
    candidates: &[u32],
    start: u32,
    n: usize,
    scale: f64,
) -> Result<(Vec<u32>, Vec<f64>)> {
    let n_v = g.adj.n_rows;
    if let Some(&s) = candidates
        .iter()
        .chain([&start])
        .find(|&&s| s as usize >= n_v)
    {
        return invalid(format!("vertex {s} out of range for {n_v} vertices"));
    }
    if !(scale > 0.0 && scale.is_finite()) {
        return invalid("the scale must be positive and finite");
    }
    let mut nearest = distance_fields(g, &[start])?;
    let mut chosen = vec![start];
    let mut dj = Dijkstra::new(n_v);
    for _ in 1..n.min(candidates.len()) {
        // The first candidate of the largest scaled distance (unreachable ones count as -1).
        let mut best = (0usize, f64::NEG_INFINITY);
        for (i, &c) in candidates.iter().enumerate() {
            let d = nearest[c as usize] / scale;
            let d = if d.is_finite() { d } else { -1.0 };
            if d > best.1 {
                best = (i, d);
            }
        }
        let next = candidates[best.0];
        if nearest[next as usize] / scale <= 0.0 {
            break;
        }
        dj.lower(g, next as usize, &mut nearest);
        chosen.push(next);
    }
    // The start's field is searched again rather than kept: the fields are then the only
    // array of their size (`nearest` is one row).
    drop(nearest);
    let size = chosen.len().saturating_mul(n_v);
    let mut fields = try_filled_vec(size, f64::INFINITY, "the distance fields")?;
    fill_fields(g, &chosen, &mut fields);
    Ok((chosen, fields))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::adjacency_from_faces;

    #[test]
    fn thread_workspace_follows_the_size_asked_for() {
        let len = |n| Dijkstra::with_local(n, |dj| dj.dist.len());
        assert_eq!(len(1000), 1000);
        assert_eq!(
            len(500),
            1000,
            "within the slack the kept workspace is reused"
        );
        assert_eq!(len(10), 10, "a workspace far too large is replaced");
        assert_eq!(len(2000), 2000);
    }

    #[test]
    fn distances_along_a_strip() {
        // Vertices on a line x = i, triangles (i, i+1, i+2): the shortest path hops by two.
        let v: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 0.0, 0.0]).collect();
        let f: Vec<[u32; 3]> = (0..8).map(|i| [i, i + 1, i + 2]).collect();
        let adj = adjacency_from_faces(&f, 11).unwrap();
        let mut v11 = v.clone();
        v11.push([0.0, 5.0, 0.0]);
        let g = EdgeGraph::new(&v11, adj.view());
        let d = pair_distances(&g, &[0, 3, 9, 0], &[9, 3, 0, 10]).unwrap();
        assert_eq!(&d[..3], &[9.0, 0.0, 9.0]);
        assert!(d[3].is_infinite());
        assert!(pair_distances(&g, &[0], &[11]).is_err());
    }

    #[test]
    fn edge_lengths_follow_entry_order_across_chunks() {
        // A 60 x 40 grid (over 13k entries, so several chunks) with a few empty rows at the end.
        let w = 60u32;
        let v: Vec<[f64; 3]> = (0..w * 40 + 3)
            .map(|i| {
                [
                    (i % w) as f64,
                    (i / w) as f64 * 0.7,
                    ((i * 7) % 5) as f64 * 0.1,
                ]
            })
            .collect();
        let mut f = Vec::new();
        for y in 0..39 {
            for x in 0..w - 1 {
                let i = y * w + x;
                f.push([i, i + 1, i + w]);
                f.push([i + 1, i + w + 1, i + w]);
            }
        }
        let adj = adjacency_from_faces(&f, v.len()).unwrap();
        let g = EdgeGraph::new(&v, adj.view());
        assert!(g.lengths.len() > 3 * 4096);
        for a in 0..v.len() {
            let (lo, hi) = (adj.indptr[a], adj.indptr[a + 1]);
            for e in lo..hi {
                assert_eq!(g.lengths[e], g.straight_line(a, adj.indices[e] as usize));
            }
        }
    }

    #[test]
    fn fields_match_pair_distances() {
        let v: Vec<[f64; 3]> = (0..12)
            .map(|i| {
                [
                    (i % 4) as f64,
                    (i / 4) as f64 * 1.3,
                    ((i * 5) % 3) as f64 * 0.2,
                ]
            })
            .collect();
        let mut f = Vec::new();
        for y in 0..2u32 {
            for x in 0..3u32 {
                let i = y * 4 + x;
                f.push([i, i + 1, i + 4]);
                f.push([i + 1, i + 5, i + 4]);
            }
        }
        let mut v13 = v.clone();
        v13.push([9.0, 9.0, 9.0]); // isolated
        let adj = adjacency_from_faces(&f, 13).unwrap();
        let g = EdgeGraph::new(&v13, adj.view());
        let sources = [0u32, 7, 12];
        let fields = distance_fields(&g, &sources).unwrap();
        for (i, &s) in sources.iter().enumerate() {
            let targets: Vec<u32> = (0..13).collect();
            let d = pair_distances(&g, &[s; 13], &targets).unwrap();
            assert_eq!(&fields[i * 13..(i + 1) * 13], &d[..]);
        }
        assert!(fields[13 * 2 + 12] == 0.0 && fields[13 * 2].is_infinite());
        assert!(distance_fields(&g, &[13]).is_err());
    }
    /// The farthest-point samples as one would pick them with every full field at hand.
    fn naive_farthest(g: &EdgeGraph, cand: &[u32], start: u32, n: usize, scale: f64) -> Vec<u32> {
        let n_v = g.adj.n_rows;
        let mut chosen = vec![start];
        let mut nearest = distance_fields(g, &[start]).unwrap();
        for _ in 1..n.min(cand.len()) {
            let d: Vec<f64> = cand
                .iter()
                .map(|&c| nearest[c as usize] / scale)
                .map(|d| if d.is_finite() { d } else { -1.0 })
                .collect();
            let i = (0..d.len()).fold(0, |b, i| if d[i] > d[b] { i } else { b });
            if nearest[cand[i] as usize] / scale <= 0.0 {
                break;
            }
            chosen.push(cand[i]);
            let field = distance_fields(g, &[cand[i]]).unwrap();
            for v in 0..n_v {
                nearest[v] = nearest[v].min(field[v]);
            }
        }
        chosen
    }

    #[test]
    fn farthest_points_match_full_searches() {
        // A bumpy 30 x 20 grid with irregular edge lengths, and a second component.
        let w = 30u32;
        let mut v: Vec<[f64; 3]> = (0..w * 20)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                [
                    x + ((i * 13) % 7) as f64 * 0.05,
                    y * 0.9,
                    ((i * 7) % 5) as f64 * 0.3,
                ]
            })
            .collect();
        let mut f = Vec::new();
        for y in 0..19 {
            for x in 0..w - 1 {
                let i = y * w + x;
                f.push([i, i + 1, i + w]);
                f.push([i + 1, i + w + 1, i + w]);
            }
        }
        let off = v.len() as u32;
        v.extend([[50.0, 0.0, 0.0], [51.0, 0.0, 0.0], [50.0, 1.0, 0.0]]);
        f.push([off, off + 1, off + 2]);
        let adj = adjacency_from_faces(&f, v.len()).unwrap();
        let g = EdgeGraph::new(&v, adj.view());
        let every: Vec<u32> = (0..v.len() as u32).collect();
        let odd: Vec<u32> = every.iter().copied().filter(|c| c % 3 != 0).collect();
        for (cand, start, n, scale) in [
            (&every[..], 0u32, 40usize, 1.0),
            (&odd[..], 301, 25, 0.37),
            (&every[..], off, 10, 2.0),
            (&odd[..5], 1, 9, 1.0),
        ] {
            let (chosen, fields) = farthest_point_fields(&g, cand, start, n, scale).unwrap();
            assert_eq!(chosen, naive_farthest(&g, cand, start, n, scale));
            assert_eq!(fields, distance_fields(&g, &chosen).unwrap());
        }
        // `lower` gives exactly the minimum with each further full field.
        let mut bound = distance_fields(&g, &[7]).unwrap();
        let mut want = bound.clone();
        let mut dj = Dijkstra::new(v.len());
        for s in [590u32, 7, 301, off + 1, 44] {
            dj.lower(&g, s as usize, &mut bound);
            let field = distance_fields(&g, &[s]).unwrap();
            for (w, d) in want.iter_mut().zip(&field) {
                *w = w.min(*d);
            }
            assert_eq!(bound, want, "after source {s}");
        }
        assert!(farthest_point_fields(&g, &[0, 9999], 0, 4, 1.0).is_err());
        assert!(farthest_point_fields(&g, &[0, 1], 0, 4, 0.0).is_err());
    }
}
