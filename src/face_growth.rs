//! Growing a partial vertex map across the faces two meshes share.
//!
//! Where A and B are one triangulation in two poses, a face (u, v, w) of A whose edge (u, v) is
//! mapped onto an edge of B names the image of w: the third vertex of the face of B on the same
//! side of that edge. Where the triangulations differ (a retriangulated region), that vertex is
//! wrong, and wrong images then spread. A proposal is therefore kept only if the two triangles
//! have nearly the same shape, and the best-shaped proposals are taken first.
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

use crate::error::{invalid, Result};

const NONE: i64 = -1;
/// A half-edge of B that two faces claim (a non-manifold edge or flipped orientation).
const AMBIGUOUS: u32 = u32::MAX;

/// Position of `w` relative to the edge (u, v), in units of its length: the coordinate along
/// the edge and the distance from its line. `None` for a degenerate edge.
fn edge_coordinates(u: [f64; 3], v: [f64; 3], w: [f64; 3]) -> Option<(f64, f64)> {
    let e = [v[0] - u[0], v[1] - u[1], v[2] - u[2]];
    let d = [w[0] - u[0], w[1] - u[1], w[2] - u[2]];
    let ee = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
    if ee.is_nan() || ee <= 0.0 {
        return None;
    }
    let along = (d[0] * e[0] + d[1] * e[1] + d[2] * e[2]) / ee;
    let p = [
        d[0] - along * e[0],
        d[1] - along * e[1],
        d[2] - along * e[2],
    ];
    let off = ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) / ee).sqrt();
    Some((along, off))
}

