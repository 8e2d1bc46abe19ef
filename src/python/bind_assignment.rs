//! The exact sparse assignment solvers on integer and float costs given as CSR arrays.
use super::convert::{convert_vec, cost_csr, owned, plain_vec};
use super::detached;
use crate::auction::{
    auction_assignment_float, auction_assignment_int_hinted, warm_assignment, DEFAULT_FLOOR_DIV,
};
use crate::csr::{Csr, CsrView};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;

/// Runs `solver` on an owned cost without the GIL.
fn solve_assignment<'py, T: Sync>(
    py: Python<'py>,
    cost: Csr<T>,
    solver: impl FnOnce(&CsrView<T>) -> crate::error::Result<Vec<i64>> + Send,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let g = detached(py, || solver(&cost.view()))?;
    Ok(owned(py, &g))
}

/// Optimal assignment on an integer sparse cost; -1 marks unassigned rows. `floor_div`: see
/// `auction_assignment_int_with` (HOPE's refinement passes 16); `hint`: a full assignment in
/// the pattern that proves feasibility (see `auction_assignment_int_hinted`).
#[pyfunction]
#[pyo3(name = "auction_assignment_int", signature = (indptr, indices, data, n_rows, n_cols, maximize, floor_div=DEFAULT_FLOOR_DIV, hint=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn py_auction_assignment_int<'py>(
    py: Python<'py>,
    indptr: PyReadonlyArray1<'py, i64>,
    indices: PyReadonlyArray1<'py, i32>,
    data: PyReadonlyArray1<'py, i64>,
    n_rows: usize,
    n_cols: usize,
    maximize: bool,
    floor_div: i64,
    hint: Option<PyReadonlyArray1<'py, i64>>,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let hint = hint.map(|h| plain_vec(&h));
    let hint = hint.as_deref();
    // Values that fit in 32 bits (every overlap cost) are copied as such: half the memory to
    // fault in and to stream through the solver's rescans (28k, k = 8: 28M values).
    match convert_vec::<i64, i32>(&data, "cost data") {
        Ok(narrow) => solve_assignment(
            py,
            cost_csr(&indptr, &indices, narrow, n_rows, n_cols)?,
            |c| auction_assignment_int_hinted(c, maximize, floor_div, hint),
        ),
        Err(_) => solve_assignment(
            py,
            cost_csr(&indptr, &indices, plain_vec(&data), n_rows, n_cols)?,
            |c| auction_assignment_int_hinted(c, maximize, floor_div, hint),
        ),
    }
}

/// Optimal assignment on a float sparse cost; -1 marks unassigned rows.
#[pyfunction]
#[pyo3(name = "auction_assignment_float")]
pub(super) fn py_auction_assignment_float<'py>(
    py: Python<'py>,
    indptr: PyReadonlyArray1<'py, i64>,
    indices: PyReadonlyArray1<'py, i32>,
    data: PyReadonlyArray1<'py, f64>,
    n_rows: usize,
    n_cols: usize,
    maximize: bool,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let cost = cost_csr(&indptr, &indices, plain_vec(&data), n_rows, n_cols)?;
    solve_assignment(py, cost, |c| auction_assignment_float(c, maximize))
}

/// A warm-started exact solve (see `auction::warm_assignment`) of a maximisation on an integer
/// sparse cost: (assignment, prices, rows repaired, unique) or None when the warm start does
/// not apply (the caller then solves cold).
#[pyfunction]
#[pyo3(name = "warm_assignment_int")]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(super) fn py_warm_assignment_int<'py>(
    py: Python<'py>,
    indptr: PyReadonlyArray1<'py, i64>,
    indices: PyReadonlyArray1<'py, i32>,
    data: PyReadonlyArray1<'py, i64>,
    n_rows: usize,
    n_cols: usize,
    prev: PyReadonlyArray1<'py, i64>,
    prices: PyReadonlyArray1<'py, i64>,
    max_repair: usize,
) -> PyResult<
    Option<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        usize,
        bool,
    )>,
> {
    let cost = cost_csr(&indptr, &indices, plain_vec(&data), n_rows, n_cols)?;
    let prev = plain_vec(&prev);
    let prices = plain_vec(&prices);
    let out = detached(py, || {
        warm_assignment(&cost.view(), &prev, &prices, max_repair)
    })?;
    Ok(out.map(|s| {
        (
            owned(py, &s.assign),
            owned(py, &s.prices),
            s.repaired,
            s.unique,
        )
    }))
}
