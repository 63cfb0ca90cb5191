//! Dataset maintenance: info, verify, delete episodes, compact, vacuum.
//!
//! Each operation that changes the dataset is one [`Transaction`], hence one version.

use std::collections::{BTreeMap, BTreeSet};

use deltalake::arrow::array::{Array, BinaryArray, BooleanArray, Int32Array, RecordBatch};
use deltalake::arrow::compute::filter_record_batch;
use serde::Serialize;

use crate::columns::column;
use crate::dataset::{Dataset, TableFile, Transaction};
use crate::error::{Error, Result};
use crate::frame_codec;
use crate::log::CommitMeta;
use crate::rows::{Episode, episodes_from_batches};
use crate::schema::TableKind;
use crate::shard::{ShardOptions, episode_ids};

/// Size of one table at one version.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TableInfo {
    pub files: usize,
    pub rows: u64,
    pub bytes: u64,
    /// The Delta table version this dataset version pins (None: table not created yet).
    pub delta_version: Option<u64>,
}

/// What `milv-ds info` prints.
#[derive(Clone, Debug, Serialize)]
pub struct Info {
    pub path: String,
    pub version: u64,
    pub latest_version: u64,
    pub tables: BTreeMap<String, TableInfo>,
    pub episodes: u64,
    pub frames: u64,
    /// "domain/kind" -> episodes
    pub by_domain_kind: BTreeMap<String, u64>,
    /// task_id -> (episodes, frames)
    pub by_task: BTreeMap<String, (u64, u64)>,
    pub pending_delta_commits: usize,
}

/// All episodes at a version.
pub fn episodes(ds: &Dataset, version: u64) -> Result<Vec<Episode>> {
    episodes_from_batches(&ds.read_all(TableKind::Episodes, version)?)
}

pub fn info(ds: &Dataset, version: u64) -> Result<Info> {
    let pinned = ds.pinned_delta_versions(version)?;
    let mut tables = BTreeMap::new();
    for t in TableKind::ALL {
        let files = ds.files(t, version)?;
        tables.insert(
            t.name().to_string(),
            TableInfo {
                files: files.len(),
                rows: files.iter().map(|f| f.info.num_records).sum(),
                bytes: files.iter().map(|f| f.info.size).sum(),
                delta_version: pinned.get(&t).copied(),
            },
        );
    }
    let eps = episodes(ds, version)?;
    let mut by_domain_kind = BTreeMap::new();
    let mut by_task: BTreeMap<String, (u64, u64)> = BTreeMap::new();
    for e in &eps {
        *by_domain_kind
            .entry(format!("{}/{}", e.domain, e.kind))
            .or_insert(0) += 1;
        let t = by_task
            .entry(e.task_id.clone().unwrap_or_else(|| "-".into()))
            .or_default();
        t.0 += 1;
        t.1 += e.n_frames as u64;
    }
    Ok(Info {
        path: ds.root().display().to_string(),
        version,
        latest_version: ds.latest_version()?,
        episodes: eps.len() as u64,
        frames: eps.iter().map(|e| e.n_frames as u64).sum(),
        tables,
        by_domain_kind,
        by_task,
        pending_delta_commits: ds.pending()?.len(),
    })
}

/// What `milv-ds verify` found.
#[derive(Clone, Debug, Default, Serialize)]
pub struct VerifyReport {
    pub version: u64,
    pub files_checked: usize,
    pub rows_checked: u64,
    pub frames_decoded: u64,
    /// (version, table) pairs logged but not yet committed to Delta.
    pub pending: Vec<(u64, TableKind)>,
    pub problems: Vec<String>,
    /// Groups a run wrote more than once (by tools older than the idempotent writer):
    /// readers use the first copy, so they are warnings, not problems.
    pub duplicates: Vec<crate::read::DuplicateGroup>,
}

impl VerifyReport {
    pub fn ok(&self) -> bool {
        self.problems.is_empty()
    }
}

