//! # milv-data — the MILV dataset store
//!
//! A dataset is a folder (or an `s3://bucket/prefix` on any S3-compatible store) holding one [Delta Lake](https://delta.io) table per kind of row
//! (`episodes`, `frames`, …; see [`schema`]) plus a dataset-level version log in
//! `_milv/versions/`. Spark, Polars, DuckDB or pyarrow read the tables directly; MILV
//! tools read them at a pinned dataset version.
//!
//! | module | what it holds |
//! |---|---|
//! | [`schema`] | [`TableKind`], the column lists, Arrow schemas, the `schemas/v1` JSON |
//! | [`rows`] | typed rows of every table ([`Episode`] with [`Domain`], [`Kind`], [`Split`]; [`ScoreRow`], [`CuratedRow`], [`AlignmentRow`]) and batch builders ([`FrameRows`], [`ImaginedRows`]) |
//! | [`write`] | [`GroupWriter`]: adds a table's rows group by group; a run's groups are written once |
//! | [`read`] | whole episodes, translation models, a scoring run, a curation, an alignment run |
//! | [`dataset`] | [`Dataset`] (open `PATH` / `PATH@N`, list files, scan) and [`Transaction`] |
//! | [`frame_codec`] | PNG / JPEG / raw encoding of the `image` column |
//! | [`shard`] | [`ShardWriter`]: zstd Parquet files of bounded size, episode-aligned row groups |
//! | [`log`] | the version log: [`VersionEntry`], [`CommitMeta`] (command line, tool version, input digests) |
//! | [`ops`] | maintenance: info, verify, delete episodes, compact, vacuum |
//! | [`partition`] | [`Partition`]: `--partition i/n` shares for stateless parallel workers |
//! | [`store`] | where the bytes live: a folder or `s3://bucket/prefix` (commit point, uploads, ranged reads) |
//!
//! ## How a change becomes a version
//! 1. A [`Transaction`] is planned against the latest version; its new Parquet files are
//!    written (invisible: no table references them yet).
//! 2. `commit()` atomically creates `_milv/versions/<N>.json` (hard link in a folder,
//!    `If-None-Match: *` put on S3), naming the files each table
//!    gains or loses. This is the commit point: the version exists from here on.
//! 3. Each touched Delta table gets one commit carrying application transaction
//!    `(milv, N)`; a writer that died before this step is completed by the next writer
//!    (`roll_forward`), and the transaction id makes that idempotent.
//!
//! A crash before step 2 leaves only unreferenced files (removed by `vacuum`); the dataset
//! stays at its last good version.
//!
//! ```
//! use milv_data::{CommitMeta, Dataset, DatasetRef, TableKind};
//! let dir = tempfile::tempdir().unwrap();
//! let ds = Dataset::open_or_create(dir.path(), CommitMeta::for_this_process("doc", "create")).unwrap();
//! assert_eq!(ds.latest_version().unwrap(), 0);
//! assert!(ds.files(TableKind::Frames, 0).unwrap().is_empty());
//! let r: DatasetRef = "data/robot@3".parse().unwrap();
//! assert_eq!(r.version, Some(3));
//! ```

mod columns;
pub mod dataset;
mod delta;
pub mod error;
pub mod frame_codec;
pub mod log;
pub mod ops;
pub mod partition;
pub mod read;
pub mod rows;
pub mod schema;
pub mod shard;
pub mod store;
pub mod view;
pub mod write;

pub use dataset::{Dataset, DatasetRef, TableFile, Transaction};
pub use error::{Error, Result};
pub use log::{CommitMeta, FileAdd, InputDigest, TableChange, VersionEntry, run_id};
pub use partition::Partition;
pub use read::{
    AlignedPair, AlignmentRun, DuplicateGroup, EpisodeRows, alignment_run, episode_rows, imagined_models,
    resolve_model, run_groups, score_run,
};
pub use rows::{
    AlignmentRow, CuratedRow, Domain, Episode, FrameEncoding, FrameRows, ImaginedRecord, ImaginedRow,
    ImaginedRows, Kind, Latent, Row, RowBuffer, ScoreRow, Split, episodes_from_batches, episodes_to_batch,
};
pub use schema::{ColType, Column, SCHEMA_VERSION, TableKind};
pub use shard::{ClosedShard, ShardOptions, ShardWriter};
pub use write::{GroupWriter, Written};

/// Re-exported so callers use the exact Arrow/Parquet versions the tables are written with.
pub use deltalake::{arrow, parquet};

/// Version of the MILV tools, recorded in every commit.
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");

/// A temporary file in `out`'s folder, for writers that rename onto `out` only when the
/// file is complete (a failed write then leaves nothing under the final name).
pub fn temp_file_beside(out: &std::path::Path) -> Result<tempfile::NamedTempFile> {
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut b = tempfile::Builder::new();
    let prefix = format!(".{name}.");
    b.prefix(&prefix).suffix(".tmp");
    // The file becomes the output: the mode of an ordinary new file, not tempfile's 0600.
    #[cfg(unix)]
    b.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644));
    b.tempfile_in(&dir).map_err(|source| Error::Io {
        op: "cannot create the output file in",
        source,
        path: dir,
    })
}
