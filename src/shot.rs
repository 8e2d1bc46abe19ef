//! SHOT local shape descriptors (Signature of Histograms of OrienTations; Tombari, Salti and
//! Di Stefano, ECCV 2010) for every vertex of a triangle mesh, computed in parallel with rayon.
//!
//! For each vertex `p`, the neighbours are the mesh vertices within `radius` (Euclidean ball).
//! * Local reference frame (as in the paper / PCL's `SHOTLocalReferenceFrameEstimation`): the
//!   weighted covariance `M = 1/sum(w) * sum w_i (p_i - p)(p_i - p)^T`, `w_i = radius - |p_i - p|`,
//!   is diagonalised; `x` is the eigenvector of the largest eigenvalue, `z` that of the smallest.
//!   The sign of `x` is chosen so that most neighbours have a positive projection on it (ties:
//!   the sign of the summed projections). The sign of `z` is chosen so that it agrees with the
//!   area-weighted mesh normal of `p` (more stable on meshes than the paper's majority vote, which
//!   is only used when the vertex has no normal). `y = z x x`: the frame is right-handed, so a
//!   mirrored shape gives different (azimuthally mirrored) descriptors, which lets a matcher tell
//!   left from right.
//! * Histogram: 32 spatial volumes (8 azimuth sectors x 2 elevations x 2 radial shells, shell
//!   boundary at `radius / 2`) times 11 bins of `cos(angle(n_i, z))` (bin centres at
//!   `cos = -1, -0.8, ..., 1`), `n_i` the neighbour's mesh normal. Every neighbour votes with total
//!   weight 1 spread by quadrilinear interpolation (cosine, azimuth — circular —, elevation,
//!   radius) over the 16 surrounding bins, i.e. the product form of the paper's interpolation
//!   (PCL adds the four one-dimensional weights instead). Rows are L2-normalised.
//!
//! Layout of a row: `index = ((azimuth * 2 + elevation) * 2 + shell) * 11 + cos_bin`, where
//! azimuth sector `s` is centred at `(s + 0.5) * 45` degrees from `x` towards `y`, elevation 0 is
//! the upper half (`z > 0`) and shell 0 the inner one.
//!
//! Vertices not referenced by any non-degenerate face have no normal; they are left out of every
//! neighbourhood (they are not on the surface), but still get a descriptor of their own.
//! Coincident neighbours (distance 0) carry no direction and are ignored. A vertex with fewer
//! than 5 usable neighbours gets an all-zero row.
use crate::error::{invalid, Result};
use crate::jacobi::sym_eigen;
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// Length of one SHOT descriptor: 32 spatial volumes x 11 cosine bins.
pub const SHOT_DIM: usize = 352;

const COS_BINS: usize = 11;
const AZIMUTH_SECTORS: usize = 8;
/// Fewer usable neighbours than this gives an all-zero descriptor (PCL uses the same bound for
/// its local reference frame).
const MIN_NEIGHBOURS: usize = 5;

type V3 = [f64; 3];

#[inline]
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn neg(a: V3) -> V3 {
    [-a[0], -a[1], -a[2]]
}

/// Centre and exact power-of-two scale that bring the (finite) vertices and `extra` (a length,
/// e.g. the radius) to magnitudes around 1, so that no squared distance or cross product can
/// overflow or underflow whatever the units. Power-of-two scaling is exact, and every quantity
/// computed here is invariant to translation and uniform scale, so this changes nothing but
/// rounding.
fn normalisation(vertices: &[V3], extra: f64) -> (V3, f64) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in vertices {
        for k in 0..3 {
            if v[k].is_finite() {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
    }
    let mut centre = [0.0; 3];
    let mut half_extent: f64 = 0.0;
    for k in 0..3 {
        if lo[k] <= hi[k] {
            centre[k] = 0.5 * lo[k] + 0.5 * hi[k];
            half_extent = half_extent.max(0.5 * hi[k] - 0.5 * lo[k]);
        }
    }
    let reference = half_extent.max(if extra.is_finite() { extra } else { 0.0 });
    let scale = if reference > 0.0 {
        let e = (reference.log2().round() as i64).clamp(-1000, 1000);
        f64::from_bits(((1023 - e) as u64) << 52)
    } else {
        1.0
    };
    (centre, scale)
}

fn normalised_points(vertices: &[V3], centre: V3, scale: f64) -> Vec<V3> {
    vertices
        .iter()
        .map(|v| {
            [
                (v[0] - centre[0]) * scale,
                (v[1] - centre[1]) * scale,
                (v[2] - centre[2]) * scale,
            ]
        })
        .collect()
}

/// Area-weighted unit normals of already normalised points; faces with an out-of-range index
/// are skipped.
fn normals_of(points: &[V3], faces: &[[u32; 3]]) -> Vec<V3> {
    let n = points.len();
    let mut acc = vec![[0.0f64; 3]; n];
    for f in faces {
        let [a, b, c] = [f[0] as usize, f[1] as usize, f[2] as usize];
        if a >= n || b >= n || c >= n {
            continue;
        }
        // |cross| = 2 * area: summing unnormalised face normals weights them by area.
        let fnrm = cross(sub(points[b], points[a]), sub(points[c], points[a]));
        if !fnrm.iter().all(|x| x.is_finite()) {
            continue;
        }
        for &v in &[a, b, c] {
            for k in 0..3 {
                acc[v][k] += fnrm[k];
            }
        }
    }
    for v in acc.iter_mut() {
        let len = dot(*v, *v).sqrt();
        if len.is_finite() && len > 0.0 {
            for x in v.iter_mut() {
                *x /= len;
            }
        } else {
            *v = [0.0; 3];
        }
    }
    acc
}

/// Area-weighted vertex normals: the unit vector along the sum of the incident faces' normals
/// weighted by face area (orientation from the face winding, counter-clockwise = outward).
/// Zero for vertices referenced by no face of non-zero area (and where the incident normals
/// cancel). Faces with an out-of-range index are skipped; non-finite coordinates give zero
/// normals on the faces that use them. Never panics.
pub fn vertex_normals(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<[f64; 3]> {
    let (centre, scale) = normalisation(vertices, 0.0);
    normals_of(&normalised_points(vertices, centre, scale), faces)
}

/// Grid cells per search radius: 2 scans a (2.5 r)^2 patch of a surface instead of (3 r)^2
/// for 1, for 30% fewer candidate points.
const CELLS_PER_RADIUS: usize = 2;
const COLUMNS: usize = (2 * CELLS_PER_RADIUS + 1) * (2 * CELLS_PER_RADIUS + 1);

/// Uniform grid over the surface points (vertices with a normal), cells of side slightly larger
/// than `radius / CELLS_PER_RADIUS`, stored as a sorted list of occupied cells (memory linear in the
/// number of points whatever the radius); points and normals in cell order, structure-of-arrays.
struct Grid {
    lo: V3,
    cell: f64,
    keys: Vec<[i64; 3]>,
    /// `starts[c]..starts[c + 1]` is the range of cell `keys[c]` in the point arrays.
    starts: Vec<usize>,
    px: Vec<f64>,
    py: Vec<f64>,
    pz: Vec<f64>,
    nx: Vec<f64>,
    ny: Vec<f64>,
    nz: Vec<f64>,
}

impl Grid {
    fn new(points: &[V3], normals: &[V3], radius: f64) -> Grid {
        let mut lo = [f64::INFINITY; 3];
        for p in points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
            }
        }
        // A margin so that rounding in the cell computation can never put two points closer
        // than `radius` into non-adjacent cells.
        let cell = radius / CELLS_PER_RADIUS as f64 * (1.0 + 1e-9);
        let mut grid = Grid {
            lo,
            cell,
            keys: Vec::new(),
            starts: Vec::new(),
            px: Vec::new(),
            py: Vec::new(),
            pz: Vec::new(),
            nx: Vec::new(),
            ny: Vec::new(),
            nz: Vec::new(),
        };
        let mut items: Vec<([i64; 3], u32)> = points
            .iter()
            .zip(normals)
            .enumerate()
            .filter(|(_, (_, n))| **n != [0.0; 3])
            .map(|(i, (p, _))| (grid.key(*p), i as u32))
            .collect();
        items.sort_unstable();
        for (j, &(key, i)) in items.iter().enumerate() {
            if grid.keys.last() != Some(&key) {
                grid.keys.push(key);
                grid.starts.push(j);
            }
            let (p, n) = (points[i as usize], normals[i as usize]);
            grid.px.push(p[0]);
            grid.py.push(p[1]);
            grid.pz.push(p[2]);
            grid.nx.push(n[0]);
            grid.ny.push(n[1]);
            grid.nz.push(n[2]);
        }
        grid.starts.push(items.len());
        grid
    }

    #[inline]
    fn key(&self, p: V3) -> [i64; 3] {
        // `as` saturates (and maps NaN to 0): no overflow whatever the ratio of extent to cell.
        [
            ((p[0] - self.lo[0]) / self.cell).floor() as i64,
            ((p[1] - self.lo[1]) / self.cell).floor() as i64,
            ((p[2] - self.lo[2]) / self.cell).floor() as i64,
        ]
    }

    /// Index ranges (into the point arrays) of the occupied cells that can hold points within
    /// the radius of `p` (the `(2 * CELLS_PER_RADIUS + 1)^3` cells around it): one range per
    /// column `(x, y, z - S..=z + S)`, as those cells are consecutive in key order.
    /// Returns the ranges and their number.
    fn ranges_around(&self, p: V3) -> ([(usize, usize); COLUMNS], usize) {
        let k = self.key(p);
        let mut out = [(0usize, 0usize); COLUMNS];
        let span = CELLS_PER_RADIUS as i64;
        let mut count = 0;
        for dx in -span..=span {
            let Some(x) = k[0].checked_add(dx) else {
                continue;
            };
            for dy in -span..=span {
                let Some(y) = k[1].checked_add(dy) else {
                    continue;
                };
                // Saturation keeps every stored key within i64, so clamping the column ends
                // loses nothing.
                let first = [x, y, k[2].saturating_sub(span)];
                let last = [x, y, k[2].saturating_add(span)];
                let c0 = self.keys.partition_point(|key| *key < first);
                let c1 = c0 + self.keys[c0..].partition_point(|key| *key <= last);
                if c1 > c0 {
                    out[count] = (self.starts[c0], self.starts[c1]);
                    count += 1;
                }
            }
        }
        (out, count)
    }
}