/// Reads every file of every table at `version`; checks row counts against the log and the
/// episodes table, the Delta file lists against the log, and that every frame decodes to
/// its episode's size.
pub fn verify(ds: &Dataset, version: u64, mut progress: impl FnMut(u64)) -> Result<VerifyReport> {
    let mut rep = VerifyReport {
        version,
        ..Default::default()
    };
    let pinned = ds.pinned_delta_versions(version)?;
    // Versions logged but not yet committed to Delta are durable; they are reported, and
    // the Delta comparison waits until a writer (or `--repair`) completes them.
    rep.pending = ds.pending()?.into_iter().filter(|(v, _)| *v <= version).collect();
    for t in TableKind::ALL {
        if rep.pending.iter().any(|(_, pt)| *pt == t) {
            continue;
        }
        let files = ds.files(t, version)?;
        let ours: BTreeSet<String> = files.iter().map(|f| f.info.path.clone()).collect();
        match pinned.get(&t) {
            Some(dv) => {
                let theirs: BTreeSet<String> = ds.delta_files(t, *dv)?.into_iter().collect();
                if theirs != ours {
                    rep.problems.push(format!(
                        "table {t}: Delta version {dv} lists {} files, the version log {}",
                        theirs.len(),
                        ours.len()
                    ));
                }
            }
            None if !files.is_empty() => rep.problems.push(format!(
                "table {t} has files at version {version} but no Delta commit for them"
            )),
            None => {}
        }
    }
    let eps = match episodes(ds, version) {
        Ok(e) => e,
        Err(e) => {
            rep.problems.push(format!("episodes table unreadable: {e}"));
            return Ok(rep);
        }
    };
    let by_id: BTreeMap<&str, &Episode> = eps.iter().map(|e| (e.episode_id.as_str(), e)).collect();
    if by_id.len() != eps.len() {
        rep.problems
            .push("episodes table has duplicate episode_id values".into());
    }
    let mut seen: BTreeMap<String, Vec<i32>> = BTreeMap::new();
    for t in TableKind::ALL {
        for f in ds.files(t, version)? {
            rep.files_checked += 1;
            match check_file(ds, &f, &by_id, &mut seen, &mut rep.frames_decoded, &mut progress) {
                Ok(rows) => {
                    rep.rows_checked += rows;
                    if rows != f.info.num_records {
                        rep.problems.push(format!(
                            "{}: {} rows, the version log says {}",
                            f.abs_path.display(),
                            rows,
                            f.info.num_records
                        ));
                    }
                }
                Err(e) => rep.problems.push(e.to_string()),
            }
        }
    }
    for e in &eps {
        let mut idx = seen.remove(&e.episode_id).unwrap_or_default();
        idx.sort_unstable();
        let expected: Vec<i32> = (0..e.n_frames as i32).collect();
        if idx != expected {
            rep.problems.push(format!(
                "episode {}: {} frame rows (indices not 0..{}), n_frames = {}",
                e.episode_id,
                idx.len(),
                e.n_frames,
                e.n_frames
            ));
        }
    }
    for id in seen.keys() {
        rep.problems.push(format!(
            "frames of episode {id} have no row in the episodes table"
        ));
    }
    rep.duplicates = crate::read::duplicate_groups(ds, version)?;
    Ok(rep)
}

fn check_file(
    ds: &Dataset,
    f: &TableFile,
    episodes: &BTreeMap<&str, &Episode>,
    seen: &mut BTreeMap<String, Vec<i32>>,
    decoded: &mut u64,
    progress: &mut impl FnMut(u64),
) -> Result<u64> {
    let mut rows = 0;
    for batch in ds.read_file(f, None)? {
        let batch = batch?;
        rows += batch.num_rows() as u64;
        if f.table == TableKind::Frames {
            check_frames(&batch, episodes, seen, f)?;
            *decoded += batch.num_rows() as u64;
            progress(batch.num_rows() as u64);
        }
    }
    Ok(rows)
}

