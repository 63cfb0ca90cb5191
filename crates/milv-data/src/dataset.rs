//! [`Dataset`]: a folder of versioned tables, opened at `PATH` or `PATH@N`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use deltalake::arrow::array::RecordBatch;

use crate::delta;
use crate::error::{Error, Result};
use crate::log::{self, CommitMeta, FileAdd, TableChange, VersionEntry};
use crate::schema::TableKind;
use crate::shard::{ShardOptions, ShardWriter};
use crate::store::{self, Root};

/// `PATH` or `PATH@VERSION`, as given on a command line; `PATH` may be `s3://bucket/prefix`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DatasetRef {
    pub root: PathBuf,
    pub version: Option<u64>,
}

impl FromStr for DatasetRef {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        if s.is_empty() {
            return Err(Error::BadReference(s.into()));
        }
        // Only a trailing `@digits` is a version, so paths containing '@' still work.
        if let Some((path, v)) = s.rsplit_once('@')
            && !v.is_empty()
            && v.bytes().all(|b| b.is_ascii_digit())
        {
            if path.is_empty() {
                return Err(Error::BadReference(s.into()));
            }
            let version = v.parse().map_err(|_| Error::BadReference(s.into()))?;
            return Ok(DatasetRef {
                root: PathBuf::from(path),
                version: Some(version),
            });
        }
        Ok(DatasetRef {
            root: PathBuf::from(s),
            version: None,
        })
    }
}

impl std::fmt::Display for DatasetRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.version {
            Some(v) => write!(f, "{}@{v}", self.root.display()),
            None => write!(f, "{}", self.root.display()),
        }
    }
}

/// One data file of a table at some version.
#[derive(Clone, Debug, PartialEq)]
pub struct TableFile {
    pub table: TableKind,
    /// Where the file is: its path, or its `s3://` URL (for messages; read it with
    /// [`Dataset::read_file`]).
    pub abs_path: PathBuf,
    pub info: FileAdd,
    /// Dataset version that added the file.
    pub added_in: u64,
}

/// A versioned dataset in a folder or at `s3://bucket/prefix`. Cheap to open; every read
/// names a version.
pub struct Dataset {
    root: Root,
    /// Log entries read so far: an entry never changes once created, and on an object
    /// store every read is a request.
    entries: std::sync::Mutex<BTreeMap<u64, VersionEntry>>,
}

impl std::fmt::Debug for Dataset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Dataset").field("root", &self.root).finish()
    }
}

impl Dataset {
    /// Opens an existing dataset (a folder, or `s3://bucket/prefix`).
    pub fn open(root: impl AsRef<Path>) -> Result<Self> {
        let root = Root::parse(root.as_ref())?;
        log::list_versions(&root)?;
        Ok(Dataset {
            root,
            entries: Default::default(),
        })
    }

    /// Opens a dataset, creating an empty one (version 0) if the location has none.
    pub fn open_or_create(root: impl AsRef<Path>, meta: CommitMeta) -> Result<Self> {
        let root = Root::parse(root.as_ref())?;
        root.ensure_dir(log::LOG_DIR)?;
        let empty = match log::list_versions(&root) {
            Ok(v) => v.is_empty(),
            // An object store has no empty folders: no entry yet means no dataset yet.
            Err(Error::NotADataset(_)) if !root.is_local() => true,
            Err(e) => return Err(e),
        };
        if empty {
            let entry = VersionEntry {
                format: log::ENTRY_FORMAT.into(),
                version: 0,
                parent: None,
                timestamp_ms: now_ms(),
                meta: CommitMeta {
                    operation: "create".into(),
                    ..meta
                },
                tables: BTreeMap::new(),
            };
            // Losing this race just means someone else created it.
            log::try_create_entry(&root, &entry)?;
        }
        Ok(Dataset {
            root,
            entries: Default::default(),
        })
    }

    /// The folder, or `s3://bucket/prefix` (as a path, for messages).
    pub fn root(&self) -> &Path {
        self.root.label()
    }

    /// True for a local folder, false for an object store.
    pub fn is_local(&self) -> bool {
        self.root.is_local()
    }

    /// A local folder for files not yet part of the dataset (resume journals).
    pub fn staging_dir(&self) -> PathBuf {
        self.root.staging()
    }

    /// The size of data file `path` (relative to `table`'s root), `None` if absent.
    pub fn file_size(&self, table: TableKind, path: &str) -> Result<Option<u64>> {
        self.root.size(&format!("{}/{path}", table.name()))
    }

