//! The thin `hope_rs._core` extension module: converts NumPy buffers into owned Rust data,
//! releases the GIL around the kernels, and maps every core error to a Python exception here.
use crate::auction::{auction_assignment_float, auction_assignment_int_hinted, DEFAULT_FLOOR_DIV};
use crate::csr::{Csr, CsrView};
use crate::error::CoreError;
use crate::geodesic::{distance_fields, pair_distances, EdgeGraph};
use crate::graph::adjacency_from_faces;
use crate::khop::{khop_csr, HopBalls};
use crate::lmd::{lmd_table_cutoff, local_map_distortion, LocalDistances, RingDistances};
use crate::memory::{try_filled_vec, zeroed_vec};
use crate::overlap::{overlap_rows, BallsAt, OverlapOptions, OverlapRows};
use crate::shot::{shot_descriptors, shot_descriptors_at};
use crate::step::{best_overlap, overlap_assignment};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3,
};
use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use rayon::prelude::*;
use std::borrow::Cow;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Mutex};

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

fn faces_vec(faces: &PyReadonlyArray2<'_, i64>) -> PyResult<Vec<[u32; 3]>> {
    let a = faces.as_array();
    if a.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "faces must be an (M, 3) integer array, got (M, {})",
            a.ncols()
        )));
    }
    a.outer_iter()
        .map(|r| {
            let mut t = [0u32; 3];
            for (o, &x) in t.iter_mut().zip(r.iter()) {
                *o = u32::try_from(x).map_err(|_| {
                    PyValueError::new_err(format!("face index {x} is negative or too large"))
                })?;
            }
            Ok(t)
        })
        .collect()
}

fn points_vec(v: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 3]>> {
    let a = v.as_array();
    if a.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "vertices must be an (N, 3) float array, got (N, {})",
            a.ncols()
        )));
    }
    Ok(a.outer_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// Copies a 1-D NumPy array out as `U`, one range check per element. These copies hold tens of
/// millions of entries for a k = 8 cost, so contiguous arrays (the common case) are written in
/// parallel into one zeroed allocation: its pages are then first touched, and faulted in, by
/// both cores (collecting the converted items instead went through per-task buffers and a
/// second copy).
fn convert_vec<T, U>(a: &PyReadonlyArray1<'_, T>, what: &str) -> PyResult<Vec<U>>
where
    T: numpy::Element + Copy + TryInto<U> + std::fmt::Display + Sync,
    U: Send + Copy + Default,
{
    let out_of_range = |x: T| PyValueError::new_err(format!("{what} holds {x}, out of range"));
    match a.as_slice() {
        Ok(s) => {
            let mut out = zeroed_vec::<U>(s.len());
            let bad = out
                .par_chunks_mut(COPY_CHUNK)
                .zip(s.par_chunks(COPY_CHUNK))
                .find_map_any(|(dst, src)| {
                    for (d, &x) in dst.iter_mut().zip(src) {
                        match x.try_into() {
                            Ok(v) => *d = v,
                            Err(_) => return Some(x),
                        }
                    }
                    None
                });
            match bad {
                Some(x) => Err(out_of_range(x)),
                None => Ok(out),
            }
        }
        Err(_) => a
            .as_array()
            .iter()
            .map(|&x| x.try_into().map_err(|_| out_of_range(x)))
            .collect(),
    }
}

/// Entries per parallel task of the input copies.
const COPY_CHUNK: usize = 1 << 16;

fn u32_vec<T>(a: &PyReadonlyArray1<'_, T>, what: &str) -> PyResult<Vec<u32>>
where
    T: numpy::Element + Copy + TryInto<u32> + std::fmt::Display + Sync,
{
    convert_vec(a, what)
}

fn usize_vec(a: &PyReadonlyArray1<'_, i64>, what: &str) -> PyResult<Vec<usize>> {
    convert_vec(a, what)
}

fn plain_vec<T: numpy::Element + Copy + Default + Send + Sync>(
    a: &PyReadonlyArray1<'_, T>,
) -> Vec<T> {
    match a.as_slice() {
        Ok(s) => {
            let mut out = zeroed_vec::<T>(s.len());
            out.par_chunks_mut(COPY_CHUNK)
                .zip(s.par_chunks(COPY_CHUNK))
                .for_each(|(d, s)| d.copy_from_slice(s));
            out
        }
        Err(_) => a.as_array().to_vec(),
    }
}

/// A NumPy array that owns its memory. Arrays wrapping a Rust `Vec` have a non-array base,
/// on which NumPy refuses `flags.writeable = True`, and scipy's fancy indexing sets exactly
/// that on its broadcast views (`K[rows, result]` raised ValueError), so every result is
/// handed over as an ordinary array.
fn owned<'py, T: numpy::Element>(py: Python<'py>, v: &[T]) -> Bound<'py, PyArray1<T>> {
    PyArray1::from_slice(py, v)
}

type PyCsr<'py, T> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i32>>,
    Bound<'py, PyArray1<T>>,
);