fn check_frames(
    batch: &RecordBatch,
    episodes: &BTreeMap<&str, &Episode>,
    seen: &mut BTreeMap<String, Vec<i32>>,
    f: &TableFile,
) -> Result<()> {
    let bad = |msg: String| Error::Invalid(format!("{msg}: {}", f.abs_path.display()));
    let ids = episode_ids(batch).ok_or_else(|| bad("episode_id column unreadable".into()))?;
    let unreadable = |e: Error| bad(e.to_string());
    let idx: &Int32Array = column(batch, "frame_index", f.table).map_err(unreadable)?;
    let images: &BinaryArray = column(batch, "image", f.table).map_err(unreadable)?;
    for i in 0..batch.num_rows() {
        let id = ids.value(i);
        seen.entry(id.to_string()).or_default().push(idx.value(i));
        let Some(ep) = episodes.get(id) else { continue };
        frame_codec::decode(
            ep.frame_encoding,
            images.value(i),
            ep.width as u32,
            ep.height as u32,
        )
        .map_err(|e| bad(format!("episode {id} frame {}: {e}", idx.value(i))))?;
    }
    Ok(())
}

/// Rewrites `file` without the rows of `drop` episodes into `w`'s shards, episode by episode.
fn rewrite_without(
    ds: &Dataset,
    file: &TableFile,
    drop: &BTreeSet<String>,
    w: &mut crate::shard::ShardWriter,
) -> Result<()> {
    let mut current: Option<String> = None;
    for batch in ds.read_file(file, None)? {
        let batch = batch?;
        let ids = episode_ids(&batch)
            .ok_or_else(|| Error::Invalid(format!("no episode_id column: {}", file.abs_path.display())))?
            .clone();
        // Split the batch into runs of one episode each so row groups stay episode-aligned.
        let mut start = 0;
        while start < batch.num_rows() {
            let id = ids.value(start);
            let mut end = start + 1;
            while end < batch.num_rows() && ids.value(end) == id {
                end += 1;
            }
            if !drop.contains(id) {
                if current.as_deref() != Some(id) {
                    if current.is_some() {
                        w.end_episode()?;
                    }
                    w.begin_episode()?;
                    current = Some(id.to_string());
                }
                w.push(batch.slice(start, end - start))?;
            }
            start = end;
        }
    }
    if current.is_some() {
        w.end_episode()?;
    }
    Ok(())
}

fn file_has_any(ds: &Dataset, file: &TableFile, ids: &BTreeSet<String>) -> Result<bool> {
    if let (Some(lo), Some(hi)) = (&file.info.min_episode, &file.info.max_episode)
        && !ids.iter().any(|id| id >= lo && id <= hi)
    {
        return Ok(false);
    }
    for batch in ds.read_file(file, Some(&["episode_id"]))? {
        let batch = batch?;
        if let Some(a) = episode_ids(&batch)
            && (0..a.len()).any(|i| ids.contains(a.value(i)))
        {
            return Ok(true);
        }
    }
    Ok(false)
}

/// Rewrites the given files of `table` into new shards, dropping `drop` episodes, as part
/// of `txn`. Returns the number of files replaced.
fn rewrite_files(
    txn: &mut Transaction<'_>,
    table: TableKind,
    files: Vec<TableFile>,
    drop: &BTreeSet<String>,
    opts: &ShardOptions,
) -> Result<usize> {
    if files.is_empty() {
        return Ok(0);
    }
    let mut w = txn.shard_writer(table, opts.clone())?;
    for f in &files {
        if let Err(e) = rewrite_without(txn.dataset(), f, drop, &mut w) {
            w.abort();
            return Err(e);
        }
    }
    let added = w.finish()?;
    let n = files.len();
    txn.remove_files(
        table,
        files.into_iter().map(|f| f.info.path).collect(),
        drop.iter().cloned().collect(),
    );
    txn.add_files(table, added, Vec::new());
    Ok(n)
}