/// How differently shaped the triangles (u, v, w) of A and (u', v', w') of B are: the distance
/// between w's and w''s coordinates relative to their edge (0 for similar triangles; a few
/// tenths for a strong stretch; about one edge length for a neighbouring vertex).
pub fn shape_error(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> Option<f64> {
    let (s, t) = edge_coordinates(a[0], a[1], a[2])?;
    let (s2, t2) = edge_coordinates(b[0], b[1], b[2])?;
    let e = (s - s2).hypot(t - t2);
    e.is_finite().then_some(e)
}

fn check_faces(faces: &[[u32; 3]], n: usize, name: &str) -> Result<()> {
    if faces.iter().flatten().any(|&x| x as usize >= n) {
        return invalid(format!("faces of {name} must index its {n} vertices"));
    }
    Ok(())
}

/// Extends `map` (A's vertex → B's vertex, −1 where unknown; one-to-one where known) across the
/// faces of A that map onto faces of B with the same orientation, keeping a proposal only if
/// its triangles' [`shape_error`] is below `max_error`, lowest first. Known entries never change.
pub fn grow_across_faces(
    faces_a: &[[u32; 3]],
    points_a: &[[f64; 3]],
    faces_b: &[[u32; 3]],
    points_b: &[[f64; 3]],
    map: &[i64],
    max_error: f64,
) -> Result<Vec<i64>> {
    let (n_a, n_b) = (points_a.len(), points_b.len());
    if map.len() != n_a {
        return invalid(format!(
            "the partial map needs one entry per vertex of A ({n_a}), got {}",
            map.len()
        ));
    }
    if max_error.is_nan() || max_error < 0.0 {
        return invalid(format!("max_error must be a number >= 0, got {max_error}"));
    }
    check_faces(faces_a, n_a, "A")?;
    check_faces(faces_b, n_b, "B")?;
    let mut g = map.to_vec();
    let mut inv = vec![NONE; n_b];
    for (i, &x) in g.iter().enumerate() {
        if x == NONE {
            continue;
        }
        if x < 0 || x as usize >= n_b {
            return invalid(format!(
                "partial map entries must be -1 or vertices of B (0..{n_b}), got {x}"
            ));
        }
        if inv[x as usize] != NONE {
            return invalid(format!(
                "the partial map must be one-to-one: vertices {} and {i} both map to {x}",
                inv[x as usize]
            ));
        }
        inv[x as usize] = i as i64;
    }

    let mut third = HashMap::with_capacity(3 * faces_b.len());
    for &[p, q, r] in faces_b {
        for (u, v, w) in [(p, q, r), (q, r, p), (r, p, q)] {
            third
                .entry((u, v))
                .and_modify(|x| *x = AMBIGUOUS)
                .or_insert(w);
        }
    }
    // A's half-edges (u, v, w) listed under u and under v: the ones a new image of either enables.
    let half: Vec<[u32; 3]> = faces_a
        .iter()
        .flat_map(|&[p, q, r]| [[p, q, r], [q, r, p], [r, p, q]])
        .collect();
    let mut start = vec![0usize; n_a + 1];
    for h in &half {
        start[h[0] as usize + 1] += 1;
        start[h[1] as usize + 1] += 1;
    }
    for i in 0..n_a {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut incident = vec![0u32; 2 * half.len()];
    for (i, h) in half.iter().enumerate() {
        for &p in &h[..2] {
            incident[fill[p as usize]] = i as u32;
            fill[p as usize] += 1;
        }
    }

    // Non-negative finite f64s order like their bit patterns; ties go to the lower indices.
    let mut heap = BinaryHeap::new();
    let propose = |h: [u32; 3], g: &[i64], inv: &[i64], heap: &mut BinaryHeap<_>| {
        let [u, v, w] = h.map(|x| x as usize);
        if g[u] == NONE || g[v] == NONE || g[w] != NONE {
            return;
        }
        let (gu, gv) = (g[u] as u32, g[v] as u32);
        let Some(&x) = third.get(&(gu, gv)) else {
            return;
        };
        if x == AMBIGUOUS || inv[x as usize] != NONE {
            return;
        }
        let ta = [points_a[u], points_a[v], points_a[w]];
        let tb = [
            points_b[gu as usize],
            points_b[gv as usize],
            points_b[x as usize],
        ];
        if let Some(e) = shape_error(ta, tb) {
            if e < max_error {
                heap.push(Reverse((e.to_bits(), w as u32, x)));
            }
        }
    };
    for &h in &half {
        propose(h, &g, &inv, &mut heap);
    }
    while let Some(Reverse((_, w, x))) = heap.pop() {
        let (w, x) = (w as usize, x as usize);
        if g[w] != NONE || inv[x] != NONE {
            continue;
        }
        g[w] = x as i64;
        inv[x] = w as i64;
        for &i in &incident[start[w]..start[w + 1]] {
            propose(half[i as usize], &g, &inv, &mut heap);
        }
    }
    Ok(g)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A (w + 1) × (h + 1) grid of vertices, two triangles per cell, counter-clockwise.
    fn grid(w: u32, h: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let id = |i: u32, j: u32| j * (w + 1) + i;
        let mut points = Vec::new();
        for j in 0..=h {
            for i in 0..=w {
                // Jittered so that no two triangles are alike by accident.
                let jit = ((i * 7 + j * 13) % 5) as f64 * 0.03;
                points.push([i as f64 + jit, j as f64 - jit, 0.0]);
            }
        }
        let mut faces = Vec::new();
        for j in 0..h {
            for i in 0..w {
                faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (points, faces)
    }

    /// B = A with vertex i renumbered to perm[i] (faces renumbered alike) and its points
    /// stretched by 20% along x.
    fn relabelled(
        points: &[[f64; 3]],
        faces: &[[u32; 3]],
        perm: &[u32],
    ) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut pb = vec![[0.0; 3]; points.len()];
        for (i, p) in points.iter().enumerate() {
            pb[perm[i] as usize] = [1.2 * p[0], p[1], p[2]];
        }
        let fb = faces.iter().map(|f| f.map(|x| perm[x as usize])).collect();
        (pb, fb)
    }

    fn permutation(n: u32) -> Vec<u32> {
        (0..n).map(|i| (i * 37 + 11) % n).collect()
    }

    #[test]
    fn one_mapped_face_grows_into_the_whole_shared_triangulation() {
        let (pa, fa) = grid(8, 6);
        let n = pa.len() as u32;
        let perm = permutation(n);
        let mut sorted = perm.clone();
        sorted.sort_unstable();
        assert!(sorted.iter().enumerate().all(|(i, &x)| x == i as u32));
        let (pb, fb) = relabelled(&pa, &fa, &perm);
        let mut map = vec![NONE; n as usize];
        for &v in &fa[20] {
            map[v as usize] = perm[v as usize] as i64;
        }
        let g = grow_across_faces(&fa, &pa, &fb, &pb, &map, 0.3).unwrap();
        let want: Vec<i64> = perm.iter().map(|&x| x as i64).collect();
        assert_eq!(g, want);
    }

    #[test]
    fn a_retriangulated_cell_is_not_grown_into_from_a_misshapen_face() {
        let (pa, fa) = grid(4, 4);
        let n = pa.len();
        let perm: Vec<u32> = (0..n as u32).collect();
        let (pb, mut fb) = relabelled(&pa, &fa, &perm);
        // Flip the diagonal of cell (1, 1) in B: its triangles become (a, b, d) and (b, c, d).
        let (a, b, c, d) = (6, 7, 12, 11);
        let k = fb.iter().position(|f| *f == [a, b, c]).unwrap();
        fb[k] = [a, b, d];
        let k = fb.iter().position(|f| *f == [a, c, d]).unwrap();
        fb[k] = [b, c, d];
        // Only the bottom row is known. Crossing edge (a, b) of A's face (a, b, c) proposes d
        // for c, a misshapen triangle; c must come from a face both meshes share.
        let at = |t: [usize; 3], p: &[[f64; 3]]| t.map(|i| p[i]);
        assert!(
            shape_error(
                at([a, b, c].map(|x| x as usize), &pa),
                at([a, b, d].map(|x| x as usize), &pb)
            )
            .unwrap()
                > 0.3
        );
        let mut map = vec![NONE; n];
        for (v, x) in map.iter_mut().enumerate().take(5) {
            *x = v as i64;
        }
        let g = grow_across_faces(&fa, &pa, &fb, &pb, &map, 0.3).unwrap();
        let want: Vec<i64> = (0..n as i64).collect();
        assert_eq!(g, want);
    }

    #[test]
    fn known_entries_stay_and_bad_partial_maps_are_refused() {
        let (pa, fa) = grid(3, 3);
        let n = pa.len();
        let mut map = vec![NONE; n];
        map[0] = 5; // wrong, but known entries are kept as given
        let g = grow_across_faces(&fa, &pa, &fa, &pa, &map, 0.3).unwrap();
        assert_eq!(g[0], 5);
        map[1] = 5;
        assert!(grow_across_faces(&fa, &pa, &fa, &pa, &map, 0.3).is_err());
        map[1] = n as i64;
        assert!(grow_across_faces(&fa, &pa, &fa, &pa, &map, 0.3).is_err());
        assert!(grow_across_faces(&fa, &pa, &fa, &pa, &map[1..], 0.3).is_err());
        assert!(grow_across_faces(&fa, &pa, &fa, &pa, &vec![NONE; n], f64::NAN).is_err());
        let bad = vec![[0, 1, n as u32]];
        assert!(grow_across_faces(&bad, &pa, &fa, &pa, &vec![NONE; n], 0.3).is_err());
    }

    #[test]
    fn shape_error_is_zero_for_similar_triangles_and_none_for_a_degenerate_edge() {
        let a = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.8, 0.0]];
        let b = a.map(|p| [2.0 * p[1] + 5.0, -2.0 * p[0], 3.0]); // rotated, scaled, moved
        assert!(shape_error(a, b).unwrap() < 1e-12);
        let c = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.3, 0.8, 0.0]];
        assert!((shape_error(a, c).unwrap() - 1.0).abs() < 1e-12);
        assert!(shape_error([a[0], a[0], a[2]], b).is_none());
    }
}
