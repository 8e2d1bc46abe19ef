//! Geometry and map helpers: closest rotations, growing a map across shared faces, greedy
//! pairing with row capacities and coarsening by manifold-keeping edge collapses.
use super::convert::{faces_vec, owned, plain_vec, points_vec, u32_vec, usize_vec};
use super::detached;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// `n` row-major 3 × 3 matrices (`9 n` values) as an (n, 3, 3) array.
fn rotations_out(py: Python<'_>, n: usize, r: Vec<f64>) -> Bound<'_, PyArray3<f64>> {
    numpy::ndarray::Array3::from_shape_vec((n, 3, 3), r)
        .expect("n * 9 values")
        .into_pyarray(py)
}

/// For each 3 × 3 matrix `M` of an (n, 3, 3) array, the rotation maximising `tr(R M)` (see
/// `rotation.rs`).
#[pyfunction]
pub(super) fn closest_rotations<'py>(
    py: Python<'py>,
    m: PyReadonlyArray3<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let a = m.as_array();
    if a.shape()[1..] != [3, 3] {
        return Err(PyValueError::new_err(format!(
            "closest_rotations needs an (n, 3, 3) array, got {:?}",
            a.shape()
        )));
    }
    let n = a.shape()[0];
    let flat: Vec<f64> = match a.as_slice() {
        Some(s) => s.to_vec(),
        None => a.iter().copied().collect(),
    };
    let r = detached(py, || crate::rotation::closest_rotations(&flat))?;
    Ok(rotations_out(py, n, r))
}

/// ARAP's local step: for each vertex the closest rotation to the sum of its directed edges'
/// outer products `ex[e] ey[e]ᵀ`, edges `edges[indptr[v]..indptr[v + 1]]` (see
/// `rotation::edge_rotations`). Returns (n, 3, 3).
#[pyfunction]
pub(super) fn edge_rotations<'py>(
    py: Python<'py>,
    indptr: PyReadonlyArray1<'py, i64>,
    edges: PyReadonlyArray1<'py, i64>,
    ex: PyReadonlyArray2<'py, f64>,
    ey: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let indptr = usize_vec(&indptr, "indptr")?;
    let edges = u32_vec(&edges, "edges")?;
    let (ex, ey) = (points_vec(&ex)?, points_vec(&ey)?);
    if ex.len() != ey.len() {
        return Err(PyValueError::new_err(format!(
            "edge_rotations needs ex and ey of one shape (n_edges, 3), got {} and {} rows",
            ex.len(),
            ey.len()
        )));
    }
    let (ex, ey) = (ex.as_flattened(), ey.as_flattened());
    let n = indptr.len().saturating_sub(1);
    let r = detached(py, || {
        crate::rotation::edge_rotations(&indptr, &edges, ex, ey)
    })?;
    Ok(rotations_out(py, n, r))
}

/// Grows a partial map (−1 where unknown) across the faces A and B share (see
/// `face_growth.rs`).
#[pyfunction]
pub(super) fn grow_across_faces<'py>(
    py: Python<'py>,
    faces_a: PyReadonlyArray2<'py, i64>,
    points_a: PyReadonlyArray2<'py, f64>,
    faces_b: PyReadonlyArray2<'py, i64>,
    points_b: PyReadonlyArray2<'py, f64>,
    partial_map: PyReadonlyArray1<'py, i64>,
    max_error: f64,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (fa, pa) = (faces_vec(&faces_a)?, points_vec(&points_a)?);
    let (fb, pb) = (faces_vec(&faces_b)?, points_vec(&points_b)?);
    let map = plain_vec(&partial_map);
    let g = detached(py, || {
        crate::face_growth::grow_across_faces(&fa, &pa, &fb, &pb, &map, max_error)
    })?;
    Ok(owned(py, &g))
}

/// Paired row and column indices.
type PairsOut<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<i64>>);

