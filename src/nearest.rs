//! Nearest neighbours among given candidates: for each query row, the candidate row of a base
//! set that is closest in Euclidean distance (the spectral pass's search among the vertices of
//! B near a guess, see `python/hope_rs/spectral.py`); and [`PointClusters`], the exact nearest
//! point of a set for queries far from it (the anchor placement of the global repair).
use crate::error::{invalid, Result};
use rayon::prelude::*;

/// Queries per rayon task.
const CHUNK: usize = 256;

/// For each query `i` (row `i` of `query`, `dim` values per row), the candidate `c` of
/// `cand[i * m .. (i + 1) * m]` whose row of `base` is nearest; ties go to the earlier candidate.
///
/// Reading the candidates' rows in place keeps the work at `n * m * dim` operations with no
/// temporary: the NumPy version gathered an `n x m x dim` array for each call (123 MB for 8000
/// queries, 32 candidates and a 120-dimensional embedding).
pub fn nearest_among(
    query: &[f32],
    base: &[f32],
    dim: usize,
    cand: &[u32],
    m: usize,
) -> Result<Vec<u32>> {
    if dim == 0 || m == 0 {
        return invalid("nearest_among needs at least one dimension and one candidate per query");
    }
    if !query.len().is_multiple_of(dim) || !base.len().is_multiple_of(dim) {
        return invalid(format!(
            "query and base must hold whole rows of {dim} values, got {} and {}",
            query.len(),
            base.len()
        ));
    }
    let (n, n_base) = (query.len() / dim, base.len() / dim);
    if cand.len() != n * m {
        return invalid(format!(
            "cand must hold {m} candidates for each of the {n} queries, got {}",
            cand.len()
        ));
    }
    if let Some(&c) = cand.par_iter().find_any(|&&c| c as usize >= n_base) {
        return invalid(format!(
            "candidate {c} is out of range for the {n_base} rows of base"
        ));
    }
    let mut out = vec![0u32; n];
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(chunk, out)| {
            for (j, o) in out.iter_mut().enumerate() {
                let i = chunk * CHUNK + j;
                let q = &query[i * dim..(i + 1) * dim];
                let mut best = (f32::INFINITY, cand[i * m]);
                for &c in &cand[i * m..(i + 1) * m] {
                    let row = &base[c as usize * dim..(c as usize + 1) * dim];
                    let d = squared_distance(q, row);
                    if d < best.0 {
                        best = (d, c);
                    }
                }
                *o = best.1;
            }
        });
    Ok(out)
}

/// Sum of squared differences, in eight independent lanes so that the compiler vectorises it
/// (a single running sum is a serial dependency chain).
#[inline]
fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ta, tb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            let d = x[l] - y[l];
            acc[l] += d * d;
        }
    }
    let tail: f32 = ta.iter().zip(tb).map(|(x, y)| (x - y) * (x - y)).sum();
    acc.iter().sum::<f32>() + tail
}

/// Points per cluster of [`PointClusters`] at most.
const CLUSTER: usize = 16;
/// Queries searched together (they share one list of candidate clusters).
const QUERY_GROUP: usize = 32;

/// Exact nearest-point search for queries that lie far from a point set sampled densely along a
/// surface: the global repair's anchor coordinates, where a query's nearest point is often many
/// sample spacings away and many points lie within a few percent of that distance. A k-d tree
/// then visits most of its cells near that sphere, and the cells it visits grow with the
/// sampling density; here the points are cut into small clusters bounded by balls, each group
/// of nearby queries first keeps the clusters that can hold any of its nearest points, and
/// each query then scans those in order of their lower bound.
///
/// Each answer comes with a flag saying whether another point lies within rounding distance of
/// the nearest one (see [`PointClusters::nearest`]), so that a caller bound to another search's
/// choice among near-equal points can ask that one for them.
#[derive(Debug, Clone)]
pub struct PointClusters {
    dim: usize,
    /// The points, rows grouped by cluster.
    rows: Vec<f64>,
    /// The input index of each row of `rows`.
    ids: Vec<u32>,
    /// Cluster c holds rows `start[c]..start[c + 1]`.
    start: Vec<usize>,
    centre: Vec<f64>,
    /// Every point of cluster c is at most this far from its centre.
    radius: Vec<f64>,
    /// Largest absolute coordinate.
    scale: f64,
    /// Every coordinate is finite (else every query is flagged).
    finite: bool,
}

/// Squared Euclidean distance in four independent lanes (vectorised by the compiler).
#[inline]
fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ta, tb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..4 {
            let d = x[l] - y[l];
            acc[l] += d * d;
        }
    }
    let tail: f64 = ta.iter().zip(tb).map(|(x, y)| (x - y) * (x - y)).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Orders `idx` (rows of `rows`, `dim` wide) into groups of at most `leaf` rows by splitting
