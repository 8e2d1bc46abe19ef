//! Nearest neighbours among given candidates: for each query row, the candidate row of a base
//! set that is closest in Euclidean distance (the spectral pass's search among the vertices of
//! B near a guess, see `python/hope_rs/spectral.py`).
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
}
