//! Mesh faces → undirected vertex adjacency in CSR form (sorted, no self-loops, no duplicates).
use crate::csr::Csr;
use crate::error::{invalid, Result};
use crate::memory::{check_budget, try_filled_vec};
use rayon::prelude::*;

/// Most vertices a graph may have: column indices reach Python as scipy's int32.
pub const MAX_VERTICES: usize = i32::MAX as usize;
/// Bytes per vertex this module and a k-hop pattern on top of it need at least (three counting
/// arrays, a row vector, and the output's index pointer and self entry), for the up-front
/// memory check.
const BYTES_PER_VERTEX: usize = 3 * 8 + 24 + 8 + 4 + 1;

/// Adjacency of the edge graph of a triangle mesh with `n_vertices` vertices.
///
/// Vertices referenced by no face become isolated rows; degenerate faces (repeated indices)
/// contribute only their distinct edges.
pub fn adjacency_from_faces(faces: &[[u32; 3]], n_vertices: usize) -> Result<Csr<()>> {
    if n_vertices > MAX_VERTICES {
        return invalid(format!(
            "n_vertices = {n_vertices} is too large: at most {MAX_VERTICES} vertices are \
             supported (scipy's int32 indices)"
        ));
    }
    let what = format!("the edge graph of {n_vertices} vertices");
    check_budget(n_vertices.checked_mul(BYTES_PER_VERTEX), &what)?;
    if let Some((i, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v as usize >= n_vertices))
    {
        return invalid(format!(
            "faces[{i}] = {f:?} refers to a vertex >= n_vertices = {n_vertices}"
        ));
    }
    // Counting sort by source vertex keeps this O(m) and allocation-light on big meshes.
    let mut degree = try_filled_vec(n_vertices + 1, 0usize, &what)?;
    for f in faces {
        for e in 0..3 {
            let (a, b) = (f[e], f[(e + 1) % 3]);
            if a != b {
                degree[a as usize] += 1;
                degree[b as usize] += 1;
            }
        }
    }
    let mut start = try_filled_vec(n_vertices + 1, 0usize, &what)?;
    for v in 0..n_vertices {
        start[v + 1] = start[v] + degree[v];
    }
    let mut fill = start.clone();
    let mut nbr = vec![0u32; start[n_vertices]];
    for f in faces {
        for e in 0..3 {
            let (a, b) = (f[e], f[(e + 1) % 3]);
            if a != b {
                nbr[fill[a as usize]] = b;
                fill[a as usize] += 1;
                nbr[fill[b as usize]] = a;
                fill[b as usize] += 1;
            }
        }
    }
    let rows: Vec<Vec<u32>> = (0..n_vertices)
        .into_par_iter()
        .map(|v| {
            let mut r = nbr[start[v]..start[v + 1]].to_vec();
            r.sort_unstable();
            r.dedup();
            r
        })
        .collect();
    Ok(from_rows(rows, n_vertices))
}

/// Concatenates per-row column lists into a pattern CSR.
pub fn from_rows(rows: Vec<Vec<u32>>, n_cols: usize) -> Csr<()> {
    let mut indptr = Vec::with_capacity(rows.len() + 1);
    indptr.push(0);
    let total: usize = rows.iter().map(Vec::len).sum();
    let mut indices = Vec::with_capacity(total);
    for r in &rows {
        indices.extend_from_slice(r);
        indptr.push(indices.len());
    }
    Csr {
        n_rows: rows.len(),
        n_cols,
        indptr,
        indices,
        data: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_triangles_share_an_edge() {
        let a = adjacency_from_faces(&[[0, 1, 2], [2, 1, 3]], 5).unwrap();
        assert_eq!(a.indptr, vec![0, 2, 5, 8, 10, 10]);
        assert_eq!(a.indices, vec![1, 2, 0, 2, 3, 0, 1, 3, 1, 2]);
    }

    #[test]
    fn degenerate_face_and_out_of_range() {
        let a = adjacency_from_faces(&[[0, 0, 1]], 2).unwrap();
        assert_eq!(a.indices, vec![1, 0]);
        assert!(adjacency_from_faces(&[[0, 1, 7]], 3).is_err());
    }

    #[test]
    fn absurd_vertex_counts_are_errors_not_aborts() {
        use crate::error::CoreError;
        let e = adjacency_from_faces(&[[0, 1, 2]], 1_000_000_000_000).unwrap_err();
        assert!(matches!(e, CoreError::InvalidInput(ref m) if m.contains("too large")));
        // Within the index range but beyond the machine's memory: refused up front.
        let n = MAX_VERTICES;
        if n * BYTES_PER_VERTEX > crate::memory::physical_memory() {
            let e = adjacency_from_faces(&[[0, 1, 2]], n).unwrap_err();
            assert!(matches!(e, CoreError::OutOfMemory { .. }), "{e:?}");
        }
    }
}
