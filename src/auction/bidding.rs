//! Bertsekas' epsilon-scaling auction on the person view: the value views (`Direct`, `Stored`),
//! each person's top-K candidates, the dummies' min-price tree and the bidding loop (`solve`).
use rayon::prelude::*;

use super::person_csr::PersonCsr;
use super::{DUMMY, NONE, NO_ARC, PAR_ROWS};
use crate::error::{invalid, Result};

/// Prices never legitimately come near this; it guards the value-minus-price arithmetic.
const PRICE_CAP: i64 = 1 << 62;
/// epsilon shrinks by this factor between scaling phases.
const EPS_FACTOR: i64 = 4;
/// The first phase's epsilon is the scaled median gap between best and second best over this,
const EPS_GAP_DIV: i64 = 4;
/// or, when every person has a tie at the top, the scaled value range over this,
const EPS_START_DIV: i64 = 64;
/// and never less than the scaled value range over `EPS_START_DIV * EPS_FLOOR_DIV`
/// (the default `floor_div` of [`super::auction_assignment_int_with`]).
const EPS_FLOOR_DIV: i64 = 16;
pub const DEFAULT_FLOOR_DIV: i64 = EPS_START_DIV * EPS_FLOOR_DIV;
/// Candidate arcs kept per person.
const K: usize = 12;

/// Integer value types the exact solver reads in place. Costs whose values fit in 32 bits (every
/// HOPE overlap cost) are best passed as `i32` or `u32`: half the memory to fault in and to stream through
/// the rescans.
pub trait IntValue: Copy + Default + Send + Sync + Into<i64> {}
impl IntValue for i32 {}
impl IntValue for u32 {}
impl IntValue for i64 {}

/// Shifted, unscaled person values (all <= 0, >= -range) by (person, arc).
pub(super) trait Values: Sync {
    fn get(&self, i: usize, a: usize) -> i64;
    /// The K + 1 best arcs of person `i` (arcs `lo..hi`) by reduced value
    /// `get(i, a) * scale - price[obj[a]]`, among those above `floor` (unused slots: `NO_ARC`).
    fn top_reduced(&self, i: usize, lo: usize, hi: usize, s: &Rescan) -> TopK;
}

/// What a rescan measures arcs against. Every `obj[a]` must be below `price.len()`.
pub(super) struct Rescan<'a> {
    obj: &'a [u32],
    price: &'a [i64],
    scale: i64,
    floor: i64,
}

/// [`Values::top_reduced`] over one row's values `w` (arcs `lo..lo + w.len()`), each turned
/// into a shifted value by `value`. The auction's hottest loop (a rescan reads the whole row,
/// and on HOPE's k = 8 costs rows hold about 1000 arcs), so it reads prices unchecked and
/// compares a block of reduced values with the threshold at once.
#[inline(always)]
fn top_reduced_of<W: Copy>(w: &[W], value: impl Fn(W) -> i64, lo: usize, s: &Rescan) -> TopK {
    const BLOCK: usize = 8;
    let Rescan {
        obj,
        price,
        scale,
        floor,
    } = *s;
    let obj = &obj[lo..lo + w.len()];
    debug_assert!(obj.iter().all(|&o| (o as usize) < price.len()));
    let reduced = |v: W, o: u32| -> i64 {
        // SAFETY: objects are < n_obj = price.len(): `PersonCsr::build` renumbers them from
        // columns that `check_header` bounded, and the caller promises it.
        value(v) * scale - unsafe { *price.get_unchecked(o as usize) }
    };
    let mut t = TopK {
        vs: [i64::MIN; K + 1],
        ks: [NO_ARC; K + 1],
        len: K + 1,
    };
    let mut thr = floor;
    let (wb, ob) = (w.chunks_exact(BLOCK), obj.chunks_exact(BLOCK));
    let (wr, or) = (wb.remainder(), ob.remainder());
    let mut at = lo;
    for (wc, oc) in wb.zip(ob) {
        let mut r = [0i64; BLOCK];
        for j in 0..BLOCK {
            r[j] = reduced(wc[j], oc[j]);
        }
        if r.iter().any(|&x| x > thr) {
            for (j, &x) in r.iter().enumerate() {
                if x > thr {
                    t.insert(K, x, at + j);
                    thr = thr.max(t.vs[K]);
                }
            }
        }
        at += BLOCK;
    }
    for (j, (&v, &o)) in wr.iter().zip(or).enumerate() {
        let x = reduced(v, o);
        if x > thr {
            t.insert(K, x, at + j);
            thr = thr.max(t.vs[K]);
        }
    }
    t.len = t.ks.iter().take_while(|&&a| a != NO_ARC).count();
    t
}