/// at the median of the widest coordinate; returns the group boundaries (start of each group,
/// then `idx.len()`).
fn spatial_groups(rows: &[f64], dim: usize, idx: &mut [u32], leaf: usize) -> Vec<usize> {
    fn split(rows: &[f64], dim: usize, idx: &mut [u32], leaf: usize, off: usize) -> Vec<usize> {
        if idx.len() <= leaf {
            return vec![off];
        }
        let mut widest = (0, f64::NEG_INFINITY);
        for t in 0..dim {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for &i in idx.iter() {
                let x = rows[i as usize * dim + t];
                lo = lo.min(x);
                hi = hi.max(x);
            }
            if hi - lo > widest.1 {
                widest = (t, hi - lo);
            }
        }
        let t = widest.0;
        let mid = idx.len() / 2;
        idx.select_nth_unstable_by(mid, |&a, &b| {
            rows[a as usize * dim + t].total_cmp(&rows[b as usize * dim + t])
        });
        let (lo, hi) = idx.split_at_mut(mid);
        let (mut a, b) = if lo.len() > 4096 {
            rayon::join(
                || split(rows, dim, lo, leaf, off),
                || split(rows, dim, hi, leaf, off + mid),
            )
        } else {
            (
                split(rows, dim, lo, leaf, off),
                split(rows, dim, hi, leaf, off + mid),
            )
        };
        a.extend(b);
        a
    }
    let mut starts = split(rows, dim, idx, leaf.max(1), 0);
    starts.push(idx.len());
    starts
}

/// Centre (mean) and radius (largest distance to it, rounded up) of the rows `idx`.
fn ball(rows: &[f64], dim: usize, idx: &[u32]) -> (Vec<f64>, f64) {
    let mut c = vec![0.0; dim];
    for &i in idx {
        for (ct, &x) in c
            .iter_mut()
            .zip(&rows[i as usize * dim..(i as usize + 1) * dim])
        {
            *ct += x;
        }
    }
    for ct in c.iter_mut() {
        *ct /= idx.len().max(1) as f64;
    }
    let r2 = idx
        .iter()
        .map(|&i| sq_dist(&c, &rows[i as usize * dim..(i as usize + 1) * dim]))
        .fold(0.0, f64::max);
    // Rounded up well beyond the error of the sums, so that it bounds the exact distances.
    (c, r2.sqrt() * (1.0 + 1e-9) + 1e-12)
}

impl PointClusters {
    /// The clusters of `points` (`dim` values per row).
    pub fn new(points: &[f64], dim: usize) -> Result<Self> {
        if dim == 0 {
            return invalid("points must have at least one column, got 0");
        }
        if !points.len().is_multiple_of(dim) {
            return invalid(format!(
                "points must hold whole rows of {dim} values, got {} values",
                points.len()
            ));
        }
        let n = points.len() / dim;
        if n > u32::MAX as usize {
            return invalid("too many points");
        }
        let finite = points.iter().all(|x| x.is_finite());
        let mut order: Vec<u32> = (0..n as u32).collect();
        let start = if finite {
            spatial_groups(points, dim, &mut order, CLUSTER)
        } else {
            vec![0, n]
        };
        let balls: Vec<(Vec<f64>, f64)> = start
            .par_windows(2)
            .map(|w| ball(points, dim, &order[w[0]..w[1]]))
            .collect();
        let mut rows = Vec::with_capacity(points.len());
        for &i in &order {
            rows.extend_from_slice(&points[i as usize * dim..(i as usize + 1) * dim]);
        }
        let scale = points.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        Ok(PointClusters {
            dim,
            rows,
            ids: order,
            start,
            centre: balls.iter().flat_map(|b| b.0.iter().copied()).collect(),
            radius: balls.iter().map(|b| b.1).collect(),
            scale,
            finite,
        })
    }

