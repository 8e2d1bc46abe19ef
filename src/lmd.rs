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
        })
    }

    fn of(&self, p: usize) -> &[f64] {
        &self.dist[self.offsets[p]..self.offsets[p + 1]]
    }
}

/// Per-vertex distortion of the map `f` (A → B) over the 2-ring of each vertex of A.
///
/// Distances are divided by each shape's `scale` (sqrt of its area) so the measure does not depend
/// on the shapes' sizes, and the result is in units of A's mean edge length. Returns, per vertex,
/// the mean distortion over its 2-ring and the fraction of its 2-ring whose distortion is below
/// one mean edge length (a robust score when many neighbours are mismatched).
pub fn local_map_distortion(
    balls_a: &HopBalls,
    rings_a: &RingDistances,
    b: &EdgeGraph,
    f: &[u32],
    scale_a: f64,
    scale_b: f64,
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
    let edge = rings_a.mean_edge / scale_a;
    let unit = if edge > 0.0 { edge } else { 1.0 };
    let results: Vec<(f32, f32)> = (0..n_a)
        .into_par_iter()
        .map_init(
            || (Dijkstra::new(n_b), Vec::new(), Vec::new()),
            |(djb, db, ftargets), p| {
                let ring = &balls_a.ball(p, 2)[1..];
                if ring.is_empty() {
                    return (0.0, 1.0);
                }
                let da = rings_a.of(p);
                let reach = da.iter().copied().fold(0.0, f64::max) / scale_a + 2.0 * unit;
                ftargets.clear();
                ftargets.extend(ring.iter().map(|&r| f[r as usize]));
                djb.run(b, f[p] as usize, ftargets, reach * scale_b, db);
                let (mut sum, mut good) = (0.0, 0usize);
                for (&x, &y) in da.iter().zip(db.iter()) {
                    let dist = (x / scale_a - (y / scale_b).min(reach)).abs() / unit;
                    sum += dist;
                    good += (dist < 1.0) as usize;
                }
                let m = ring.len() as f64;
                ((sum / m) as f32, (good as f64 / m) as f32)
            },
        )
        .collect();
    Ok(results.into_iter().unzip())
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

    #[test]
    fn identity_has_zero_distortion_and_scale_does_not_matter() {
        let (va, fa) = grid(12, 10, 1.0);
        let (vb, _) = grid(12, 10, 1.7);
        let adj = adjacency_from_faces(&fa, va.len()).unwrap();
        let balls = HopBalls::new(&adj.view(), 2).unwrap();
        let ga = EdgeGraph {
            vertices: &va,
            adj: adj.view(),
        };
        let gb = EdgeGraph {
            vertices: &vb,
            adj: adj.view(),
        };
        let id: Vec<u32> = (0..va.len() as u32).collect();
        let rings = RingDistances::new(&ga, &balls).unwrap();
        let (mean, frac) = local_map_distortion(&balls, &rings, &gb, &id, 1.0, 1.7).unwrap();
        assert!(mean.iter().all(|&m| m < 1e-6));
        assert!(frac.iter().all(|&x| x == 1.0));
        // Swapping two far-apart vertices distorts exactly the neighbourhoods that see them.
        let mut f = id.clone();
        f.swap(13, 100);
        let (mean, _) = local_map_distortion(&balls, &rings, &gb, &f, 1.0, 1.7).unwrap();
        assert!(mean[13] > 1.0 && mean[100] > 1.0);
        let far = 60;
        assert!(mean[far] < 1e-6);
        for p in 0..va.len() {
            let sees = balls.ball(p, 2).contains(&13) || balls.ball(p, 2).contains(&100);
            assert_eq!(mean[p] > 1e-6, sees, "vertex {p}");
        }
    }
}
