//! Warm-started exact assignment: repair a previous optimum with shortest augmenting paths.
//!
//! Given a previous assignment and column prices that were optimal duals for a similar cost,
//! every row whose assigned entry is still tight (reduced cost 0 under the new cost) keeps it;
//! the others are freed and re-inserted one by one by Dijkstra on the reduced costs over the
//! sparse pattern (the augmentation phase of Jonker–Volgenant). Maximisation, integer costs,
//! `n_rows <= n_cols`; dual feasibility `u[i] + v[j] >= c[i][j]` with equality on the
//! assignment, `v >= 0` and `v = 0` on the columns left free, so the result is exactly optimal
//! and its prices are optimal duals (valid for every optimal assignment of the same cost).
use std::cmp::Reverse;
use std::collections::BinaryHeap;

use rayon::prelude::*;

use super::bidding::IntValue;
use super::checks::{check_duplicates, check_header};
use super::{NONE, PAR_ROWS};
use crate::csr::CsrView;
use crate::error::{invalid, Result};

/// Costs beyond this magnitude are left to the auction, and prices beyond `PRICE_LIMIT` are
/// refused: path lengths (at most `n` times the value range plus the price span) then stay far
/// inside i64. A solution whose prices would exceed the limit is not returned, so a chain of
/// warm solves never feeds a solve prices it refuses.
const VALUE_LIMIT: i64 = 1 << 30;
const PRICE_LIMIT: i64 = 1 << 52;

/// An exact optimum found from a warm start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WarmSolution {
    /// Row -> column (every row is assigned).
    pub assign: Vec<i64>,
    /// Optimal column duals (>= 0, 0 on free columns): the warm start of the next solve.
    pub prices: Vec<i64>,
    /// Rows that had to be re-inserted by an augmenting path.
    pub repaired: usize,
    /// No other assignment reaches the same total, so every exact solver returns `assign`.
    pub unique: bool,
}

/// Exact maximum-total assignment of every row, starting from `prev` (row -> column, -1 or a
/// column outside the row's pattern for none) and `prices` (one per column, >= 0).
///
/// Returns `Ok(None)` when the warm start does not pay or cannot apply: more than
/// `max_repair` rows break, `n_rows > n_cols`, values beyond +-2^30, or no full assignment
/// exists (the caller's full solver then reports it). Errors only on malformed input
/// (including a column stored twice in a row).
pub fn warm_assignment<T: IntValue>(
    cost: &CsrView<T>,
    prev: &[i64],
    prices: &[i64],
    max_repair: usize,
) -> Result<Option<WarmSolution>> {
    check_header(cost)?;
    check_duplicates(cost)?;
    let (nr, nc) = (cost.n_rows, cost.n_cols);
    if prev.len() != nr {
        return invalid(format!(
            "previous assignment must hold one entry per row ({nr}), got {}",
            prev.len()
        ));
    }
    if prices.len() != nc {
        return invalid(format!(
            "prices must hold one entry per column ({nc}), got {}",
            prices.len()
        ));
    }
    if prices.iter().any(|&p| !(0..=PRICE_LIMIT).contains(&p)) {
        return invalid("prices must lie in [0, 2^52]".to_string());
    }
    if nr > nc
        || cost
            .data
            .par_iter()
            .any(|&d| Into::<i64>::into(d).unsigned_abs() > VALUE_LIMIT as u64)
    {
        return Ok(None);
    }
    let mut s = State::new(cost, prev, prices);
    if !s.settle(max_repair) {
        return Ok(None);
    }
    let broken: Vec<usize> = (0..nr).filter(|&i| s.col[i] == NONE).collect();
    for &r in &broken {
        if !s.augment(r) {
            return Ok(None);
        }
    }
    let unique = s.unique();
    if nr == nc {
        // No column is free, so only price differences matter: the lowest becomes 0.
        let low = s.v.iter().copied().min().unwrap_or(0);
        s.v.iter_mut().for_each(|p| *p -= low);
    }
    if s.v.iter().any(|&p| p > PRICE_LIMIT) {
        return Ok(None);
    }
    Ok(Some(WarmSolution {
        assign: s.col.iter().map(|&c| c as i64).collect(),
        prices: s.v,
        repaired: broken.len(),
        unique,
    }))
}

