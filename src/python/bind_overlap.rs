//! The overlap cost and the HOPE step kernels between two `MeshGraph`s: the cost as CSR
//! arrays, each vertex's best overlap, and the exactly solved step.
use super::bind_graph::MeshGraph;
use super::convert::{csr_out, owned, pattern, plain_vec, u32_vec, PyCsr};
use super::detached;
use crate::csr::Csr;
use crate::overlap::{overlap_rows, BallsAt, OverlapOptions, OverlapRows};
use crate::step::{best_overlap, overlap_assignment_timed, step_cost, StepOptions};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

/// Lays the cost's rows out straight into NumPy-owned arrays (no intermediate copy of the
/// tens of millions of entries a k = 8 cost holds), without the GIL.
fn overlap_out(py: Python<'_>, rows: OverlapRows) -> PyResult<PyCsr<'_, u32>> {
    let nnz = rows.nnz();
    let indptr: Vec<i64> = rows.indptr.iter().map(|&x| x as i64).collect();
    let indices = PyArray1::<i32>::zeros(py, nnz, false);
    let data = PyArray1::<u32>::zeros(py, nnz, false);
    {
        let mut idx = indices.readwrite();
        let mut val = data.readwrite();
        let idx = idx
            .as_slice_mut()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        let val = val
            .as_slice_mut()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        // SAFETY: same size and alignment; every column index is below n_b < 2^31.
        let idx: &mut [u32] =
            unsafe { std::slice::from_raw_parts_mut(idx.as_mut_ptr() as *mut u32, idx.len()) };
        detached(py, || {
            rows.write_into(idx, val);
            Ok(())
        })?;
    }
    Ok((owned(py, &indptr), indices, data))
}

/// Overlap cost from two neighbourhood patterns given as CSR arrays.
#[pyfunction]
#[pyo3(signature = (a_indptr, a_indices, n_a, b_indptr, b_indices, n_b, f, witnesses, top_k=None, keep=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn overlap_cost_csr<'py>(
    py: Python<'py>,
    a_indptr: PyReadonlyArray1<'py, i64>,
    a_indices: PyReadonlyArray1<'py, i32>,
    n_a: usize,
    b_indptr: PyReadonlyArray1<'py, i64>,
    b_indices: PyReadonlyArray1<'py, i32>,
    n_b: usize,
    f: PyReadonlyArray1<'py, i64>,
    witnesses: PyReadonlyArray1<'py, bool>,
    top_k: Option<usize>,
    keep: Option<PyReadonlyArray1<'py, i64>>,
) -> PyResult<PyCsr<'py, u32>> {
    let a = pattern(&a_indptr, &a_indices, n_a, "nbrs_a")?;
    let b = pattern(&b_indptr, &b_indices, n_b, "nbrs_b")?;
    let f = u32_vec(&f, "f")?;
    let w: Vec<bool> = plain_vec(&witnesses);
    let keep = keep.map(|k| u32_vec(&k, "keep")).transpose()?;
    let opts = OverlapOptions {
        top_k,
        keep: keep.as_deref(),
    };
    let rows = detached(py, || overlap_rows(&a.view(), &b.view(), &f, &w, opts))?;
    overlap_out(py, rows)
}

/// The hop balls at radius k of both graphs, and the map and witnesses of a step, checked.
type StepInputs<'g> = (BallsAt<'g>, BallsAt<'g>, Vec<u32>, Vec<bool>);

fn step_inputs<'g>(
    a: &'g MeshGraph,
    b: &'g MeshGraph,
    k: usize,
    f: &PyReadonlyArray1<'_, i64>,
    witnesses: &PyReadonlyArray1<'_, bool>,
) -> PyResult<StepInputs<'g>> {
    if k > a.balls.k_max.min(b.balls.k_max) {
        return Err(PyValueError::new_err("k exceeds the graphs' k_max"));
    }
    Ok((
        BallsAt { balls: &a.balls, k },
        BallsAt { balls: &b.balls, k },
        u32_vec(f, "f")?,
        plain_vec(witnesses),
    ))
}

/// Each vertex's best-overlapping vertex of B at hop radius k between two prebuilt graphs,
/// without the one-to-one constraint (see `step::best_overlap`).
#[pyfunction]
pub(super) fn best_overlap_graphs<'py>(
    py: Python<'py>,
    a: &MeshGraph,
    b: &MeshGraph,
    k: usize,
    f: PyReadonlyArray1<'py, i64>,
    witnesses: PyReadonlyArray1<'py, bool>,
    top_k: Option<usize>,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (ra, rb, f, w) = step_inputs(a, b, k, &f, &witnesses)?;
    let g = detached(py, || best_overlap(&ra, &rb, &f, &w, top_k))?;
    Ok(owned(py, &g))
}

/// One HOPE step between two prebuilt graphs at hop radius k: the overlap cost with the
/// current-match bonus, solved exactly (see `step::overlap_assignment`), without the cost ever
/// reaching Python. Returns the map and the seconds spent building the cost and solving it.
#[pyfunction]
#[pyo3(signature = (a, b, k, f, witnesses, top_k, keep, hint, floor_div, stay))]
#[allow(clippy::too_many_arguments)]
pub(super) fn overlap_assignment_graphs<'py>(
    py: Python<'py>,
    a: &MeshGraph,
    b: &MeshGraph,
    k: usize,
    f: PyReadonlyArray1<'py, i64>,
    witnesses: PyReadonlyArray1<'py, bool>,
    top_k: Option<usize>,
    keep: PyReadonlyArray1<'py, i64>,
    hint: PyReadonlyArray1<'py, i64>,
    floor_div: i64,
    stay: u32,
) -> PyResult<(Bound<'py, PyArray1<i64>>, f64, f64)> {
    let (ra, rb, f, w) = step_inputs(a, b, k, &f, &witnesses)?;
    let keep = u32_vec(&keep, "keep")?;
    let hint = plain_vec(&hint);
    let opts = StepOptions {
        top_k,
        floor_div,
        stay,
    };
    let (g, t) = detached(py, || {
        overlap_assignment_timed(&ra, &rb, &f, &w, &keep, &hint, opts)
    })?;
    Ok((owned(py, &g), t.cost, t.assign))
}

/// The cost one [`overlap_assignment_graphs`] step solves (overlap counts with the
/// current-match bonus, `keep` stored in every row), as CSR arrays: for replaying steps.
#[pyfunction]
#[pyo3(signature = (a, b, k, f, witnesses, top_k, keep, stay))]
#[allow(clippy::too_many_arguments)]
pub(super) fn overlap_step_cost_graphs<'py>(
    py: Python<'py>,
    a: &MeshGraph,
    b: &MeshGraph,
    k: usize,
    f: PyReadonlyArray1<'py, i64>,
    witnesses: PyReadonlyArray1<'py, bool>,
    top_k: Option<usize>,
    keep: PyReadonlyArray1<'py, i64>,
    stay: u32,
) -> PyResult<PyCsr<'py, i64>> {
    let (ra, rb, f, w) = step_inputs(a, b, k, &f, &witnesses)?;
    let keep = u32_vec(&keep, "keep")?;
    let cost = detached(py, || step_cost(&ra, &rb, &f, &w, top_k, &keep, stay))?;
    // As i64, the type the assignment bindings take.
    let cost = Csr {
        n_rows: cost.n_rows,
        n_cols: cost.n_cols,
        data: cost.data.iter().map(|&v| v as i64).collect(),
        indptr: cost.indptr,
        indices: cost.indices,
    };
    Ok(csr_out(py, cost))
}