    pub(crate) fn location(&self) -> &Root {
        &self.root
    }

    /// All versions, ascending.
    pub fn versions(&self) -> Result<Vec<u64>> {
        log::list_versions(&self.root)
    }

    /// The newest version. Versions are visible as soon as their log entry exists.
    pub fn latest_version(&self) -> Result<u64> {
        self.versions()?
            .last()
            .copied()
            .ok_or_else(|| Error::NotADataset(self.root().to_path_buf()))
    }

    /// `None` -> latest; `Some(v)` -> `v` if it exists.
    pub fn resolve(&self, version: Option<u64>) -> Result<u64> {
        let latest = self.latest_version()?;
        match version {
            None => Ok(latest),
            Some(v) if v <= latest && self.versions()?.binary_search(&v).is_ok() => Ok(v),
            Some(v) => Err(Error::NoSuchVersion {
                version: v,
                latest,
                path: self.root().to_path_buf(),
            }),
        }
    }

    pub fn entry(&self, version: u64) -> Result<VersionEntry> {
        let cached = self
            .entries
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&version)
            .cloned();
        if let Some(e) = cached {
            return Ok(e);
        }
        let e = log::read_entry(&self.root, version)?;
        self.entries
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(version, e.clone());
        Ok(e)
    }

    /// Every entry up to and including `version`.
    pub fn entries_until(&self, version: u64) -> Result<Vec<VersionEntry>> {
        self.versions()?
            .into_iter()
            .filter(|v| *v <= version)
            .map(|v| self.entry(v))
            .collect()
    }

    /// The table's folder or URL (for messages).
    pub fn table_root(&self, table: TableKind) -> PathBuf {
        self.root.label_of(table.name())
    }

    /// The files making up `table` at dataset `version`, in the order they were added.
    pub fn files(&self, table: TableKind, version: u64) -> Result<Vec<TableFile>> {
        let mut live: Vec<TableFile> = Vec::new();
        for entry in self.entries_until(version)? {
            let Some(change) = entry.tables.get(table.name()) else {
                continue;
            };
            let removed: BTreeSet<&str> = change.remove.iter().map(String::as_str).collect();
            live.retain(|f| !removed.contains(f.info.path.as_str()));
            live.extend(change.add.iter().map(|a| TableFile {
                table,
                abs_path: self.table_root(table).join(&a.path),
                info: a.clone(),
                added_in: entry.version,
            }));
        }
        Ok(live)
    }

    /// Streams the rows of `table` at `version`, optionally only some columns.
    pub fn scan(
        &self,
        table: TableKind,
        version: u64,
        columns: Option<&[&str]>,
    ) -> Result<impl Iterator<Item = Result<RecordBatch>> + use<>> {
        let files = self.files(table, version)?;
        let columns: Option<Vec<String>> = columns.map(|c| c.iter().map(|s| s.to_string()).collect());
        let root = self.root.clone();
        Ok(files.into_iter().flat_map(
            move |f| match root.open_parquet(&file_key(&f), columns.as_deref()) {
                Ok(r) => r,
                Err(e) => Box::new(std::iter::once(Err(e))),
            },
        ))
    }

    /// Streams the rows of one data file of this dataset, optionally only some columns.
    pub fn read_file(
        &self,
        file: &TableFile,
        columns: Option<&[&str]>,
    ) -> Result<impl Iterator<Item = Result<RecordBatch>> + use<>> {
        let cols: Option<Vec<String>> = columns.map(|c| c.iter().map(|s| s.to_string()).collect());
        self.root.open_parquet(&file_key(file), cols.as_deref())
    }

    /// The Parquet footer of one data file.
    pub fn file_footer(
        &self,
        file: &TableFile,
    ) -> Result<std::sync::Arc<deltalake::parquet::file::metadata::ParquetMetaData>> {
        self.root.parquet_metadata(&file_key(file))
    }

    /// Reads a whole (small) table into memory.
    pub fn read_all(&self, table: TableKind, version: u64) -> Result<Vec<RecordBatch>> {
        self.scan(table, version, None)?.collect()
    }

    /// The Delta version each table had at each dataset version (from the tables' history).
    pub fn delta_versions(&self) -> Result<BTreeMap<TableKind, BTreeMap<u64, u64>>> {
        store::block_on(async {
            let mut out = BTreeMap::new();
            for t in TableKind::ALL {
                out.insert(t, delta::version_map(&self.root, t).await?);
            }
            Ok(out)
        })
    }

    /// Delta table versions pinned by dataset `version` (tables created by then).
    pub fn pinned_delta_versions(&self, version: u64) -> Result<BTreeMap<TableKind, u64>> {
        let maps = self.delta_versions()?;
        Ok(maps
            .into_iter()
            .filter_map(|(t, m)| m.range(..=version).next_back().map(|(_, tv)| (t, *tv)))
            .collect())
    }

    /// Relative file paths Delta itself lists for a table at a Delta version.
    pub fn delta_files(&self, table: TableKind, delta_version: u64) -> Result<Vec<String>> {
        store::block_on(delta::files_at(&self.root, table, delta_version))
    }

    /// Versions whose entries some table has not received yet (a writer stopped between
    /// creating the entry and committing it to the tables).
    pub fn pending(&self) -> Result<Vec<(u64, TableKind)>> {
        store::block_on(async {
            let mut out = Vec::new();
            let versions = self.versions()?;
            for t in TableKind::ALL {
                let applied = if delta::has_delta_log(&self.root, t)? {
                    let table = delta::open_or_create(&self.root, t).await?;
                    delta::applied_version(&self.root, &table, t).await?
                } else {
                    None
                };
                for &v in &versions {
                    if applied.is_some_and(|a| v <= a) {
                        continue;
                    }
                    if self.entry(v)?.tables.contains_key(t.name()) {
                        out.push((v, t));
                    }
                }
            }
            out.sort();
            Ok(out)
        })
    }

    /// Commits every logged version to the Delta tables that lack it. Idempotent.
    pub fn roll_forward(&self) -> Result<usize> {
        let pending = self.pending()?;
        store::block_on(async {
            for (v, t) in &pending {
                let entry = self.entry(*v)?;
                delta::apply(&self.root, *t, &entry).await?;
            }
            Ok(pending.len())
        })
    }

    /// Runs Delta's vacuum (full mode) on every table; returns the deleted paths.
    pub fn vacuum_tables(&self, retain_hours: u64, dry_run: bool) -> Result<Vec<String>> {
        store::block_on(async {
            let mut deleted = Vec::new();
            for t in TableKind::ALL {
                if !delta::has_delta_log(&self.root, t)? {
                    continue;
                }
                let table = delta::open_or_create(&self.root, t).await?;
                deleted.extend(delta::vacuum(&self.root, table, t, retain_hours, dry_run).await?);
            }
            Ok(deleted)
        })
    }

    /// Starts a change planned against the latest version.
    pub fn begin(&self, meta: CommitMeta) -> Result<Transaction<'_>> {
        Ok(Transaction {
            ds: self,
            base: self.latest_version()?,
            meta,
            changes: BTreeMap::new(),
            adopted: BTreeSet::new(),
        })
    }
}

