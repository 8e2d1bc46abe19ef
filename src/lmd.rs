//! Local map distortion (LMD): how well a map preserves geodesic distances around each vertex.
//!
//! Geodesics are shortest paths on the edge graph (see `geodesic`), truncated to a small radius.
//! They overestimate surface distance by a few percent, but LMD compares the same kind of distance
//! on both shapes at the scale of a 2-ring, so the bias largely cancels; exact surface geodesics
//! would cost one or two orders of magnitude more per vertex for no measurable gain.
use crate::error::{invalid, Result};
use crate::geodesic::{Dijkstra, EdgeGraph};
use crate::khop::HopBalls;
use rayon::prelude::*;

/// Edge-graph distances from each vertex to its 2-ring (in `HopBalls` order), computed once per
/// shape: LMD needs them for the source shape at every refinement step.
#[derive(Debug, Clone)]
pub struct RingDistances {
    offsets: Vec<usize>,
    dist: Vec<f64>,
    /// Mean edge length of the graph.
    pub mean_edge: f64,
    /// Mean length of each vertex's edges.
    local_edge: Vec<f64>,
}

impl RingDistances {
    pub fn new(g: &EdgeGraph, balls: &HopBalls) -> Result<Self> {
        if balls.k_max < 2 || balls.n != g.adj.n_rows {
            return invalid("ring distances need the 2-ring neighbourhoods of the same graph");
        }
        let n = balls.n;
        let per_vertex: Vec<Vec<f64>> = (0..n)
            .into_par_iter()
            .map_init(
                || (Dijkstra::new(n), Vec::new()),
                |(dj, out), p| {
                    dj.run(g, p, &balls.ball(p, 2)[1..], f64::INFINITY, out);
                    out.clone()
                },
            )
            .collect();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        let mut dist = Vec::new();
        for d in per_vertex {
            dist.extend_from_slice(&d);
            offsets.push(dist.len());
        }
        Ok(RingDistances {
            offsets,
            dist,
            mean_edge: g.mean_edge_length(),
            local_edge: (0..n).map(|p| g.local_edge_length(p)).collect(),
        })
    }

    fn of(&self, p: usize) -> &[f64] {
        &self.dist[self.offsets[p]..self.offsets[p + 1]]
    }
}

/// Edge-graph distances from every vertex of a shape to the vertices around it, rows sorted by
/// vertex id. LMD looks up d_B(f(p), f(r)) here instead of running a search from f(p) at every
/// refinement step (a pass calls LMD about ten times), while a lookup is a binary search in a
/// row of about a hundred entries.
#[derive(Debug, Clone)]
pub struct LocalDistances {
    offsets: Vec<usize>,
    ids: Vec<u32>,
    dist: Vec<f64>,
    /// Per row: every vertex at most this far away is listed.
    complete: Vec<f64>,
    /// The search radius the table was built with (unscaled edge-graph units).
    pub cutoff: f64,
}

/// Entries per row at most, so a shape far finer than its partner cannot blow up the table;
/// rows cut short are used only for maps whose 2-ring images they still cover.
const MAX_ROW: usize = 256;

impl LocalDistances {
    pub fn new(g: &EdgeGraph, cutoff: f64) -> Self {
        Self::with_cap(g, cutoff, MAX_ROW)
    }

    fn with_cap(g: &EdgeGraph, cutoff: f64, cap: usize) -> Self {
        let n = g.adj.n_rows;
        let rows: Vec<(Vec<u32>, Vec<f64>, f64)> = (0..n)
            .into_par_iter()
            .map_init(
                || (Dijkstra::new(n), Vec::new(), Vec::new()),
                |(dj, ids, dists), q| {
                    let complete = dj.ball(g, q, cutoff, cap.max(1), ids, dists);
                    let mut row: Vec<(u32, f64)> =
                        ids.iter().copied().zip(dists.iter().copied()).collect();
                    row.sort_unstable_by_key(|e| e.0);
                    let (i, d) = row.into_iter().unzip();
                    (i, d, complete)
                },
            )
            .collect();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        let total = rows.iter().map(|r| r.0.len()).sum();
        let (mut ids, mut dist) = (Vec::with_capacity(total), Vec::with_capacity(total));
        let mut complete = Vec::with_capacity(n);
        for (i, d, c) in rows {
            ids.extend_from_slice(&i);
            dist.extend_from_slice(&d);
            complete.push(c);
            offsets.push(ids.len());
        }
        LocalDistances {
            offsets,
            ids,
            dist,
            complete,
            cutoff,
        }
    }

