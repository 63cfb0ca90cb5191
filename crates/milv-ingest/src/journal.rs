//! The resume journal of an ingest run: `_milv/staging/ingest-<key>.jsonl` (for a dataset
//! on S3, in a local staging folder named after the dataset's URL: a worker restarted on
//! the same node resumes; journaled files are already uploaded).
//!
//! Whenever a worker closes a shard (every ~128 MiB, or after a long episode), the file and
//! the episode rows it completes are appended here, synced. An interrupted run leaves the
//! journal behind; the same command run again (same pending episodes, hence same key)
//! adopts every journaled file that is still intact instead of decoding its episodes again.
//! A successful commit deletes the journal.

use std::collections::BTreeSet;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use milv_data::{Dataset, Episode, FileAdd, TableKind};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::error::{Error, Result};

#[derive(Serialize, Deserialize)]
struct Line {
    file: FileAdd,
    episodes: Vec<Episode>,
}

/// Files and episodes an earlier, interrupted run of the same batch finished.
#[derive(Default)]
pub(crate) struct Adopted {
    pub files: Vec<FileAdd>,
    pub episodes: Vec<Episode>,
}

pub(crate) struct Journal {
    path: PathBuf,
    file: Mutex<std::fs::File>,
}

fn io(op: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> Error {
    let path = path.to_path_buf();
    move |source| Error::Io { op, source, path }
}

impl Journal {
    /// Opens the journal of the batch made of `pending` episode ids and returns what it
    /// holds that can be reused (files still present with their recorded size).
    pub fn open(ds: &Dataset, pending: &BTreeSet<String>) -> Result<(Journal, Adopted)> {
        let mut h = Sha256::new();
        for id in pending {
            h.update(id.as_bytes());
            h.update([0]);
        }
        let key: String = h.finalize()[..12].iter().map(|b| format!("{b:02x}")).collect();
        let dir = ds.staging_dir();
        std::fs::create_dir_all(&dir).map_err(io("create staging folder", &dir))?;
        let path = dir.join(format!("ingest-{key}.jsonl"));
        let open = |p: &Path| {
            std::fs::OpenOptions::new()
                .create(true)
                .read(true)
                .append(true)
                .open(p)
                .map_err(io("open journal", p))
        };
        let file = open(&path)?;
        if file.try_lock().is_err() {
            // The same batch is being ingested right now by another process: its files
            // are not ours to take. Journal on the side instead.
            let own = dir.join(format!("ingest-{key}-{}.jsonl", uuid_like()));
            let file = open(&own)?;
            file.try_lock()
                .map_err(|e| Error::input(&own, format!("lock journal: {e}")))?;
            return Ok((
                Journal {
                    path: own,
                    file: Mutex::new(file),
                },
                Adopted::default(),
            ));
        }
        let mut adopted = Adopted::default();
        if let Ok(text) = std::fs::read_to_string(&path) {
            // A torn last line (crash mid-append) simply doesn't parse and is ignored.
            for line in text.lines().filter_map(|l| serde_json::from_str::<Line>(l).ok()) {
                let intact = ds
                    .file_size(TableKind::Frames, &line.file.path)
                    .is_ok_and(|size| size == Some(line.file.size));
                if intact && line.episodes.iter().all(|e| pending.contains(&e.episode_id)) {
                    adopted.files.push(line.file);
                    adopted.episodes.extend(line.episodes);
                }
            }
        }
        Ok((
            Journal {
                path,
                file: Mutex::new(file),
            },
            adopted,
        ))
    }

    /// Records a finished file and the episodes it completes.
    pub fn record(&self, file: FileAdd, episodes: Vec<Episode>) -> Result<()> {
        let mut text = serde_json::to_string(&Line { file, episodes })
            .map_err(|e| Error::input(&self.path, format!("journal: {e}")))?;
        text.push('\n');
        let mut f = self.file.lock().unwrap_or_else(|p| p.into_inner());
        f.write_all(text.as_bytes())
            .map_err(io("write journal", &self.path))?;
        f.sync_data().map_err(io("sync journal", &self.path))
    }

    /// The batch is committed: the journal is no longer needed. (Its lock goes with the
    /// file handle.)
    pub fn remove(self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// A unique suffix without another dependency: time and process id.
fn uuid_like() -> String {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    format!("{t:x}-{}", std::process::id())
}