    /// Coordinates per point.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// For each query row (`dim` values per row), the index of its nearest point and whether
    /// that answer is not certain to be the one every exact search gives: another point's
    /// squared distance is within about 1e-11 (times the squared coordinate scale) of the
    /// nearest one's, a gap below which rounding may order them either way; or a coordinate is
    /// not finite. Flagged answers are still a nearest point up to that tolerance.
    pub fn nearest(&self, queries: &[f64]) -> Result<(Vec<u32>, Vec<bool>)> {
        let dim = self.dim;
        if !queries.len().is_multiple_of(dim) {
            return invalid(format!(
                "queries must hold whole rows of {dim} values, got {} values",
                queries.len()
            ));
        }
        let m = queries.len() / dim;
        if self.is_empty() || !self.finite || !queries.iter().all(|x| x.is_finite()) {
            let ids = vec![0u32; m];
            return Ok((ids, vec![true; m]));
        }
        // Squared distances within this of the nearest count as near-equal to it: far above
        // the rounding error of any sum of `dim` squares of such coordinates.
        let scale = queries.iter().fold(self.scale, |m, x| m.max(x.abs()));
        let tie = 1e-11 * (1.0 + dim as f64 * scale * scale);
        let mut order: Vec<u32> = (0..m as u32).collect();
        let groups = spatial_groups(queries, dim, &mut order, QUERY_GROUP);
        let answers: Vec<Vec<(u32, u32, bool)>> = groups
            .par_windows(2)
            .map_init(
                || (Vec::new(), Vec::new()),
                |(cand, lb), w| self.search_group(queries, &order[w[0]..w[1]], tie, cand, lb),
            )
            .collect();
        let (mut ids, mut tie) = (vec![0u32; m], vec![false; m]);
        for (q, id, t) in answers.into_iter().flatten() {
            ids[q as usize] = id;
            tie[q as usize] = t;
        }
        Ok((ids, tie))
    }

