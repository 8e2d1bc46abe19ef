//! Coarsening a triangle mesh by manifold-keeping half-edge collapses.
//!
//! Each vertex is merged into its cluster's site one half-edge collapse at a time, along the
//! shortest-path tree from the site (farthest vertices first), and a collapse is made only when
//! it keeps the mesh a manifold (the link condition of Dey et al. 1999, the boundary kept) and
//! turns no face over. A vertex whose collapses are all refused stays. Every kept vertex is a
//! vertex of the input; genus and orientation are kept. The shortest-path tree (distance,
//! predecessor and site of each vertex) is computed by the caller.
use crate::error::{invalid, Result};

/// No predecessor or site (a vertex no site reaches).
const NONE: u32 = u32::MAX;

/// A coarse copy: coarse vertex `j` is input vertex `sites[j]`, input vertex `i` was merged
/// into coarse vertex `owner[i]`, and `faces` are the remaining faces in coarse numbering
/// (orientation kept).
#[derive(Debug, Clone, PartialEq)]
pub struct Collapsed {
    pub sites: Vec<u32>,
    pub owner: Vec<u32>,
    pub faces: Vec<[u32; 3]>,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Sorted `a` ∩ sorted `b` equals sorted `c`.
fn intersection_is(a: &[u32], b: &[u32], c: &[u32]) -> bool {
    let (mut i, mut j, mut k) = (0, 0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                if c.get(k) != Some(&a[i]) {
                    return false;
                }
                k += 1;
                i += 1;
                j += 1;
            }
        }
    }
    k == c.len()
}

/// A triangle mesh under half-edge collapses.
struct Collapser<'a> {
    points: &'a [[f64; 3]],
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    /// The live faces at each vertex.
    vfaces: Vec<Vec<u32>>,
    /// The vertex each removed vertex was merged into (itself while kept).
    merged_into: Vec<u32>,
}

impl<'a> Collapser<'a> {
    fn new(points: &'a [[f64; 3]], faces: &[[u32; 3]]) -> Self {
        let mut vfaces = vec![Vec::new(); points.len()];
        for (i, f) in faces.iter().enumerate() {
            for &x in f {
                vfaces[x as usize].push(i as u32);
            }
        }
        Collapser {
            points,
            faces: faces.to_vec(),
            face_alive: vec![true; faces.len()],
            vfaces,
            merged_into: (0..points.len() as u32).collect(),
        }
    }

    /// The other corners of `u`'s faces, with repeats (one per face).
    fn corners(&self, u: u32) -> Vec<u32> {
        let mut out = Vec::with_capacity(2 * self.vfaces[u as usize].len());
        for &i in &self.vfaces[u as usize] {
            out.extend(self.faces[i as usize].iter().filter(|&&x| x != u));
        }
        out.sort_unstable();
        out
    }

    /// The neighbours of `u`, sorted.
    fn neighbours(&self, u: u32) -> Vec<u32> {
        let mut out = self.corners(u);
        out.dedup();
        out
    }

    /// Whether an edge at `u` lies on one face only.
    fn on_boundary(&self, u: u32) -> bool {
        let c = self.corners(u);
        c.chunk_by(|a, b| a == b).any(|run| run.len() == 1)
    }

    fn normal(&self, f: [u32; 3]) -> [f64; 3] {
        let p = |x: u32| self.points[x as usize];
        cross(sub(p(f[1]), p(f[0])), sub(p(f[2]), p(f[0])))
    }