    /// Number of vertices of the shape the table was built for.
    pub fn n_vertices(&self) -> usize {
        self.complete.len()
    }

    /// Writes into `out` the distances from `q` to `targets` as `Dijkstra::run` with this
    /// `cutoff` would give them (infinite beyond it); false, with `out` unspecified, when q's
    /// row cannot tell: a target is not listed and the row is not complete up to `cutoff`.
    /// A row cut short still answers for the targets it lists, whose distances are exact: the
    /// images of a 2-ring under a right map lie close to q even where the mesh is too fine for
    /// the row to reach the cutoff.
    fn lookup(&self, q: usize, targets: &[u32], cutoff: f64, out: &mut Vec<f64>) -> bool {
        let lo = self.offsets[q];
        let (ids, dist) = (&self.ids[lo..self.offsets[q + 1]], &self.dist[lo..]);
        // Every vertex nearer than `complete[q]` is listed, so an unlisted one is farther.
        let unlisted_beyond = cutoff <= self.complete[q];
        out.clear();
        for t in targets {
            out.push(match ids.binary_search(t) {
                Ok(i) if dist[i] <= cutoff => dist[i],
                Ok(_) => f64::INFINITY,
                Err(_) if unlisted_beyond => f64::INFINITY,
                Err(_) => return false,
            });
        }
        true
    }
}

/// The search radius on B (unscaled) that covers LMD's searches for all but the farthest-reaching
/// 0.5% of A's vertices (those fall back to a search of their own).
pub fn lmd_table_cutoff(rings_a: &RingDistances, scale_a: f64, scale_b: f64) -> f64 {
    let n = rings_a.offsets.len() - 1;
    let unit = lmd_unit(rings_a, scale_a);
    let mut reach: Vec<f64> = (0..n)
        .map(|p| lmd_reach(rings_a.of(p), scale_a, unit))
        .collect();
    if reach.is_empty() {
        return 0.0;
    }
    let at = ((reach.len() - 1) as f64 * 0.995) as usize;
    let (_, r, _) = reach.select_nth_unstable_by(at, f64::total_cmp);
    *r * scale_b
}

/// How far (scaled) LMD looks on B around f(p): p's farthest 2-ring neighbour plus two units,
/// beyond which every distance counts the same.
fn lmd_reach(ring_dists: &[f64], scale_a: f64, unit: f64) -> f64 {
    ring_dists.iter().copied().fold(0.0, f64::max) / scale_a + 2.0 * unit
}

/// Scale of [`tolerance`]; see docs/decisions.md#lmd for the values measured.
const TOLERANCE: f64 = 1.25;

/// How far d_B(f(p), f(r)) may stray from d_A(p, r) for r to count as consistent:
/// [`TOLERANCE`] times the geometric mean of A's mean edge length (`unit`) and the local edge
/// length at both ends, the mean of p's edges on A and of f(p)'s on B (`la`, `lb`; all scaled).
///
/// A right map's errors are at the scale of the edges where it lands: its image of p is off by
/// up to about half of B's local edge, and a flipped diagonal changes a graph distance by a
/// fraction of an edge. Meshes are far from uniform (the TOSCA cat's edges run from 0.12 to 2.3
/// times their mean, the FAUST remeshes' from 0.36 to 1.8), and one global mean edge spans
/// several local edges in fine regions, where maps slid by a few vertices then pass as
/// witnesses. A's local edge alone (no global part) did worse where the triangulations differ
/// in a few percent of their edges (a flip changes a graph distance by a fraction of an edge, a
/// large share of a fine one; docs/decisions.md#lmd).
/// Capped at two units, the margin by which the search radius exceeds the 2-ring, so that
/// clamping B's distances there never changes a verdict.
fn tolerance(unit: f64, la: f64, lb: f64) -> f64 {
    if la > 0.0 && lb > 0.0 {
        (TOLERANCE * (unit * 0.5 * (la + lb)).sqrt()).min(2.0 * unit)
    } else {
        TOLERANCE * unit
    }
}

fn lmd_unit(rings_a: &RingDistances, scale_a: f64) -> f64 {
    let edge = rings_a.mean_edge / scale_a;
    if edge > 0.0 {
        edge
    } else {
        1.0
    }
}

