//! The problem seen from the smaller side ("persons"): the person-major CSR, with objects
//! renumbered compactly, and the conversions between persons' arcs and the caller's rows.
use std::borrow::Cow;

use rayon::prelude::*;

use super::hopcroft_karp::hopcroft_karp;
use super::{DUMMY, NONE, NO_ARC, PAR_ROWS};
use crate::csr::CsrView;
use crate::error::{invalid, CoreError, Result};

/// Renumbers the used columns 0..n_used in increasing order. Returns (n_used, compact->original
/// table or None when nothing was dropped, remapped indices or None when unchanged).
pub(super) fn compact_columns(
    idx: &[u32],
    n_cols: usize,
) -> (usize, Option<Vec<u32>>, Option<Vec<u32>>) {
    if n_cols <= 2 * idx.len() + 1024 {
        let mut map = vec![NONE; n_cols];
        for &c in idx {
            map[c as usize] = 0;
        }
        let mut table = Vec::new();
        for (c, m) in map.iter_mut().enumerate() {
            if *m == 0 {
                *m = table.len() as u32;
                table.push(c as u32);
            }
        }
        if table.len() == n_cols {
            return (n_cols, None, None);
        }
        let remapped = idx.par_iter().map(|&c| map[c as usize]).collect();
        (table.len(), Some(table), Some(remapped))
    } else {
        let mut table = idx.to_vec();
        table.par_sort_unstable();
        table.dedup();
        let remapped = idx
            .par_iter()
            .map(|c| table.binary_search(c).unwrap_or(0) as u32)
            .collect();
        (table.len(), Some(table), Some(remapped))
    }
}

/// The problem seen from the smaller side ("persons"), objects renumbered compactly.
pub(super) struct PersonCsr<'a> {
    pub(super) m: usize,
    pub(super) n_obj: usize,
    n_rows: usize,
    transposed: bool,
    pub(super) ptr: Cow<'a, [usize]>,
    pub(super) obj: Cow<'a, [u32]>,
    /// Compact object -> original column (or row, when transposed); None: identity.
    obj_orig: Option<Vec<u32>>,
}

impl<'a> PersonCsr<'a> {
    /// The person view and the values in its arc order.
    pub(super) fn build<T: Copy + Default>(cost: &CsrView<'a, T>) -> Result<(Self, Cow<'a, [T]>)> {
        let (nr, nc) = (cost.n_rows, cost.n_cols);
        if nr.min(nc) >= DUMMY as usize {
            return invalid(format!("cost: {nr} x {nc} is too large for the auction"));
        }
        if nr <= nc {
            // Square: an unused column makes the problem infeasible, which Hopcroft–Karp
            // reports, so there is nothing to compact.
            let (n_obj, obj_orig, remapped) = if nr == nc {
                (nc, None, None)
            } else {
                compact_columns(cost.indices, nc)
            };
            let obj = match remapped {
                Some(v) => Cow::Owned(v),
                None => Cow::Borrowed(cost.indices),
            };
            let pc = PersonCsr {
                m: nr,
                n_obj,
                n_rows: nr,
                transposed: false,
                ptr: Cow::Borrowed(cost.indptr),
                obj,
                obj_orig,
            };
            Ok((pc, Cow::Borrowed(cost.data)))
        } else {
            // Persons are the columns; objects are the non-empty rows, in row order.
            let m = nc;
            let nnz = cost.indices.len();
            let mut ptr = vec![0usize; m + 1];
            for &c in cost.indices {
                ptr[c as usize + 1] += 1;
            }
            for i in 0..m {
                ptr[i + 1] += ptr[i];
            }
            let mut next = ptr.clone();
            let mut obj = vec![0u32; nnz];
            let mut val = vec![T::default(); nnz];
            let mut obj_orig = Vec::new();
            for r in 0..nr {
                let (lo, hi) = (cost.indptr[r], cost.indptr[r + 1]);
                if lo == hi {
                    continue;
                }
                let id = obj_orig.len() as u32;
                obj_orig.push(r as u32);
                for (k, &c) in cost.indices[lo..hi].iter().enumerate() {
                    let p = &mut next[c as usize];
                    obj[*p] = id;
                    val[*p] = cost.data[lo + k];
                    *p += 1;
                }
            }
            if obj_orig.len() >= DUMMY as usize {
                return invalid(format!("cost: {nr} x {nc} is too large for the auction"));
            }
            let pc = PersonCsr {
                m,
                n_obj: obj_orig.len(),
                n_rows: nr,
                transposed: true,
                ptr: Cow::Owned(ptr),
                obj: Cow::Owned(obj),
                obj_orig: Some(obj_orig),
            };
            Ok((pc, Cow::Owned(val)))
        }
    }

    /// Maps every arc through `f(person, arc)`, in arc order.
    pub(super) fn arcs_map<W: Send, F: Fn(usize, usize) -> W + Sync>(&self, f: F) -> Vec<W> {
        (0..self.m)
            .into_par_iter()
            .with_min_len(PAR_ROWS)
            .flat_map_iter(|i| (self.ptr[i]..self.ptr[i + 1]).map(move |a| (i, a)))
            .map(|(i, a)| f(i, a))
            .collect()
    }

    pub(super) fn matching(&self) -> (usize, Vec<u32>) {
        hopcroft_karp(self.m, self.n_obj, &self.ptr, &self.obj)
    }

    /// Person -> object into person -> arc.
    pub(super) fn arcs_of(&self, mates: &[u32]) -> Vec<usize> {
        mates
            .iter()
            .enumerate()
            .map(|(i, &o)| {
                let lo = self.ptr[i];
                self.obj[lo..self.ptr[i + 1]]
                    .iter()
                    .position(|&x| x == o)
                    .map_or(NO_ARC, |k| lo + k)
            })
            .collect()
    }

    pub(super) fn infeasible(&self, size: usize) -> CoreError {
        CoreError::Infeasible {
            uncovered: self.m - size,
            side: if self.transposed { "columns" } else { "rows" },
        }
    }

    /// Person -> arc (NO_ARC for unassigned) into row -> column.
    pub(super) fn to_rows(&self, arc_of: &[usize]) -> Vec<i64> {
        let orig = |o: u32| -> i64 {
            self.obj_orig
                .as_ref()
                .map_or(o as i64, |t| t[o as usize] as i64)
        };
        let mut out = vec![-1i64; self.n_rows];
        for (i, &a) in arc_of.iter().enumerate() {
            if a == NO_ARC {
                continue;
            }
            let o = orig(self.obj[a]);
            if self.transposed {
                out[o as usize] = i as i64;
            } else {
                out[i] = o;
            }
        }
        out
    }
}
