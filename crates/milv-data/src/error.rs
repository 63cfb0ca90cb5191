//! The crate's one error type.

use std::path::PathBuf;

/// Everything that can go wrong in the dataset store. Paths come last in messages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{op}: {source}: {path}")]
    Io {
        op: &'static str,
        #[source]
        source: std::io::Error,
        path: PathBuf,
    },
    #[error("not a MILV dataset (no _milv/versions folder): {0}")]
    NotADataset(PathBuf),
    #[error("dataset version {version} does not exist (latest is {latest}): {path}")]
    NoSuchVersion {
        version: u64,
        latest: u64,
        path: PathBuf,
    },
    #[error("invalid dataset reference {0:?}: expected PATH or PATH@VERSION")]
    BadReference(String),
    #[error("corrupt version log entry {version}: {msg}: {path}")]
    BadLogEntry {
        version: u64,
        msg: String,
        path: PathBuf,
    },
    #[error("conflict: {0}")]
    Conflict(String),
    /// The version exists (it is durable and readable), but committing it to the Delta
    /// tables failed; the next writer or `milv-ds verify --repair` completes it.
    #[error("version {version} is committed, but not yet in the Delta tables: {source}")]
    NotYetInDelta {
        version: u64,
        #[source]
        source: Box<Error>,
    },
    #[error("delta table {table}: {source}")]
    Delta {
        table: String,
        #[source]
        source: Box<deltalake::DeltaTableError>,
    },
    #[error("parquet: {source}: {path}")]
    Parquet {
        #[source]
        source: deltalake::parquet::errors::ParquetError,
        path: PathBuf,
    },
    #[error("arrow: {0}")]
    Arrow(#[from] deltalake::arrow::error::ArrowError),
    #[error("schema mismatch in {table}: {msg}")]
    Schema { table: String, msg: String },
    #[error("{op}: {source}: {uri}")]
    Store {
        op: &'static str,
        #[source]
        source: Box<deltalake::logstore::object_store::Error>,
        uri: String,
    },
    #[error("refusing {setting}: {why}; unset it")]
    UnsafeSetting { setting: String, why: &'static str },
    #[error("unsupported dataset location {uri}: {msg}")]
    Location { uri: String, msg: String },
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn io(op: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
        let path = path.into();
        move |source| Error::Io { op, source, path }
    }

    pub(crate) fn delta(table: &str) -> impl FnOnce(deltalake::DeltaTableError) -> Error {
        let table = table.to_string();
        move |e| Error::Delta {
            table,
            source: Box::new(e),
        }
    }

    pub(crate) fn parquet(
        path: impl Into<PathBuf>,
    ) -> impl FnOnce(deltalake::parquet::errors::ParquetError) -> Error {
        let path = path.into();
        move |source| Error::Parquet { source, path }
    }
}