/// `atan(x)` for `|x| <= tan(pi / 8)`: the single-precision minimax polynomial of Cephes'
/// `atanf`, evaluated in f64 (absolute error below 1e-7 rad, which is all a histogram needs).
#[inline]
fn atan_small(x: f64) -> f64 {
    let z = x * x;
    (((8.053_744_495_38e-2 * z - 1.387_768_560_32e-1) * z + 1.997_771_064_78e-1) * z
        - 3.333_294_915_39e-1)
        * z
        * x
        + x
}

/// `atan2(num, den)` for `num, den >= 0`, in `[0, pi / 2]` (0 when both are 0); branch-free, so
/// that random octants cost no mispredictions, with one division (error below 1e-7 rad).
#[inline]
fn atan2_quadrant(num: f64, den: f64) -> f64 {
    const TAN_PI_8: f64 = 0.414_213_562_373_095_1;
    let (lo, hi) = (num.min(den), num.max(den));
    // atan(lo / hi), reduced to |argument| <= tan(pi / 8) through
    // atan(t) = pi / 4 + atan((t - 1) / (t + 1)) = pi / 4 + atan((lo - hi) / (lo + hi)).
    let reduce = lo > TAN_PI_8 * hi;
    let n = if reduce { lo - hi } else { lo };
    let d = if reduce { lo + hi } else { hi };
    let offset = if reduce { FRAC_PI_4 } else { 0.0 };
    let r = offset + atan_small(n / d.max(f64::MIN_POSITIVE));
    if num > den {
        FRAC_PI_2 - r
    } else {
        r
    }
}

/// `atan2(y, x)` in `[-pi, pi]` (up to the sign of `pi` and 0 at the origin).
#[inline]
fn azimuth(x: f64, y: f64) -> f64 {
    let a = atan2_quadrant(y.abs(), x.abs());
    let a = if x < 0.0 { PI - a } else { a };
    a.copysign(y)
}

/// Per-thread scratch: the usable neighbours of the current vertex (offset from the centre,
/// distance, mesh normal) and their histogram coordinates, as structure-of-arrays so that the
/// per-neighbour arithmetic vectorises. The vectors only grow; the first `len` entries are valid.
#[derive(Default)]
struct Scratch {
    len: usize,
    /// Grid indices of the neighbours.
    index: Vec<u32>,
    dx: Vec<f64>,
    dy: Vec<f64>,
    dz: Vec<f64>,
    dist: Vec<f64>,
    nx: Vec<f64>,
    ny: Vec<f64>,
    nz: Vec<f64>,
    /// Continuous bin coordinates: cosine in `[0, 10]`, azimuth in `[3.5, 11.5]` (mod 8),
    /// and the weights of the lower elevation and of the outer shell, in `[0, 1]`.
    t_cos: Vec<f64>,
    t_azimuth: Vec<f64>,
    f_elevation: Vec<f64>,
    f_shell: Vec<f64>,
}

impl Scratch {
    /// Makes room for `n` entries in every array.
    fn reserve(&mut self, n: usize) {
        if self.dx.len() < n {
            let n = n.next_power_of_two();
            for v in [
                &mut self.dx,
                &mut self.dy,
                &mut self.dz,
                &mut self.dist,
                &mut self.nx,
                &mut self.ny,
                &mut self.nz,
                &mut self.t_cos,
                &mut self.t_azimuth,
                &mut self.f_elevation,
                &mut self.f_shell,
            ] {
                v.resize(n, 0.0);
            }
        }
    }

