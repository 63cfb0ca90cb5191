//! # milv-export — the `milv-export` CLI
//!
//! A thin front over [`milv_mcap`] (`milv-export mcap`) and [`milv_rerun`]
//! (`milv-export rerun`); both read the selection through [`milv_data::view`]. The binary
//! lives in `src/bin/milv-export.rs`; this crate exists so that only it builds the Rerun
//! SDK.

pub use milv_mcap as mcap;
pub use milv_rerun as rerun;