/// Per-vertex distortion of the map `f` (A → B) over the 2-ring of each vertex of A.
///
/// Distances are divided by each shape's `scale` (sqrt of its area) so the measure does not depend
/// on the shapes' sizes. Returns, per vertex, the mean distortion over its 2-ring in units of A's
/// mean edge length, and the fraction of its 2-ring whose distortion is below the vertex's
/// tolerance (a robust score when many neighbours are mismatched; see [`tolerance`]).
///
/// `prev`: an earlier map with its result, `(f_prev, mean_prev, frac_prev)`. Only vertices whose
/// 2-ring (themselves included) maps differently are then recomputed; the others keep their
/// values, which are exactly what a full computation gives. Late refinement steps move a few
/// percent of the vertices, so most of the work is skipped.
#[allow(clippy::too_many_arguments)]
pub fn local_map_distortion(
    balls_a: &HopBalls,
    rings_a: &RingDistances,
    b: &EdgeGraph,
    f: &[u32],
    scale_a: f64,
    scale_b: f64,
    table: Option<&LocalDistances>,
    prev: Option<(&[u32], &[f32], &[f32])>,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let n_a = balls_a.n;
    let n_b = b.adj.n_rows;
    if balls_a.k_max < 2 || rings_a.offsets.len() != n_a + 1 {
        return invalid("LMD needs the 2-ring neighbourhoods of A");
    }
    if f.len() != n_a || f.iter().any(|&q| q as usize >= n_b) {
        return invalid(format!(
            "the map must hold one vertex of B (< {n_b}) per vertex of A ({n_a})"
        ));
    }
    if !(scale_a > 0.0 && scale_b > 0.0 && scale_a.is_finite() && scale_b.is_finite()) {
        return invalid("shape scales must be positive and finite");
    }
    if table.is_some_and(|t| t.n_vertices() != n_b) {
        return invalid("the distance table was built for another shape");
    }
    let unit = lmd_unit(rings_a, scale_a);
    let job = Job {
        balls_a,
        rings_a,
        b,
        f,
        scale_a,
        scale_b,
        table,
        unit,
    };
    let Some((prev_f, prev_mean, prev_frac)) = prev else {
        return Ok(job
            .rows((0..n_a as u32).into_par_iter())
            .into_iter()
            .unzip());
    };
    if prev_f.len() != n_a || prev_mean.len() != n_a || prev_frac.len() != n_a {
        return invalid(format!(
            "the previous map and its LMD must have one entry per vertex of A ({n_a})"
        ));
    }
    // LMD of p depends on f over p's 2-ring only: recompute where that changed.
    let mut dirty = vec![false; n_a];
    for (c, (&x, &y)) in f.iter().zip(prev_f).enumerate() {
        if x != y {
            for &r in balls_a.ball(c, 2) {
                dirty[r as usize] = true;
            }
        }
    }
    let stale: Vec<u32> = (0..n_a as u32).filter(|&p| dirty[p as usize]).collect();
    let (mut mean, mut frac) = (prev_mean.to_vec(), prev_frac.to_vec());
    for (&p, (m, c)) in stale.iter().zip(job.rows(stale.par_iter().copied())) {
        mean[p as usize] = m;
        frac[p as usize] = c;
    }
    Ok((mean, frac))
}

/// Buffers of one worker's LMD rows.
#[derive(Default)]
struct Scratch {
    /// Per 2-ring vertex: whether its image may be within the cutoff of f(p).
    near: Vec<bool>,
    /// Those images, and their distances from f(p).
    targets: Vec<u32>,
    found: Vec<f64>,
    /// The distance of every image (infinite beyond the cutoff).
    db: Vec<f64>,
}

/// Everything the LMD of one vertex needs.
struct Job<'a> {
    balls_a: &'a HopBalls,
    rings_a: &'a RingDistances,
    b: &'a EdgeGraph<'a>,
    f: &'a [u32],
    scale_a: f64,
    scale_b: f64,
    table: Option<&'a LocalDistances>,
    unit: f64,
}