/// Greedy pairing from candidate pairs ranked best first, rows with capacities (see
/// `pairing.rs`).
#[pyfunction]
pub(super) fn greedy_pairs<'py>(
    py: Python<'py>,
    rows: PyReadonlyArray1<'py, i64>,
    cols: PyReadonlyArray1<'py, i64>,
    capacity: PyReadonlyArray1<'py, i64>,
    n_cols: usize,
) -> PyResult<PairsOut<'py>> {
    let rows = u32_vec(&rows, "rows")?;
    let cols = u32_vec(&cols, "cols")?;
    let capacity = u32_vec(&capacity, "capacity")?;
    let (r, c) = detached(py, || {
        crate::pairing::greedy_pairs(&rows, &cols, &capacity, n_cols)
    })?;
    let widen = |v: Vec<u32>| v.into_iter().map(i64::from).collect::<Vec<i64>>();
    Ok((owned(py, &widen(r)), owned(py, &widen(c))))
}

/// The nearest point of each query and whether another is about as near.
type NearestOut<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<bool>>);

/// Exact nearest points of a fixed set for many queries (see `nearest::PointClusters`).
#[pyclass(module = "hope_rs._core", frozen, name = "PointClusters")]
pub(super) struct PyPointClusters {
    inner: crate::nearest::PointClusters,
}

/// Rows of an (n, d) float array, row-major, and d.
fn f64_rows(a: &PyReadonlyArray2<'_, f64>) -> (Vec<f64>, usize) {
    let v = a.as_array();
    let flat = match v.as_slice() {
        Some(s) => s.to_vec(),
        None => v.iter().copied().collect(),
    };
    (flat, v.ncols())
}

#[pymethods]
impl PyPointClusters {
    /// The clusters of `points`, an (n, d) float array with d > 0.
    #[new]
    fn new(py: Python<'_>, points: PyReadonlyArray2<'_, f64>) -> PyResult<Self> {
        let (p, dim) = f64_rows(&points);
        let inner = detached(py, || crate::nearest::PointClusters::new(&p, dim))?;
        Ok(PyPointClusters { inner })
    }

    /// For each row of `queries` ((m, d) floats), the index of its nearest point (int64) and
    /// whether another point is about as near (bool): only unflagged answers are certain to be
    /// the one any exact search gives.
    fn nearest<'py>(
        &self,
        py: Python<'py>,
        queries: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<NearestOut<'py>> {
        let (q, dim) = f64_rows(&queries);
        if dim != self.inner.dim() {
            return Err(PyValueError::new_err(format!(
                "queries must have {} columns like the points, got {dim}",
                self.inner.dim()
            )));
        }
        let (ids, tie) = detached(py, || self.inner.nearest(&q))?;
        let ids: Vec<i64> = ids.into_iter().map(i64::from).collect();
        Ok((owned(py, &ids), owned(py, &tie)))
    }
}

/// Kept input vertices, the coarse vertex each input vertex went to, and the coarse faces.
type CollapsedOut<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<i64>>,
);

/// Merges every vertex into its site by manifold-keeping half-edge collapses along the
/// shortest-path tree `dist`, `pred`, `source` from `sites` (see `collapse.rs`; negative
/// predecessor or source: none).
#[pyfunction]
pub(super) fn collapse_to_sites<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    sites: PyReadonlyArray1<'py, i64>,
    dist: PyReadonlyArray1<'py, f64>,
    pred: PyReadonlyArray1<'py, i64>,
    source: PyReadonlyArray1<'py, i64>,
) -> PyResult<CollapsedOut<'py>> {
    let (p, f) = (points_vec(&vertices)?, faces_vec(&faces)?);
    let sites = u32_vec(&sites, "sites")?;
    let (dist, pred, source) = (plain_vec(&dist), plain_vec(&pred), plain_vec(&source));
    let c = detached(py, || {
        crate::collapse::collapse_to_sites(&p, &f, &sites, &dist, &pred, &source)
    })?;
    let widen = |v: &[u32]| v.iter().map(|&x| i64::from(x)).collect::<Vec<i64>>();
    let flat: Vec<i64> = widen(c.faces.as_flattened());
    let faces_out = numpy::ndarray::Array2::from_shape_vec((c.faces.len(), 3), flat)
        .expect("3 indices per face")
        .into_pyarray(py);
    Ok((
        owned(py, &widen(&c.sites)),
        owned(py, &widen(&c.owner)),
        faces_out,
    ))
}
