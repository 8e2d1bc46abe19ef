//! Local map distortion of a map between two `MeshGraph`s.
use super::bind_graph::MeshGraph;
use super::convert::{owned, plain_vec, u32_vec};
use super::detached;
use crate::lmd::{lmd_table_cutoff, local_map_distortion};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

type PerVertexPair<'py> = (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>);

/// Local map distortion of `f` (A → B): (mean over the 2-ring, fraction of consistent neighbours).
/// `prev`: (an earlier map, its mean, its fraction); only vertices whose 2-ring maps differently
/// are recomputed (see `lmd::local_map_distortion`).
#[pyfunction]
#[pyo3(signature = (a, b, f, scale_a, scale_b, prev=None))]
pub(super) fn local_map_distortion_graphs<'py>(
    py: Python<'py>,
    a: &MeshGraph,
    b: &MeshGraph,
    f: PyReadonlyArray1<'py, i64>,
    scale_a: f64,
    scale_b: f64,
    prev: Option<PrevLmd<'py>>,
) -> PyResult<PerVertexPair<'py>> {
    let f = u32_vec(&f, "f")?;
    let prev = prev
        .map(|(pf, pm, pc)| -> PyResult<_> {
            Ok((
                u32_vec(&pf, "previous map")?,
                plain_vec(&pm),
                plain_vec(&pc),
            ))
        })
        .transpose()?;
    let rings = a
        .rings
        .as_ref()
        .ok_or_else(|| PyValueError::new_err("LMD needs a source graph built with k_max >= 2"))?;
    let (mean, frac) = detached(py, || {
        let table = b.lmd_table(lmd_table_cutoff(rings, scale_a, scale_b));
        local_map_distortion(
            &a.balls,
            rings,
            &b.edge_graph(),
            &f,
            scale_a,
            scale_b,
            Some(&table),
            prev.as_ref()
                .map(|(pf, pm, pc)| (pf.as_slice(), pm.as_slice(), pc.as_slice())),
        )
    })?;
    Ok((owned(py, &mean), owned(py, &frac)))
}

type PrevLmd<'py> = (
    PyReadonlyArray1<'py, i64>,
    PyReadonlyArray1<'py, f32>,
    PyReadonlyArray1<'py, f32>,
);