/// Integer costs read in place: no copy of the values for the common non-transposed case.
pub(super) struct Direct<'a, const MAXIMIZE: bool, T> {
    pub(super) data: &'a [T],
    pub(super) refv: Vec<i64>,
}

impl<const MAXIMIZE: bool, T: IntValue> Values for Direct<'_, MAXIMIZE, T> {
    #[inline(always)]
    fn get(&self, i: usize, a: usize) -> i64 {
        let d: i64 = self.data[a].into();
        if MAXIMIZE {
            d.wrapping_sub(self.refv[i])
        } else {
            self.refv[i].wrapping_sub(d)
        }
    }
    #[inline]
    fn top_reduced(&self, i: usize, lo: usize, hi: usize, s: &Rescan) -> TopK {
        let r = self.refv[i];
        let w = &self.data[lo..hi];
        if MAXIMIZE {
            top_reduced_of(w, |d: T| d.into().wrapping_sub(r), lo, s)
        } else {
            top_reduced_of(w, |d: T| r.wrapping_sub(d.into()), lo, s)
        }
    }
}

/// Precomputed values (transposed or quantized problems); i32 when the range allows.
pub(super) struct Stored<W>(pub(super) Vec<W>);

impl<W: Copy + Into<i64> + Sync> Values for Stored<W> {
    #[inline(always)]
    fn get(&self, _i: usize, a: usize) -> i64 {
        self.0[a].into()
    }
    #[inline]
    fn top_reduced(&self, _: usize, lo: usize, hi: usize, s: &Rescan) -> TopK {
        top_reduced_of(&self.0[lo..hi], |v: W| v.into(), lo, s)
    }
}

/// Min and second-min price over all objects, for the dummy persons' bids. Price changes are
/// only recorded and applied when the minimum is asked for: dummies bid rarely while persons
/// raise the same contested prices many times in between, so updating the tree on every raise
/// would cost more than the bids it serves.
struct MinTree {
    size: usize,
    m1: Vec<i64>,
    m2: Vec<i64>,
    arg: Vec<u32>,
    dirty: Vec<u32>,
    is_dirty: Vec<bool>,
}

impl MinTree {
    fn new(n: usize) -> Self {
        let size = n.next_power_of_two().max(2);
        let mut t = MinTree {
            size,
            m1: vec![i64::MAX; 2 * size],
            m2: vec![i64::MAX; 2 * size],
            arg: vec![0; 2 * size],
            dirty: Vec::new(),
            is_dirty: vec![false; n],
        };
        for j in 0..size {
            t.arg[size + j] = j as u32;
            if j < n {
                t.m1[size + j] = 0;
            }
        }
        for v in (1..size).rev() {
            t.pull(v);
        }
        t
    }
    #[inline]
    fn pull(&mut self, v: usize) {
        let (a, b) = (2 * v, 2 * v + 1);
        if self.m1[a] <= self.m1[b] {
            self.m1[v] = self.m1[a];
            self.arg[v] = self.arg[a];
            self.m2[v] = self.m2[a].min(self.m1[b]);
        } else {
            self.m1[v] = self.m1[b];
            self.arg[v] = self.arg[b];
            self.m2[v] = self.m2[b].min(self.m1[a]);
        }
    }
    /// Records that object `j`'s price changed.
    #[inline]
    fn mark(&mut self, j: usize) {
        if !self.is_dirty[j] {
            self.is_dirty[j] = true;
            self.dirty.push(j as u32);
        }
    }
    #[inline]
    fn set(&mut self, j: usize, p: i64) {
        let mut v = self.size + j;
        self.m1[v] = p;
        v /= 2;
        while v >= 1 {
            self.pull(v);
            v /= 2;
        }
    }
    /// (min price, its object, second-smallest price) given the current prices.
    #[inline]
    fn top(&mut self, price: &[i64]) -> (i64, usize, i64) {
        while let Some(j) = self.dirty.pop() {
            self.is_dirty[j as usize] = false;
            self.set(j as usize, price[j as usize]);
        }
        (self.m1[1], self.arg[1] as usize, self.m2[1])
    }
}

/// The K + 1 largest keys of a row with their arcs, largest first.
pub(super) struct TopK {
    vs: [i64; K + 1],
    ks: [usize; K + 1],
    len: usize,
}

