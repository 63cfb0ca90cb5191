//! The dataset-level version log: `_milv/versions/<N>.json`, one file per dataset version.
//!
//! An entry is the commit point of a change that may touch several tables: it is created
//! atomically only after every data file it names is completely written — in a folder by
//! writing a temp file and hard-linking it to its final name, on an object store by a
//! create-if-absent put (`If-None-Match: *`); either fails if a concurrent writer took
//! that number first. Each table then receives the entry as one Delta commit tagged with
//! the application transaction `(milv, N)`, so applying an entry twice is a no-op and a
//! crash between the two steps is repaired by the next writer ("roll forward").

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::store::Root;

/// Folder (under the dataset root) holding the version log.
pub const LOG_DIR: &str = "_milv/versions";

/// One data file added to a table by a version.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FileAdd {
    /// Path relative to the table root.
    pub path: String,
    pub size: u64,
    pub num_records: u64,
    /// Smallest and largest `episode_id` in the file (file skipping by episode).
    pub min_episode: Option<String>,
    pub max_episode: Option<String>,
    pub modification_time_ms: i64,
}

/// What one version does to one table.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct TableChange {
    #[serde(default)]
    pub add: Vec<FileAdd>,
    /// Paths (relative to the table root) of files this version removes.
    #[serde(default)]
    pub remove: Vec<String>,
    /// Episodes whose rows this version adds to the table (for conflict checks and logs).
    #[serde(default)]
    pub episodes_added: Vec<String>,
    /// Episodes whose rows this version removes from the table.
    #[serde(default)]
    pub episodes_removed: Vec<String>,
}

/// A digest of one input of a run (a video, a sidecar, a manifest).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct InputDigest {
    pub uri: String,
    pub sha256: String,
}

/// Who made a version and why.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct CommitMeta {
    /// Short operation name: create, ingest, delete-episodes, compact, ...
    pub operation: String,
    /// The command line, argument by argument.
    pub command: Vec<String>,
    pub tool: String,
    pub tool_version: String,
    #[serde(default)]
    pub inputs: Vec<InputDigest>,
    /// Free-form summary (counts, options).
    #[serde(default)]
    pub summary: serde_json::Value,
}

impl CommitMeta {
    /// Metadata for a run of `tool` with this process's command line.
    pub fn for_this_process(tool: &str, operation: &str) -> Self {
        CommitMeta {
            operation: operation.into(),
            command: std::env::args().collect(),
            tool: tool.into(),
            tool_version: crate::TOOL_VERSION.into(),
            inputs: Vec::new(),
            summary: serde_json::Value::Null,
        }
    }
}

/// A short, stable id (16 hex chars of sha256) naming a run by what it read and how:
/// re-running the same stage on the same inputs gets the same id, so it can find its own
/// earlier output, and partitioned workers of one run agree on it.
pub fn run_id<S: AsRef<str>>(parts: &[S]) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for p in parts {
        h.update(p.as_ref().as_bytes());
        h.update([0]);
    }
    h.finalize().iter().take(8).map(|b| format!("{b:02x}")).collect()
}

/// One dataset version.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct VersionEntry {
    pub format: String,
    pub version: u64,
    /// The version this change was planned against.
    pub parent: Option<u64>,
    pub timestamp_ms: i64,
    #[serde(flatten)]
    pub meta: CommitMeta,
    /// Table name -> change.
    pub tables: BTreeMap<String, TableChange>,
}

pub(crate) const ENTRY_FORMAT: &str = "milv-version/1";

fn entry_name(version: u64) -> String {
    format!("{LOG_DIR}/{version:020}.json")
}

/// All version numbers present in the log, ascending.
pub(crate) fn list_versions(root: &Root) -> Result<Vec<u64>> {
    let Some(names) = root.list(LOG_DIR)? else {
        return Err(Error::NotADataset(root.label().to_path_buf()));
    };
    let mut out: Vec<u64> = names
        .iter()
        // Temp files start with '.', so only complete entries parse.
        .filter_map(|name| {
            let stem = name.strip_suffix(".json")?;
            if stem.len() == 20 { stem.parse().ok() } else { None }
        })
        .collect();
    out.sort_unstable();
    Ok(out)
}

pub(crate) fn read_entry(root: &Root, version: u64) -> Result<VersionEntry> {
    let name = entry_name(version);
    let path = root.label_of(&name);
    let bytes = root.read(&name)?;
    let entry: VersionEntry = serde_json::from_slice(&bytes).map_err(|e| Error::BadLogEntry {
        version,
        msg: e.to_string(),
        path: path.clone(),
    })?;
    if entry.version != version || entry.format != ENTRY_FORMAT {
        return Err(Error::BadLogEntry {
            version,
            msg: format!("holds version {} in format {:?}", entry.version, entry.format),
            path,
        });
    }
    Ok(entry)
}

/// Atomically creates the entry for `entry.version`; `Ok(false)` if that number is taken.
/// A hard link locally, a create-if-absent put on an object store: same semantics.
pub(crate) fn try_create_entry(root: &Root, entry: &VersionEntry) -> Result<bool> {
    let bytes = serde_json::to_vec_pretty(entry).map_err(|e| Error::Invalid(e.to_string()))?;
    root.create_new(&entry_name(entry.version), &bytes)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn entry(v: u64) -> VersionEntry {
        VersionEntry {
            format: ENTRY_FORMAT.into(),
            version: v,
            parent: v.checked_sub(1),
            timestamp_ms: 1,
            meta: CommitMeta::default(),
            tables: BTreeMap::new(),
        }
    }

    #[test]
    fn entries_are_created_once() {
        let dir = tempfile::tempdir().unwrap();
        let root = Root::Local(dir.path().to_path_buf());
        root.ensure_dir(LOG_DIR).unwrap();
        assert!(try_create_entry(&root, &entry(0)).unwrap());
        assert!(!try_create_entry(&root, &entry(0)).unwrap());
        assert!(try_create_entry(&root, &entry(1)).unwrap());
        assert_eq!(list_versions(&root).unwrap(), vec![0, 1]);
        assert_eq!(read_entry(&root, 1).unwrap(), entry(1));
        // No temp files left behind.
        let names: Vec<_> = std::fs::read_dir(dir.path().join(LOG_DIR)).unwrap().collect();
        assert_eq!(names.len(), 2);
    }

    #[test]
    fn missing_log_is_not_a_dataset() {
        let dir = tempfile::tempdir().unwrap();
        let root = Root::Local(dir.path().to_path_buf());
        assert!(matches!(list_versions(&root), Err(Error::NotADataset(_))));
    }
}
