//! hope_rs core: the compute kernels of HOPE shape matching, free of Python.
//!
//! The `python` feature (enabled by maturin) adds the thin `_core` extension module in `python.rs`.
pub mod auction;
pub mod csr;
pub mod error;
pub mod geodesic;
pub mod graph;
pub mod khop;
pub mod lmd;
pub mod memory;
pub mod overlap;
pub mod pairing;
pub mod shot;
pub mod step;

#[cfg(feature = "python")]
mod python;