impl TopK {
    #[inline]
    fn of(mut items: impl Iterator<Item = (i64, usize)>) -> TopK {
        let mut t = TopK {
            vs: [i64::MIN; K + 1],
            ks: [NO_ARC; K + 1],
            len: 0,
        };
        while t.len < K + 1 {
            let Some((v, a)) = items.next() else {
                return t;
            };
            t.len += 1;
            t.insert(t.len - 1, v, a);
        }
        // The threshold lives in a register; the arrays are only touched on insertion.
        let mut thr = t.vs[K];
        for (v, a) in items {
            if v > thr {
                t.insert(K, v, a);
                thr = t.vs[K];
            }
        }
        t
    }

    /// Inserts (v, a) in order, dropping what was at position `last`.
    #[inline(always)]
    fn insert(&mut self, last: usize, v: i64, a: usize) {
        let mut p = last;
        while p > 0 && self.vs[p - 1] < v {
            self.vs[p] = self.vs[p - 1];
            self.ks[p] = self.ks[p - 1];
            p -= 1;
        }
        self.vs[p] = v;
        self.ks[p] = a;
    }
}

/// One pass over an integer row: (min, max, top K + 1 arcs by value).
#[inline]
pub(super) fn scan_row<T: IntValue>(row: &[T], lo: usize, maximize: bool) -> (i64, i64, TopK) {
    if maximize {
        scan_row_key(row, lo, |c| c)
    } else {
        // `!c` orders like `-c` without overflowing at i64::MIN.
        scan_row_key(row, lo, |c| !c)
    }
}

#[inline(always)]
fn scan_row_key<T: IntValue>(row: &[T], lo: usize, key: impl Fn(i64) -> i64) -> (i64, i64, TopK) {
    let head = row.len().min(K + 1);
    let mut t = TopK::of(
        row[..head]
            .iter()
            .enumerate()
            .map(|(k, &c)| (key(c.into()), lo + k)),
    );
    let (mut mn, mut mx) = row[..head].iter().fold((i64::MAX, i64::MIN), |(a, b), &c| {
        (a.min(c.into()), b.max(c.into()))
    });
    let mut thr = t.vs[K];
    for (k, &c) in row[head..].iter().enumerate() {
        let c: i64 = c.into();
        mn = mn.min(c);
        mx = mx.max(c);
        let v = key(c);
        if v > thr {
            t.insert(K, v, lo + head + k);
            thr = t.vs[K];
        }
    }
    (mn, mx, t)
}

fn price_overflow<T>() -> Result<T> {
    invalid(
        "cost range too large for the exact auction: prices exceeded the safe integer range; \
         rescale the costs"
            .to_string(),
    )
}

/// An arc as the bidding loop needs it.
#[derive(Clone, Copy)]
struct Cand {
    arc: usize,
    obj: u32,
    /// value * scale
    val: i64,
}

const NO_CAND: Cand = Cand {
    arc: NO_ARC,
    obj: NONE,
    val: i64::MIN,
};

struct Auction<'p, V> {
    ptr: &'p [usize],
    obj: &'p [u32],
    vals: &'p V,
    scale: i64,
    /// Scaled value range: the increment used when a person has a single candidate.
    range: i64,
    price: Vec<i64>,
    owner: Vec<u32>,
    /// Arc held by each person (NO_ARC: unassigned).
    arc: Vec<usize>,
    /// Lower bound on (own value) - (best other value), valid since the last bid or check: other
    /// prices only rise, so it stays a lower bound and lets a phase skip the person unscanned.
    slack: Vec<i64>,
    /// Each person's K candidate arcs with their objects and scaled values, so that a bid reads
    /// them in one place rather than through the arc in the value and object arrays.
    cand: Vec<Cand>,
    cand_len: Vec<u8>,
    /// Object and scaled value of the arc each person holds (valid while `arc[i] != NO_ARC`).
    held: Vec<Cand>,
    /// Upper bound on the reduced value of every non-candidate arc.
    bound: Vec<i64>,
    stack: Vec<u32>,
    queued: Vec<bool>,
    tree: Option<MinTree>,
    free_dummies: usize,
}