/// Removes every row of these episodes from every table, as one new version.
pub fn delete_episodes(ds: &Dataset, ids: &[String], meta: CommitMeta) -> Result<u64> {
    let mut txn = ds.begin(meta)?;
    let base = txn.base_version();
    let existing: BTreeSet<String> = episodes(ds, base)?.into_iter().map(|e| e.episode_id).collect();
    let drop: BTreeSet<String> = ids.iter().cloned().collect();
    if let Some(missing) = drop.iter().find(|id| !existing.contains(*id)) {
        return Err(Error::Invalid(format!(
            "episode {missing} is not in {}@{base}",
            ds.root().display()
        )));
    }
    for t in TableKind::ALL {
        let mut touched = Vec::new();
        for f in ds.files(t, base)? {
            if file_has_any(ds, &f, &drop)? {
                touched.push(f);
            }
        }
        if let Err(e) = rewrite_files(&mut txn, t, touched, &drop, &ShardOptions::default()) {
            txn.abort();
            return Err(e);
        }
    }
    txn.commit()
}

/// Merges files smaller than half the target size, per table, as one new version.
/// Returns `(new version, files replaced)`.
pub fn compact(ds: &Dataset, opts: &ShardOptions, meta: CommitMeta) -> Result<(u64, usize)> {
    let mut txn = ds.begin(meta)?;
    let base = txn.base_version();
    let mut replaced = 0;
    for t in TableKind::ALL {
        let small: Vec<TableFile> = ds
            .files(t, base)?
            .into_iter()
            .filter(|f| f.info.size < opts.target_file_bytes / 2)
            .collect();
        if small.len() < 2 {
            continue;
        }
        match rewrite_files(&mut txn, t, small, &BTreeSet::new(), opts) {
            Ok(n) => replaced += n,
            Err(e) => {
                txn.abort();
                return Err(e);
            }
        }
    }
    Ok((txn.commit()?, replaced))
}

/// Deletes data files no version newer than `retain_hours` still needs (Delta's vacuum in
/// full mode, which also removes files of writers that died before committing).
pub fn vacuum(ds: &Dataset, retain_hours: u64, dry_run: bool) -> Result<Vec<String>> {
    ds.roll_forward()?;
    let mut deleted = ds.vacuum_tables(retain_hours, dry_run)?;
    deleted.extend(vacuum_journals(ds, retain_hours, dry_run)?);
    Ok(deleted)
}

/// Resume journals of ingests that never finished, older than the retention and not held
/// (locked) by a running ingest.
fn vacuum_journals(ds: &Dataset, retain_hours: u64, dry_run: bool) -> Result<Vec<String>> {
    let dir = ds.staging_dir();
    let Ok(rd) = std::fs::read_dir(&dir) else {
        return Ok(Vec::new());
    };
    let retain = std::time::Duration::from_secs(retain_hours * 3600);
    let mut out = Vec::new();
    for ent in rd.flatten() {
        let path = ent.path();
        // Only journal files (an S3 dataset's staging folder also holds shard folders).
        if !ent.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        let old = ent
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= retain);
        let unlocked = std::fs::File::open(&path).is_ok_and(|f| f.try_lock().is_ok());
        if old && unlocked {
            if !dry_run {
                std::fs::remove_file(&path).map_err(Error::io("remove journal", &path))?;
            }
            out.push(format!("_milv/staging/{}", ent.file_name().to_string_lossy()));
        }
    }
    Ok(out)
}

/// Keeps only the rows of `batch` whose `episode_id` is in `keep`.
pub fn filter_episodes(batch: &RecordBatch, keep: &BTreeSet<String>) -> Result<RecordBatch> {
    let ids = episode_ids(batch).ok_or_else(|| Error::Invalid("no episode_id column".into()))?;
    let mask: BooleanArray = (0..ids.len())
        .map(|i| Some(keep.contains(ids.value(i))))
        .collect();
    Ok(filter_record_batch(batch, &mask)?)
}
