//! Eigen-decomposition of small symmetric matrices by cyclic Jacobi rotations (SHOT's local
//! reference frame, 3 × 3; Horn's closest rotation, 4 × 4).

/// Sweeps at most; a 3 × 3 or 4 × 4 matrix converges in well under ten.
const SWEEPS: usize = 64;

/// The eigenvalues of the symmetric `N × N` matrix `a` and its eigenvectors as the columns of
/// the second matrix (in no particular order).
pub fn sym_eigen<const N: usize>(mut a: [[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..SWEEPS {
        let off: f64 = a
            .iter()
            .enumerate()
            .flat_map(|(p, row)| row[p + 1..].iter())
            .map(|x| x.abs())
            .sum();
        let diag: f64 = (0..N).map(|i| a[i][i].abs()).sum();
        if off == 0.0 || off <= 1e-18 * diag || !off.is_finite() {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                rotate(&mut a, &mut v, p, q);
            }
        }
    }
    (std::array::from_fn(|i| a[i][i]), v)
}

/// One Jacobi rotation zeroing `a[p][q]`, applied to `a` on both sides and to `v` on the right.
fn rotate<const N: usize>(a: &mut [[f64; N]; N], v: &mut [[f64; N]; N], p: usize, q: usize) {
    let apq = a[p][q];
    if apq == 0.0 {
        return;
    }
    let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
    let t = if theta.abs() > 1e150 {
        0.5 / theta
    } else {
        theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
    };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    for row in a.iter_mut() {
        let (akp, akq) = (row[p], row[q]);
        row[p] = c * akp - s * akq;
        row[q] = s * akp + c * akq;
    }
    let (row_p, row_q) = (a[p], a[q]);
    for k in 0..N {
        a[p][k] = c * row_p[k] - s * row_q[k];
        a[q][k] = s * row_p[k] + c * row_q[k];
    }
    a[p][q] = 0.0;
    a[q][p] = 0.0;
    for row in v.iter_mut() {
        let (vkp, vkq) = (row[p], row[q]);
        row[p] = c * vkp - s * vkq;
        row[q] = s * vkp + c * vkq;
    }
}
