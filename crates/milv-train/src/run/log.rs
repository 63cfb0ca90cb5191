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

/// Drops the lines of `path` whose `"step"` is past `step`: a run resumed from its
/// checkpoint at `step` logs those steps again, and a killed run may have logged them
/// already. Lines without a step are kept; a missing file is fine.
pub fn truncate_after(path: &Path, step: u64) -> Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(Error::io("read", path)(e)),
    };
    let past = |line: &str| {
        serde_json::from_str::<serde_json::Value>(line)
            .ok()
            .and_then(|v| v["step"].as_u64())
            .is_some_and(|s| s > step)
    };
    if !text.lines().any(past) {
        return Ok(());
    }
    let kept: String = text
        .lines()
        .filter(|l| !past(l))
        .map(|l| format!("{l}\n"))
        .collect();
    // Temp file and rename: a crash here leaves the old log, never half of it.
    let tmp = path.with_extension("jsonl.tmp");
    std::fs::write(&tmp, kept).map_err(Error::io("write", &tmp))?;
    std::fs::rename(&tmp, path).map_err(Error::io("rename into", path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resuming_drops_the_steps_past_the_checkpoint_only() {
        let dir = tempfile::tempdir().expect("temp dir");
        let p = dir.path().join("losses.jsonl");
        truncate_after(&p, 3).expect("a missing log is fine");
        for step in 1..=6u64 {
            append_json(&p, &serde_json::json!({ "step": step })).expect("append");
        }
        append_json(&p, &serde_json::json!({ "note": "no step" })).expect("append");
        truncate_after(&p, 4).expect("truncate");
        let steps: Vec<Option<u64>> = std::fs::read_to_string(&p)
            .expect("read")
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("json")["step"].as_u64())
            .collect();
        assert_eq!(steps, vec![Some(1), Some(2), Some(3), Some(4), None]);
    }
}
