//! The crate's error type: every message names the file (and the episode) it is about.

use std::path::PathBuf;

/// What can go wrong reading or writing a LeRobot dataset.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{op} {}: {source}", .path.display())]
    Io {
        op: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: invalid JSON: {source}", .path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: {source}", .path.display())]
    Parquet {
        path: PathBuf,
        #[source]
        source: milv_data::parquet::errors::ParquetError,
    },
    #[error("{}: {source}", .path.display())]
    Arrow {
        path: PathBuf,
        #[source]
        source: milv_data::arrow::error::ArrowError,
    },
    /// The dataset as a whole cannot be used (bad info.json, unsupported version, ...).
    #[error("{}: {msg}", .path.display())]
    Format { path: PathBuf, msg: String },
    /// One episode cannot be used; the others still can.
    #[error("episode {episode}: {msg} ({})", .path.display())]
    Episode {
        path: PathBuf,
        episode: i64,
        msg: String,
    },
    #[error(transparent)]
    Video(#[from] milv_video::Error),
    #[error(transparent)]
    Data(#[from] milv_data::Error),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn format(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            msg: msg.into(),
        }
    }

    pub(crate) fn episode(path: impl Into<PathBuf>, episode: i64, msg: impl Into<String>) -> Self {
        Error::Episode {
            path: path.into(),
            episode,
            msg: msg.into(),
        }
    }

    pub(crate) fn io(op: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| Error::Io { op, path, source }
    }

    pub(crate) fn parquet(
        path: impl Into<PathBuf>,
    ) -> impl FnOnce(milv_data::parquet::errors::ParquetError) -> Self {
        let path = path.into();
        move |source| Error::Parquet { path, source }
    }

    pub(crate) fn arrow(
        path: impl Into<PathBuf>,
    ) -> impl FnOnce(milv_data::arrow::error::ArrowError) -> Self {
        let path = path.into();
        move |source| Error::Arrow { path, source }
    }
}
