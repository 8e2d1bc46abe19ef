//! hope_rs core: the compute kernels of HOPE shape matching, free of Python.
//!
//! The `python` feature (enabled by maturin) adds the thin `_core` extension module in `python/`.
pub mod auction;
pub mod collapse;
pub mod csr;
pub mod error;
pub mod face_growth;
pub mod geodesic;
pub mod graph;
pub mod jacobi;
pub mod khop;
pub mod lmd;
pub mod memory;
pub mod nearest;
pub mod overlap;
pub mod pairing;
pub mod rotation;
pub mod shot;
pub mod step;
#[cfg(test)]
mod test_meshes;

#[cfg(feature = "python")]
mod python;

/// `HOPE_NO_SIMD` in the environment: run the portable loops instead of the AVX2/AVX-512 ones
/// (an escape hatch for comparing the two paths; the results are the same).
pub(crate) fn simd_disabled() -> bool {
    std::env::var_os("HOPE_NO_SIMD").is_some()
}
