//! Per-vertex descriptors: SHOT, and the nearest candidate row of a descriptor table.
use super::convert::{f32_rows, faces_vec, owned, points_vec, u32_vec};
use super::detached;
use crate::shot::{shot_descriptors, shot_descriptors_at};
use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// SHOT descriptors, flat (n * 352) float32; of the vertices `centres` only when given.
#[pyfunction]
#[pyo3(name = "shot_descriptors", signature = (vertices, faces, radius, centres=None))]
pub(super) fn py_shot_descriptors<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    radius: f64,
    centres: Option<PyReadonlyArray1<'py, i64>>,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let v = points_vec(&vertices)?;
    let f = faces_vec(&faces)?;
    let centres = centres.map(|c| u32_vec(&c, "centres")).transpose()?;
    let d = detached(py, || match &centres {
        Some(c) => shot_descriptors_at(&v, &f, radius, c),
        None => shot_descriptors(&v, &f, radius),
    })?;
    Ok(owned(py, &d))
}

/// For each query row, its nearest candidate row of `base` (see `nearest.rs`).
#[pyfunction]
#[pyo3(name = "nearest_among")]
pub(super) fn py_nearest_among<'py>(
    py: Python<'py>,
    query: PyReadonlyArray2<'py, f32>,
    base: PyReadonlyArray2<'py, f32>,
    cand: PyReadonlyArray2<'py, i64>,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (q, dim) = f32_rows(&query);
    let (b, dim_b) = f32_rows(&base);
    let c = cand.as_array();
    if dim != dim_b || c.nrows() != query.as_array().nrows() {
        return Err(PyValueError::new_err(format!(
            "query (n, d), base (m, d) and cand (n, c) must agree, got {:?}, {:?} and {:?}",
            query.as_array().shape(),
            base.as_array().shape(),
            cand.as_array().shape()
        )));
    }
    let m = c.ncols();
    let c: Vec<u32> = c
        .iter()
        .map(|&x| u32::try_from(x))
        .collect::<Result<_, _>>()
        .map_err(|_| PyValueError::new_err("cand holds a negative or too large index"))?;
    let best = detached(py, || crate::nearest::nearest_among(&q, &b, dim, &c, m))?;
    let best: Vec<i64> = best.into_iter().map(i64::from).collect();
    Ok(owned(py, &best))
}
