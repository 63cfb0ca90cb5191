//! # milv-mcap — MCAP recordings of what the translation did
//!
//! Exports a pinned dataset version — human frames, their translations by one model
//! (imagined frame, latent, predicted action), quality and curated weight, and the
//! aligned robot frames with their true actions — as MCAP files that Foxglove, the `mcap`
//! tools and Rerun's MCAP importer open.
//!
//! | module | what it holds |
//! |---|---|
//! | [`schema`] | topics, the protobuf [`schema::Tensor`] latent message and its descriptor, the JSON schemas of actions and quality |
//! | [`write`] | [`write_recording`] (one file, episodes end to end) and [`write_per_episode`]; temporary name + rename |
//! | [`read`] | [`Recording::read`]: our reader, with chunk CRCs checked, for round trips |
//!
//! What goes in comes from [`milv_data::view::ViewPlan`] (the selection, joined per frame).
//! Files use the `mcap` crate's defaults: zstd chunks, message and chunk indexes,
//! statistics and a summary section; metadata record `milv` names the dataset, version,
//! model, tool version and command line, one `episode` record per episode gives its log
//! time span, and the model's configuration is attached as `model_config.json`.

pub use mcap;

pub mod read;
pub mod schema;
pub mod write;

use std::path::PathBuf;

pub use read::{RecordedMessage, Recording};
pub use write::{McapOptions, RecordingInfo, Written, write_per_episode, write_recording};

/// Everything that can go wrong in an export. Paths come last in messages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Data(#[from] milv_data::Error),
    #[error("mcap: {source}: {path}")]
    Mcap {
        #[source]
        source: mcap::McapError,
        path: PathBuf,
    },
    #[error("{op}: {source}: {path}")]
    Io {
        op: &'static str,
        #[source]
        source: std::io::Error,
        path: PathBuf,
    },
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, Error>;
