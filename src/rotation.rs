//! Closest rotations: for each 3 × 3 matrix `M`, the rotation `R` that maximises `tr(R M)`
//! (the local step of as-rigid-as-possible deformation, see
//! `python/hope_rs/shared_faces.py`).
//!
//! Horn's quaternion method (J. Opt. Soc. Am. A, 1987): the rotation is the unit quaternion
//! that is the top eigenvector of a symmetric 4 × 4 matrix built from `M`, so it is always a
//! proper rotation and needs no sign fix. Faster than NumPy's batched SVD.
use crate::error::{invalid, Result};
use crate::jacobi::sym_eigen;
use rayon::prelude::*;

/// Matrices per rayon task.
const CHUNK: usize = 1024;

/// The rotation maximising `tr(R M)` for each row-major 3 × 3 matrix `M` of `m` (9 values
/// each), row-major. A matrix of zeros gives the identity.
pub fn closest_rotations(m: &[f64]) -> Result<Vec<f64>> {
    if !m.len().is_multiple_of(9) {
        return invalid(format!(
            "closest_rotations needs whole 3 x 3 matrices (9 values each), got {} values",
            m.len()
        ));
    }
    if m.iter().any(|x| !x.is_finite()) {
        return invalid("closest_rotations needs finite matrices");
    }
    let mut out = vec![0.0; m.len()];
    out.par_chunks_mut(9 * CHUNK)
        .zip(m.par_chunks(9 * CHUNK))
        .for_each(|(o, a)| {
            for (r, mm) in o.chunks_exact_mut(9).zip(a.chunks_exact(9)) {
                r.copy_from_slice(&closest_rotation(mm.try_into().unwrap()));
            }
        });
    Ok(out)
}

/// The local step of ARAP with uniform weights: for each vertex v, the rotation maximising
/// `tr(R M_v)` (see [`closest_rotations`]) where `M_v = sum_e ex[e] ey[e]ᵀ` over the directed
/// edges `edges[indptr[v]..indptr[v + 1]]` of v, summed in that order. `ex` and `ey` hold one
/// 3-vector per directed edge (the edge at rest and deformed). The sums run as a sparse product
/// of the edges' outer products with a 0/1 matrix would (each product rounded once, added in
/// order to 0), so the rotations are the same bits as those of that product's matrices.
pub fn edge_rotations(indptr: &[usize], edges: &[u32], ex: &[f64], ey: &[f64]) -> Result<Vec<f64>> {
    let n_edges = ex.len() / 3;
    if !ex.len().is_multiple_of(3) || ey.len() != ex.len() {
        return invalid("edge_rotations needs ex and ey of the same shape (n_edges, 3)");
    }
    if indptr.is_empty()
        || indptr[0] != 0
        || indptr.last() != Some(&edges.len())
        || indptr.windows(2).any(|w| w[0] > w[1])
    {
        return invalid("edge_rotations needs a row pointer over the edge list");
    }
    if edges.iter().any(|&e| e as usize >= n_edges) {
        return invalid("edge_rotations: an edge index is out of range");
    }
    if ex.iter().chain(ey).any(|x| !x.is_finite()) {
        return invalid("edge_rotations needs finite edge vectors");
    }
    let n = indptr.len() - 1;
    let mut out = vec![0.0; 9 * n];
    out.par_chunks_mut(9 * CHUNK)
        .enumerate()
        .for_each(|(c, o)| {
            for (k, r) in o.chunks_exact_mut(9).enumerate() {
                let v = c * CHUNK + k;
                let mut m = [0.0f64; 9];
                for &e in &edges[indptr[v]..indptr[v + 1]] {
                    let e = e as usize;
                    let (a, b) = (&ex[3 * e..3 * e + 3], &ey[3 * e..3 * e + 3]);
                    for i in 0..3 {
                        for j in 0..3 {
                            m[3 * i + j] += a[i] * b[j];
                        }
                    }
                }
                r.copy_from_slice(&closest_rotation(&m));
            }
        });
    Ok(out)
}

/// Horn's method for one matrix `m` (row-major): with `m = sum a bᵀ`, the result rotates the
/// `a`s onto the `b`s as well as a rotation can.
fn closest_rotation(m: &[f64; 9]) -> [f64; 9] {
    let s = |i: usize, j: usize| m[3 * i + j];
    let (sxx, sxy, sxz) = (s(0, 0), s(0, 1), s(0, 2));
    let (syx, syy, syz) = (s(1, 0), s(1, 1), s(1, 2));
    let (szx, szy, szz) = (s(2, 0), s(2, 1), s(2, 2));
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let q = top_eigenvector(n);
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    [
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - z * w),
        2.0 * (x * z + y * w),
        2.0 * (x * y + z * w),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - x * w),
        2.0 * (x * z - y * w),
        2.0 * (y * z + x * w),
        1.0 - 2.0 * (x * x + y * y),
    ]
}

