//! Parquet shard writing: bounded file size, zstd, row groups aligned to episodes.
//!
//! Rows arrive one episode at a time ([`ShardWriter::begin_episode`] … `push` …
//! [`ShardWriter::end_episode`]). A short episode is buffered whole and only then appended
//! to the current shard, so a failing episode never leaves rows behind and row groups are
//! only cut between episodes. An episode that outgrows the buffer is spilled to a file of
//! its own, written as it streams (memory stays bounded however long the clip): its row
//! groups are cut at `max_row_group_bytes`, and aborting the episode deletes that file.
//!
//! For a dataset on an object store, files are written to a local staging folder and
//! uploaded as each one closes, so memory stays bounded there too.

use std::fs::File;
use std::path::{Path, PathBuf};

use deltalake::arrow::array::{Array, RecordBatch, StringArray};
use deltalake::arrow::datatypes::DataType;
use deltalake::arrow::datatypes::SchemaRef;
use deltalake::parquet::arrow::ArrowWriter;
use deltalake::parquet::basic::{Compression, ZstdLevel};
use deltalake::parquet::file::metadata::KeyValue;
use deltalake::parquet::file::properties::{EnabledStatistics, WriterProperties};
use deltalake::parquet::schema::types::ColumnPath;

use crate::error::{Error, Result};
use crate::log::FileAdd;
use crate::schema::TableKind;
use crate::store::Root;

/// Size policy of the shards.
#[derive(Clone, Debug)]
pub struct ShardOptions {
    /// A shard is closed once it reaches this size (an episode is never split across files).
    pub target_file_bytes: u64,
    /// A row group is closed at the first episode boundary past this size.
    pub row_group_bytes: usize,
    /// Episodes buffered in memory up to this size; larger ones stream to their own file.
    pub episode_buffer_bytes: usize,
    /// Row-group cut inside a streamed (very long) episode.
    pub max_row_group_bytes: usize,
    pub zstd_level: i32,
    /// Per-column compression overrides: `None` stores the column uncompressed (already
    /// compressed payloads such as PNG frames gain nothing from zstd and cost CPU).
    pub column_zstd: Vec<(String, Option<i32>)>,
    /// Key-value pairs written into every file's Parquet footer (e.g. a run's parameters,
    /// readable with `pyarrow.parquet.read_metadata(f).metadata`).
    pub file_metadata: Vec<(String, String)>,
}

impl Default for ShardOptions {
    fn default() -> Self {
        ShardOptions {
            target_file_bytes: 128 << 20,
            row_group_bytes: 32 << 20,
            episode_buffer_bytes: 32 << 20,
            max_row_group_bytes: 32 << 20,
            zstd_level: 3,
            column_zstd: Vec::new(),
            file_metadata: Vec::new(),
        }
    }
}

struct OpenShard {
    writer: ArrowWriter<File>,
    /// Episodes completed in this file, in order.
    episodes: Vec<String>,
    rel_path: String,
    abs_path: PathBuf,
    rows: u64,
    min_episode: Option<String>,
    max_episode: Option<String>,
}

impl OpenShard {
    fn size(&self) -> u64 {
        (self.writer.bytes_written() + self.writer.in_progress_size()) as u64
    }

    fn note_episode(&mut self, id: &str) {
        if self.min_episode.as_deref().is_none_or(|m| id < m) {
            self.min_episode = Some(id.to_string());
        }
        if self.max_episode.as_deref().is_none_or(|m| id > m) {
            self.max_episode = Some(id.to_string());
        }
    }

    fn write(&mut self, batch: &RecordBatch) -> Result<()> {
        // File statistics come from the rows themselves, so they can't disagree with them.
        if let Some(ids) = episode_ids(batch) {
            for i in 0..ids.len() {
                self.note_episode(ids.value(i));
            }
        }
        self.rows += batch.num_rows() as u64;
        self.writer.write(batch).map_err(Error::parquet(&self.abs_path))
    }

    fn close(self) -> Result<ClosedShard> {
        let OpenShard {
            writer,
            episodes,
            rel_path,
            abs_path,
            rows,
            min_episode,
            max_episode,
        } = self;
        let file = writer.into_inner().map_err(Error::parquet(&abs_path))?;
        file.sync_all().map_err(Error::io("sync", &abs_path))?;
        let meta = file.metadata().map_err(Error::io("stat", &abs_path))?;
        let modification_time_ms = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_millis() as i64);
        Ok(ClosedShard {
            file: FileAdd {
                path: rel_path,
                size: meta.len(),
                num_records: rows,
                min_episode,
                max_episode,
                modification_time_ms,
            },
            episodes,
        })
    }

    fn discard(self) {
        drop(self.writer);
        let _ = std::fs::remove_file(&self.abs_path);
    }
}

enum Pending {
    None,
    Buffered { batches: Vec<RecordBatch>, bytes: usize },
    Spilled(Box<OpenShard>),
}

