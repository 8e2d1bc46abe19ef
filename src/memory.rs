//! Large buffers backed by transparent huge pages.
//!
//! Linux often offers huge pages only to memory that asks for them ("madvise" mode, the default
//! of many distributions; NumPy asks for its own large arrays). The kernels' big buffers (a
//! k = 8 cost holds hundreds of MB) otherwise fault in 4 KiB at a time, and at 28k vertices
//! those faults cost as much as writing the data.
//!
//! Buffers whose size comes from a number the caller passed (a vertex count, a column count, a
//! hop radius) are allocated with the fallible `try_*` functions instead: a size beyond the
//! machine becomes [`CoreError::OutOfMemory`](crate::error::CoreError) rather than an abort.
use crate::error::{out_of_memory, Result};

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

/// Total physical memory in bytes (`usize::MAX` where unknown).
pub fn physical_memory() -> usize {
    physical_memory_impl().unwrap_or(usize::MAX)
}

#[cfg(target_os = "linux")]
fn physical_memory_impl() -> Option<usize> {
    // SAFETY: sysconf only reads system configuration.
    let (pages, page) = unsafe {
        (
            libc::sysconf(libc::_SC_PHYS_PAGES),
            libc::sysconf(libc::_SC_PAGESIZE),
        )
    };
    let (pages, page) = (usize::try_from(pages).ok()?, usize::try_from(page).ok()?);
    pages.checked_mul(page)
}

#[cfg(not(target_os = "linux"))]
fn physical_memory_impl() -> Option<usize> {
    None
}

/// Fails with `OutOfMemory` when `bytes` (`None`: overflowed) exceeds the physical memory. An
/// allocator with overcommit grants such sizes and the process dies when it touches them, so
/// this is checked before allocating, not left to the allocator.
pub fn check_budget(bytes: Option<usize>, what: &str) -> Result<()> {
    match bytes {
        Some(b) if b <= physical_memory() => Ok(()),
        _ => out_of_memory(what, bytes),
    }
}

/// Bytes of `n` values of `T`, `None` on overflow.
pub fn bytes_of<T>(n: usize) -> Option<usize> {
    n.checked_mul(std::mem::size_of::<T>())
}

/// An empty vector with room for `n` values, or `OutOfMemory` (see [`check_budget`]).
pub fn try_with_capacity<T>(n: usize, what: &str) -> Result<Vec<T>> {
    check_budget(bytes_of::<T>(n), what)?;
    let mut v = Vec::new();
    match v.try_reserve_exact(n) {
        Ok(()) => Ok(v),
        Err(_) => out_of_memory(what, bytes_of::<T>(n)),
    }
}

/// `vec![value; n]`, or `OutOfMemory` (see [`check_budget`]).
pub fn try_filled_vec<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let mut v = try_with_capacity(n, what)?;
    v.resize(n, value);
    Ok(v)
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

    #[test]
    fn fallible_vectors_refuse_sizes_beyond_the_machine() {
        use crate::error::CoreError;
        let v = try_filled_vec(5, 7u32, "test").unwrap();
        assert_eq!(v, vec![7; 5]);
        assert!(try_with_capacity::<u8>(0, "test").unwrap().is_empty());
        // More than the physical memory: refused before the allocator is asked.
        let big = physical_memory().saturating_add(1).min(usize::MAX / 2);
        match try_filled_vec(big, 0u8, "a test buffer") {
            Err(CoreError::OutOfMemory { what, bytes }) => {
                assert_eq!(what, "a test buffer");
                assert_eq!(bytes, Some(big));
            }
            other => panic!("expected OutOfMemory, got {other:?}"),
        }
        // A size whose byte count overflows usize.
        let e = try_with_capacity::<u64>(usize::MAX / 4, "huge").unwrap_err();
        assert_eq!(
            e,
            CoreError::OutOfMemory {
                what: "huge".into(),
                bytes: None
            }
        );
        assert!(e.to_string().starts_with("not enough memory for huge"));
        assert!(check_budget(Some(1 << 20), "small").is_ok());
    }
}