impl Job<'_> {
    /// (mean, consistent fraction) of each vertex of `rows`, in parallel.
    fn rows(&self, rows: impl IndexedParallelIterator<Item = u32>) -> Vec<(f32, f32)> {
        let n_b = self.b.adj.n_rows;
        rows.map_init(Scratch::default, |scratch, p| {
            Dijkstra::with_local(n_b, |djb| self.vertex(p as usize, djb, scratch))
        })
        .collect()
    }

    fn vertex(&self, p: usize, djb: &mut Dijkstra, s: &mut Scratch) -> (f32, f32) {
        let ring = &self.balls_a.ball(p, 2)[1..];
        if ring.is_empty() {
            return (0.0, 1.0);
        }
        let da = self.rings_a.of(p);
        let reach = lmd_reach(da, self.scale_a, self.unit);
        let q = self.f[p] as usize;
        let cutoff = reach * self.scale_b;
        // No path is shorter than the straight line between its ends: an image farther than
        // the cutoff in space is beyond it on the graph too (the margin dwarfs any rounding),
        // so only the others are looked up or searched for. A wrong match's images lie
        // scattered, and the search for them would otherwise cover the whole cutoff ball.
        let beyond = cutoff * (1.0 + 1e-9);
        s.near.clear();
        s.targets.clear();
        for &r in ring {
            let t = self.f[r as usize];
            let near = self.b.straight_line(q, t as usize) <= beyond;
            s.near.push(near);
            if near {
                s.targets.push(t);
            }
        }
        if !self
            .table
            .is_some_and(|t| t.lookup(q, &s.targets, cutoff, &mut s.found))
        {
            djb.run(self.b, q, &s.targets, cutoff, &mut s.found);
        }
        let mut found = s.found.iter();
        s.db.clear();
        s.db.extend(s.near.iter().map(|&near| match near {
            true => *found.next().expect("one distance per near target"),
            false => f64::INFINITY,
        }));
        let db = &s.db;
        let tol = tolerance(
            self.unit,
            self.rings_a.local_edge[p] / self.scale_a,
            self.b.local_edge_length(q) / self.scale_b,
        );
        let (mut sum, mut good) = (0.0, 0usize);
        for (&x, &y) in da.iter().zip(db.iter()) {
            let dist = (x / self.scale_a - (y / self.scale_b).min(reach)).abs();
            sum += dist;
            good += (dist < tol) as usize;
        }
        let sum = sum / self.unit;
        let m = ring.len() as f64;
        ((sum / m) as f32, (good as f64 / m) as f32)
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // tests index several parallel arrays
mod tests {
    use super::*;
    use crate::graph::adjacency_from_faces;

    fn grid(w: u32, h: u32, s: f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut v = Vec::new();
        for y in 0..h {
            for x in 0..w {
                v.push([
                    x as f64 * s,
                    y as f64 * s,
                    ((x * 7 + y * 3) % 5) as f64 * 0.1 * s,
                ]);
            }
        }
        let mut f = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let i = y * w + x;
                f.push([i, i + 1, i + w]);
                f.push([i + 1, i + w + 1, i + w]);
            }
        }
        (v, f)
    }

    fn graph<'a>(v: &'a [[f64; 3]], adj: &'a crate::csr::Csr<()>) -> EdgeGraph<'a> {
        EdgeGraph::new(v, adj.view())
    }

    #[test]
    fn identity_has_zero_distortion_and_scale_does_not_matter() {
        let (va, fa) = grid(12, 10, 1.0);
        let (vb, _) = grid(12, 10, 1.7);
        let adj = adjacency_from_faces(&fa, va.len()).unwrap();
        let balls = HopBalls::new(&adj.view(), 2).unwrap();
        let (ga, gb) = (graph(&va, &adj), graph(&vb, &adj));
        let id: Vec<u32> = (0..va.len() as u32).collect();
        let rings = RingDistances::new(&ga, &balls).unwrap();
        let (mean, frac) =
            local_map_distortion(&balls, &rings, &gb, &id, 1.0, 1.7, None, None).unwrap();
        assert!(mean.iter().all(|&m| m < 1e-6));
        assert!(frac.iter().all(|&x| x == 1.0));
        // Swapping two far-apart vertices distorts exactly the neighbourhoods that see them.
        let mut f = id.clone();
        f.swap(13, 100);
        let (mean, _) =
            local_map_distortion(&balls, &rings, &gb, &f, 1.0, 1.7, None, None).unwrap();
        assert!(mean[13] > 1.0 && mean[100] > 1.0);
        let far = 60;
        assert!(mean[far] < 1e-6);
        for p in 0..va.len() {
            let sees = balls.ball(p, 2).contains(&13) || balls.ball(p, 2).contains(&100);
            assert_eq!(mean[p] > 1e-6, sees, "vertex {p}");
        }
    }

    /// A unit grid A and the same grid scaled by `s` as B, B's heights bumped by
    /// `((i * mul) % modulo) * step`; the two share one adjacency.
    fn bumped_pair(
        w: u32,
        h: u32,
        s: f64,
        (mul, modulo, step): (usize, usize, f64),
    ) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, crate::csr::Csr<()>) {
        let (va, fa) = grid(w, h, 1.0);
        let (mut vb, _) = grid(w, h, s);
        for (i, v) in vb.iter_mut().enumerate() {
            v[2] += ((i * mul) % modulo) as f64 * step;
        }
        let adj = adjacency_from_faces(&fa, va.len()).unwrap();
        (va, vb, adj)
    }

    #[test]
    fn table_lookups_give_the_searched_distortion() {
        let (va, vb, adj) = bumped_pair(15, 13, 2.3, (37, 11, 0.07));
        let balls = HopBalls::new(&adj.view(), 2).unwrap();
        let (ga, gb) = (graph(&va, &adj), graph(&vb, &adj));
        let rings = RingDistances::new(&ga, &balls).unwrap();
        let n = va.len();
        // A map that is right in places, shifted by one vertex in others and scrambled elsewhere.
        let f: Vec<u32> = (0..n)
            .map(|i| match i % 5 {
                0 => ((i * 7919) % n) as u32,
                1 => ((i + 1) % n) as u32,
                _ => i as u32,
            })
            .collect();
        let want = local_map_distortion(&balls, &rings, &gb, &f, 1.0, 2.3, None, None).unwrap();
        let cutoff = lmd_table_cutoff(&rings, 1.0, 2.3);
        // Full rows, rows cut short (searches fall back), and a radius that covers too little.
        for (radius, cap) in [(cutoff, MAX_ROW), (cutoff, 12), (cutoff * 0.5, MAX_ROW)] {
            let table = LocalDistances::with_cap(&gb, radius, cap);
            let got = local_map_distortion(&balls, &rings, &gb, &f, 1.0, 2.3, Some(&table), None);
            assert_eq!(got.unwrap(), want, "radius {radius}, cap {cap}");
        }
        let other = LocalDistances::new(&ga, 1.0);
        let mut small = other.clone();
        small.complete.pop();
        assert!(
            local_map_distortion(&balls, &rings, &gb, &f, 1.0, 2.3, Some(&small), None).is_err()
        );

        // Updating from another map's result gives exactly the full computation.
        let table = LocalDistances::new(&gb, cutoff);
        let prev =
            local_map_distortion(&balls, &rings, &gb, &f, 1.0, 2.3, Some(&table), None).unwrap();
        let mut g = f.clone();
        for i in (0..n).step_by(9) {
            g[i] = ((i * 31 + 5) % n) as u32;
        }
        let full =
            local_map_distortion(&balls, &rings, &gb, &g, 1.0, 2.3, Some(&table), None).unwrap();
        assert_ne!(full, prev);
        let p = Some((f.as_slice(), prev.0.as_slice(), prev.1.as_slice()));
        let got = local_map_distortion(&balls, &rings, &gb, &g, 1.0, 2.3, Some(&table), p);
        assert_eq!(got.unwrap(), full);
        let short = Some((&f[1..], prev.0.as_slice(), prev.1.as_slice()));
        assert!(local_map_distortion(&balls, &rings, &gb, &g, 1.0, 2.3, None, short).is_err());
    }

    /// LMD as defined, one full search per vertex to every image of its 2-ring.
    fn plain_lmd(
        balls: &HopBalls,
        rings: &RingDistances,
        b: &EdgeGraph,
        f: &[u32],
        scale_a: f64,
        scale_b: f64,
    ) -> (Vec<f32>, Vec<f32>) {
        let unit = lmd_unit(rings, scale_a);
        let mut dj = Dijkstra::new(b.adj.n_rows);
        let mut db = Vec::new();
        (0..balls.n)
            .map(|p| {
                let ring = &balls.ball(p, 2)[1..];
                let da = rings.of(p);
                let reach = lmd_reach(da, scale_a, unit);
                let targets: Vec<u32> = ring.iter().map(|&r| f[r as usize]).collect();
                let q = f[p] as usize;
                dj.run(b, q, &targets, reach * scale_b, &mut db);
                let tol = tolerance(
                    unit,
                    rings.local_edge[p] / scale_a,
                    b.local_edge_length(q) / scale_b,
                );
                let (mut sum, mut good) = (0.0, 0usize);
                for (&x, &y) in da.iter().zip(db.iter()) {
                    let dist = (x / scale_a - (y / scale_b).min(reach)).abs();
                    sum += dist;
                    good += (dist < tol) as usize;
                }
                let m = ring.len() as f64;
                ((sum / unit / m) as f32, (good as f64 / m) as f32)
            })
            .unzip()
    }

    #[test]
    fn skipping_far_images_and_short_rows_changes_nothing() {
        // A scrambled map sends most 2-rings far beyond the cutoff (no search for those), and
        // rows of 8 entries answer only for the images they list.
        let (va, vb, adj) = bumped_pair(20, 16, 1.9, (53, 7, 0.11));
        let balls = HopBalls::new(&adj.view(), 2).unwrap();
        let (ga, gb) = (graph(&va, &adj), graph(&vb, &adj));
        let rings = RingDistances::new(&ga, &balls).unwrap();
        let n = va.len();
        let f: Vec<u32> = (0..n)
            .map(|i| match i % 4 {
                0 => ((i * 7919 + 13) % n) as u32,
                1 => ((i + 21) % n) as u32,
                _ => i as u32,
            })
            .collect();
        let want = plain_lmd(&balls, &rings, &gb, &f, 1.0, 1.9);
        let cutoff = lmd_table_cutoff(&rings, 1.0, 1.9);
        for table in [None, Some(LocalDistances::with_cap(&gb, cutoff, 8))] {
            let got = local_map_distortion(&balls, &rings, &gb, &f, 1.0, 1.9, table.as_ref(), None);
            assert_eq!(got.unwrap(), want, "table {}", table.is_some());
        }
    }

    #[test]
    fn tolerance_follows_the_local_edges() {
        assert_eq!(tolerance(1.0, 1.0, 1.0), TOLERANCE);
        assert!((tolerance(1.0, 0.25, 0.25) - 0.5 * TOLERANCE).abs() < 1e-12);
        assert!((tolerance(1.0, 0.5, 2.5) - 1.5f64.sqrt() * TOLERANCE).abs() < 1e-12);
        assert_eq!(tolerance(1.0, 9.0, 9.0), 2.0);
        assert_eq!(tolerance(0.7, 0.0, 0.3), 0.7 * TOLERANCE);
    }

    #[test]
    fn fine_regions_distrust_what_one_global_edge_would_pass() {
        // Two components: a fine grid (spacing 0.25) and a coarse one (spacing 1). The mean
        // edge lies between, so a vertex of the fine grid whose image is three columns off
        // (0.75) is distorted by less than one mean edge on average, yet it is no witness.
        let (mut v, mut f) = grid(12, 10, 0.25);
        let (vc, fc) = grid(12, 10, 1.0);
        let off = v.len() as u32;
        v.extend(vc.iter().map(|p| [p[0] + 100.0, p[1], p[2]]));
        f.extend(fc.iter().map(|t| [t[0] + off, t[1] + off, t[2] + off]));
        let adj = adjacency_from_faces(&f, v.len()).unwrap();
        let balls = HopBalls::new(&adj.view(), 2).unwrap();
        let g = graph(&v, &adj);
        let rings = RingDistances::new(&g, &balls).unwrap();
        let id: Vec<u32> = (0..v.len() as u32).collect();
        let (_, frac) =
            local_map_distortion(&balls, &rings, &g, &id, 1.0, 1.0, None, None).unwrap();
        assert!(frac.iter().all(|&x| x == 1.0));
        let p = 5 * 12 + 4;
        let mut moved = id.clone();
        moved[p] = p as u32 + 3;
        let (mean, frac) =
            local_map_distortion(&balls, &rings, &g, &moved, 1.0, 1.0, None, None).unwrap();
        assert!(mean[p] < 1.0, "mean distortion {} mean edges", mean[p]);
        // 8 of its 18 ring neighbours stay within its tolerance; 10 within one mean edge (more
        // within the global tolerance, TOLERANCE mean edges).
        assert!(frac[p] < 0.5, "consistent fraction {}", frac[p]);
    }
}