impl<V: Values> Auction<'_, V> {
    #[inline]
    fn push(&mut self, i: usize) {
        if !self.queued[i] {
            self.queued[i] = true;
            self.stack.push(i as u32);
        }
    }

    #[inline]
    fn set_price(&mut self, j: usize, p: i64) {
        self.price[j] = p;
        if let Some(t) = self.tree.as_mut() {
            t.mark(j);
        }
    }

    /// Exact (best, best candidate, second best) of person `i`, from the candidates when they
    /// certify it, otherwise by a full rescan that refreshes them.
    #[inline]
    fn best_two(&mut self, i: usize) -> (i64, Cand, i64) {
        let base = i * K;
        let cnt = self.cand_len[i] as usize;
        let (mut b1, mut c1, mut b2) = (i64::MIN, NO_CAND, i64::MIN);
        let mut low = i64::MAX;
        for c in &self.cand[base..base + cnt] {
            let v = c.val - self.price[c.obj as usize];
            low = low.min(v);
            if v > b2 {
                if v > b1 {
                    b2 = b1;
                    b1 = v;
                    c1 = *c;
                } else {
                    b2 = v;
                }
            }
        }
        if b2 >= self.bound[i] {
            return (b1, c1, b2);
        }
        let (lo, hi) = (self.ptr[i], self.ptr[i + 1]);
        // The K current candidates are K arcs worth at least `low`, so the new K best are all
        // among the arcs worth `low` or more: the scan skips the rest, which on HOPE's costs
        // cut its insertions into the top list, the hot spot, to a few per row. The rest are
        // then bounded by `low - 1` rather than by the exact (K + 1)-th value.
        let floor = if cnt == K { low - 1 } else { i64::MIN };
        let scan = Rescan {
            obj: self.obj,
            price: &self.price,
            scale: self.scale,
            floor,
        };
        let t = self.vals.top_reduced(i, lo, hi, &scan);
        let cnt = t.len.min(K);
        for (slot, (&v, &a)) in self.cand[base..base + cnt]
            .iter_mut()
            .zip(t.vs.iter().zip(&t.ks))
        {
            let o = self.obj[a];
            *slot = Cand {
                arc: a,
                obj: o,
                val: v + self.price[o as usize],
            };
        }
        self.cand_len[i] = cnt as u8;
        self.bound[i] = t.vs[K].max(floor);
        let best = if cnt > 0 { self.cand[base] } else { NO_CAND };
        (t.vs[0], best, t.vs[1])
    }

    /// Re-checks an assigned person's eps-CS (keeping it if it holds) or bids for its best object.
    fn process(&mut self, i: usize, eps: i64) -> Result<()> {
        let (b1, best, b2) = self.best_two(i);
        let best_arc = best.arc;
        if best_arc == NO_ARC {
            // No arcs at all: excluded by the feasibility check.
            return Ok(());
        }
        let cur = self.arc[i];
        if cur != NO_ARC {
            let jc = self.held[i].obj as usize;
            let vc = self.held[i].val - self.price[jc];
            let other = if best_arc == cur { b2 } else { b1 };
            if other == i64::MIN {
                self.slack[i] = i64::MAX;
                return Ok(());
            }
            if vc >= other - eps {
                self.slack[i] = vc - other;
                return Ok(());
            }
            self.owner[jc] = NONE;
            self.arc[i] = NO_ARC;
        }
        let j = best.obj as usize;
        let prev = self.owner[j];
        if prev == NONE {
            // An unowned object is taken at its current price: eps-CS holds with slack b1 - b2
            // >= 0, so the person survives later phases untouched unless outbid. Objects never
            // lose their owner within a phase, so this happens at most n times per phase.
            self.slack[i] = if b2 == i64::MIN { i64::MAX } else { b1 - b2 };
        } else {
            let (gamma, slack) = if b2 == i64::MIN {
                (self.range.saturating_add(eps), i64::MAX)
            } else {
                // Any increment in [eps, b1 - b2 + eps] keeps eps-CS; b1 - b2 + 1 leaves slack -1,
                // which survives every later phase.
                let g = (b1 - b2 + 1).max(eps);
                (g, b1 - g - b2)
            };
            let np = match self.price[j].checked_add(gamma) {
                Some(p) if p <= PRICE_CAP => p,
                _ => return price_overflow(),
            };
            self.set_price(j, np);
            self.slack[i] = slack;
            if prev == DUMMY {
                self.free_dummies += 1;
            } else {
                self.arc[prev as usize] = NO_ARC;
                self.push(prev as usize);
            }
        }
        self.owner[j] = i as u32;
        self.arc[i] = best_arc;
        self.held[i] = best;
        Ok(())
    }

    /// One free dummy bids for the cheapest object.
    fn dummy_bid(&mut self, eps: i64) -> Result<()> {
        let Some(t) = self.tree.as_mut() else {
            self.free_dummies = 0;
            return Ok(());
        };
        let (pmin, j, p2) = t.top(&self.price);
        let prev = self.owner[j];
        if prev != NONE {
            let gamma = p2.saturating_sub(pmin).saturating_add(1).max(eps);
            let np = match pmin.checked_add(gamma) {
                Some(p) if p <= PRICE_CAP => p,
                _ => return price_overflow(),
            };
            self.set_price(j, np);
        }
        match prev {
            NONE => self.free_dummies -= 1,
            DUMMY => {}
            o => {
                self.free_dummies -= 1;
                self.arc[o as usize] = NO_ARC;
                self.push(o as usize);
            }
        }
        self.owner[j] = DUMMY;
        Ok(())
    }

    fn drain(&mut self, eps: i64) -> Result<()> {
        loop {
            while let Some(i) = self.stack.pop() {
                let i = i as usize;
                self.queued[i] = false;
                self.process(i, eps)?;
            }
            if self.free_dummies > 0 {
                self.dummy_bid(eps)?;
            } else {
                return Ok(());
            }
        }
    }
}