/// The unit eigenvector of the largest eigenvalue of a symmetric 4 × 4 matrix (ties go to
/// the lower index; the zero matrix gives (1, 0, 0, 0)).
fn top_eigenvector(a: [[f64; 4]; 4]) -> [f64; 4] {
    let (vals, v) = sym_eigen(a);
    let mut best = 0;
    for i in 1..4 {
        if vals[i] > vals[best] {
            best = i;
        }
    }
    let q = [v[0][best], v[1][best], v[2][best], v[3][best]];
    let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    q.map(|x| x / norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn matmul(a: &[f64; 9], b: &[f64; 9]) -> [f64; 9] {
        let mut c = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                c[3 * i + j] = (0..3).map(|k| a[3 * i + k] * b[3 * k + j]).sum();
            }
        }
        c
    }

    fn transpose(a: &[f64; 9]) -> [f64; 9] {
        let mut t = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                t[3 * j + i] = a[3 * i + j];
            }
        }
        t
    }

    fn det(a: &[f64; 9]) -> f64 {
        a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6])
            + a[2] * (a[3] * a[7] - a[4] * a[6])
    }

    fn trace(a: &[f64; 9]) -> f64 {
        a[0] + a[4] + a[8]
    }

    /// A rotation about a unit axis by an angle (Rodrigues).
    fn rotation(axis: [f64; 3], angle: f64) -> [f64; 9] {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let [x, y, z] = axis.map(|c| c / n);
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        [
            t * x * x + c,
            t * x * y - s * z,
            t * x * z + s * y,
            t * x * y + s * z,
            t * y * y + c,
            t * y * z - s * x,
            t * x * z - s * y,
            t * y * z + s * x,
            t * z * z + c,
        ]
    }

    /// Pseudo-random numbers in [-1, 1) (a fixed LCG, so the test needs no crate).
    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    #[test]
    fn recovers_the_rotation_of_rotated_points() {
        let mut seed = 7;
        for trial in 0..200 {
            let r = rotation(
                [lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)],
                3.0 * lcg(&mut seed),
            );
            // m = sum a bᵀ with b = R a: the best rotation is R itself.
            let mut m = [0.0; 9];
            for _ in 0..5 {
                let a = [lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)];
                let b: Vec<f64> = (0..3)
                    .map(|i| (0..3).map(|k| r[3 * i + k] * a[k]).sum())
                    .collect();
                for i in 0..3 {
                    for j in 0..3 {
                        m[3 * i + j] += a[i] * b[j];
                    }
                }
            }
            let got = closest_rotations(&m).unwrap();
            for (g, want) in got.iter().zip(r.iter()) {
                assert!((g - want).abs() < 1e-9, "trial {trial}: {got:?} != {r:?}");
            }
        }
    }

    #[test]
    fn result_is_a_rotation_that_beats_random_rotations() {
        let mut seed = 11;
        for _ in 0..200 {
            let m: [f64; 9] = std::array::from_fn(|_| lcg(&mut seed));
            let r: [f64; 9] = closest_rotations(&m).unwrap().try_into().unwrap();
            let rrt = matmul(&r, &transpose(&r));
            for i in 0..3 {
                for j in 0..3 {
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((rrt[3 * i + j] - want).abs() < 1e-9);
                }
            }
            assert!(
                (det(&r) - 1.0).abs() < 1e-9,
                "a reflection: det {}",
                det(&r)
            );
            let best = trace(&matmul(&r, &m));
            for _ in 0..50 {
                let other = rotation(
                    [lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)],
                    3.0 * lcg(&mut seed),
                );
                assert!(trace(&matmul(&other, &m)) <= best + 1e-9);
            }
        }
    }

    #[test]
    fn zero_matrix_gives_identity_and_bad_input_is_an_error() {
        let r = closest_rotations(&[0.0; 9]).unwrap();
        assert_eq!(r, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        assert!(closest_rotations(&[0.0; 8]).is_err());
        let mut nan = [0.0; 9];
        nan[4] = f64::NAN;
        assert!(closest_rotations(&nan).is_err());
        assert!(closest_rotations(&[]).unwrap().is_empty());
    }

    #[test]
    fn edge_rotations_sum_each_vertexs_outer_products_in_order() {
        // Two vertices: vertex 0 owns edges 2 and 0 (in that order), vertex 1 edge 1.
        let ex = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let ey = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let got = edge_rotations(&[0, 2, 3], &[2, 0, 1], &ex, &ey).unwrap();
        let mut m0 = [0.0; 9];
        for e in [2usize, 0] {
            for i in 0..3 {
                for j in 0..3 {
                    m0[3 * i + j] += ex[3 * e + i] * ey[3 * e + j];
                }
            }
        }
        let m1 = [0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let want = closest_rotations(&[m0, m1].concat()).unwrap();
        assert_eq!(got, want);
        assert!(edge_rotations(&[0, 2, 3], &[2, 0, 3], &ex, &ey).is_err());
        assert!(edge_rotations(&[0, 2], &[2, 0, 1], &ex, &ey).is_err());
        assert!(edge_rotations(&[0, 2, 3], &[2, 0, 1], &ex, &ey[..6]).is_err());
    }
}