/// Column indices as NumPy's i32 (scipy's index type for matrices this size).
fn indices_out<'py>(py: Python<'py>, v: &[u32]) -> Bound<'py, PyArray1<i32>> {
    debug_assert!(v.iter().all(|&x| x <= i32::MAX as u32));
    // SAFETY: u32 and i32 have the same size and alignment, and every index is < 2^31: each
    // kernel produces indices below a vertex count that came from an i32-indexable NumPy array.
    let as_i32 = unsafe { std::slice::from_raw_parts(v.as_ptr() as *const i32, v.len()) };
    owned(py, as_i32)
}

/// Hands a CSR to NumPy as scipy's (indptr, indices, data).
fn csr_out<T: numpy::Element>(py: Python<'_>, m: Csr<T>) -> PyCsr<'_, T> {
    let indptr: Vec<i64> = m.indptr.iter().map(|&x| x as i64).collect();
    (
        owned(py, &indptr),
        indices_out(py, &m.indices),
        owned(py, &m.data),
    )
}

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

/// Owned pattern built from (indptr, indices) arrays.
fn pattern(
    indptr: &PyReadonlyArray1<'_, i64>,
    indices: &PyReadonlyArray1<'_, i32>,
    n: usize,
    what: &str,
) -> PyResult<Csr<()>> {
    let m = Csr {
        n_rows: n,
        n_cols: n,
        indptr: usize_vec(indptr, what)?,
        indices: u32_vec(indices, what)?,
        data: Vec::new(),
    };
    m.view().validate(what, false).map_err(to_py_err)?;
    Ok(m)
}

/// A mesh's edge graph and hop balls up to `k_max`, built once and reused by every iteration.
#[pyclass(module = "hope_rs._core", frozen)]
struct MeshGraph {
    vertices: Vec<[f64; 3]>,
    adj: Csr<()>,
    /// Edge lengths in `adj`'s entry order (see `EdgeGraph::lengths`).
    lengths: Vec<f64>,
    balls: HopBalls,
    /// 2-ring distances for LMD; `None` when k_max < 2.
    rings: Option<RingDistances>,
    /// Local distances for LMD when this graph is the target, built on first use with the
    /// radius the first partner needed (a wider one replaces it when a partner needs more).
    lmd_table: Mutex<Option<Arc<LocalDistances>>>,
}

impl MeshGraph {
    fn edge_graph(&self) -> EdgeGraph<'_> {
        EdgeGraph {
            vertices: &self.vertices,
            adj: self.adj.view(),
            lengths: Cow::Borrowed(&self.lengths),
        }
    }

    /// The cached distance table, rebuilt when it does not reach `cutoff`.
    fn lmd_table(&self, cutoff: f64) -> Arc<LocalDistances> {
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

    /// Mean edge length of the mesh graph.
    fn mean_edge_length(&self) -> f64 {
        self.edge_graph().mean_edge_length()
    }
}

/// k-hop neighbourhoods of the mesh graph given by `faces` (M x 3) on `n_vertices` vertices.
#[pyfunction]
fn khop_neighbourhoods<'py>(
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
fn overlap_cost_csr<'py>(
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
fn best_overlap_graphs<'py>(
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
/// reaching Python.
#[pyfunction]
#[pyo3(signature = (a, b, k, f, witnesses, top_k, keep, hint, floor_div, stay))]
#[allow(clippy::too_many_arguments)]
fn overlap_assignment_graphs<'py>(
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
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (ra, rb, f, w) = step_inputs(a, b, k, &f, &witnesses)?;
    let keep = u32_vec(&keep, "keep")?;
    let hint = plain_vec(&hint);
    let g = detached(py, || {
        overlap_assignment(&ra, &rb, &f, &w, top_k, &keep, &hint, floor_div, stay)
    })?;
    Ok(owned(py, &g))
}

