//! The crate's one error type.

use std::path::PathBuf;

/// Why an input (or the whole ingest) failed. Paths come last in messages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{op}: {source}: {path}")]
    Io {
        op: &'static str,
        #[source]
        source: std::io::Error,
        path: PathBuf,
    },
    #[error("sidecar: {msg}: {path}")]
    Sidecar { msg: String, path: PathBuf },
    #[error("manifest line {line}: {msg}: {path}")]
    Manifest { line: usize, msg: String, path: PathBuf },
    #[error("{msg}: {path}")]
    Input { msg: String, path: PathBuf },
    #[error(transparent)]
    Video(#[from] milv_video::Error),
    #[error(transparent)]
    Data(#[from] milv_data::Error),
    #[error(transparent)]
    LeRobot(#[from] milv_lerobot::Error),
    #[error("frame {index}: {msg}: {path}")]
    Frame { index: u64, msg: String, path: PathBuf },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn input(path: impl Into<PathBuf>, msg: impl Into<String>) -> Error {
        Error::Input {
            msg: msg.into(),
            path: path.into(),
        }
    }
}