/// The primal-dual state of the repair.
struct State<'a, T> {
    c: &'a CsrView<'a, T>,
    /// Row -> column, column -> row (NONE: free).
    col: Vec<u32>,
    row: Vec<u32>,
    u: Vec<i64>,
    v: Vec<i64>,
    // Dijkstra scratch, reset through `touched` after each path.
    dist: Vec<i64>,
    pred: Vec<u32>,
    done: Vec<bool>,
    touched: Vec<u32>,
}

impl<'a, T: IntValue> State<'a, T> {
    fn new(c: &'a CsrView<'a, T>, prev: &[i64], prices: &[i64]) -> Self {
        let (nr, nc) = (c.n_rows, c.n_cols);
        let mut col = vec![NONE; nr];
        let mut row = vec![NONE; nc];
        for (i, &p) in prev.iter().enumerate() {
            let ok = p >= 0
                && (p as usize) < nc
                && row[p as usize] == NONE
                && c.row(i).contains(&(p as u32));
            if ok {
                col[i] = p as u32;
                row[p as usize] = i as u32;
            }
        }
        State {
            c,
            col,
            row,
            u: vec![0; nr],
            v: prices.to_vec(),
            dist: vec![i64::MAX; nc],
            pred: vec![NONE; nc],
            done: vec![false; nc],
            touched: Vec::new(),
        }
    }

    #[inline]
    fn value(&self, a: usize) -> i64 {
        self.c.data[a].into()
    }

    /// Row potentials from the prices, freeing every row whose entry is not tight; with more
    /// columns than rows, freed columns drop to price 0, which can break further rows. False
    /// when more than `max_repair` rows break.
    fn settle(&mut self, max_repair: usize) -> bool {
        let rect = self.c.n_cols > self.c.n_rows;
        if rect {
            for j in 0..self.c.n_cols {
                if self.row[j] == NONE {
                    self.v[j] = 0;
                }
            }
        }
        loop {
            let c = self.c;
            let v = &self.v;
            let col = &self.col;
            let rows: Vec<(i64, bool)> = (0..c.n_rows)
                .into_par_iter()
                .with_min_len(PAR_ROWS)
                .map(|i| {
                    let (lo, hi) = (c.indptr[i], c.indptr[i + 1]);
                    let mut best = i64::MIN;
                    let mut own = i64::MIN;
                    for a in lo..hi {
                        let j = c.indices[a];
                        let r = Into::<i64>::into(c.data[a]) - v[j as usize];
                        best = best.max(r);
                        if j == col[i] {
                            own = r;
                        }
                    }
                    (best, col[i] != NONE && own == best)
                })
                .collect();
            let mut freed = false;
            for (i, &(best, tight)) in rows.iter().enumerate() {
                self.u[i] = best;
                if !tight && self.col[i] != NONE {
                    let j = self.col[i] as usize;
                    self.col[i] = NONE;
                    self.row[j] = NONE;
                    if rect && self.v[j] != 0 {
                        self.v[j] = 0;
                        freed = true;
                    }
                }
            }
            let broken = self.col.iter().filter(|&&j| j == NONE).count();
            if broken > max_repair {
                return false;
            }
            if !freed {
                return true;
            }
        }
    }

