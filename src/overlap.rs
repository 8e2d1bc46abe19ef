//! The HOPE overlap cost K[p, q] = #{ witnesses v : v in B(p), f(v) in B(q) }, built sparse.
//!
//! Each row lives in a dense per-thread counter over B's vertices (a sparse accumulator) that is
//! updated from one row to the next, so no n_a x n_b array ever exists.
use crate::csr::{Csr, CsrView};
use crate::error::{invalid, Result};
use crate::khop::HopBalls;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use std::sync::OnceLock;

/// Anything that can hand out neighbourhood rows: a CSR pattern or the k-prefix of `HopBalls`.
pub trait Rows: Sync {
    fn n_rows(&self) -> usize;
    fn row(&self, r: usize) -> &[u32];
    /// Whether each row lists its members nearest first (BFS order), so that the first
    /// unvisited member of a row is a good next step for the walk (see `walk_order`).
    fn nearest_first(&self) -> bool {
        false
    }
}

impl Rows for CsrView<'_, ()> {
    fn n_rows(&self) -> usize {
        self.n_rows
    }
    fn row(&self, r: usize) -> &[u32] {
        CsrView::row(self, r)
    }
}

/// B_k of every vertex, read from precomputed `HopBalls`.
pub struct BallsAt<'a> {
    pub balls: &'a HopBalls,
    pub k: usize,
}

impl Rows for BallsAt<'_> {
    fn n_rows(&self) -> usize {
        self.balls.n
    }
    fn row(&self, r: usize) -> &[u32] {
        self.balls.ball(r, self.k)
    }
    fn nearest_first(&self) -> bool {
        true
    }
}

/// Options bounding the size of the cost.
#[derive(Debug, Clone, Copy, Default)]
pub struct OverlapOptions<'a> {
    /// Keep only the `top_k` largest counts of each row (ties: smaller column first).
    pub top_k: Option<usize>,
    /// Column that row p always keeps (stored even when its count is 0), e.g. the current match,
    /// so that a full assignment stays available.
    pub keep: Option<&'a [u32]>,
}

/// Rows of one parallel task: consecutive positions of the walk (see `walk_order`).
const SEGMENT: usize = 256;

/// Sparse overlap-count cost, rows = vertices of A, columns = vertices of B, columns sorted.
///
/// Rows are visited along a walk in which consecutive vertices are neighbours, and each row's
/// counts are obtained from the previous row's by adding the balls of the witnesses that enter
/// B(p) and removing those that leave it. Neighbouring k-balls share most of their vertices, so
/// this does a fraction of the work of accumulating every row from scratch (which it falls back
/// to whenever the difference is larger than the ball itself).
pub fn overlap_cost<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    opts: OverlapOptions<'_>,
) -> Result<Csr<u32>> {
    Ok(overlap_rows(nbrs_a, nbrs_b, f, witnesses, opts)?.into_csr())
}

/// [`overlap_cost`] before its rows are laid out (see [`OverlapRows`]).
pub fn overlap_rows<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    opts: OverlapOptions<'_>,
) -> Result<OverlapRows> {
    overlap_rows_with(nbrs_a, nbrs_b, f, witnesses, opts, simd_available())
}

/// [`overlap_rows`] with the AVX-512 inner loops on or off (`simd` only where available).
fn overlap_rows_with<A: Rows, B: Rows>(
    nbrs_a: &A,
    nbrs_b: &B,
    f: &[u32],
    witnesses: &[bool],
    opts: OverlapOptions<'_>,
    simd: bool,
) -> Result<OverlapRows> {
    let n_a = nbrs_a.n_rows();
    let n_b = nbrs_b.n_rows();
    if f.len() != n_a || witnesses.len() != n_a {
        return invalid(format!(
            "f and witnesses must have one entry per vertex of A ({n_a}), got {} and {}",
            f.len(),
            witnesses.len()
        ));
    }
    if let Some(&bad) = f.iter().find(|&&q| q as usize >= n_b) {
        return invalid(format!(
            "f contains {bad}, out of range for the {n_b} vertices of B"
        ));
    }
    if let Some(keep) = opts.keep {
        if keep.len() != n_a || keep.iter().any(|&q| q as usize >= n_b) {
            return invalid("keep must hold one vertex of B per vertex of A");
        }
    }
    if opts.top_k == Some(0) {
        return invalid("top_k must be at least 1");
    }
    // The accumulator indexes its counters by B's columns unchecked: make sure they fit.
    if (0..n_b)
        .into_par_iter()
        .any(|q| nbrs_b.row(q).iter().any(|&c| c as usize >= n_b))
    {
        return invalid(format!("nbrs_b holds a column outside its {n_b} vertices"));
    }
    let (walk, segments) = walk_and_segments(n_a, n_b, simd, nbrs_a, |acc, first, rows| {
        acc.segment(nbrs_a, nbrs_b, f, witnesses, &opts, first, rows)
    });
    let mut len = vec![0usize; n_a];
    for (seg, rows) in segments.iter().zip(walk.chunks(SEGMENT)) {
        for (i, &p) in rows.iter().enumerate() {
            len[p as usize] = seg.starts[i + 1] - seg.starts[i];
        }
    }
    let mut indptr = Vec::with_capacity(n_a + 1);
    indptr.push(0usize);
    for l in &len {
        indptr.push(indptr.last().unwrap() + l);
    }
    Ok(OverlapRows {
        n_cols: n_b,
        walk,
        segments,
        indptr,
    })
}