    /// Gathers the surface points within `radius` of `p`, except those coinciding with it.
    #[inline(always)]
    fn gather(&mut self, grid: &Grid, p: V3, radius: f64) {
        let (ranges, count) = grid.ranges_around(p);
        let ranges = &ranges[..count];
        self.reserve(ranges.iter().map(|(a, b)| b - a).sum::<usize>() + 1);
        if self.index.len() < self.dx.len() {
            self.index.resize(self.dx.len(), 0);
        }
        let r2 = radius * radius;
        let mut m = 0;
        let (index, dist) = (&mut self.index[..], &mut self.dist[..]);
        for &(a, b) in ranges {
            let (px, py, pz) = (&grid.px[a..b], &grid.py[a..b], &grid.pz[a..b]);
            for (j, ((&x, &y), &z)) in px.iter().zip(py).zip(pz).enumerate() {
                let (dx, dy, dz) = (x - p[0], y - p[1], z - p[2]);
                let d2 = dx * dx + dy * dy + dz * dz;
                // Branch-free compaction: always write, advance only for a keeper (the
                // distance test is unpredictable near the sphere).
                index[m] = (a + j) as u32;
                dist[m] = d2;
                m += (d2 <= r2 && d2 > 0.0) as usize;
            }
        }
        let (dx, dy, dz) = (&mut self.dx[..m], &mut self.dy[..m], &mut self.dz[..m]);
        let (nx, ny, nz) = (&mut self.nx[..m], &mut self.ny[..m], &mut self.nz[..m]);
        for (k, &j) in self.index[..m].iter().enumerate() {
            let j = j as usize;
            dx[k] = grid.px[j] - p[0];
            dy[k] = grid.py[j] - p[1];
            dz[k] = grid.pz[j] - p[2];
            nx[k] = grid.nx[j];
            ny[k] = grid.ny[j];
            nz[k] = grid.nz[j];
        }
        for d in &mut self.dist[..m] {
            *d = d.sqrt();
        }
        self.len = m;
    }
}

/// Majority-vote sign: `+1` if most neighbours project non-negatively on `axis`
/// (ties broken by the sign of the summed projections).
#[inline(always)]
fn majority_sign(nb: &Scratch, axis: V3) -> f64 {
    let (mut balance, mut sum) = (0i64, 0.0f64);
    let m = nb.len;
    for ((&x, &y), &z) in nb.dx[..m].iter().zip(&nb.dy[..m]).zip(&nb.dz[..m]) {
        let dp = x * axis[0] + y * axis[1] + z * axis[2];
        balance += (dp > 0.0) as i64 - (dp < 0.0) as i64;
        sum += dp;
    }
    if balance < 0 || (balance == 0 && sum < 0.0) {
        -1.0
    } else {
        1.0
    }
}

/// Local reference frame `(x, y, z)`, or `None` when the neighbourhood has no weight.
#[inline(always)]
fn local_frame(nb: &Scratch, radius: f64, normal: V3) -> Option<[V3; 3]> {
    let mut m = [0.0f64; 6];
    let mut wsum = 0.0;
    let n = nb.len;
    let (xs, ys, zs, ds) = (&nb.dx[..n], &nb.dy[..n], &nb.dz[..n], &nb.dist[..n]);
    for (((&x, &y), &z), &d) in xs.iter().zip(ys).zip(zs).zip(ds) {
        let w = (radius - d).max(0.0);
        wsum += w;
        let (wx, wy) = (w * x, w * y);
        m[0] += wx * x;
        m[1] += wx * y;
        m[2] += wx * z;
        m[3] += wy * y;
        m[4] += wy * z;
        m[5] += w * z * z;
    }
    if wsum <= 0.0 {
        return None;
    }
    let m = m.map(|v| v / wsum);
    let (vals, vecs) = sym_eigen([[m[0], m[1], m[2]], [m[1], m[3], m[4]], [m[2], m[4], m[5]]]);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| vals[j].total_cmp(&vals[i]));
    let column = |k: usize| [vecs[0][k], vecs[1][k], vecs[2][k]];
    let mut x = column(order[0]);
    let mut z = column(order[2]);
    if majority_sign(nb, x) < 0.0 {
        x = neg(x);
    }
    let zn = dot(z, normal);
    let z_sign = if zn != 0.0 {
        zn.signum()
    } else {
        majority_sign(nb, z)
    };
    if z_sign < 0.0 {
        z = neg(z);
    }
    let y = cross(z, x);
    Some([x, y, z])
}