    /// Inserts free row `r` along a shortest augmenting path (reduced costs
    /// `u[i] + v[j] - c[i][j]`, all >= 0) and updates the duals; false when no free column is
    /// reachable.
    fn augment(&mut self, r: usize) -> bool {
        let c = self.c;
        // Row r's potential may be stale after earlier paths moved prices.
        let (lo, hi) = (c.indptr[r], c.indptr[r + 1]);
        let Some(ur) = (lo..hi)
            .map(|a| self.value(a) - self.v[c.indices[a] as usize])
            .max()
        else {
            return false;
        };
        self.u[r] = ur;
        let mut heap: BinaryHeap<Reverse<(i64, bool, u32)>> = BinaryHeap::new();
        let mut scanned_rows: Vec<(u32, i64)> = vec![(r as u32, 0)];
        let relax = |s: &mut Self, i: usize, base: i64, heap: &mut BinaryHeap<_>| {
            for a in c.indptr[i]..c.indptr[i + 1] {
                let j = c.indices[a] as usize;
                if s.done[j] {
                    continue;
                }
                let nd = base + s.u[i] + s.v[j] - s.value(a);
                if nd < s.dist[j] {
                    if s.dist[j] == i64::MAX {
                        s.touched.push(j as u32);
                    }
                    s.dist[j] = nd;
                    s.pred[j] = i as u32;
                    // Ties: free columns first, so the search stops as early as possible.
                    heap.push(Reverse((nd, s.row[j] != NONE, j as u32)));
                }
            }
        };
        relax(self, r, 0, &mut heap);
        let mut sink = NONE;
        let mut delta = 0;
        while let Some(Reverse((d, _, j))) = heap.pop() {
            let ju = j as usize;
            if self.done[ju] || d > self.dist[ju] {
                continue;
            }
            self.done[ju] = true;
            if self.row[ju] == NONE {
                sink = j;
                delta = d;
                break;
            }
            let i = self.row[ju] as usize;
            scanned_rows.push((i as u32, d));
            relax(self, i, d, &mut heap);
        }
        let found = sink != NONE;
        if found {
            // Duals: scanned columns rise by delta - dist, their rows (and r) drop by
            // delta - label; every reduced cost stays >= 0 and the path becomes tight.
            for &j in &self.touched {
                let ju = j as usize;
                if self.done[ju] {
                    self.v[ju] += delta - self.dist[ju];
                }
            }
            for &(i, d) in &scanned_rows {
                self.u[i as usize] -= delta - d;
            }
            let mut j = sink as usize;
            loop {
                let i = self.pred[j] as usize;
                let next = self.col[i];
                self.col[i] = j as u32;
                self.row[j] = i as u32;
                if i == r {
                    break;
                }
                j = next as usize;
            }
        }
        for &j in &self.touched {
            let ju = j as usize;
            self.dist[ju] = i64::MAX;
            self.pred[ju] = NONE;
            self.done[ju] = false;
        }
        self.touched.clear();
        found
    }

    /// Whether the assignment is the only optimum: no cycle of tight exchanges among the rows
    /// (row i -> the owner of a column it is tight on), where the free columns form one node
    /// that every row on a price-0 column can be released to.
    fn unique(&self) -> bool {
        let c = self.c;
        let nr = c.n_rows;
        let z = nr; // the pool of free columns
        let out: Vec<Vec<u32>> = (0..nr)
            .into_par_iter()
            .with_min_len(PAR_ROWS)
            .map(|i| {
                let mut e = Vec::new();
                for a in c.indptr[i]..c.indptr[i + 1] {
                    let j = c.indices[a] as usize;
                    if j as u32 != self.col[i] && self.u[i] + self.v[j] == self.value(a) {
                        let o = self.row[j];
                        e.push(if o == NONE { z as u32 } else { o });
                    }
                }
                e
            })
            .collect();
        let mut indeg = vec![0usize; nr + 1];
        for e in &out {
            for &t in e {
                indeg[t as usize] += 1;
            }
        }
        let released: Vec<u32> = (0..nr)
            .filter(|&i| self.v[self.col[i] as usize] == 0)
            .map(|i| i as u32)
            .collect();
        let has_free = c.n_cols > nr;
        if has_free {
            for &i in &released {
                indeg[i as usize] += 1;
            }
        }
        // Kahn's topological sort: acyclic iff every node is removed.
        let mut stack: Vec<usize> = (0..=nr).filter(|&x| indeg[x] == 0).collect();
        let mut removed = 0;
        while let Some(x) = stack.pop() {
            removed += 1;
            let succ: &[u32] = if x == z {
                if has_free {
                    &released
                } else {
                    &[]
                }
            } else {
                &out[x]
            };
            for &t in succ {
                let t = t as usize;
                indeg[t] -= 1;
                if indeg[t] == 0 {
                    stack.push(t);
                }
            }
        }
        removed == nr + 1
    }
}