/// The overlap cost as computed: rows in walk order, plus the row pointer of the final CSR.
/// [`OverlapRows::write_into`] lays the rows out by index into buffers the caller owns (NumPy's,
/// from Python), so the big arrays are written once.
pub struct OverlapRows {
    pub n_cols: usize,
    walk: Vec<u32>,
    segments: Vec<Segment>,
    pub indptr: Vec<usize>,
}

/// A raw base pointer that parallel tasks write through at disjoint offsets.
#[derive(Clone, Copy)]
struct SharedMut<T>(*mut T);
// SAFETY: only used by `write_into`, where every task writes a disjoint set of rows.
unsafe impl<T: Send> Send for SharedMut<T> {}
unsafe impl<T: Send> Sync for SharedMut<T> {}

impl<T> SharedMut<T> {
    /// A method rather than field access, so closures capture the Send wrapper.
    fn at(self, offset: usize) -> *mut T {
        // SAFETY: callers stay within the buffer the pointer came from.
        unsafe { self.0.add(offset) }
    }
}

impl OverlapRows {
    pub fn nnz(&self) -> usize {
        *self.indptr.last().unwrap_or(&0)
    }

    /// Copies every row to its place: `indices` and `data` must have length `nnz()`. Each
    /// segment is freed as soon as it is copied, so the peak is the output plus the segments in
    /// flight rather than two whole copies.
    pub fn write_into(self, indices: &mut [u32], data: &mut [u32]) {
        let nnz = self.nnz();
        assert!(
            indices.len() == nnz && data.len() == nnz,
            "buffers must hold nnz entries"
        );
        let (idx, val) = (
            SharedMut(indices.as_mut_ptr()),
            SharedMut(data.as_mut_ptr()),
        );
        let indptr = &self.indptr;
        self.segments
            .into_par_iter()
            .zip(self.walk.par_chunks(SEGMENT))
            .for_each(move |(seg, rows)| {
                for (i, &p) in rows.iter().enumerate() {
                    let (lo, hi) = (seg.starts[i], seg.starts[i + 1]);
                    let at = indptr[p as usize];
                    // SAFETY: the walk is a permutation of the rows, so the ranges
                    // [indptr[p], indptr[p + 1]) written by different tasks never overlap, and
                    // each lies inside the buffers (checked above against nnz).
                    unsafe {
                        std::ptr::copy_nonoverlapping(seg.cols[lo..].as_ptr(), idx.at(at), hi - lo);
                        std::ptr::copy_nonoverlapping(seg.vals[lo..].as_ptr(), val.at(at), hi - lo);
                    }
                }
            });
    }

    pub fn into_csr(self) -> Csr<u32> {
        let nnz = self.nnz();
        let (n_rows, n_cols, indptr) = (self.walk.len(), self.n_cols, self.indptr.clone());
        let mut indices = vec![0u32; nnz];
        let mut data = vec![0u32; nnz];
        self.write_into(&mut indices, &mut data);
        Csr {
            n_rows,
            n_cols,
            indptr,
            indices,
            data,
        }
    }
}

/// The walk (see [`walk_into`]) and the segments of rows along it, computed by `work` on
/// consecutive chunks of `SEGMENT` positions. One thread walks while the others start on the
/// segments already walked, then joins them: the walk alone is a sizeable share of a call.
fn walk_and_segments<A, W>(
    n_a: usize,
    n_b: usize,
    simd: bool,
    a: &A,
    work: W,
) -> (Vec<u32>, Vec<Segment>)
where
    A: Rows,
    W: Fn(&mut Accumulator, usize, &[u32]) -> Segment + Sync,
{
    let sketch = (!a.nearest_first()).then(|| min_hashes(a));
    let order: Vec<AtomicU32> = (0..n_a).map(|_| AtomicU32::new(0)).collect();
    let walked = AtomicUsize::new(0);
    let n_seg = n_a.div_ceil(SEGMENT);
    let next = AtomicUsize::new(0);
    let slots: Vec<OnceLock<Segment>> = (0..n_seg).map(|_| OnceLock::new()).collect();
    let run = || {
        let mut acc = Accumulator::new(n_a, n_b, simd);
        let mut rows = Vec::with_capacity(SEGMENT);
        loop {
            let s = next.fetch_add(1, Ordering::Relaxed);
            if s >= n_seg {
                break;
            }
            let (lo, hi) = (s * SEGMENT, ((s + 1) * SEGMENT).min(n_a));
            while walked.load(Ordering::Acquire) < hi {
                std::hint::spin_loop();
                std::thread::yield_now();
            }
            rows.clear();
            rows.extend(order[lo..hi].iter().map(|p| p.load(Ordering::Relaxed)));
            // Each index is claimed once, so the slot is empty.
            let _ = slots[s].set(work(&mut acc, lo, &rows));
        }
    };
    rayon::scope(|scope| {
        for _ in 1..rayon::current_num_threads().min(n_seg) {
            scope.spawn(|_| run());
        }
        {
            // Should the walk panic, the workers must not wait for it forever: the panic then
            // reaches the caller at the end of the scope (as a Python RuntimeError).
            let _release = Release(&walked, n_a);
            walk_into(a, sketch.as_deref(), &order, &walked);
        }
        run();
    });
    let walk = order.into_iter().map(AtomicU32::into_inner).collect();
    let segments = slots
        .into_iter()
        .map(|s| s.into_inner().expect("every segment was computed"))
        .collect();
    (walk, segments)
}

