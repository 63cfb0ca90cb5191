//! # milv-lerobot — LeRobot v3.0 datasets in and out of MILV
//!
//! | module | what it holds |
//! |---|---|
//! | [`format`] | `meta/info.json` ([`Info`], [`Feature`]), safe path templates, `tasks.parquet` (with the pandas index LeRobot needs), typed column readers |
//! | [`read`] | [`LeRobotDataset`]: plans every episode of a local dataset; streams one episode's frames from the shared video file (at `from_timestamp + timestamp`, within LeRobot's 1e-4 s) or from inline images |
//! | [`write`] | [`export`]: a dataset version as a LeRobot dataset (AV1 video checked frame by frame, or lossless inline images), built in a temporary folder and renamed into place; [`write::stats`] |
//! | [`stats`] | LeRobot's statistics (min, max, mean, std, count, q01…q99) |
//! | [`error`] | [`Error`]: messages name the file and, where it applies, the episode |
//!
//! Ingesting goes through `milv-ingest` (its `lerobot` module), so imported episodes get
//! the same guarantees as videos: one version with input digests, resumable, re-running
//! is a no-op. The format as LeRobot 0.6.1 reads it is written up in
//! `docs/interop/lerobot-v3.md`.

pub mod error;
pub mod format;
pub mod read;
pub mod stats;
pub mod write;

pub use error::{Error, Result};
pub use format::{Feature, Info};
pub use read::{EpisodePlan, FrameLocation, LeRobotDataset};
pub use write::{ExportOptions, ExportReport, Source, export};
