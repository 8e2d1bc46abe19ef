//! The thin `hope_rs._core` extension module: converts NumPy buffers into owned Rust data
//! (`convert`), wraps the kernels (the `bind_*` files, by concern), releases the GIL around them
//! (`detached`) and maps every core error to a Python exception in one place (`to_py_err`).
mod bind_assignment;
mod bind_descriptors;
mod bind_geometry;
mod bind_graph;
mod bind_lmd;
mod bind_overlap;
mod convert;

use crate::error::CoreError;
use bind_assignment::{
    py_auction_assignment_float, py_auction_assignment_int, py_warm_assignment_int,
};
use bind_descriptors::{py_nearest_among, py_shot_descriptors};
use bind_geometry::{
    closest_rotations, collapse_to_sites, edge_rotations, greedy_pairs, grow_across_faces,
    PyPointClusters,
};
use bind_graph::{khop_neighbourhoods, MeshGraph};
use bind_lmd::local_map_distortion_graphs;
use bind_overlap::{
    best_overlap_graphs, overlap_assignment_graphs, overlap_cost_csr, overlap_step_cost_graphs,
};
use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};

pyo3::create_exception!(
    _core,
    DuplicateEntries,
    PyValueError,
    "A sparse cost stores one entry twice."
);

/// The one place where core errors become Python exceptions.
fn to_py_err(e: CoreError) -> PyErr {
    match e {
        CoreError::Duplicate { .. } => DuplicateEntries::new_err(e.to_string()),
        CoreError::OutOfMemory { .. } => PyMemoryError::new_err(e.to_string()),
        CoreError::InvalidInput(_) | CoreError::Infeasible { .. } => {
            PyValueError::new_err(e.to_string())
        }
    }
}

/// Runs `work` without the GIL; a panic becomes a RuntimeError instead of reaching the user raw.
/// A Ctrl-C that arrived meanwhile is raised as soon as it returns, before its result is
/// handed to NumPy.
fn detached<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> crate::error::Result<T> + Send,
) -> PyResult<T> {
    let out = py
        .detach(|| catch_unwind(AssertUnwindSafe(work)))
        .map_err(|_| PyRuntimeError::new_err("internal error in hope_rs (please report it)"))?
        .map_err(to_py_err);
    py.check_signals()?;
    out
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<MeshGraph>()?;
    m.add_class::<PyPointClusters>()?;
    m.add("DuplicateEntries", m.py().get_type::<DuplicateEntries>())?;
    m.add_function(wrap_pyfunction!(khop_neighbourhoods, m)?)?;
    m.add_function(wrap_pyfunction!(overlap_cost_csr, m)?)?;
    m.add_function(wrap_pyfunction!(best_overlap_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(local_map_distortion_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(py_auction_assignment_int, m)?)?;
    m.add_function(wrap_pyfunction!(overlap_assignment_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(overlap_step_cost_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(py_warm_assignment_int, m)?)?;
    m.add_function(wrap_pyfunction!(py_auction_assignment_float, m)?)?;
    m.add_function(wrap_pyfunction!(py_shot_descriptors, m)?)?;
    m.add_function(wrap_pyfunction!(greedy_pairs, m)?)?;
    m.add_function(wrap_pyfunction!(py_nearest_among, m)?)?;
    m.add_function(wrap_pyfunction!(closest_rotations, m)?)?;
    m.add_function(wrap_pyfunction!(edge_rotations, m)?)?;
    m.add_function(wrap_pyfunction!(grow_across_faces, m)?)?;
    m.add_function(wrap_pyfunction!(collapse_to_sites, m)?)?;
    Ok(())
}