/// Publishes the whole walk when dropped, finished or not (see `walk_and_segments`).
struct Release<'a>(&'a AtomicUsize, usize);

impl Drop for Release<'_> {
    fn drop(&mut self) {
        self.0.store(self.1, Ordering::Release);
    }
}

/// An order of A's vertices in which each vertex is, where possible, an unvisited member of the
/// previous vertex's row that is close to it: the first one for rows in BFS order, otherwise the
/// one whose row looks most like the previous row by MinHash (sorted rows, as scipy patterns
/// come, would otherwise step to the smallest index, often across the neighbourhood, which
/// doubled the kernel's work on a 28k-vertex mesh at k = 8).
///
/// Positions are stored into `out` and published through `walked` every `SEGMENT` rows, so
/// that segments can be computed while the walk goes on. Runs no parallel work itself: it
/// would let this thread pick up a segment task that waits for the walk.
fn walk_into<A: Rows>(a: &A, sketch: Option<&[u32]>, out: &[AtomicU32], walked: &AtomicUsize) {
    let n = a.n_rows();
    let mut visited = vec![false; n];
    let mut len = 0usize;
    let mut scan = 0usize;
    let mut current: Option<usize> = None;
    while len < n {
        let unvisited = |&&v: &&u32| (v as usize) < n && !visited[v as usize];
        let next = current
            .and_then(|p| {
                let row = a.row(p);
                match sketch {
                    None => row.iter().find(unvisited).copied(),
                    Some(h) => {
                        let hp = &h[p * HASHES..(p + 1) * HASHES];
                        let hp: [u32; HASHES] = hp.try_into().expect("HASHES entries");
                        row.iter().filter(unvisited).copied().max_by_key(|&v| {
                            let at = v as usize * HASHES;
                            let hv: &[u32; HASHES] =
                                h[at..at + HASHES].try_into().expect("HASHES entries");
                            // Fixed-size arrays: the comparison compiles to a few vector ops
                            // (slices made the walk slower).
                            let same: u32 = (0..HASHES).map(|j| (hp[j] == hv[j]) as u32).sum();
                            // Ties go to the earliest member (max_by_key keeps the last).
                            (same, std::cmp::Reverse(v))
                        })
                    }
                }
            })
            .map(|v| v as usize)
            .unwrap_or_else(|| {
                while visited[scan] {
                    scan += 1;
                }
                scan
            });
        visited[next] = true;
        out[len].store(next as u32, Ordering::Relaxed);
        len += 1;
        if len.is_multiple_of(SEGMENT) || len == n {
            walked.store(len, Ordering::Release);
        }
        current = Some(next);
    }
}

/// MinHash signatures per row: the fraction of equal entries of two signatures estimates the
/// Jaccard similarity of the rows.
const HASHES: usize = 8;

fn min_hashes<A: Rows>(a: &A) -> Vec<u32> {
    let n = a.n_rows();
    // Each vertex's hashes once, so that a row's signature is an element-wise minimum over
    // table rows (a few vector ops per member, instead of hashing every member 8 times).
    let table: Vec<[u32; HASHES]> = (0..n as u32)
        .into_par_iter()
        .map(|v| std::array::from_fn(|h| mix(v, h as u32)))
        .collect();
    let mut out = vec![u32::MAX; n * HASHES];
    out.par_chunks_mut(HASHES).enumerate().for_each(|(r, sig)| {
        let mut acc = [u32::MAX; HASHES];
        for &v in a.row(r) {
            let hv = table
                .get(v as usize)
                .copied()
                .unwrap_or_else(|| std::array::from_fn(|h| mix(v, h as u32)));
            for h in 0..HASHES {
                acc[h] = acc[h].min(hv[h]);
            }
        }
        sig.copy_from_slice(&acc);
    });
    out
}