/// Epsilon-scaling auction on the person view; returns person -> arc.
/// `tops`: each person's initial candidates, ordered like its values (computed here if None).
pub(super) fn solve<V: Values>(
    pc: &PersonCsr,
    vals: &V,
    range: i64,
    tops: Option<Vec<TopK>>,
    floor_div: i64,
) -> Result<Vec<usize>> {
    let (m, n) = (pc.m, pc.n_obj);
    let scale = n as i64 + 1;
    // Checked by the callers: range * (n+1) * (n+2) <= 2^60.
    let range_scaled = range * scale;
    let price = vec![0i64; n];
    let mut cand = vec![NO_CAND; m * K];
    let mut cand_len = vec![0u8; m];
    let mut bound = vec![i64::MIN; m];
    let (ptr, obj): (&[usize], &[u32]) = (&pc.ptr, &pc.obj);
    let tops = tops.unwrap_or_else(|| {
        (0..m)
            .into_par_iter()
            .with_min_len(PAR_ROWS)
            .map(|i| TopK::of((ptr[i]..ptr[i + 1]).map(|a| (vals.get(i, a), a))))
            .collect()
    });
    // At zero prices the reduced values are the scaled values, so key order is value order.
    for (i, t) in tops.iter().enumerate() {
        let cnt = t.len.min(K);
        for (c, &a) in cand[i * K..i * K + cnt].iter_mut().zip(&t.ks) {
            *c = Cand {
                arc: a,
                obj: obj[a],
                val: vals.get(i, a) * scale,
            };
        }
        cand_len[i] = cnt as u8;
        if t.len > K {
            bound[i] = vals.get(i, t.ks[K]) * scale;
        }
    }
    let mut a = Auction {
        ptr,
        obj,
        vals,
        scale,
        range: range_scaled,
        price,
        owner: vec![NONE; n],
        arc: vec![NO_ARC; m],
        slack: vec![i64::MIN; m],
        cand,
        cand_len,
        held: vec![NO_CAND; m],
        bound,
        stack: Vec::with_capacity(m),
        queued: vec![false; m],
        tree: if n > m { Some(MinTree::new(n)) } else { None },
        free_dummies: n - m,
    };
    // First epsilon from the data: a quarter of the median positive gap between persons' two
    // best values. Persons whose best object beats the rest by more than that settle with a
    // slack no later phase revisits, while ties still get coarse price steps (starting from a
    // fixed fraction of the range was several times slower on near-tie problems). The floor
    // bounds the price wars of the first phase when a few values dwarf the typical gap.
    let mut gaps: Vec<i64> = tops
        .iter()
        .filter(|t| t.len >= 2)
        .map(|t| t.vs[0].saturating_sub(t.vs[1]))
        .filter(|&g| g > 0)
        .collect();
    let floor = range_scaled / EPS_START_DIV;
    let mut eps = if gaps.is_empty() {
        floor
    } else {
        let mid = gaps.len() / 2;
        let median = *gaps.select_nth_unstable(mid).1;
        (median.saturating_mul(scale) / EPS_GAP_DIV).max(range_scaled / floor_div)
    }
    .clamp(1, range_scaled.max(1));
    let mut first = true;
    loop {
        if first {
            for i in (0..m).rev() {
                a.push(i);
            }
            first = false;
        } else {
            if let Some(t) = a.tree.as_mut() {
                let limit = t.top(&a.price).0.saturating_add(eps);
                for j in 0..n {
                    if a.owner[j] == DUMMY && a.price[j] > limit {
                        a.owner[j] = NONE;
                        a.free_dummies += 1;
                    }
                }
            }
            for i in (0..m).rev() {
                if a.slack[i] < -eps {
                    a.push(i);
                }
            }
        }
        a.drain(eps)?;
        if eps == 1 {
            break;
        }
        eps = (eps / EPS_FACTOR).max(1);
    }
    Ok(a.arc)
}
