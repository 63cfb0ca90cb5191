//! JSON lines: one record per step or evaluation, appended as training goes.

use std::io::Write;
use std::path::Path;

use serde::Serialize;

use crate::{Error, Result};

/// Appends `v` as one JSON line to `path` (created if absent).
pub fn append_json(path: &Path, v: &impl Serialize) -> Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(Error::io("open for appending", path))?;
    let line = serde_json::to_string(v).map_err(|source| Error::Json {
        op: "serialise",
        source,
        path: path.to_path_buf(),
    })?;
    writeln!(f, "{line}").map_err(Error::io("append to", path))
}
