//! # milv-export — the `milv-export` CLI
//!
//! A thin front over [`milv_mcap`] (`milv-export mcap`), [`milv_rerun`]
//! (`milv-export rerun`), both reading the selection through [`milv_data::view`], and
//! [`milv_lerobot`] (`milv-export lerobot`). The binary
//! lives in `src/bin/milv-export.rs`; this crate exists so that only it builds the Rerun
//! SDK.

pub use milv_lerobot as lerobot;
pub use milv_mcap as mcap;
pub use milv_rerun as rerun;