    /// Whether removing `u` into its neighbour `w` keeps a manifold with no face turned over
    /// or flattened.
    fn can_collapse(&self, u: u32, w: u32) -> bool {
        let shared: Vec<u32> = self.vfaces[u as usize]
            .iter()
            .copied()
            .filter(|&i| self.faces[i as usize].contains(&w))
            .collect();
        if shared.is_empty() {
            return false; // not an edge
        }
        let mut opposite: Vec<u32> = shared
            .iter()
            .flat_map(|&i| self.faces[i as usize])
            .filter(|&x| x != u && x != w)
            .collect();
        opposite.sort_unstable();
        opposite.dedup();
        // Link condition: the only common neighbours of u and w are the edge's opposite
        // corners (otherwise the collapse makes a non-manifold edge or a duplicate face).
        if !intersection_is(&self.neighbours(u), &self.neighbours(w), &opposite) {
            return false;
        }
        // The boundary keeps its shape: a boundary vertex moves only along a boundary edge.
        if shared.len() != 1 && self.on_boundary(u) {
            return false;
        }
        for &i in &self.vfaces[u as usize] {
            if shared.contains(&i) {
                continue;
            }
            let f = self.faces[i as usize];
            let before = self.normal(f);
            let after = self.normal(f.map(|x| if x == u { w } else { x }));
            let dot = before[0] * after[0] + before[1] * after[1] + before[2] * after[2];
            // No face turns over or collapses to a line.
            if dot.is_nan() || dot <= 0.0 || after == [0.0; 3] {
                return false;
            }
        }
        true
    }

    /// Removes `u` into `w` (checked by `can_collapse`).
    fn collapse(&mut self, u: u32, w: u32) {
        let faces_u = std::mem::take(&mut self.vfaces[u as usize]);
        for i in faces_u {
            let f = self.faces[i as usize];
            if f.contains(&w) {
                // A face of the edge (u, w): it collapses.
                self.face_alive[i as usize] = false;
                for x in f {
                    if x != u {
                        self.vfaces[x as usize].retain(|&j| j != i);
                    }
                }
            } else {
                self.faces[i as usize] = f.map(|x| if x == u { w } else { x });
                self.vfaces[w as usize].push(i);
            }
        }
        self.merged_into[u as usize] = w;
    }

    /// The collapsed mesh in compact numbering.
    fn result(self) -> Collapsed {
        let n = self.points.len();
        let mut index = vec![NONE; n];
        let mut sites = Vec::new();
        for (u, &m) in self.merged_into.iter().enumerate() {
            if m as usize == u {
                index[u] = sites.len() as u32;
                sites.push(u as u32);
            }
        }
        let owner = (0..n)
            .map(|u| {
                let mut r = u;
                while self.merged_into[r] as usize != r {
                    r = self.merged_into[r] as usize; // merge chains end at a kept vertex
                }
                index[r]
            })
            .collect();
        let faces = self
            .faces
            .iter()
            .zip(&self.face_alive)
            .filter(|(_, &alive)| alive)
            .map(|(f, _)| f.map(|x| index[x as usize]))
            .collect();
        Collapsed {
            sites,
            owner,
            faces,
        }
    }
}