/// A finished file and the episodes whose rows it holds.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedShard {
    pub file: FileAdd,
    pub episodes: Vec<String>,
}

/// Writes the rows of one table into new Parquet files under the table's folder.
pub struct ShardWriter {
    table_root: PathBuf,
    schema: SchemaRef,
    opts: ShardOptions,
    props: WriterProperties,
    current: Option<OpenShard>,
    pending: Pending,
    /// Episode id of the open episode (from its first row).
    pending_id: Option<String>,
    done: Vec<ClosedShard>,
    /// How many of `done` [`ShardWriter::take_closed`] has handed out.
    taken: usize,
    /// Object-store dataset and table folder closed files are uploaded to (`table_root`
    /// is then a local staging folder).
    upload: Option<(Root, String)>,
}

impl ShardWriter {
    pub fn new(table_root: &Path, table: TableKind, opts: ShardOptions) -> Result<Self> {
        std::fs::create_dir_all(table_root).map_err(Error::io("create table folder", table_root))?;
        let zstd = |level: i32| {
            ZstdLevel::try_new(level)
                .map(Compression::ZSTD)
                .map_err(|e| Error::Invalid(format!("zstd level {level}: {e}")))
        };
        let schema = table.arrow_schema();
        let mut props = WriterProperties::builder()
            .set_compression(zstd(opts.zstd_level)?)
            // Row groups are cut by bytes at episode boundaries, never by row count.
            .set_max_row_group_row_count(Some(usize::MAX));
        // Binary payloads (frames) are unique blobs: dictionaries and min/max statistics
        // over them only burn CPU and bloat the footer.
        for f in schema.fields() {
            if f.data_type() == &DataType::Binary {
                let col = ColumnPath::from(f.name().as_str());
                props = props
                    .set_column_dictionary_enabled(col.clone(), false)
                    .set_column_statistics_enabled(col, EnabledStatistics::None);
            }
        }
        for (name, level) in &opts.column_zstd {
            let c = match level {
                Some(l) => zstd(*l)?,
                None => Compression::UNCOMPRESSED,
            };
            props = props.set_column_compression(ColumnPath::from(name.as_str()), c);
        }
        if !opts.file_metadata.is_empty() {
            let kv = opts
                .file_metadata
                .iter()
                .map(|(k, v)| KeyValue::new(k.clone(), v.clone()))
                .collect();
            props = props.set_key_value_metadata(Some(kv));
        }
        let props = props.build();
        Ok(ShardWriter {
            table_root: table_root.to_path_buf(),
            schema,
            opts,
            props,
            current: None,
            pending: Pending::None,
            pending_id: None,
            done: Vec::new(),
            taken: 0,
            upload: None,
        })
    }

    /// A writer for new files of `table` in the dataset at `root`.
    pub(crate) fn for_dataset(root: &Root, table: TableKind, opts: ShardOptions) -> Result<Self> {
        match root {
            Root::Local(dir) => ShardWriter::new(&dir.join(table.name()), table, opts),
            Root::Object(_) => {
                let staging = root.staging().join(table.name());
                let mut w = ShardWriter::new(&staging, table, opts)?;
                w.upload = Some((root.clone(), table.name().to_string()));
                Ok(w)
            }
        }
    }

    /// Records a closed file, after uploading it when the dataset is remote.
    fn closed(&mut self, shard: ClosedShard) -> Result<()> {
        if let Some((root, table)) = &self.upload {
            let local = self.table_root.join(&shard.file.path);
            let uploaded = root.upload(&local, &format!("{table}/{}", shard.file.path));
            let _ = std::fs::remove_file(&local);
            uploaded?;
        }
        self.done.push(shard);
        Ok(())
    }

    fn remove_closed(&self, path: &str) {
        match &self.upload {
            Some((root, table)) => root.remove(&format!("{table}/{path}")),
            None => {
                let _ = std::fs::remove_file(self.table_root.join(path));
            }
        }
    }

    pub fn schema(&self) -> &SchemaRef {
        &self.schema
    }

    fn open_shard(&self) -> Result<OpenShard> {
        let rel_path = format!("part-{}.zstd.parquet", uuid::Uuid::new_v4());
        let abs_path = self.table_root.join(&rel_path);
        let file = File::create_new(&abs_path).map_err(Error::io("create shard", &abs_path))?;
        let writer = ArrowWriter::try_new(file, self.schema.clone(), Some(self.props.clone()))
            .map_err(Error::parquet(&abs_path))?;
        Ok(OpenShard {
            writer,
            episodes: Vec::new(),
            rel_path,
            abs_path,
            rows: 0,
            min_episode: None,
            max_episode: None,
        })
    }

