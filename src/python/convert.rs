//! NumPy arrays in and out: checked copies into owned Rust vectors (vertices, faces, indices,
//! CSR patterns and costs) and results handed back as NumPy-owned arrays.
use super::to_py_err;
use crate::csr::Csr;
use crate::memory::zeroed_vec;
use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;

pub(super) fn faces_vec(faces: &PyReadonlyArray2<'_, i64>) -> PyResult<Vec<[u32; 3]>> {
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

pub(super) fn points_vec(v: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 3]>> {
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
pub(super) fn convert_vec<T, U>(a: &PyReadonlyArray1<'_, T>, what: &str) -> PyResult<Vec<U>>
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

pub(super) fn u32_vec<T>(a: &PyReadonlyArray1<'_, T>, what: &str) -> PyResult<Vec<u32>>
where
    T: numpy::Element + Copy + TryInto<u32> + std::fmt::Display + Sync,
{
    convert_vec(a, what)
}

pub(super) fn usize_vec(a: &PyReadonlyArray1<'_, i64>, what: &str) -> PyResult<Vec<usize>> {
    convert_vec(a, what)
}

pub(super) fn plain_vec<T: numpy::Element + Copy + Default + Send + Sync>(
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
pub(super) fn owned<'py, T: numpy::Element>(py: Python<'py>, v: &[T]) -> Bound<'py, PyArray1<T>> {
    PyArray1::from_slice(py, v)
}

pub(super) type PyCsr<'py, T> = (
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
pub(super) fn csr_out<T: numpy::Element>(py: Python<'_>, m: Csr<T>) -> PyCsr<'_, T> {
    let indptr: Vec<i64> = m.indptr.iter().map(|&x| x as i64).collect();
    (
        owned(py, &indptr),
        indices_out(py, &m.indices),
        owned(py, &m.data),
    )
}

/// Owned pattern built from (indptr, indices) arrays.
pub(super) fn pattern(
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

/// Owned sparse cost from (indptr, indices) arrays and values already copied out.
pub(super) fn cost_csr<T>(
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

/// Rows of a 2-D float32 array, flattened and owned, with the row length.
pub(super) fn f32_rows(a: &PyReadonlyArray2<'_, f32>) -> (Vec<f32>, usize) {
    let v = a.as_array();
    let flat = match v.as_slice() {
        Some(s) => s.to_vec(),
        None => v.iter().copied().collect(),
    };
    (flat, v.ncols())
}
