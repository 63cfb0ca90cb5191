//! # milv-ingest — human and robot videos into the `episodes` and `frames` tables
//!
//! | module | what it holds |
//! |---|---|
//! | [`ingest`] | [`ingest()`](ingest::ingest): plan, decode/encode in parallel, commit one version; [`IngestOptions`], [`IngestReport`] |
//! | [`sidecar`] | per-episode action/state sidecars (JSON `milv-sidecar/1`, CSV) and [`EpisodeMeta`] |
//! | `lerobot` | LeRobot v3.0 episodes as inputs ([`ingest_lerobot`]): file digests, one planned episode per LeRobot episode |
//! | [`manifest`] | many inputs at once (JSON lines or CSV): [`InputSpec`] |
//! | `journal` | the resume journal: shards an interrupted run finished are reused by the next |
//! | [`error`] | [`Error`]: every message names the file it is about |
//!
//! Episode ids are content hashes of the source bytes, the sidecar bytes, the metadata and
//! the options, so ingesting the same inputs again is a no-op. A failing input is reported
//! and skipped; the others land in one new dataset version.

pub mod error;
pub mod ingest;
mod journal;
mod lerobot;
pub mod manifest;
pub mod sidecar;

pub use error::{Error, Result};
pub use ingest::{IngestOptions, IngestReport, NoProgress, Partition, Progress, ingest, ingest_lerobot};
pub use manifest::InputSpec;
pub use sidecar::{EpisodeMeta, Sidecar};
