//! Large buffers backed by transparent huge pages.
//!
//! Linux often offers huge pages only to memory that asks for them ("madvise" mode, the default
//! of many distributions; NumPy asks for its own large arrays). The kernels' big buffers (a
//! k = 8 cost holds hundreds of MB) otherwise fault in 4 KiB at a time, and at 28k vertices
//! those faults cost as much as writing the data.

/// Asks for huge pages on the whole capacity of `v`, which should not be touched yet.
pub fn advise_huge_pages<T>(v: &mut Vec<T>) {
    let bytes = v.capacity() * std::mem::size_of::<T>();
    advise(v.as_mut_ptr() as usize, bytes);
}

/// A zeroed vector of length `n` whose pages are not touched yet and, when large, ask for huge
/// pages.
pub fn zeroed_vec<T: Copy + Default>(n: usize) -> Vec<T> {
    // Zero-valued elements come from calloc, which maps fresh (untouched) pages at this size.
    let mut v = vec![T::default(); n];
    advise_huge_pages(&mut v);
    v
}

#[cfg(target_os = "linux")]
fn advise(start: usize, bytes: usize) {
    const HUGE: usize = 2 << 20;
    let (lo, hi) = (start.next_multiple_of(HUGE), (start + bytes) & !(HUGE - 1));
    if hi > lo {
        // SAFETY: [lo, hi) lies inside an allocation the caller owns; MADV_HUGEPAGE is a hint
        // that never changes the memory's contents, and its result does not matter.
        unsafe { libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE) };
    }
}

#[cfg(not(target_os = "linux"))]
fn advise(_start: usize, _bytes: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zeroed_vectors_are_zero_and_writable() {
        for n in [0usize, 1, 1000, 3 << 20] {
            let mut v = zeroed_vec::<u32>(n);
            assert_eq!(v.len(), n);
            assert!(v.iter().all(|&x| x == 0));
            v.iter_mut().enumerate().for_each(|(i, x)| *x = i as u32);
            assert!(v.iter().enumerate().all(|(i, &x)| x == i as u32));
        }
        let mut w: Vec<u64> = Vec::with_capacity(1 << 20);
        advise_huge_pages(&mut w);
        w.extend(0..1000u64);
        assert_eq!(w[999], 999);
    }
}