    /// Starts the rows of a new episode. The previous one must have ended or been aborted.
    pub fn begin_episode(&mut self) -> Result<()> {
        if !matches!(self.pending, Pending::None) {
            return Err(Error::Invalid("begin_episode while an episode is open".into()));
        }
        self.pending = Pending::Buffered {
            batches: Vec::new(),
            bytes: 0,
        };
        Ok(())
    }

    /// Adds rows of the open episode.
    pub fn push(&mut self, batch: RecordBatch) -> Result<()> {
        if batch.schema() != self.schema {
            return Err(Error::Schema {
                table: self.table_root.display().to_string(),
                msg: format!("batch schema {:?} differs from the table's", batch.schema()),
            });
        }
        if self.pending_id.is_none()
            && let Some(ids) = episode_ids(&batch)
            && !ids.is_empty()
        {
            self.pending_id = Some(ids.value(0).to_string());
        }
        let spill = match &mut self.pending {
            Pending::None => return Err(Error::Invalid("push without begin_episode".into())),
            Pending::Buffered { batches, bytes, .. } => {
                *bytes += batch_bytes(&batch);
                batches.push(batch);
                *bytes > self.opts.episode_buffer_bytes
            }
            Pending::Spilled(shard) => {
                shard.write(&batch)?;
                if shard.writer.in_progress_size() > self.opts.max_row_group_bytes {
                    shard.writer.flush().map_err(Error::parquet(&shard.abs_path))?;
                }
                false
            }
        };
        if spill {
            let mut shard = self.open_shard()?;
            if let Pending::Buffered { batches, .. } = std::mem::replace(&mut self.pending, Pending::None) {
                for b in &batches {
                    shard.write(b)?;
                }
                self.pending = Pending::Spilled(Box::new(shard));
            }
        }
        Ok(())
    }

    /// Ends the open episode: its rows become part of the output.
    pub fn end_episode(&mut self) -> Result<()> {
        let id = self.pending_id.take();
        match std::mem::replace(&mut self.pending, Pending::None) {
            Pending::None => Err(Error::Invalid("end_episode without begin_episode".into())),
            Pending::Spilled(mut shard) => {
                shard.episodes.extend(id);
                let closed = shard.close()?;
                self.closed(closed)
            }
            Pending::Buffered { batches, bytes } => {
                if let Some(cur) = &self.current
                    && cur.rows > 0
                    && cur.size() + bytes as u64 > self.opts.target_file_bytes
                {
                    self.close_current()?;
                }
                let mut cur = match self.current.take() {
                    Some(c) => c,
                    None => self.open_shard()?,
                };
                for b in &batches {
                    cur.write(b)?;
                }
                cur.episodes.extend(id);
                if cur.writer.in_progress_size() >= self.opts.row_group_bytes {
                    cur.writer.flush().map_err(Error::parquet(&cur.abs_path))?;
                }
                self.current = Some(cur);
                Ok(())
            }
        }
    }

    /// Drops the rows of the open episode (e.g. its video turned out corrupt).
    pub fn abort_episode(&mut self) {
        self.pending_id = None;
        if let Pending::Spilled(shard) = std::mem::replace(&mut self.pending, Pending::None) {
            shard.discard();
        }
    }

    fn close_current(&mut self) -> Result<()> {
        if let Some(cur) = self.current.take() {
            let closed = cur.close()?;
            self.closed(closed)?;
        }
        Ok(())
    }

    /// Files closed since the last call (complete in the store; e.g. to journal them so an
    /// interrupted run can reuse them).
    pub fn take_closed(&mut self) -> Vec<ClosedShard> {
        let new = self.done[self.taken..].to_vec();
        self.taken = self.done.len();
        new
    }

    /// Closes every file and returns them, ready to be committed.
    pub fn finish(mut self) -> Result<Vec<FileAdd>> {
        self.abort_episode();
        self.close_current()?;
        Ok(std::mem::take(&mut self.done)
            .into_iter()
            .map(|c| c.file)
            .collect())
    }

    /// Deletes every file written so far (nothing was committed).
    pub fn abort(mut self) {
        self.abort_episode();
        if let Some(cur) = self.current.take() {
            cur.discard();
        }
        for c in &self.done {
            self.remove_closed(&c.file.path);
        }
    }
}

/// Bytes a batch's rows occupy; unlike `get_array_memory_size`, a slice counts only its
/// own rows, not its parent's whole buffers.
pub fn batch_bytes(batch: &RecordBatch) -> usize {
    batch
        .columns()
        .iter()
        .map(|c| c.to_data().get_slice_memory_size().unwrap_or(0))
        .sum()
}

/// The `episode_id` column of a batch (first column of every MILV table that has one).
pub fn episode_ids(batch: &RecordBatch) -> Option<&StringArray> {
    batch
        .column_by_name("episode_id")?
        .as_any()
        .downcast_ref::<StringArray>()
        .filter(|a| a.null_count() == 0)
}