/// Merges every vertex into the site nearest it along the edge graph, by manifold-keeping
/// half-edge collapses (see the module notes).
///
/// `dist`, `pred` and `source` are the multi-source shortest-path tree from `sites`: each
/// vertex's distance (infinite when no site reaches it), its predecessor on the path and its
/// site (negative when there is none). First each vertex, farthest first, is collapsed into its
/// predecessor; then each vertex refused there into another neighbour of the same site that is
/// nearer that site, nearest first, until no more can go.
pub fn collapse_to_sites(
    points: &[[f64; 3]],
    faces: &[[u32; 3]],
    sites: &[u32],
    dist: &[f64],
    pred: &[i64],
    source: &[i64],
) -> Result<Collapsed> {
    let n = points.len();
    if dist.len() != n || pred.len() != n || source.len() != n {
        return invalid(format!(
            "collapse_to_sites needs dist, pred and source of one entry per vertex ({n}), got \
             {}, {} and {}",
            dist.len(),
            pred.len(),
            source.len()
        ));
    }
    if let Some(f) = faces.iter().find(|f| f.iter().any(|&x| x as usize >= n)) {
        return invalid(format!(
            "face {f:?} refers to a vertex beyond the {n} vertices"
        ));
    }
    if let Some(f) = faces
        .iter()
        .find(|f| f[0] == f[1] || f[1] == f[2] || f[2] == f[0])
    {
        return invalid(format!(
            "face {f:?} repeats a vertex; remove degenerate faces"
        ));
    }
    let mut is_site = vec![false; n];
    for &s in sites {
        match is_site.get_mut(s as usize) {
            Some(x) => *x = true,
            None => return invalid(format!("site {s} is beyond the {n} vertices")),
        }
    }
    let as_vertex = |x: i64| -> u32 {
        if (0..n as i64).contains(&x) {
            x as u32
        } else {
            NONE
        }
    };
    let pred: Vec<u32> = pred.iter().map(|&x| as_vertex(x)).collect();
    let source: Vec<u32> = source.iter().map(|&x| as_vertex(x)).collect();
    // Farthest first (ties in vertex order): every vertex whose path to the site runs
    // through u is merged before u.
    let mut order: Vec<u32> = (0..n as u32)
        .filter(|&u| dist[u as usize].is_finite() && !is_site[u as usize])
        .collect();
    order.sort_by(|&x, &y| dist[y as usize].total_cmp(&dist[x as usize]));
    if let Some(&u) = order.iter().find(|&&u| pred[u as usize] == NONE) {
        return invalid(format!(
            "vertex {u} has a finite distance but no predecessor on the path to a site"
        ));
    }
    let mut c = Collapser::new(points, faces);
    for &u in &order {
        let w = pred[u as usize];
        if c.can_collapse(u, w) {
            c.collapse(u, w);
        }
    }
    let alive = |c: &Collapser, u: u32| c.merged_into[u as usize] == u;
    loop {
        let mut changed = false;
        for &u in &order {
            if !alive(&c, u) {
                continue;
            }
            let du = dist[u as usize];
            let mut cands: Vec<u32> = c
                .neighbours(u)
                .into_iter()
                .filter(|&x| source[x as usize] == source[u as usize] && dist[x as usize] < du)
                .collect();
            cands.sort_by(|&x, &y| dist[x as usize].total_cmp(&dist[y as usize]));
            if let Some(&x) = cands.iter().find(|&&x| c.can_collapse(u, x)) {
                c.collapse(u, x);
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    Ok(c.result())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_meshes::icosphere;
    use std::collections::HashMap;

    /// An icosahedron subdivided `levels` times onto the unit sphere, bumped so that no two
    /// distances tie, faces counter-clockwise seen from outside.
    fn sphere(levels: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let (mut p, f) = icosphere(levels as usize);
        for (i, x) in p.iter_mut().enumerate() {
            let r = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            let bump = 1.0 + 0.05 * ((i as f64) * 1.7).sin();
            *x = x.map(|c| c / r * bump);
        }
        (p, f)
    }

    /// Multi-source Dijkstra along the edges: (dist, pred, source), -1 where none.
    fn tree(p: &[[f64; 3]], f: &[[u32; 3]], sites: &[u32]) -> (Vec<f64>, Vec<i64>, Vec<i64>) {
        let n = p.len();
        let mut adj = vec![Vec::new(); n];
        for t in f {
            for k in 0..3 {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                let d = sub(p[a], p[b]);
                let w = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                adj[a].push((b, w));
                adj[b].push((a, w));
            }
        }
        let (mut dist, mut pred, mut src) = (vec![f64::INFINITY; n], vec![-1; n], vec![-1; n]);
        let mut done = vec![false; n];
        for &s in sites {
            dist[s as usize] = 0.0;
            src[s as usize] = s as i64;
        }
        // O(n^2) selection: the test meshes are small.
        while let Some(u) = (0..n)
            .filter(|&u| !done[u] && dist[u].is_finite())
            .min_by(|&a, &b| dist[a].total_cmp(&dist[b]))
        {
            done[u] = true;
            for &(v, w) in &adj[u] {
                if dist[u] + w < dist[v] {
                    dist[v] = dist[u] + w;
                    pred[v] = u as i64;
                    src[v] = src[u];
                }
            }
        }
        (dist, pred, src)
    }

    /// (vertices, edges, faces) counts, with the number of edges not on exactly two faces and
    /// of directed edges used twice (a face turned over).
    fn check(c: &Collapsed) -> (i64, usize, usize) {
        let mut undirected: HashMap<(u32, u32), usize> = HashMap::new();
        let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
        for t in &c.faces {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
                *directed.entry((a, b)).or_default() += 1;
            }
        }
        let euler = c.sites.len() as i64 - undirected.len() as i64 + c.faces.len() as i64;
        let bad_edges = undirected.values().filter(|&&k| k != 2).count();
        let doubled = directed.values().filter(|&&k| k > 1).count();
        (euler, bad_edges, doubled)
    }

    #[test]
    fn a_sphere_stays_a_closed_oriented_manifold() {
        let (p, f) = sphere(3); // 642 vertices
        let sites: Vec<u32> = (0..p.len() as u32).step_by(7).collect();
        let (dist, pred, src) = tree(&p, &f, &sites);
        let c = collapse_to_sites(&p, &f, &sites, &dist, &pred, &src).unwrap();
        assert_eq!(check(&c), (2, 0, 0));
        // Every site kept, few others; each vertex owned by a kept one, a site by itself.
        assert!(sites.iter().all(|s| c.sites.contains(s)));
        assert!(
            c.sites.len() < sites.len() + sites.len() / 4,
            "{}",
            c.sites.len()
        );
        for (j, &s) in c.sites.iter().enumerate() {
            assert_eq!(c.owner[s as usize], j as u32);
        }
        assert!(c.owner.iter().all(|&o| (o as usize) < c.sites.len()));
        // Every face keeps its outward orientation (a convex-ish bumped sphere).
        for t in &c.faces {
            let q = t.map(|j| p[c.sites[j as usize] as usize]);
            let nrm = cross(sub(q[1], q[0]), sub(q[2], q[0]));
            let centre = [0, 1, 2].map(|k| (q[0][k] + q[1][k] + q[2][k]) / 3.0);
            assert!(nrm[0] * centre[0] + nrm[1] * centre[1] + nrm[2] * centre[2] > 0.0);
        }
    }

    #[test]
    fn every_vertex_a_site_changes_nothing() {
        let (p, f) = sphere(1);
        let sites: Vec<u32> = (0..p.len() as u32).collect();
        let (dist, pred, src) = tree(&p, &f, &sites);
        let c = collapse_to_sites(&p, &f, &sites, &dist, &pred, &src).unwrap();
        assert_eq!(c.faces, f);
        assert_eq!(c.sites, sites);
    }

    #[test]
    fn an_open_disc_keeps_its_boundary_vertices() {
        let (p, f) = sphere(3);
        // Keep the faces below z = 0.5: a disc.
        let keep: Vec<[u32; 3]> = f
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&x| p[x as usize][2] <= 0.5))
            .collect();
        let boundary = |faces: &[[u32; 3]]| {
            let mut e: HashMap<(u32, u32), usize> = HashMap::new();
            for t in faces {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    *e.entry((a.min(b), a.max(b))).or_default() += 1;
                }
            }
            let mut v: Vec<u32> = e
                .iter()
                .filter(|(_, &k)| k == 1)
                .flat_map(|(&(a, b), _)| [a, b])
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        let before = boundary(&keep);
        let used: Vec<u32> = {
            let mut u: Vec<u32> = keep.iter().flatten().copied().collect();
            u.sort_unstable();
            u.dedup();
            u
        };
        let sites: Vec<u32> = used.iter().copied().step_by(6).collect();
        let (dist, pred, src) = tree(&p, &keep, &sites);
        let c = collapse_to_sites(&p, &keep, &sites, &dist, &pred, &src).unwrap();
        let (_, _, doubled) = check(&c);
        assert_eq!(doubled, 0);
        let after: Vec<u32> = boundary(&c.faces)
            .iter()
            .map(|&j| c.sites[j as usize])
            .collect();
        assert!(!after.is_empty());
        assert!(after.iter().all(|v| before.binary_search(v).is_ok()));
    }

    #[test]
    fn bad_input_is_refused() {
        let (p, f) = sphere(0);
        let (dist, pred, src) = tree(&p, &f, &[0]);
        assert!(collapse_to_sites(&p, &f, &[99], &dist, &pred, &src).is_err());
        assert!(collapse_to_sites(&p, &f, &[0], &dist[1..], &pred, &src).is_err());
        let mut g = f.clone();
        g[0] = [0, 0, 1];
        assert!(collapse_to_sites(&p, &g, &[0], &dist, &pred, &src).is_err());
    }
}
