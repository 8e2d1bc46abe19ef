//! The `MeshGraph` class (edge graph, hop balls and LMD distance tables of one mesh, built once)
//! and the one-shot `khop_neighbourhoods`.
use super::convert::{csr_out, faces_vec, owned, points_vec, u32_vec, PyCsr};
use super::detached;
use crate::csr::Csr;
use crate::geodesic::{distance_fields, farthest_point_fields, pair_distances, EdgeGraph};
use crate::graph::adjacency_from_faces;
use crate::khop::{khop_csr, HopBalls};
use crate::lmd::{LocalDistances, RingDistances};
use crate::memory::try_filled_vec;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::borrow::Cow;
use std::sync::{Arc, Mutex};

/// A pattern with every stored entry set to 1, as scipy expects of a boolean-like matrix.
fn ones(p: Csr<()>) -> crate::error::Result<Csr<u8>> {
    let data = try_filled_vec(p.nnz(), 1u8, "the pattern's values")?;
    Ok(Csr {
        n_rows: p.n_rows,
        n_cols: p.n_cols,
        indptr: p.indptr,
        indices: p.indices,
        data,
    })
}

/// Farthest-point samples and their distance fields.
type SamplesOut<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray2<f64>>);

/// A mesh's edge graph and hop balls up to `k_max`, built once and reused by every iteration.
#[pyclass(module = "hope_rs._core", frozen)]
pub(super) struct MeshGraph {
    vertices: Vec<[f64; 3]>,
    adj: Csr<()>,
    /// Edge lengths in `adj`'s entry order (see `EdgeGraph::lengths`).
    lengths: Vec<f64>,
    pub(super) balls: HopBalls,
    /// 2-ring distances for LMD; `None` when k_max < 2.
    pub(super) rings: Option<RingDistances>,
    /// Local distances for LMD when this graph is the target, built on first use with the
    /// radius the first partner needed (a wider one replaces it when a partner needs more).
    lmd_table: Mutex<Option<Arc<LocalDistances>>>,
}

impl MeshGraph {
    pub(super) fn edge_graph(&self) -> EdgeGraph<'_> {
        EdgeGraph {
            vertices: &self.vertices,
            adj: self.adj.view(),
            lengths: Cow::Borrowed(&self.lengths),
        }
    }

    /// The cached distance table, rebuilt when it does not reach `cutoff`.
    pub(super) fn lmd_table(&self, cutoff: f64) -> Arc<LocalDistances> {
        let mut slot = self.lmd_table.lock().unwrap_or_else(|e| e.into_inner());
        match slot.as_ref() {
            Some(t) if t.cutoff >= cutoff => t.clone(),
            _ => {
                // Some slack, so partners of about the same resolution reuse it.
                let t = Arc::new(LocalDistances::new(&self.edge_graph(), cutoff * 1.25));
                *slot = Some(t.clone());
                t
            }
        }
    }
}

#[pymethods]
impl MeshGraph {
    #[new]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        k_max: usize,
    ) -> PyResult<Self> {
        let vertices = points_vec(&vertices)?;
        let faces = faces_vec(&faces)?;
        let (adj, lengths, balls, rings) = detached(py, || {
            let adj = adjacency_from_faces(&faces, vertices.len())?;
            let balls = HopBalls::new(&adj.view(), k_max)?;
            let g = EdgeGraph::new(&vertices, adj.view());
            let rings = if k_max >= 2 {
                Some(RingDistances::new(&g, &balls)?)
            } else {
                None
            };
            let lengths = g.lengths.into_owned();
            Ok((adj, lengths, balls, rings))
        })?;
        Ok(MeshGraph {
            vertices,
            adj,
            lengths,
            balls,
            rings,
            lmd_table: Mutex::new(None),
        })
    }

    #[getter]
    fn n_vertices(&self) -> usize {
        self.balls.n
    }

    #[getter]
    fn k_max(&self) -> usize {
        self.balls.k_max
    }

    /// (indptr, indices, data) of the k-hop neighbourhoods, columns sorted.
    fn khop<'py>(&self, py: Python<'py>, k: usize) -> PyResult<PyCsr<'py, u8>> {
        if k > self.balls.k_max {
            return Err(PyValueError::new_err(format!(
                "k = {k} exceeds this graph's k_max = {}",
                self.balls.k_max
            )));
        }
        let m = detached(py, || ones(self.balls.to_csr(k)))?;
        Ok(csr_out(py, m))
    }

    /// Edge-graph distance of each pair (sources[i], targets[i]); inf where disconnected.
    fn pair_distances<'py>(
        &self,
        py: Python<'py>,
        sources: PyReadonlyArray1<'py, i64>,
        targets: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let s = u32_vec(&sources, "sources")?;
        let t = u32_vec(&targets, "targets")?;
        let d = detached(py, || pair_distances(&self.edge_graph(), &s, &t))?;
        Ok(owned(py, &d))
    }

    /// Edge-graph distance from each source to every vertex, (len(sources), n); inf where
    /// disconnected.
    fn distance_fields<'py>(
        &self,
        py: Python<'py>,
        sources: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let s = u32_vec(&sources, "sources")?;
        let d = detached(py, || distance_fields(&self.edge_graph(), &s))?;
        let n = self.balls.n;
        owned(py, &d).reshape([s.len(), n])
    }

    /// Farthest-point samples of `candidates` from `start` (at most `n`) and their distance
    /// fields, (len(samples), n_vertices) (see `geodesic::farthest_point_fields`; `scale`
    /// divides the distances compared).
    fn farthest_fields<'py>(
        &self,
        py: Python<'py>,
        candidates: PyReadonlyArray1<'py, i64>,
        start: u32,
        n: usize,
        scale: f64,
    ) -> PyResult<SamplesOut<'py>> {
        let c = u32_vec(&candidates, "candidates")?;
        let (chosen, d) = detached(py, || {
            farthest_point_fields(&self.edge_graph(), &c, start, n, scale)
        })?;
        let k = chosen.len();
        let chosen: Vec<i64> = chosen.into_iter().map(i64::from).collect();
        Ok((
            owned(py, &chosen),
            owned(py, &d).reshape([k, self.balls.n])?,
        ))
    }

    /// Mean edge length of the mesh graph.
    fn mean_edge_length(&self) -> f64 {
        self.edge_graph().mean_edge_length()
    }
}

/// k-hop neighbourhoods of the mesh graph given by `faces` (M x 3) on `n_vertices` vertices.
#[pyfunction]
pub(super) fn khop_neighbourhoods<'py>(
    py: Python<'py>,
    faces: PyReadonlyArray2<'py, i64>,
    k: usize,
    n_vertices: usize,
) -> PyResult<PyCsr<'py, u8>> {
    let faces = faces_vec(&faces)?;
    let m = detached(py, || {
        let adj = adjacency_from_faces(&faces, n_vertices)?;
        ones(khop_csr(&adj.view(), k)?)
    })?;
    Ok(csr_out(py, m))
}