/// A cheap 32-bit integer hash (the finaliser of MurmurHash3), seeded per signature entry.
#[inline]
fn mix(v: u32, seed: u32) -> u32 {
    let mut x = v ^ seed.wrapping_mul(0x9e37_79b9);
    x ^= x >> 16;
    x = x.wrapping_mul(0x85eb_ca6b);
    x ^= x >> 13;
    x = x.wrapping_mul(0xc2b2_ae35);
    x ^ (x >> 16)
}

/// The rows of one segment, in walk order.
struct Segment {
    starts: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<u32>,
}

/// Flag bit of `Accumulator::count`: the column is in `support`. Counts are below the number
/// of witnesses (< 2^31), so the low bits hold the count and one load serves both questions.
const LISTED: u32 = 1 << 31;

/// The scalar count update of [`Accumulator::add`], branch-free (whether a column is new is
/// data-dependent and mispredicts often, so every column is written at `buf[len]` and the
/// length advances only for new ones). Returns the new length.
///
/// # Safety
/// Every column of `ball` indexes `count`, and `buf` has room for `len + ball.len()` entries.
#[inline]
unsafe fn add_raw(count: *mut u32, buf: *mut u32, mut len: usize, ball: &[u32]) -> usize {
    for &q in ball {
        let c = count.add(q as usize);
        let old = *c;
        *c = (old | LISTED) + 1;
        *buf.add(len) = q;
        len += (old < LISTED) as usize;
    }
    len
}

/// The scalar count update of [`Accumulator::remove`].
///
/// # Safety
/// Every column of `ball` indexes `count`.
#[inline]
unsafe fn remove_raw(count: *mut u32, ball: &[u32]) {
    for &q in ball {
        *count.add(q as usize) -= 1;
    }
}

/// Whether the inner loops use AVX-512F gather/scatter: the CPU has it (see [`avx512_present`])
/// and scatters well. AMD's cores through Zen 4 microcode their scatters, and there the scalar
/// loops are faster; on Intel the gather/scatter loops are the faster ones (see
/// docs/decisions.md#speed). Both paths give the same output bit for bit.
fn simd_available() -> bool {
    avx512_present() && scatter_is_fast()
}