    /// The answers (query, nearest point, near tie) of the queries `group`.
    fn search_group(
        &self,
        queries: &[f64],
        group: &[u32],
        tie_gap: f64,
        cand: &mut Vec<u32>,
        lb: &mut Vec<(f64, u32)>,
    ) -> Vec<(u32, u32, bool)> {
        let dim = self.dim;
        let row = |q: u32| &queries[q as usize * dim..(q as usize + 1) * dim];
        let (centre, sigma) = ball(queries, dim, group);
        // Every point of cluster c is within [dc - sigma - r, dc + sigma + r] of every query of
        // the group: the clusters whose lower end is beyond the least upper end (plus the tie
        // gap) hold no nearest point of any of them.
        let n_c = self.radius.len();
        let dc: Vec<f64> = (0..n_c)
            .map(|c| sq_dist(&centre, &self.centre[c * dim..(c + 1) * dim]).sqrt())
            .collect();
        let upper = (0..n_c)
            .map(|c| dc[c] + sigma + self.radius[c])
            .fold(f64::INFINITY, f64::min);
        let reach = (upper * upper + tie_gap).sqrt() * (1.0 + 1e-9) + 1e-12;
        cand.clear();
        cand.extend(
            (0..n_c as u32).filter(|&c| dc[c as usize] - sigma - self.radius[c as usize] <= reach),
        );
        group
            .iter()
            .map(|&q| {
                let x = row(q);
                lb.clear();
                lb.extend(cand.iter().map(|&c| {
                    let c = c as usize;
                    let d = sq_dist(x, &self.centre[c * dim..(c + 1) * dim]).sqrt();
                    (d - self.radius[c], c as u32)
                }));
                lb.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
                let (mut best, mut best_row, mut tie) = (f64::INFINITY, 0usize, false);
                for &(low, c) in lb.iter() {
                    // No point of this cluster or a later one can come within the tie gap.
                    if low > 0.0 && low * low > (best + tie_gap) * (1.0 + 1e-9) {
                        break;
                    }
                    for r in self.start[c as usize]..self.start[c as usize + 1] {
                        let d = sq_dist(x, &self.rows[r * dim..(r + 1) * dim]);
                        if d < best - tie_gap {
                            tie = false;
                        } else if d <= best + tie_gap {
                            tie = true;
                        }
                        if d < best {
                            best = d;
                            best_row = r;
                        }
                    }
                }
                (q, self.ids[best_row], tie)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_the_nearest_candidate_not_the_nearest_row() {
        // Rows of base on a line; query 0 sits on row 3, but only rows 0, 1 and 5 are its
        // candidates, so it gets 1. Query 1 ties between 2 and 4: the earlier candidate wins.
        let dim = 9; // one full chunk of eight lanes plus a tail
        let base: Vec<f32> = (0..6).flat_map(|r| vec![r as f32; dim]).collect();
        let query: Vec<f32> = [3.0f32, 3.0].iter().flat_map(|&x| vec![x; dim]).collect();
        let cand = [0u32, 1, 5, 4, 2, 0];
        assert_eq!(nearest_among(&query, &base, dim, &cand, 3).unwrap(), [1, 4]);
    }

    #[test]
    fn matches_a_brute_force_search() {
        let (n, n_base, dim, m) = (1000, 300, 37, 16);
        let mut x = 0x9e37_79b9u32;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        let query: Vec<f32> = (0..n * dim)
            .map(|_| (next() % 1000) as f32 / 100.0)
            .collect();
        let base: Vec<f32> = (0..n_base * dim)
            .map(|_| (next() % 1000) as f32 / 100.0)
            .collect();
        let cand: Vec<u32> = (0..n * m).map(|_| next() % n_base as u32).collect();
        let got = nearest_among(&query, &base, dim, &cand, m).unwrap();
        for i in 0..n {
            let d = |c: u32| -> f64 {
                (0..dim)
                    .map(|t| {
                        (query[i * dim + t] as f64 - base[c as usize * dim + t] as f64).powi(2)
                    })
                    .sum()
            };
            let best = cand[i * m..(i + 1) * m]
                .iter()
                .map(|&c| d(c))
                .fold(f64::INFINITY, f64::min);
            assert!(d(got[i]) <= best * (1.0 + 1e-5) + 1e-9, "query {i}");
            assert!(cand[i * m..(i + 1) * m].contains(&got[i]));
        }
    }

    #[test]
    fn bad_shapes_and_candidates_are_errors() {
        let base = [0f32; 6];
        assert!(nearest_among(&[0.0; 3], &base, 3, &[2], 1).is_err()); // out of range
        assert!(nearest_among(&[0.0; 3], &base, 3, &[0, 1], 1).is_err()); // wrong count
        assert!(nearest_among(&[0.0; 4], &base, 3, &[0], 1).is_err()); // partial row
        assert!(nearest_among(&[0.0; 3], &base, 0, &[0], 1).is_err());
        assert!(nearest_among(&[0.0; 3], &base, 3, &[], 0).is_err());
        assert_eq!(
            nearest_among(&[], &base, 3, &[], 1).unwrap(),
            Vec::<u32>::new()
        );
    }
    /// Points on a wavy surface in `dim` dimensions and queries off it, some far.
    fn surface(n: usize, dim: usize, seed: u32) -> Vec<f64> {
        let mut x = seed;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x % 100_000) as f64 / 100_000.0
        };
        (0..n)
            .flat_map(|_| {
                let (u, v) = (next() * 4.0, next() * 3.0);
                (0..dim)
                    .map(|t| (u * (t + 1) as f64 * 0.7).sin() + v * (t % 3) as f64 * 0.3)
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    fn brute(points: &[f64], x: &[f64], dim: usize) -> (usize, f64, f64) {
        let mut d: Vec<(f64, usize)> = points
            .chunks_exact(dim)
            .enumerate()
            .map(|(i, p)| (sq_dist(x, p), i))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        (d[0].1, d[0].0, d.get(1).map_or(f64::INFINITY, |e| e.0))
    }

    #[test]
    fn clusters_find_the_exact_nearest_point() {
        for (dim, n, m) in [(12, 3000, 500), (3, 2000, 300), (5, 40, 50)] {
            let points = surface(n, dim, 7 + dim as u32);
            let mut queries = surface(m, dim, 99);
            // Push queries off the surface by up to a few units, in every direction.
            for (i, q) in queries.iter_mut().enumerate() {
                *q += ((i * 7919) % 13) as f64 * 0.2 - 1.2;
            }
            let index = PointClusters::new(&points, dim).unwrap();
            assert_eq!(index.len(), n);
            let (ids, tie) = index.nearest(&queries).unwrap();
            for (i, x) in queries.chunks_exact(dim).enumerate() {
                let (want, d1, d2) = brute(&points, x, dim);
                let gap = d2 - d1;
                if !tie[i] {
                    assert_eq!(ids[i] as usize, want, "dim {dim} query {i}");
                } else {
                    assert!(gap < 1e-6, "flagged without a near tie: gap {gap}");
                }
                let got = sq_dist(x, &points[ids[i] as usize * dim..][..dim]);
                assert!(got <= d1 + 1e-9);
            }
        }
    }

    #[test]
    fn equal_points_are_flagged_and_bad_input_refused() {
        // Two copies of the same point: whichever is nearer is up to rounding.
        let points = [0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 5.0, 5.0];
        let index = PointClusters::new(&points, 2).unwrap();
        let (ids, tie) = index.nearest(&[0.9, 1.2, 0.1, -0.3, 4.0, 4.5]).unwrap();
        assert_eq!(ids[1..], [0, 3]);
        assert!(ids[0] == 1 || ids[0] == 2);
        assert_eq!(tie, [true, false, false]);
        // A query of infinite coordinates has no trustworthy answer.
        let (_, tie) = index.nearest(&[f64::INFINITY, 0.0]).unwrap();
        assert_eq!(tie, [true]);
        assert!(PointClusters::new(&points, 3).is_err());
        let zero = PointClusters::new(&points, 0).err().unwrap().to_string();
        assert_eq!(zero, "points must have at least one column, got 0");
        assert!(index.nearest(&[1.0, 2.0, 3.0]).is_err());
        let (ids, tie) = PointClusters::new(&[], 2)
            .unwrap()
            .nearest(&[1.0, 1.0])
            .unwrap();
        assert_eq!((ids, tie), (vec![0], vec![true]));
        let (ids, _) = index.nearest(&[]).unwrap();
        assert!(ids.is_empty());
    }
}