/// A data file's key relative to the dataset root.
fn file_key(f: &TableFile) -> String {
    format!("{}/{}", f.table.name(), f.info.path)
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// A change being prepared: files are written first, then [`Transaction::commit`] makes
/// them one new dataset version with one Delta commit per table touched.
pub struct Transaction<'a> {
    ds: &'a Dataset,
    base: u64,
    meta: CommitMeta,
    changes: BTreeMap<TableKind, TableChange>,
    /// Added files this transaction did not write (adopted from an interrupted run):
    /// never deleted on abort, since another run may have committed them meanwhile.
    adopted: BTreeSet<(TableKind, String)>,
}

impl Transaction<'_> {
    pub(crate) fn dataset(&self) -> &Dataset {
        self.ds
    }

    pub fn base_version(&self) -> u64 {
        self.base
    }

    pub fn meta_mut(&mut self) -> &mut CommitMeta {
        &mut self.meta
    }

    /// A writer for new files of `table` (they stay invisible until the commit).
    pub fn shard_writer(&self, table: TableKind, opts: ShardOptions) -> Result<ShardWriter> {
        ShardWriter::for_dataset(self.ds.location(), table, opts)
    }

    pub fn add_files(&mut self, table: TableKind, files: Vec<FileAdd>, episodes: Vec<String>) {
        let c = self.changes.entry(table).or_default();
        c.add.extend(files);
        c.episodes_added.extend(episodes);
    }

    /// Adds files written by an earlier, interrupted process (see [`Transaction::abort`]).
    pub fn adopt_files(&mut self, table: TableKind, files: Vec<FileAdd>, episodes: Vec<String>) {
        self.adopted.extend(files.iter().map(|f| (table, f.path.clone())));
        self.add_files(table, files, episodes);
    }

    pub fn remove_files(&mut self, table: TableKind, paths: Vec<String>, episodes: Vec<String>) {
        let c = self.changes.entry(table).or_default();
        c.remove.extend(paths);
        c.episodes_removed.extend(episodes);
    }

    pub fn is_empty(&self) -> bool {
        self.changes
            .values()
            .all(|c| c.add.is_empty() && c.remove.is_empty())
    }

    /// Deletes the files this transaction wrote (it will not be committed).
    pub fn abort(self) {
        for (t, c) in &self.changes {
            for f in &c.add {
                if !self.adopted.contains(&(*t, f.path.clone())) {
                    self.ds.root.remove(&format!("{}/{}", t.name(), f.path));
                }
            }
        }
    }

    /// Every added file must be stored, complete, with its folder entry synced, before
    /// a version may name it (e.g. a concurrent vacuum may have removed an orphan).
    fn check_files_durable(&self) -> Result<()> {
        for (t, c) in &self.changes {
            for f in &c.add {
                let size = self.ds.file_size(*t, &f.path)?;
                if size != Some(f.size) {
                    let what = size.map_or("missing".to_string(), |s| format!("{s} bytes"));
                    return Err(Error::Invalid(format!(
                        "new data file is {what}, expected {} bytes: {}",
                        f.size,
                        self.ds.table_root(*t).join(&f.path).display()
                    )));
                }
            }
            if let (false, Root::Local(root)) = (c.add.is_empty(), &self.ds.root) {
                store::sync_dir(&root.join(t.name()))?;
            }
        }
        Ok(())
    }

    /// Checks that a version committed after our base does not clash with this change.
    fn check_against(&self, other: &VersionEntry) -> Result<()> {
        for (t, mine) in &self.changes {
            let Some(theirs) = other.tables.get(t.name()) else {
                continue;
            };
            let their_removed: BTreeSet<&String> = theirs.remove.iter().collect();
            if let Some(p) = mine.remove.iter().find(|p| their_removed.contains(p)) {
                return Err(Error::Conflict(format!(
                    "file {p} of table {t} was already removed by version {}",
                    other.version
                )));
            }
            let their_added: BTreeSet<&String> = theirs.episodes_added.iter().collect();
            if let Some(e) = mine.episodes_added.iter().find(|e| their_added.contains(e)) {
                return Err(Error::Conflict(format!(
                    "episode {e} was added to table {t} concurrently by version {}",
                    other.version
                )));
            }
        }
        Ok(())
    }

    /// Publishes the change as the next dataset version and commits it to each table.
    /// Returns the new version (or the base version if there was nothing to commit).
    pub fn commit(self) -> Result<u64> {
        if self.is_empty() {
            return Ok(self.base);
        }
        if let Err(e) = self.check_files_durable() {
            self.abort();
            return Err(e);
        }
        let mut tables = BTreeMap::new();
        for (t, c) in &self.changes {
            tables.insert(t.name().to_string(), c.clone());
        }
        let mut checked = self.base;
        let version = loop {
            let latest = self.ds.latest_version()?;
            for v in (checked + 1)..=latest {
                let clash = self.ds.entry(v).and_then(|other| self.check_against(&other));
                if let Err(e) = clash {
                    self.abort();
                    return Err(e);
                }
            }
            checked = latest;
            let entry = VersionEntry {
                format: log::ENTRY_FORMAT.into(),
                version: latest + 1,
                parent: Some(self.base),
                timestamp_ms: now_ms(),
                meta: self.meta.clone(),
                tables: tables.clone(),
            };
            if log::try_create_entry(&self.ds.root, &entry)? {
                break entry.version;
            }
        };
        // The version is durable now; the Delta commits below can be redone by anyone.
        match self.ds.roll_forward() {
            Ok(_) => Ok(version),
            Err(e) => Err(Error::NotYetInDelta {
                version,
                source: Box::new(e),
            }),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn references_parse() {
        let r: DatasetRef = "data/ds@12".parse().unwrap();
        assert_eq!(r.root, PathBuf::from("data/ds"));
        assert_eq!(r.version, Some(12));
        let r: DatasetRef = "data/user@host/ds".parse().unwrap();
        assert_eq!(r.version, None);
        assert_eq!(r.root, PathBuf::from("data/user@host/ds"));
        let r: DatasetRef = "ds@".parse().unwrap();
        assert_eq!(r.root, PathBuf::from("ds@"));
        assert!("@3".parse::<DatasetRef>().is_err());
        assert!("".parse::<DatasetRef>().is_err());
        assert_eq!("a@3".parse::<DatasetRef>().unwrap().to_string(), "a@3");
    }
}