/// The CPU has AVX-512F and `HOPE_NO_SIMD` is not set (an escape hatch for comparing the paths).
fn avx512_present() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !crate::simd_disabled() && std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Intel CPUs, whose AVX-512 scatters run as a few micro-ops per lane. Asked once per process
/// (CPUID exits to the hypervisor on a virtual machine), like `is_x86_feature_detected!`.
fn scatter_is_fast() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static INTEL: OnceLock<bool> = OnceLock::new();
        *INTEL.get_or_init(|| {
            let id = std::arch::x86_64::__cpuid(0);
            let vendor = [id.ebx, id.edx, id.ecx].map(u32::to_le_bytes).concat();
            vendor == b"GenuineIntel"
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Per-thread state: the counts of the current row, kept up to date as the walk moves.
struct Accumulator {
    /// Count of each column of B in the current row, `| LISTED` when the column is in
    /// `support`, the columns whose count may be nonzero.
    count: Vec<u32>,
    support: Vec<u32>,
    /// `member[v]` = 1 + walk position of the last row that contained v.
    member: Vec<u32>,
    entering: Vec<u32>,
    leaving: Vec<u32>,
    selected: Vec<u32>,
    /// Columns at the cut-off count of a `top_k` row, and a histogram of counts (all zero
    /// between rows).
    ties: Vec<u32>,
    hist: Vec<u32>,
    bits: Vec<u64>,
    /// Entries per row of the last segment.
    per_row: usize,
    /// Whether the CPU has AVX-512F (gather/scatter versions of `add` and `remove`).
    simd: bool,
}

impl Accumulator {
    fn new(n_a: usize, n_b: usize, simd: bool) -> Self {
        Accumulator {
            count: vec![0; n_b],
            support: Vec::new(),
            member: vec![0; n_a],
            entering: Vec::new(),
            leaving: Vec::new(),
            selected: Vec::new(),
            ties: Vec::new(),
            hist: Vec::new(),
            bits: vec![0; n_b.div_ceil(64)],
            per_row: 0,
            simd,
        }
    }

    /// Adds one ball of B: every column's count goes up by one, and columns seen for the first
    /// time are appended to `support`. The innermost loop of the kernel.
    #[inline]
    fn add(&mut self, ball: &[u32]) {
        self.support.reserve(ball.len());
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: `simd` is set only when the CPU has AVX-512F; see `add_scalar` for the
            // bounds.
            unsafe { self.add_avx512(ball) };
            return;
        }
        self.add_scalar(ball);
    }

    #[inline]
    fn add_scalar(&mut self, ball: &[u32]) {
        let len = self.support.len();
        // SAFETY: every column of B is < n_b = count.len() (checked once in `overlap_rows`),
        // and `add` reserved ball.len() entries past the support's length.
        let len = unsafe {
            add_raw(
                self.count.as_mut_ptr(),
                self.support.as_mut_ptr(),
                len,
                ball,
            )
        };
        // SAFETY: entries below `len` were all written above or before.
        unsafe { self.support.set_len(len) };
    }

    /// [`Self::add_scalar`] 16 columns at a time: gather the counts, scatter them back raised,
    /// compress the new columns onto `support`. The columns of one ball are distinct, so the
    /// lanes of a scatter never collide.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn add_avx512(&mut self, ball: &[u32]) {
        use std::arch::x86_64::*;
        let mut len = self.support.len();
        let buf = self.support.as_mut_ptr();
        let count = self.count.as_mut_ptr() as *mut i32;
        let listed = _mm512_set1_epi32(LISTED as i32);
        let one = _mm512_set1_epi32(1);
        let chunks = ball.chunks_exact(16);
        let tail = chunks.remainder();
        for c in chunks {
            let q = _mm512_loadu_si512(c.as_ptr() as *const _);
            let old = _mm512_i32gather_epi32::<4>(q, count as *const _);
            let new = _mm512_add_epi32(_mm512_or_si512(old, listed), one);
            _mm512_i32scatter_epi32::<4>(count as *mut _, q, new);
            // New columns: the flag bit was clear (old >= 0 as i32).
            let fresh = _mm512_cmpge_epi32_mask(old, _mm512_setzero_si512());
            _mm512_storeu_si512(
                buf.add(len) as *mut _,
                _mm512_maskz_compress_epi32(fresh, q),
            );
            len += fresh.count_ones() as usize;
        }
        let len = add_raw(count as *mut u32, buf, len, tail);
        self.support.set_len(len);
    }

    #[inline]
    fn remove(&mut self, ball: &[u32]) {
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: as in `add`.
            unsafe { self.remove_avx512(ball) };
            return;
        }
        // SAFETY: as in `add_scalar`; the ball was added before, so no count underflows into
        // the flag.
        unsafe { remove_raw(self.count.as_mut_ptr(), ball) };
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn remove_avx512(&mut self, ball: &[u32]) {
        use std::arch::x86_64::*;
        let count = self.count.as_mut_ptr() as *mut i32;
        let one = _mm512_set1_epi32(1);
        let chunks = ball.chunks_exact(16);
        let tail = chunks.remainder();
        for c in chunks {
            let q = _mm512_loadu_si512(c.as_ptr() as *const _);
            let old = _mm512_i32gather_epi32::<4>(q, count as *const _);
            _mm512_i32scatter_epi32::<4>(count as *mut _, q, _mm512_sub_epi32(old, one));
        }
        remove_raw(count as *mut u32, tail);
    }

    fn clear(&mut self) {
        for &q in &self.support {
            self.count[q as usize] = 0;
        }
        self.support.clear();
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(never)] // keeps per-segment work visible to profilers; called once per 256 rows
    fn segment<A: Rows, B: Rows>(
        &mut self,
        nbrs_a: &A,
        nbrs_b: &B,
        f: &[u32],
        witnesses: &[bool],
        opts: &OverlapOptions<'_>,
        first_pos: usize,
        rows: &[u32],
    ) -> Segment {
        let n_a = self.member.len();
        // Sized from this thread's previous segment: growing large vectors by doubling spent
        // a good part of the call copying them.
        let guess = rows.len() * self.per_row + rows.len() * self.per_row / 8;
        let mut out = Segment {
            starts: Vec::with_capacity(rows.len() + 1),
            cols: Vec::with_capacity(guess),
            vals: Vec::with_capacity(guess),
        };
        out.starts.push(0);
        self.clear();
        let mut prev: Option<(usize, u32)> = None;
        for (i, &p) in rows.iter().enumerate() {
            let p = p as usize;
            let id = (first_pos + i + 1) as u32;
            let row = nbrs_a.row(p);
            self.entering.clear();
            self.leaving.clear();
            let prev_id = prev.map_or(0, |(_, pid)| pid);
            for &v in row {
                if (v as usize) < n_a && self.member[v as usize] != prev_id {
                    self.entering.push(v);
                }
            }
            for &v in row {
                if (v as usize) < n_a {
                    self.member[v as usize] = id;
                }
            }
            if let Some((q, _)) = prev {
                for &v in nbrs_a.row(q) {
                    if (v as usize) < n_a && self.member[v as usize] != id {
                        self.leaving.push(v);
                    }
                }
            }
            let incremental =
                prev.is_some() && self.entering.len() + self.leaving.len() < row.len();
            let entering = std::mem::take(&mut self.entering);
            let leaving = std::mem::take(&mut self.leaving);
            if !incremental {
                self.clear();
            }
            let fresh: &[u32] = if incremental { &entering } else { row };
            for &v in fresh {
                let v = v as usize;
                if v < n_a && witnesses[v] {
                    self.add(nbrs_b.row(f[v] as usize));
                }
            }
            if incremental {
                for &v in &leaving {
                    if witnesses[v as usize] {
                        self.remove(nbrs_b.row(f[v as usize] as usize));
                    }
                }
            }
            self.entering = entering;
            self.leaving = leaving;
            self.emit(p, opts, &mut out);
            prev = Some((p, id));
        }
        self.per_row = out.cols.len().div_ceil(rows.len().max(1));
        out
    }

    /// Appends row p (nonzero counts, plus the kept column) with sorted columns.
    fn emit(&mut self, p: usize, opts: &OverlapOptions<'_>, out: &mut Segment) {
        let kept = opts.keep.map(|k| k[p]);
        match opts.top_k {
            Some(t) if self.support.len() > t => self.emit_top(t, kept, out),
            _ => self.emit_all(kept, out),
        }
        out.starts.push(out.cols.len());
    }

    /// Marks the live columns of `support` in `bits` and clears the counts of the dead ones
    /// (the bare flag). Returns the number of live columns and the smallest and largest column
    /// of `support`.
    fn mark_live(&mut self) -> (usize, u32, u32) {
        let count = self.count.as_mut_ptr();
        let bits = &mut self.bits;
        let (mut n, mut lo, mut hi) = (0usize, u32::MAX, 0u32);
        for &q in &self.support {
            // SAFETY: support holds columns of B, all < n_b = count.len().
            let c = unsafe { *count.add(q as usize) };
            let live = c > LISTED;
            bits[q as usize >> 6] |= (live as u64) << (q & 63);
            unsafe { *count.add(q as usize) = c & 0u32.wrapping_sub(live as u32) };
            n += live as usize;
            lo = lo.min(q);
            hi = hi.max(q);
        }
        (n, lo, hi)
    }

    /// Every live column, in order. At k = 8 (~1000 per row) this is most of the output work.
    ///
    /// One pass over `support` marks the live columns in a bitset and clears the counts of the
    /// dead ones; a scan of the bitset then writes the sorted columns, which also become the new
    /// `support`. Sparse rows, whose columns lie far apart, are sorted instead of scanned.
    fn emit_all(&mut self, kept: Option<u32>, out: &mut Segment) {
        let (mut n, mut lo, mut hi) = self.mark_live();
        let count = self.count.as_mut_ptr();
        let bits = &mut self.bits;
        let mut extra = None;
        if let Some(q) = kept {
            // SAFETY: as above (keep is checked against n_b).
            let c = unsafe { &mut *count.add(q as usize) };
            if *c <= LISTED {
                // Stored with count 0; flagged so that the support (rebuilt below from the
                // output) lists it once, and the next row drops it again unless it gains votes.
                *c = LISTED;
                bits[q as usize >> 6] |= 1u64 << (q & 63);
                n += 1;
                lo = lo.min(q);
                hi = hi.max(q);
                extra = Some(q);
            }
        }
        if n == 0 {
            self.support.clear();
            return;
        }
        let (lo_w, hi_w) = (lo as usize >> 6, hi as usize >> 6);
        let at = out.cols.len();
        if n * 8 < hi_w - lo_w + 1 {
            // Few columns over a long range: sort them rather than scan the range.
            let count = &self.count;
            self.support.retain(|&q| count[q as usize] > LISTED);
            self.support.extend(extra);
            for &q in &self.support {
                bits[q as usize >> 6] = 0;
            }
            self.support.sort_unstable();
            out.cols.extend_from_slice(&self.support);
        } else {
            out.cols.reserve(n);
            let cols = out.cols.as_mut_ptr();
            let mut i = at;
            for (w, word) in bits[lo_w..=hi_w].iter_mut().enumerate() {
                let mut word = std::mem::take(word);
                while word != 0 {
                    let q = ((lo_w + w) << 6) | word.trailing_zeros() as usize;
                    // SAFETY: exactly n bits are set, and n entries past `at` were reserved.
                    unsafe { *cols.add(i) = q as u32 };
                    word &= word - 1;
                    i += 1;
                }
            }
            debug_assert_eq!(i, at + n);
            // SAFETY: the n entries past `at` were written above.
            unsafe { out.cols.set_len(at + n) };
            self.support.clear();
            self.support.extend_from_slice(&out.cols[at..]);
        }
        let count = &self.count;
        out.vals
            .extend(out.cols[at..].iter().map(|&q| count[q as usize] & !LISTED));
    }

    /// The `t` largest counts (ties: smaller column first) plus the kept column, sorted.
    fn emit_top(&mut self, t: usize, kept: Option<u32>, out: &mut Segment) {
        // The t-th largest count T by a histogram of the (small) counts: every column above T
        // is kept, and of those at T the smallest ones. Two passes over the row instead of a
        // quickselect keyed through the counts (the step costs of `match` keep 48 of ~1000).
        let count = &mut self.count;
        let hist = &mut self.hist;
        let mut top = 0usize;
        self.support.retain(|&q| {
            let c = count[q as usize];
            let live = c > LISTED;
            if live {
                let c = (c & !LISTED) as usize;
                if c >= hist.len() {
                    hist.resize(c + 1, 0);
                }
                hist[c] += 1;
                top = top.max(c);
            } else {
                count[q as usize] = 0;
            }
            live
        });
        let (mut above, mut cut) = (0usize, 0usize);
        for c in (1..=top).rev() {
            let h = hist[c] as usize;
            if above + h >= t {
                cut = c;
                break;
            }
            above += h;
        }
        // A support longer than t may hold no live column at all (a row that lost every
        // witness after one with t live columns and a kept one): then nothing was counted.
        if let Some(h) = hist.get_mut(..=top) {
            h.fill(0);
        }
        let count = &self.count;
        let (sel, ties) = (&mut self.selected, &mut self.ties);
        sel.clear();
        ties.clear();
        for &q in &self.support {
            let c = (count[q as usize] & !LISTED) as usize;
            if c > cut {
                sel.push(q);
            } else if c == cut {
                ties.push(q);
            }
        }
        let need = t.saturating_sub(sel.len()).min(ties.len());
        if need > 0 && need < ties.len() {
            ties.select_nth_unstable(need - 1);
        }
        sel.extend_from_slice(&ties[..need]);
        if let Some(q) = kept {
            if !sel.contains(&q) {
                sel.push(q);
            }
        }
        sel.sort_unstable();
        for &q in sel.iter() {
            out.cols.push(q);
            out.vals.push(count[q as usize] & !LISTED);
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // tests index several parallel arrays
mod tests {
    use super::*;
    use crate::graph::adjacency_from_faces;

    fn dense_reference(
        a: &HopBalls,
        b: &HopBalls,
        k: usize,
        f: &[u32],
        w: &[bool],
    ) -> Vec<Vec<u32>> {
        let mut out = vec![vec![0u32; b.n]; a.n];
        for (p, row) in out.iter_mut().enumerate() {
            for &v in a.ball(p, k) {
                if w[v as usize] {
                    for &q in b.ball(f[v as usize] as usize, k) {
                        row[q as usize] += 1;
                    }
                }
            }
        }
        out
    }

    fn grid_faces(w: u32, h: u32) -> Vec<[u32; 3]> {
        let mut f = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let v = y * w + x;
                f.push([v, v + 1, v + w]);
                f.push([v + 1, v + w + 1, v + w]);
            }
        }
        f
    }

    #[test]
    fn matches_dense_count_and_top_k_keeps_best() {
        let adj_a = adjacency_from_faces(&grid_faces(7, 6), 42).unwrap();
        let adj_b = adjacency_from_faces(&grid_faces(6, 7), 42).unwrap();
        let a = HopBalls::new(&adj_a.view(), 3).unwrap();
        let b = HopBalls::new(&adj_b.view(), 3).unwrap();
        let f: Vec<u32> = (0..42u32).map(|i| (i * 17 + 5) % 42).collect();
        let w: Vec<bool> = (0..42).map(|i| i % 3 != 0).collect();
        for k in 0..=3 {
            let dense = dense_reference(&a, &b, k, &f, &w);
            let opts = OverlapOptions::default();
            let c = overlap_cost(
                &BallsAt { balls: &a, k },
                &BallsAt { balls: &b, k },
                &f,
                &w,
                opts,
            )
            .unwrap();
            for p in 0..42 {
                let v = c.view();
                let got: Vec<(u32, u32)> = v
                    .row(p)
                    .iter()
                    .copied()
                    .zip(v.row_data(p).iter().copied())
                    .collect();
                let want: Vec<(u32, u32)> = (0..42u32)
                    .filter(|&q| dense[p][q as usize] > 0)
                    .map(|q| (q, dense[p][q as usize]))
                    .collect();
                assert_eq!(got, want);
            }
            let keep: Vec<u32> = (0..42u32).rev().collect();
            let opts = OverlapOptions {
                top_k: Some(3),
                keep: Some(&keep),
            };
            let t = overlap_cost(
                &BallsAt { balls: &a, k },
                &BallsAt { balls: &b, k },
                &f,
                &w,
                opts,
            )
            .unwrap();
            let v = t.view();
            for p in 0..42 {
                let (cols, vals) = (v.row(p), v.row_data(p));
                assert!(cols.contains(&keep[p]) && cols.len() <= 4);
                // Top-k property: nothing dropped beats anything kept (the forced column aside).
                let min_kept = cols
                    .iter()
                    .zip(vals)
                    .filter(|(&q, _)| q != keep[p])
                    .map(|(_, &c)| c)
                    .min()
                    .unwrap_or(u32::MAX);
                let max_dropped = (0..42u32)
                    .filter(|q| !cols.contains(q))
                    .map(|q| dense[p][q as usize])
                    .max()
                    .unwrap_or(0);
                assert!(max_dropped <= min_kept, "row {p}");
                for (&q, &c) in cols.iter().zip(vals) {
                    assert_eq!(c, dense[p][q as usize]);
                }
            }
        }
    }

    /// Every row of `c` as (column, count) pairs equals `want`.
    fn assert_rows(c: Result<OverlapRows>, want: &[Vec<(u32, u32)>], what: &str) {
        let c = c.unwrap().into_csr();
        let v = c.view();
        for (p, w) in want.iter().enumerate() {
            let got: Vec<(u32, u32)> = v
                .row(p)
                .iter()
                .copied()
                .zip(v.row_data(p).iter().copied())
                .collect();
            assert_eq!(&got, w, "{what}, row {p}");
        }
    }

    #[test]
    fn top_row_without_live_columns_keeps_only_the_kept_column() {
        // A fresh accumulator (empty histogram) whose support is longer than t but all dead,
        // as after a row of t live columns plus a kept one followed by a row without witnesses.
        for kept in [None, Some(7u32)] {
            let mut acc = Accumulator::new(1, 100, false);
            acc.support = (10..59).collect();
            for &q in &acc.support {
                acc.count[q as usize] = LISTED;
            }
            let mut out = Segment {
                starts: vec![0],
                cols: Vec::new(),
                vals: Vec::new(),
            };
            acc.emit_top(48, kept, &mut out);
            assert_eq!(out.cols, kept.into_iter().collect::<Vec<_>>());
            assert!(out.vals.iter().all(|&v| v == 0));
            assert!(acc.support.is_empty());
            assert!(acc.count.iter().all(|&c| c == 0));
        }
    }

    /// Several segments and both inner-loop paths: a 60 x 50 grid with scrambled labels, so that
    /// rows come as sorted CSR (the MinHash walk) and columns lie far apart (the sorting emit),
    /// beside the same balls in BFS order; with and without a kept column.
    #[test]
    fn segments_simd_and_scalar_match_dense_count() {
        let (w, h) = (60u32, 50u32);
        let n = (w * h) as usize;
        let perm: Vec<u32> = (0..n as u32).map(|i| (i * 1237 + 11) % n as u32).collect();
        let faces: Vec<[u32; 3]> = grid_faces(w, h)
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        let adj = adjacency_from_faces(&faces, n).unwrap();
        let balls = HopBalls::new(&adj.view(), 4).unwrap();
        let f: Vec<u32> = (0..n as u32)
            .map(|i| (i * 7 + (i % 5)) % n as u32)
            .collect();
        let wit: Vec<bool> = (0..n).map(|i| i % 4 != 1).collect();
        let keep: Vec<u32> = (0..n as u32).map(|i| (i * 31 + 3) % n as u32).collect();
        let paths = [false, avx512_present()];
        for k in [1usize, 4] {
            let dense = dense_reference(&balls, &balls, k, &f, &wit);
            let csr = balls.to_csr(k);
            for kept in [None, Some(&keep[..])] {
                let opts = OverlapOptions {
                    top_k: None,
                    keep: kept,
                };
                let want: Vec<Vec<(u32, u32)>> = (0..n)
                    .map(|p| {
                        (0..n as u32)
                            .filter(|&q| dense[p][q as usize] > 0 || kept.map(|c| c[p]) == Some(q))
                            .map(|q| (q, dense[p][q as usize]))
                            .collect()
                    })
                    .collect();
                // Top 5 of each row by (count desc, column asc), plus the kept column.
                let top: Vec<Vec<(u32, u32)>> = want
                    .iter()
                    .enumerate()
                    .map(|(p, row)| {
                        let mut r: Vec<(u32, u32)> =
                            row.iter().copied().filter(|&(_, c)| c > 0).collect();
                        r.sort_by_key(|&(q, c)| (std::cmp::Reverse(c), q));
                        r.truncate(5);
                        if let Some(c) = kept.map(|c| c[p]) {
                            if !r.iter().any(|e| e.0 == c) {
                                r.push((c, dense[p][c as usize]));
                            }
                        }
                        r.sort_unstable();
                        r
                    })
                    .collect();
                let top_opts = OverlapOptions {
                    top_k: Some(5),
                    keep: kept,
                };
                for simd in paths {
                    let c = overlap_rows_with(&csr.view(), &csr.view(), &f, &wit, top_opts, simd);
                    assert_rows(c, &top, &format!("top_k, k {k}, simd {simd}"));
                    let by_balls = overlap_rows_with(
                        &BallsAt { balls: &balls, k },
                        &BallsAt { balls: &balls, k },
                        &f,
                        &wit,
                        opts,
                        simd,
                    );
                    let by_csr = overlap_rows_with(&csr.view(), &csr.view(), &f, &wit, opts, simd);
                    for c in [by_balls, by_csr] {
                        assert_rows(c, &want, &format!("k {k}, simd {simd}"));
                    }
                }
            }
        }
    }
}