type PerVertexPair<'py> = (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>);

/// Local map distortion of `f` (A → B): (mean over the 2-ring, fraction of consistent neighbours).
/// `prev`: (an earlier map, its mean, its fraction); only vertices whose 2-ring maps differently
/// are recomputed (see `lmd::local_map_distortion`).
#[pyfunction]
#[pyo3(signature = (a, b, f, scale_a, scale_b, prev=None))]
fn local_map_distortion_graphs<'py>(
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

/// Owned sparse cost from (indptr, indices) arrays and values already copied out.
fn cost_csr<T>(
    indptr: &PyReadonlyArray1<'_, i64>,
    indices: &PyReadonlyArray1<'_, i32>,
    data: Vec<T>,
    n_rows: usize,
    n_cols: usize,
) -> PyResult<Csr<T>> {
    // The solvers validate the structure themselves (`check_header`).
    Ok(Csr {
        n_rows,
        n_cols,
        indptr: usize_vec(indptr, "cost indptr")?,
        indices: u32_vec(indices, "cost indices")?,
        data,
    })
}

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
fn py_auction_assignment_int<'py>(
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
fn py_auction_assignment_float<'py>(
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

/// SHOT descriptors, flat (n * 352) float32; of the vertices `centres` only when given.
#[pyfunction]
#[pyo3(name = "shot_descriptors", signature = (vertices, faces, radius, centres=None))]
fn py_shot_descriptors<'py>(
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

/// Rows of a 2-D float32 array, flattened and owned, with the row length.
fn f32_rows(a: &PyReadonlyArray2<'_, f32>) -> (Vec<f32>, usize) {
    let v = a.as_array();
    let flat = match v.as_slice() {
        Some(s) => s.to_vec(),
        None => v.iter().copied().collect(),
    };
    (flat, v.ncols())
}

/// For each query row, its nearest candidate row of `base` (see `nearest.rs`).
#[pyfunction]
#[pyo3(name = "nearest_among")]
fn py_nearest_among<'py>(
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

/// For each 3 × 3 matrix `M` of an (n, 3, 3) array, the rotation maximising `tr(R M)` (see
/// `rotation.rs`).
#[pyfunction]
fn closest_rotations<'py>(
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
    Ok(numpy::ndarray::Array3::from_shape_vec((n, 3, 3), r)
        .expect("n * 9 values")
        .into_pyarray(py))
}

/// Grows a partial map (−1 where unknown) across the faces A and B share (see
/// `face_growth.rs`).
#[pyfunction]
fn grow_across_faces<'py>(
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
fn greedy_pairs<'py>(
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

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<MeshGraph>()?;
    m.add("DuplicateEntries", m.py().get_type::<DuplicateEntries>())?;
    m.add_function(wrap_pyfunction!(khop_neighbourhoods, m)?)?;
    m.add_function(wrap_pyfunction!(overlap_cost_csr, m)?)?;
    m.add_function(wrap_pyfunction!(best_overlap_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(local_map_distortion_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(py_auction_assignment_int, m)?)?;
    m.add_function(wrap_pyfunction!(overlap_assignment_graphs, m)?)?;
    m.add_function(wrap_pyfunction!(py_auction_assignment_float, m)?)?;
    m.add_function(wrap_pyfunction!(py_shot_descriptors, m)?)?;
    m.add_function(wrap_pyfunction!(greedy_pairs, m)?)?;
    m.add_function(wrap_pyfunction!(py_nearest_among, m)?)?;
    m.add_function(wrap_pyfunction!(closest_rotations, m)?)?;
    m.add_function(wrap_pyfunction!(grow_across_faces, m)?)?;
    Ok(())
}