/// Instruction sets [`describe`] is compiled for, picked at run time. The wider ones give the
/// same descriptors bit for bit (no fused multiply-add, and the operations keep their order), and
/// are faster (docs/decisions.md#speed).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Isa {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Isa {
    /// The one to use: the widest this CPU has, or the baseline when `HOPE_NO_SIMD` is set.
    fn detect() -> Isa {
        if crate::simd_disabled() {
            Isa::Baseline
        } else {
            Isa::widest()
        }
    }

    /// The widest one this CPU has.
    fn widest() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx512f") && has!("avx512vl") && has!("avx512dq") && has!("avx2") {
                return Isa::Avx512;
            }
            if has!("avx2") {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    }

    /// Every instruction set this CPU can run, narrowest first (for tests).
    #[cfg(test)]
    fn available() -> Vec<Isa> {
        let all = [
            Isa::Baseline,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512,
        ];
        let widest = Isa::widest();
        let n = all.iter().position(|&i| i == widest).map_or(1, |p| p + 1);
        all[..n].to_vec()
    }

    fn describe(
        self,
        p: V3,
        normal: V3,
        grid: &Grid,
        radius: f64,
        nb: &mut Scratch,
        row: &mut [f32],
    ) {
        match self {
            Isa::Baseline => describe(p, normal, grid, radius, nb, row),
            // SAFETY: `widest` (behind `detect` and `available`) returns these only when the
            // CPU has the features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { describe_avx2(p, normal, grid, radius, nb, row) },
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { describe_avx512(p, normal, grid, radius, nb, row) },
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn describe_avx2(p: V3, n: V3, grid: &Grid, radius: f64, nb: &mut Scratch, row: &mut [f32]) {
    describe(p, n, grid, radius, nb, row)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2")]
unsafe fn describe_avx512(
    p: V3,
    n: V3,
    grid: &Grid,
    radius: f64,
    nb: &mut Scratch,
    row: &mut [f32],
) {
    describe(p, n, grid, radius, nb, row)
}

/// Writes the descriptor of one vertex into `row` (left untouched, i.e. zero, when the vertex has
/// too few neighbours). Inlined into each [`Isa`] version.
#[inline(always)]
fn describe(p: V3, normal: V3, grid: &Grid, radius: f64, nb: &mut Scratch, row: &mut [f32]) {
    nb.gather(grid, p, radius);
    let m = nb.len;
    if m < MIN_NEIGHBOURS {
        return;
    }
    let Some([x, y, z]) = local_frame(nb, radius, normal) else {
        return;
    };

    // Continuous bin coordinates of every neighbour (branch-free, vectorisable).
    let inv_half_radius = 2.0 / radius;
    let cos_scale = 0.5 * (COS_BINS - 1) as f64;
    let (dx, dy, dz, dist) = (&nb.dx[..m], &nb.dy[..m], &nb.dz[..m], &nb.dist[..m]);
    let (nx, ny, nz) = (&nb.nx[..m], &nb.ny[..m], &nb.nz[..m]);
    let t_cos = &mut nb.t_cos[..m];
    let t_azimuth = &mut nb.t_azimuth[..m];
    let f_elevation = &mut nb.f_elevation[..m];
    let f_shell = &mut nb.f_shell[..m];
    for k in 0..m {
        let lx = dx[k] * x[0] + dy[k] * x[1] + dz[k] * x[2];
        let ly = dx[k] * y[0] + dy[k] * y[1] + dz[k] * y[2];
        let lz = dx[k] * z[0] + dy[k] * z[1] + dz[k] * z[2];

        // Cosine of the normal with the local z: bin centres at -1, -0.8, ..., 1.
        let cosine = (nx[k] * z[0] + ny[k] * z[1] + nz[k] * z[2]).clamp(-1.0, 1.0);
        t_cos[k] = (1.0 + cosine) * cos_scale;

        // Azimuth, circular: sector s centred at (s + 0.5) * 45 degrees.
        t_azimuth[k] = azimuth(lx, ly) * (4.0 / PI) - 0.5 + AZIMUTH_SECTORS as f64;

        // Elevation: centres at 45 (upper, 0) and 135 (lower, 1) degrees from z; the weight of
        // the lower one is inclination / 90deg - 1/2 = 1/2 - atan(lz / rho) / 90deg, clamped.
        let rho = (lx * lx + ly * ly).sqrt();
        let lift = atan2_quadrant(lz.abs(), rho).copysign(lz) * (2.0 / PI);
        f_elevation[k] = (0.5 - lift).clamp(0.0, 1.0);

        // Radial shells: centres at radius / 4 (inner, 0) and 3 radius / 4 (outer, 1).
        f_shell[k] = (dist[k] * inv_half_radius - 0.5).clamp(0.0, 1.0);
    }

    // Quadrilinear voting.
    let mut hist = [0.0f64; SHOT_DIM];
    for k in 0..m {
        let tc = t_cos[k];
        let c0 = (tc as usize).min(COS_BINS - 2); // truncation = floor for tc >= 0
        let fc = (tc - c0 as f64).clamp(0.0, 1.0);
        let ta = t_azimuth[k];
        let a_floor = ta as usize;
        let fa = (ta - a_floor as f64).clamp(0.0, 1.0);
        let a0 = a_floor % AZIMUTH_SECTORS;
        let a1 = (a0 + 1) % AZIMUTH_SECTORS;
        let (fe, fr) = (f_elevation[k], f_shell[k]);

        let wa = [(a0, 1.0 - fa), (a1, fa)];
        let we = [1.0 - fe, fe];
        let wr = [1.0 - fr, fr];
        let (wc0, wc1) = (1.0 - fc, fc);
        for &(a, w_a) in &wa {
            for (e, &w_e) in we.iter().enumerate() {
                let w_ae = w_a * w_e;
                for (r, &w_r) in wr.iter().enumerate() {
                    let w = w_ae * w_r;
                    let base = ((a * 2 + e) * 2 + r) * COS_BINS + c0;
                    hist[base] += w * wc0;
                    hist[base + 1] += w * wc1;
                }
            }
        }
    }
    let norm = hist.iter().map(|h| h * h).sum::<f64>().sqrt();
    if norm.is_finite() && norm > 0.0 {
        for (o, h) in row.iter_mut().zip(hist.iter()) {
            *o = (h / norm) as f32;
        }
    }
}

/// SHOT descriptors, row-major (n_vertices x 352), each row L2-normalised (all-zero for a vertex with too few neighbours).
/// `radius` is absolute: callers pass a multiple of sqrt(surface area); hope_rs uses 0.1
/// (docs/decisions.md#descriptors, which keeps the measurements of other radii).
///
/// Cost grows with the number of neighbours (about with `radius^2`).
///
/// Errors (`InvalidInput`) if `radius` is not finite and > 0, a vertex coordinate is not finite,
/// or a face references a vertex index `>= vertices.len()`. Degenerate faces, duplicate and
/// unreferenced vertices are fine. Runs in parallel over vertices (rayon).
pub fn shot_descriptors(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    radius: f64,
) -> Result<Vec<f32>> {
    shot_descriptors_with(vertices, faces, radius, None, Isa::detect())
}

/// [`shot_descriptors`] of the vertices `centres` only (row `i` describes vertex `centres[i]`),
/// with every vertex of the mesh voting in their supports. The cost is proportional to the
/// number of centres, so on a dense mesh a spatially even subset of centres gives the
/// descriptors of the whole surface at a fraction of the time.
///
/// Errors (`InvalidInput`) as [`shot_descriptors`], and if a centre is `>= vertices.len()`.
pub fn shot_descriptors_at(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    radius: f64,
    centres: &[u32],
) -> Result<Vec<f32>> {
    shot_descriptors_with(vertices, faces, radius, Some(centres), Isa::detect())
}

fn shot_descriptors_with(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    radius: f64,
    centres: Option<&[u32]>,
    isa: Isa,
) -> Result<Vec<f32>> {
    if !(radius.is_finite() && radius > 0.0) {
        return invalid(format!(
            "shot_descriptors: radius must be finite and > 0 (an absolute length, e.g. a \
             multiple of sqrt(surface area)), got {radius}"
        ));
    }
    let n = vertices.len();
    if let Some((i, v)) = vertices
        .iter()
        .enumerate()
        .find(|(_, v)| !v.iter().all(|x| x.is_finite()))
    {
        return invalid(format!(
            "shot_descriptors: vertex {i} has a non-finite coordinate {v:?}"
        ));
    }
    if let Some((j, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&k| k as usize >= n))
    {
        return invalid(format!(
            "shot_descriptors: face {j} = {f:?} references a vertex index out of range \
             (there are {n} vertices, valid indices are 0..{n})"
        ));
    }
    if let Some(&c) = centres.and_then(|c| c.iter().find(|&&c| c as usize >= n)) {
        return invalid(format!(
            "shot_descriptors: centre {c} is out of range (there are {n} vertices)"
        ));
    }
    let rows = centres.map_or(n, <[u32]>::len);
    let mut out = vec![0.0f32; rows * SHOT_DIM];
    if rows == 0 {
        return Ok(out);
    }
    let (centre, scale) = normalisation(vertices, radius);
    let points = normalised_points(vertices, centre, scale);
    let r = radius * scale;
    if r * r <= 0.0 {
        // The radius is below the resolution of the coordinates: no vertex has a neighbour.
        return Ok(out);
    }
    let normals = normals_of(&points, faces);
    let grid = Grid::new(&points, &normals, r);
    out.par_chunks_mut(SHOT_DIM)
        .enumerate()
        .for_each_init(Scratch::default, |nbrs, (i, row)| {
            let v = centres.map_or(i, |c| c[i] as usize);
            isa.describe(points[v], normals[v], &grid, r, nbrs, row)
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_meshes::icosphere;
    use std::path::Path;

    /// The multiple of sqrt(area) recommended in the doc of `shot_descriptors`.
    const RECOMMENDED_RADIUS: f64 = 0.075;
    const FAUST_DIR: &str = "/work/shared/data/faust_reg";
    const CAT0: &str = "/work/shared/data/tosca/cat0.off";

    type Mesh = (Vec<V3>, Vec<[u32; 3]>);

    /// Minimal OFF reader (polygons are fan-triangulated); `None` if the file is missing.
    fn read_off(path: &str) -> Option<Mesh> {
        let text = std::fs::read_to_string(path).ok()?;
        let mut tokens = text
            .lines()
            .map(|l| l.split('#').next().unwrap_or(""))
            .flat_map(|l| l.split_whitespace());
        let head = tokens.next()?;
        assert!(head.ends_with("OFF"), "{path}: not an OFF file");
        let mut next_num = || tokens.next().map(|t| t.parse::<f64>().expect("OFF number"));
        let nv = next_num()? as usize;
        let nf = next_num()? as usize;
        let _ne = next_num()?;
        let mut verts = Vec::with_capacity(nv);
        for _ in 0..nv {
            verts.push([next_num()?, next_num()?, next_num()?]);
        }
        let mut faces = Vec::with_capacity(nf);
        for _ in 0..nf {
            let k = next_num()? as usize;
            let idx: Vec<u32> = (0..k)
                .map(|_| next_num().map(|x| x as u32))
                .collect::<Option<_>>()?;
            for t in 1..k.saturating_sub(1) {
                faces.push([idx[0], idx[t], idx[t + 1]]);
            }
        }
        Some((verts, faces))
    }

    fn faust(name: &str) -> Option<Mesh> {
        let path = format!("{FAUST_DIR}/{name}.off");
        if !Path::new(&path).exists() {
            eprintln!("skipping: {path} not found");
            return None;
        }
        read_off(&path)
    }

    fn area(v: &[V3], f: &[[u32; 3]]) -> f64 {
        f.iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| v[i as usize]);
                0.5 * dot(cross(sub(b, a), sub(c, a)), cross(sub(b, a), sub(c, a))).sqrt()
            })
            .sum()
    }

    /// An icosphere whose radius is modulated by a smooth asymmetric function.
    fn bumpy_sphere(subdivisions: usize) -> Mesh {
        let (mut v, f) = icosphere(subdivisions);
        for p in v.iter_mut() {
            let [x, y, z] = *p;
            let r = 1.0
                + 0.25 * (3.0 * x + 1.0).sin() * (2.0 * y - 0.5).cos()
                + 0.15 * (4.0 * z + 2.0 * x + 0.3).sin()
                + 0.1 * (5.0 * y * z + x).cos();
            *p = [x * r, y * r, z * r];
        }
        (v, f)
    }

    fn rotation(axis: V3, angle: f64) -> [[f64; 3]; 3] {
        let l = dot(axis, axis).sqrt();
        let [x, y, z] = [axis[0] / l, axis[1] / l, axis[2] / l];
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ]
    }

    fn transform(v: &[V3], rot: [[f64; 3]; 3], shift: V3) -> Vec<V3> {
        v.iter()
            .map(|p| {
                [
                    dot(rot[0], *p) + shift[0],
                    dot(rot[1], *p) + shift[1],
                    dot(rot[2], *p) + shift[2],
                ]
            })
            .collect()
    }

    fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    fn row(d: &[f32], i: usize) -> &[f32] {
        &d[i * SHOT_DIM..(i + 1) * SHOT_DIM]
    }

    fn row_dist(a: &[f32], b: &[f32]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| ((x - y) as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    fn check_rows(d: &[f32], n: usize) -> (usize, usize) {
        assert_eq!(d.len(), n * SHOT_DIM);
        assert!(
            d.iter().all(|x| x.is_finite()),
            "non-finite descriptor value"
        );
        let (mut unit, mut zero) = (0, 0);
        for i in 0..n {
            let r = row(d, i);
            let nn = r.iter().map(|x| (*x as f64).powi(2)).sum::<f64>().sqrt();
            if nn == 0.0 {
                zero += 1;
            } else {
                assert!((nn - 1.0).abs() < 1e-5, "row {i} has norm {nn}");
                assert!(r.iter().all(|x| *x >= 0.0), "row {i} has a negative entry");
                unit += 1;
            }
        }
        (unit, zero)
    }

    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> u64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            self.0 >> 33
        }
        fn uniform(&mut self) -> f64 {
            self.next() as f64 / (1u64 << 31) as f64
        }
    }

    /// The AVX2 and AVX-512 builds of `describe` must give the baseline's descriptors bit for
    /// bit (the speed-up may not change a single match). A bumpy sphere with a random jitter, so
    /// neighbourhoods vary in size and shape.
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let (mut v, f) = bumpy_sphere(4);
        let mut rng = Lcg(11);
        for p in v.iter_mut() {
            for x in p.iter_mut() {
                *x += 0.01 * (rng.uniform() - 0.5);
            }
        }
        let radius = 0.1 * area(&v, &f).sqrt();
        let isas = Isa::available();
        let base = shot_descriptors_with(&v, &f, radius, None, Isa::Baseline).unwrap();
        let (unit, _) = check_rows(&base, v.len());
        assert!(unit > v.len() / 2);
        for &isa in &isas[1..] {
            let d = shot_descriptors_with(&v, &f, radius, None, isa).unwrap();
            let same = d.iter().zip(&base).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "{isa:?} differs from the baseline");
        }
        println!("checked {isas:?}");
    }

    /// Descriptors at chosen centres are the full descriptors' rows, bit for bit, in the
    /// centres' order (repeats allowed); a centre out of range is an error.
    #[test]
    fn centres_give_the_rows_of_the_full_descriptors() {
        let (v, f) = bumpy_sphere(3);
        let radius = 0.1 * area(&v, &f).sqrt();
        let full = shot_descriptors(&v, &f, radius).unwrap();
        let centres: Vec<u32> = (0..v.len() as u32).rev().step_by(7).chain([0, 0]).collect();
        let at = shot_descriptors_at(&v, &f, radius, &centres).unwrap();
        assert_eq!(at.len(), centres.len() * SHOT_DIM);
        for (row, &c) in at.chunks(SHOT_DIM).zip(&centres) {
            let want = &full[c as usize * SHOT_DIM..(c as usize + 1) * SHOT_DIM];
            assert!(row
                .iter()
                .zip(want)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
        }
        assert!(shot_descriptors_at(&v, &f, radius, &[]).unwrap().is_empty());
        let err = shot_descriptors_at(&v, &f, radius, &[v.len() as u32]).unwrap_err();
        assert!(err.to_string().contains("out of range"), "{err}");
    }

    #[test]
    fn fast_atan_is_accurate() {
        let mut worst: f64 = 0.0;
        for i in 0..=100_000 {
            let t = i as f64 / 100_000.0;
            worst = worst.max((atan2_quadrant(t, 1.0) - t.atan()).abs());
            worst = worst.max((atan2_quadrant(1.0, t) - (1.0 / t).atan()).abs());
        }
        let mut rng = Lcg(3);
        for _ in 0..100_000 {
            let (x, y) = (rng.uniform() * 2.0 - 1.0, rng.uniform() * 2.0 - 1.0);
            worst = worst.max((azimuth(x, y) - y.atan2(x)).abs());
        }
        for (x, y) in [
            (1.0, 0.0),
            (-1.0, 0.0),
            (0.0, 1.0),
            (0.0, -1.0),
            (-1.0, -0.0),
            (-1.0, 1e-300),
            (0.0, 0.0),
        ] {
            let d = (azimuth(x, y) - f64::atan2(y, x)).abs();
            worst = worst.max(d.min((d - 2.0 * PI).abs()));
        }
        println!("fast atan: max error {worst:.2e}");
        assert!(worst < 2e-7);
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn eigen_solver_is_accurate() {
        let mut rng = Lcg(7);
        let mut cases: Vec<[[f64; 3]; 3]> = vec![
            [[0.0; 3]; 3],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 3.0]],
            [
                [1e-200, 0.0, 1e-210],
                [0.0, 2e-200, 0.0],
                [1e-210, 0.0, 3e-200],
            ],
            [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]],
        ];
        for _ in 0..500 {
            let mut m = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in r..3 {
                    m[r][c] = rng.uniform() * 2.0 - 1.0;
                    m[c][r] = m[r][c];
                }
            }
            cases.push(m);
        }
        for m in cases {
            let (vals, vecs) = sym_eigen(m);
            let scale = m
                .iter()
                .flatten()
                .map(|x| x.abs())
                .fold(0.0, f64::max)
                .max(1e-300);
            for k in 0..3 {
                let col = [vecs[0][k], vecs[1][k], vecs[2][k]];
                assert!((dot(col, col) - 1.0).abs() < 1e-12);
                for j in 0..k {
                    let other = [vecs[0][j], vecs[1][j], vecs[2][j]];
                    assert!(dot(col, other).abs() < 1e-12);
                }
                for r in 0..3 {
                    let mv = dot(m[r], col);
                    assert!((mv - vals[k] * col[r]).abs() <= 1e-12 * scale, "{m:?}");
                }
            }
        }
    }

    fn rigid_check(v: &[V3], f: &[[u32; 3]], radius: f64, label: &str) {
        let d0 = shot_descriptors(v, f, radius).unwrap();
        let (unit, _) = check_rows(&d0, v.len());
        assert!(unit > v.len() * 9 / 10, "{label}: too many empty rows");
        for (axis, angle, shift) in [
            ([0.3, -0.5, 0.8], 1.1, [0.2, -3.0, 10.0]),
            ([-1.0, 0.2, 0.1], 2.7, [-100.0, 5.0, 0.5]),
        ] {
            let v1 = transform(v, rotation(axis, angle), shift);
            let d1 = shot_descriptors(&v1, f, radius).unwrap();
            let worst = max_abs_diff(&d0, &d1);
            println!("{label}: rigid motion, max |diff| = {worst:.2e}");
            assert!(
                worst < 1e-4,
                "{label}: rigid motion changed descriptors by {worst}"
            );
        }
    }

    #[test]
    fn rigid_motion_invariance_bumpy_sphere() {
        let (v, f) = bumpy_sphere(4);
        let r = 0.1 * area(&v, &f).sqrt();
        rigid_check(&v, &f, r, "bumpy sphere");
    }

    #[test]
    fn rigid_motion_invariance_faust() {
        let Some((v, f)) = faust("tr_reg_012") else {
            return;
        };
        let r = 0.1 * area(&v, &f).sqrt();
        rigid_check(&v, &f, r, "faust tr_reg_012");
    }

    #[test]
    fn permutation_equivariance() {
        let (v, f) = bumpy_sphere(3);
        let r = 0.15 * area(&v, &f).sqrt();
        let n = v.len();
        let mut perm: Vec<usize> = (0..n).collect();
        let mut rng = Lcg(42);
        for i in (1..n).rev() {
            perm.swap(i, rng.next() as usize % (i + 1));
        }
        // new vertex j is old vertex perm[j]
        let mut inv = vec![0u32; n];
        for (j, &p) in perm.iter().enumerate() {
            inv[p] = j as u32;
        }
        let v1: Vec<V3> = perm.iter().map(|&p| v[p]).collect();
        let f1: Vec<[u32; 3]> = f.iter().rev().map(|t| t.map(|i| inv[i as usize])).collect();
        let d0 = shot_descriptors(&v, &f, r).unwrap();
        let d1 = shot_descriptors(&v1, &f1, r).unwrap();
        let mut worst = 0.0f32;
        for (j, &p) in perm.iter().enumerate() {
            worst = worst.max(max_abs_diff(row(&d1, j), row(&d0, p)));
        }
        println!("permutation: max |diff| = {worst:.2e}");
        assert!(worst < 1e-5);
    }

    /// Mirrors the azimuth of a descriptor: sector s <-> 7 - s (y -> -y).
    fn mirror_azimuth(d: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0f32; d.len()];
        let block = SHOT_DIM / AZIMUTH_SECTORS;
        for (r_in, r_out) in d.chunks(SHOT_DIM).zip(out.chunks_mut(SHOT_DIM)) {
            for s in 0..AZIMUTH_SECTORS {
                let t = AZIMUTH_SECTORS - 1 - s;
                r_out[t * block..(t + 1) * block]
                    .copy_from_slice(&r_in[s * block..(s + 1) * block]);
            }
        }
        out
    }

    #[test]
    fn mirror_sensitivity() {
        let (v, f) = bumpy_sphere(4);
        let r = 0.1 * area(&v, &f).sqrt();
        let n = v.len();
        let d0 = shot_descriptors(&v, &f, r).unwrap();
        let vm: Vec<V3> = v.iter().map(|p| [-p[0], p[1], p[2]]).collect();
        // A proper mirror image keeps outward normals: flip the winding too.
        let fm: Vec<[u32; 3]> = f.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let dm = shot_descriptors(&vm, &fm, r).unwrap();
        // Same winding (normals now point inwards): also different.
        let dm_in = shot_descriptors(&vm, &f, r).unwrap();
        let mean_dist = |a: &[f32], b: &[f32]| {
            (0..n).map(|i| row_dist(row(a, i), row(b, i))).sum::<f64>() / n as f64
        };
        let changed = mean_dist(&d0, &dm);
        let changed_in = mean_dist(&d0, &dm_in);
        // The mirrored shape's descriptors are the originals with the azimuth mirrored.
        let equivariant = mean_dist(&mirror_azimuth(&d0), &dm);
        // Nearest-neighbour matching original -> mirror mostly fails to find the mirror vertex.
        println!(
            "mirror: mean row distance {changed:.3} (inward normals {changed_in:.3}), \
             vs azimuth-mirrored originals {equivariant:.2e}"
        );
        assert!(
            changed > 0.2,
            "mirroring changed descriptors by only {changed}"
        );
        assert!(
            changed_in > 0.2,
            "mirroring changed descriptors by only {changed_in}"
        );
        assert!(
            equivariant < 1e-3,
            "mirror is not an azimuth flip: {equivariant}"
        );
    }

    #[test]
    fn uniform_scale_invariance() {
        let (v, f) = bumpy_sphere(3);
        let r = 0.12 * area(&v, &f).sqrt();
        let d0 = shot_descriptors(&v, &f, r).unwrap();
        for s in [3.7, 1e-3, 2.0f64.powi(-20) * 1.3, 1e6] {
            let vs: Vec<V3> = v.iter().map(|p| p.map(|x| x * s)).collect();
            let d1 = shot_descriptors(&vs, &f, r * s).unwrap();
            let worst = max_abs_diff(&d0, &d1);
            println!("scale {s:e}: max |diff| = {worst:.2e}");
            assert!(worst < 1e-4, "scale {s}: {worst}");
        }
    }

    #[test]
    fn degenerate_inputs_give_finite_unit_or_zero_rows() {
        // Empty mesh, no faces.
        assert!(shot_descriptors(&[], &[], 1.0).unwrap().is_empty());
        let cloud: Vec<V3> = (0..20).map(|i| [i as f64, (i * i) as f64, 0.5]).collect();
        let d = shot_descriptors(&cloud, &[], 100.0).unwrap();
        assert_eq!(check_rows(&d, cloud.len()), (0, cloud.len()));
        // A single triangle: too few neighbours.
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let d = shot_descriptors(&tri, &[[0, 1, 2]], 10.0).unwrap();
        assert_eq!(check_rows(&d, 3), (0, 3));
        // Tiny and huge radii.
        let (v, f) = bumpy_sphere(2);
        for r in [1e-300, 1e-12, 1e-3, 0.5, 1e3, 1e300, f64::MAX] {
            let d = shot_descriptors(&v, &f, r).unwrap();
            check_rows(&d, v.len());
        }
        // Extreme coordinates.
        for s in [1e-300, 1e300] {
            let vs: Vec<V3> = v.iter().map(|p| p.map(|x| x * s)).collect();
            let d = shot_descriptors(&vs, &f, 0.5 * s).unwrap();
            let (unit, _) = check_rows(&d, v.len());
            assert_eq!(unit, v.len());
        }
        let far = [
            [-1.7e308, 0.0, 0.0],
            [1.7e308, 0.0, 0.0],
            [0.0, 1e308, 0.0],
            [0.0, 0.0, 1e-308],
        ];
        let d = shot_descriptors(&far, &[[0, 1, 2], [0, 2, 3], [1, 2, 3]], 1e308).unwrap();
        check_rows(&d, 4);
        // Zero-area faces, duplicated vertices, isolated vertices, repeated indices.
        let mut v2 = v.clone();
        let mut f2 = f.clone();
        let n = v.len() as u32;
        for i in 0..20u32 {
            v2.push(v[i as usize]); // duplicate, referenced below
            f2.push([i, n + i, (i + 1) % n]); // zero-area-ish sliver / duplicate
            f2.push([i, i, i + 2]); // repeated index
        }
        f2.push([0, 1, 0]);
        v2.push([0.0, 0.0, 0.0]); // isolated, inside
        v2.push([5.0, 5.0, 5.0]); // isolated, far away
        v2.push([1.2, 0.0, 0.0]); // isolated, near the surface
        let m = v2.len();
        let d = shot_descriptors(&v2, &f2, 0.4).unwrap();
        let (unit, zero) = check_rows(&d, m);
        println!("degenerate mesh: {unit} unit rows, {zero} zero rows");
        assert!(
            row(&d, m - 2).iter().all(|x| *x == 0.0),
            "far isolated vertex must be zero"
        );
        // Collinear and coplanar configurations.
        let line: Vec<V3> = (0..10).map(|i| [i as f64 * 0.1, 0.0, 0.0]).collect();
        let lf: Vec<[u32; 3]> = (0..8).map(|i| [i, i + 1, i + 2]).collect();
        check_rows(&shot_descriptors(&line, &lf, 1.0).unwrap(), 10);
        let mut grid_pts = Vec::new();
        let mut grid_faces = Vec::new();
        for i in 0..6u32 {
            for j in 0..6u32 {
                grid_pts.push([i as f64, j as f64, 0.0]);
                if i < 5 && j < 5 {
                    let a = i * 6 + j;
                    grid_faces.push([a, a + 6, a + 1]);
                    grid_faces.push([a + 1, a + 6, a + 7]);
                }
            }
        }
        let (unit, _) = check_rows(&shot_descriptors(&grid_pts, &grid_faces, 2.5).unwrap(), 36);
        assert!(unit > 0);
    }

    #[test]
    fn invalid_inputs_are_rejected() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let faces = [[0u32, 1, 2]];
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = shot_descriptors(&tri, &faces, r).unwrap_err();
            assert!(
                matches!(e, crate::error::CoreError::InvalidInput(ref m) if m.contains("radius"))
            );
        }
        let mut bad = tri;
        bad[1][2] = f64::NAN;
        let e = shot_descriptors(&bad, &faces, 1.0).unwrap_err();
        assert!(
            matches!(e, crate::error::CoreError::InvalidInput(ref m) if m.contains("vertex 1"))
        );
        bad[1][2] = f64::INFINITY;
        assert!(shot_descriptors(&bad, &faces, 1.0).is_err());
        let e = shot_descriptors(&tri, &[[0, 1, 3]], 1.0).unwrap_err();
        assert!(matches!(e, crate::error::CoreError::InvalidInput(ref m) if m.contains("face 0")));
        // vertex_normals never panics, even on bad input.
        let nrm = vertex_normals(&bad, &[[0, 1, 2], [0, 1, 7]]);
        assert_eq!(nrm.len(), 3);
        assert!(nrm.iter().flatten().all(|x| x.is_finite()));
    }

    #[test]
    fn vertex_normals_point_outwards_and_are_unit() {
        let (mut v, f) = icosphere(3);
        v.push([0.0, 0.0, 0.0]);
        let nrm = vertex_normals(&v, &f);
        for (p, n) in v.iter().zip(&nrm).take(v.len() - 1) {
            assert!((dot(*n, *n) - 1.0).abs() < 1e-12);
            assert!(dot(*p, *n) > 0.999, "normal {n:?} at {p:?}");
        }
        assert_eq!(nrm[v.len() - 1], [0.0; 3]);
        // Area weighting: a big and a small face meeting at vertex 0.
        let v = [
            [0.0, 0.0, 0.0],
            [10.0, 0.0, 0.0],
            [0.0, 10.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let n = vertex_normals(&v, &[[0, 1, 2], [0, 3, 1]]);
        // big face normal (0,0,100) + small face normal (0,10,0)
        let l = (100.0f64 + 10000.0).sqrt();
        for k in 0..3 {
            assert!((n[0][k] - [0.0, 10.0 / l, 100.0 / l][k]).abs() < 1e-12);
        }
    }

    /// Mesh adjacency (for hop distances).
    fn adjacency(n: usize, f: &[[u32; 3]]) -> Vec<Vec<u32>> {
        let mut adj = vec![Vec::new(); n];
        for t in f {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                adj[a as usize].push(b);
                adj[b as usize].push(a);
            }
        }
        for a in adj.iter_mut() {
            a.sort_unstable();
            a.dedup();
        }
        adj
    }

    /// Hop distance from `a` to `b`, or `None` if more than `max_hops`.
    fn hops(adj: &[Vec<u32>], a: usize, b: usize, max_hops: usize) -> Option<usize> {
        let mut frontier = vec![a as u32];
        let mut seen = std::collections::HashSet::from([a as u32]);
        for h in 0..=max_hops {
            if frontier.contains(&(b as u32)) {
                return Some(h);
            }
            let mut next = Vec::new();
            for &u in &frontier {
                for &w in &adj[u as usize] {
                    if seen.insert(w) {
                        next.push(w);
                    }
                }
            }
            frontier = next;
        }
        None
    }

    fn dot8(a: &[f32], b: &[f32]) -> f32 {
        let mut acc = [0.0f32; 8];
        for (x, y) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
            for k in 0..8 {
                acc[k] += x[k] * y[k];
            }
        }
        acc.iter().sum()
    }

    struct MatchStats {
        exact: f64,
        within1: f64,
        within3: f64,
        mean_err: f64,
        median_err: f64,
    }

    /// Nearest-neighbour matching of descriptors of `queries` of mesh A into all of mesh B;
    /// ground truth is the identity. Errors are Euclidean, in units of sqrt(area of B).
    fn match_stats(
        da: &[f32],
        db: &[f32],
        vb: &[V3],
        adj: &[Vec<u32>],
        queries: &[usize],
        unit: f64,
    ) -> MatchStats {
        let nb = vb.len();
        let nn: Vec<usize> = queries
            .par_iter()
            .map(|&i| {
                let q = row(da, i);
                let mut best = (f32::NEG_INFINITY, 0usize);
                for j in 0..nb {
                    let s = dot8(q, row(db, j));
                    if s > best.0 {
                        best = (s, j);
                    }
                }
                best.1
            })
            .collect();
        let (mut exact, mut w1, mut w3) = (0usize, 0usize, 0usize);
        let mut errs = Vec::with_capacity(queries.len());
        for (&i, &j) in queries.iter().zip(&nn) {
            match hops(adj, i, j, 3) {
                Some(0) => {
                    exact += 1;
                    w1 += 1;
                    w3 += 1
                }
                Some(1) => {
                    w1 += 1;
                    w3 += 1
                }
                Some(_) => w3 += 1,
                None => {}
            }
            let e = sub(vb[i], vb[j]);
            errs.push(dot(e, e).sqrt() / unit);
        }
        errs.sort_by(f64::total_cmp);
        let q = queries.len() as f64;
        MatchStats {
            exact: exact as f64 / q,
            within1: w1 as f64 / q,
            within3: w3 as f64 / q,
            mean_err: errs.iter().sum::<f64>() / q,
            median_err: errs[errs.len() / 2],
        }
    }

    fn faust_pair_eval(
        target: &str,
        multiples: &[f64],
        stride: usize,
    ) -> Option<Vec<(f64, MatchStats)>> {
        let (va, fa) = faust("tr_reg_012")?;
        let (vb, fb) = faust(target)?;
        assert_eq!(fa, fb, "FAUST registrations share connectivity");
        let adj = adjacency(va.len(), &fa);
        let (sa, sb) = (area(&va, &fa).sqrt(), area(&vb, &fb).sqrt());
        let queries: Vec<usize> = (0..va.len()).step_by(stride).collect();
        // chance level: average fraction of vertices within 3 hops
        let chance: f64 = queries
            .iter()
            .map(|&i| {
                let mut c = 0;
                for j in 0..va.len() {
                    if hops(&adj, i, j, 3).is_some() {
                        c += 1;
                    }
                }
                c as f64 / va.len() as f64
            })
            .take(50)
            .sum::<f64>()
            / 50.0;
        println!(
            "FAUST 012 -> {target}, {} queries; chance of <= 3 hops ~ {:.4}",
            queries.len(),
            chance
        );
        let mut out = Vec::new();
        for &m in multiples {
            let t = std::time::Instant::now();
            let da = shot_descriptors(&va, &fa, m * sa).unwrap();
            let db = shot_descriptors(&vb, &fb, m * sb).unwrap();
            let dt = t.elapsed().as_secs_f64() / 2.0;
            let s = match_stats(&da, &db, &vb, &adj, &queries, sb);
            println!(
                "radius {m:.3} sqrt(area): exact {:.3}, <=1 hop {:.3}, <=3 hops {:.3}, \
                 Euclidean error mean {:.4} median {:.4} (x sqrt(area)); {dt:.3} s/mesh",
                s.exact, s.within1, s.within3, s.mean_err, s.median_err
            );
            out.push((m, s));
        }
        Some(out)
    }

    #[test]
    fn faust_nearest_neighbour_matching_beats_chance() {
        let Some(res) = faust_pair_eval("tr_reg_018", &[RECOMMENDED_RADIUS], 5) else {
            return;
        };
        let s = &res[0].1;
        // Chance of landing within 3 hops is ~0.5%; a median error of 0.5 sqrt(area) is random.
        assert!(s.within3 > 0.15, "only {:.3} within 3 hops", s.within3);
        assert!(s.median_err < 0.1, "median error {}", s.median_err);
    }

    #[test]
    #[ignore]
    fn faust_radius_sweep() {
        faust_pair_eval("tr_reg_018", &[0.05, 0.075, 0.1, 0.125, 0.15, 0.2], 1);
        // a different subject (same registration template)
        faust_pair_eval("tr_reg_020", &[0.05, 0.075, 0.1, 0.125, 0.15], 1);
    }

    #[test]
    #[ignore]
    fn timing_cat0() {
        let Some((v, f)) = read_off(CAT0) else {
            eprintln!("skipping: {CAT0} not found");
            return;
        };
        // Process CPU time (all threads) in seconds, where /proc is available: the wall time
        // alone says little on a machine shared with other builds.
        let cpu = || -> Option<f64> {
            let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
            let fields: Vec<&str> = stat.rsplit(')').next()?.split_whitespace().collect();
            let ticks: f64 =
                fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
            Some(ticks / 100.0)
        };
        let sa = area(&v, &f).sqrt();
        for m in [0.05, RECOMMENDED_RADIUS, 0.1] {
            let (t, c) = (std::time::Instant::now(), cpu());
            let d = shot_descriptors(&v, &f, m * sa).unwrap();
            let dt = t.elapsed().as_secs_f64();
            if let (Some(c0), Some(c1)) = (c, cpu()) {
                println!(
                    "cat0: radius {m} sqrt(area): {:.2} s CPU over all threads",
                    c1 - c0
                );
            }
            let (unit, zero) = check_rows(&d, v.len());
            println!(
                "cat0 ({} vertices, {} threads): radius {m} sqrt(area): {dt:.3} s ({unit} rows, {zero} zero)",
                v.len(),
                rayon::current_num_threads()
            );
        }
    }
}
