//! Where a dataset's bytes live: a local folder, or an object store at
//! `s3://bucket/prefix` (AWS S3 or any S3-compatible server).
//!
//! Everything the store does to files goes through [`Root`], so the version log, the
//! Delta tables and the data files behave the same on both:
//!
//! | operation | local folder | `s3://` |
//! |---|---|---|
//! | commit point (create a log entry once) | temp file + `hard_link` | `PUT` with `If-None-Match: *` ([`PutMode::Create`]) |
//! | new data file | written in the table folder | written to a local staging folder, uploaded when closed |
//! | read a data file | `File` | ranged `GET`s ([`ParquetObjectReader`]) |
//! | resume journal | `_milv/staging/` | a local staging folder per dataset URL |
//!
//! S3 is configured only by the standard AWS variables (`AWS_ENDPOINT_URL`,
//! `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_REGION`, `AWS_ALLOW_HTTP`, …), which
//! `deltalake`'s S3 factory reads from the environment. MILV never holds the credentials
//! itself, so they cannot reach a log line, an error, the version log or a Delta commit.
//! Settings that would make commits unsafe (`AWS_S3_ALLOW_UNSAFE_RENAME`, a locking
//! provider, conditional puts disabled) are refused.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use deltalake::arrow::array::RecordBatch;
use deltalake::logstore::object_store::path::Path as Key;
use deltalake::logstore::object_store::{
    self as os, ObjectStore, ObjectStoreExt as _, PutMode, PutOptions, PutPayload, WriteMultipart,
};
use deltalake::parquet::arrow::ProjectionMask;
use deltalake::parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use deltalake::parquet::arrow::arrow_reader::{ArrowReaderBuilder, ArrowReaderOptions};
use deltalake::parquet::arrow::async_reader::{AsyncFileReader, ParquetRecordBatchStreamBuilder};
use deltalake::parquet::errors::ParquetError;
use deltalake::parquet::file::metadata::{ParquetMetaData, ParquetMetaDataReader};
use futures::future::BoxFuture;
use futures::{FutureExt as _, StreamExt as _, TryStreamExt as _};

use crate::error::{Error, Result};

/// Rows per batch when reading data files.
const BATCH_ROWS: usize = 1024;
/// Part size of multipart uploads (S3 needs ≥ 5 MiB parts).
const PART_BYTES: usize = 16 << 20;
/// Parts in flight per upload.
const PARTS_IN_FLIGHT: usize = 4;

/// The process-wide runtime for object-store and Delta I/O. Multi-threaded, so its workers
/// drive the network while a caller blocks on a request from any thread.
pub(crate) fn runtime() -> &'static tokio::runtime::Runtime {
    static RT: OnceLock<tokio::runtime::Runtime> = OnceLock::new();
    RT.get_or_init(|| {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("milv-io")
            .enable_all()
            .build()
            // Without threads nothing can run at all; there is no better thing to do.
            .unwrap_or_else(|e| panic!("cannot start the I/O runtime: {e}"))
    })
}

thread_local! {
    static BLOCKING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` to completion on the calling thread inside [`runtime`]'s context (the
/// runtime's workers drive the network). A call made while this thread is already blocked
/// on an outer future (a synchronous store call inside a Delta operation) runs on a
/// short-lived thread of its own, since executors do not nest.
pub(crate) fn block_on<F>(f: F) -> F::Output
where
    F: Future + Send,
    F::Output: Send,
{
    if BLOCKING.with(std::cell::Cell::get) {
        return std::thread::scope(|s| s.spawn(|| block_on(f)).join())
            .unwrap_or_else(|p| std::panic::resume_unwind(p));
    }
    struct Reset;
    impl Drop for Reset {
        fn drop(&mut self) {
            BLOCKING.with(|b| b.set(false));
        }
    }
    BLOCKING.with(|b| b.set(true));
    let _reset = Reset;
    let _guard = runtime().enter();
    futures::executor::block_on(f)
}

/// `scheme` of `scheme://…`, if the text is a URL rather than a path.
pub fn url_scheme(s: &str) -> Option<&str> {
    let (scheme, _) = s.split_once("://")?;
    let mut chars = scheme.chars();
    let ok = chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'));
    ok.then_some(scheme)
}

/// A dataset root: a folder, or a prefix in an object store.
#[derive(Clone)]
pub(crate) enum Root {
    Local(PathBuf),
    Object(Arc<ObjectRoot>),
}

pub(crate) struct ObjectRoot {
    /// `s3://bucket/prefix/` (always with the trailing slash, so `join` appends).
    url: url::Url,
    /// The store, scoped to the prefix: keys are relative to the dataset root.
    store: Arc<dyn ObjectStore>,
    /// `s3://bucket/prefix`, as messages name the dataset.
    label: PathBuf,
    /// Local folder for shards before upload and for resume journals.
    staging: PathBuf,
}

/// Refuses AWS settings under which a commit could silently overwrite another one.
fn check_safe_s3_settings() -> Result<()> {
    for (k, v) in std::env::vars() {
        let key = k.to_ascii_uppercase();
        let truthy = !matches!(v.trim().to_ascii_lowercase().as_str(), "" | "0" | "false" | "no");
        let why = match key.as_str() {
            "AWS_S3_ALLOW_UNSAFE_RENAME" if truthy => "unsafe renames can overwrite a concurrent commit",
            "AWS_S3_LOCKING_PROVIDER" => "MILV commits with conditional puts and takes no lock provider",
            "AWS_CONDITIONAL_PUT" | "CONDITIONAL_PUT" if v.trim().eq_ignore_ascii_case("disabled") => {
                "commits need conditional puts (If-None-Match)"
            }
            _ => continue,
        };
        return Err(Error::UnsafeSetting {
            setting: format!("{k}={v}"),
            why,
        });
    }
    Ok(())
}

impl Root {
    /// A local path, `file:///…`, or `s3://bucket/prefix`. Other schemes are refused.
    pub fn parse(p: &Path) -> Result<Root> {
        let Some(text) = p.to_str() else {
            return Ok(Root::Local(p.to_path_buf()));
        };
        match url_scheme(text) {
            None => Ok(Root::Local(p.to_path_buf())),
            Some("file") => {
                let url = url::Url::parse(text).map_err(|e| bad_location(text, e.to_string()))?;
                url.to_file_path()
                    .map(Root::Local)
                    .map_err(|()| bad_location(text, "not a local file URL".into()))
            }
            Some("s3") => Ok(Root::Object(Arc::new(ObjectRoot::s3(text)?))),
            Some(other) => Err(bad_location(
                text,
                format!("the URL scheme `{other}` is not supported (use a local path or s3://bucket/prefix)"),
            )),
        }
    }

    /// How messages name the dataset: its folder, or `s3://bucket/prefix`.
    pub fn label(&self) -> &Path {
        match self {
            Root::Local(p) => p,
            Root::Object(o) => &o.label,
        }
    }

    pub fn is_local(&self) -> bool {
        matches!(self, Root::Local(_))
    }

    /// Local folder for files that are not part of the dataset yet (shards before upload,
    /// resume journals).
    pub fn staging(&self) -> PathBuf {
        match self {
            Root::Local(p) => p.join("_milv/staging"),
            Root::Object(o) => o.staging.clone(),
        }
    }

    /// A label for `rel` (for messages and [`crate::TableFile::abs_path`]).
    pub fn label_of(&self, rel: &str) -> PathBuf {
        self.label().join(rel)
    }

    /// The Delta table URL of the folder `rel` (created locally if needed).
    pub fn table_url(&self, rel: &str) -> Result<url::Url> {
        match self {
            Root::Local(root) => {
                let dir = root.join(rel);
                std::fs::create_dir_all(&dir).map_err(Error::io("create table folder", &dir))?;
                let abs = std::fs::canonicalize(&dir).map_err(Error::io("resolve", &dir))?;
                url::Url::from_directory_path(&abs)
                    .map_err(|()| Error::Invalid(format!("cannot make a URL of {}", abs.display())))
            }
            Root::Object(o) => o
                .url
                .join(&format!("{rel}/"))
                .map_err(|e| bad_location(o.url.as_str(), e.to_string())),
        }
    }

    /// Makes sure the folder `rel` exists (object stores have no folders).
    pub fn ensure_dir(&self, rel: &str) -> Result<()> {
        match self {
            Root::Local(root) => {
                let dir = root.join(rel);
                std::fs::create_dir_all(&dir).map_err(Error::io("create folder", &dir))
            }
            Root::Object(_) => Ok(()),
        }
    }

    /// Names of the files directly in folder `rel`; `None` if it does not exist.
    pub fn list(&self, rel: &str) -> Result<Option<Vec<String>>> {
        match self {
            Root::Local(root) => {
                let dir = root.join(rel);
                let rd = match std::fs::read_dir(&dir) {
                    Ok(rd) => rd,
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
                    Err(e) => return Err(Error::io("list", &dir)(e)),
                };
                let mut out = Vec::new();
                for ent in rd {
                    let ent = ent.map_err(Error::io("list", &dir))?;
                    if let Some(name) = ent.file_name().to_str() {
                        out.push(name.to_string());
                    }
                }
                Ok(Some(out))
            }
            Root::Object(o) => {
                let prefix = Key::from(rel);
                let metas: Vec<_> = block_on(o.store.list(Some(&prefix)).try_collect::<Vec<_>>())
                    .map_err(o.err("list", rel))?;
                let names: Vec<String> = metas
                    .iter()
                    .filter_map(|m| {
                        let name = m.location.filename()?;
                        // Only direct children, as a folder listing would give.
                        (m.location.as_ref() == format!("{prefix}/{name}")).then(|| name.to_string())
                    })
                    .collect();
                Ok((!names.is_empty()).then_some(names))
            }
        }
    }

    /// The bytes of file `rel`.
    pub fn read(&self, rel: &str) -> Result<Vec<u8>> {
        match self {
            Root::Local(root) => {
                let path = root.join(rel);
                std::fs::read(&path).map_err(Error::io("read", &path))
            }
            Root::Object(o) => {
                let key = Key::from(rel);
                block_on(async { o.store.get(&key).await?.bytes().await })
                    .map(|b| b.to_vec())
                    .map_err(o.err("read", rel))
            }
        }
    }

    /// The size of file `rel`, `None` if there is none.
    pub fn size(&self, rel: &str) -> Result<Option<u64>> {
        match self {
            Root::Local(root) => {
                let path = root.join(rel);
                match std::fs::metadata(&path) {
                    Ok(m) => Ok(Some(m.len())),
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
                    Err(e) => Err(Error::io("stat", &path)(e)),
                }
            }
            Root::Object(o) => match block_on(o.store.head(&Key::from(rel))) {
                Ok(m) => Ok(Some(m.size)),
                Err(os::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(o.err("stat", rel)(e)),
            },
        }
    }

    /// Deletes file `rel` if it exists (best effort: a leftover is an orphan that vacuum
    /// removes).
    pub fn remove(&self, rel: &str) {
        match self {
            Root::Local(root) => {
                let _ = std::fs::remove_file(root.join(rel));
            }
            Root::Object(o) => {
                let _ = block_on(o.store.delete(&Key::from(rel)));
            }
        }
    }

    /// Creates file `rel` holding `bytes` if no file of that name exists, atomically:
    /// `Ok(false)` if another writer got there first. The commit point of a version.
    pub fn create_new(&self, rel: &str, bytes: &[u8]) -> Result<bool> {
        match self {
            Root::Local(root) => create_new_local(&root.join(rel), bytes),
            Root::Object(o) => {
                let key = Key::from(rel);
                let opts = PutOptions {
                    mode: PutMode::Create,
                    ..Default::default()
                };
                let payload = PutPayload::from(bytes.to_vec());
                match block_on(o.store.put_opts(&key, payload, opts)) {
                    Ok(_) => Ok(true),
                    Err(os::Error::AlreadyExists { .. }) => {
                        // A transport-level retry of our own successful PUT also lands
                        // here: identical bytes (they carry a unique timestamp and the
                        // run's command) mean the entry is ours.
                        Ok(self.read(rel)? == bytes)
                    }
                    Err(e @ os::Error::NotImplemented { .. }) => Err(Error::Location {
                        uri: o.label.display().to_string(),
                        msg: format!("the store cannot do conditional puts, which commits need: {e}"),
                    }),
                    Err(e) => Err(o.err("create", rel)(e)),
                }
            }
        }
    }

    /// Copies the local file `local` to `rel` (object stores only; streamed in parts).
    pub fn upload(&self, local: &Path, rel: &str) -> Result<()> {
        let Root::Object(o) = self else {
            return Ok(());
        };
        let key = Key::from(rel);
        let len = std::fs::metadata(local).map_err(Error::io("stat", local))?.len();
        block_on(async {
            if len <= PART_BYTES as u64 {
                let bytes = std::fs::read(local).map_err(Error::io("read", local))?;
                o.store
                    .put(&key, PutPayload::from(bytes))
                    .await
                    .map_err(o.err("upload", rel))?;
                return Ok(());
            }
            let upload = o.store.put_multipart(&key).await.map_err(o.err("upload", rel))?;
            let mut w = WriteMultipart::new_with_chunk_size(upload, PART_BYTES);
            let mut f = std::fs::File::open(local).map_err(Error::io("open", local))?;
            loop {
                if let Err(e) = w.wait_for_capacity(PARTS_IN_FLIGHT).await {
                    return Err(o.err("upload", rel)(e));
                }
                let mut buf = vec![0u8; PART_BYTES];
                let n = read_full(&mut f, &mut buf).map_err(Error::io("read", local))?;
                if n == 0 {
                    break;
                }
                buf.truncate(n);
                w.put(buf.into());
            }
            w.finish().await.map_err(o.err("upload", rel))?;
            Ok(())
        })
    }

    /// Streams the rows of the Parquet file `rel`, optionally only some columns.
    pub fn open_parquet(
        &self,
        rel: &str,
        columns: Option<&[String]>,
    ) -> Result<Box<dyn Iterator<Item = Result<RecordBatch>> + Send>> {
        let label = self.label_of(rel);
        match self {
            Root::Local(root) => {
                let reader = projected(local_builder(root, rel)?, columns)
                    .build()
                    .map_err(Error::parquet(&label))?;
                Ok(Box::new(reader.map(move |b| {
                    b.map_err(|e| Error::Parquet {
                        source: e.into(),
                        path: label.clone(),
                    })
                })))
            }
            Root::Object(o) => {
                let mut stream = projected(o.builder(rel)?, columns)
                    .build()
                    .map_err(Error::parquet(&label))?;
                Ok(Box::new(std::iter::from_fn(move || {
                    block_on(stream.next()).map(|b| b.map_err(Error::parquet(&label)))
                })))
            }
        }
    }

    /// The footer of the Parquet file `rel`.
    pub fn parquet_metadata(&self, rel: &str) -> Result<Arc<ParquetMetaData>> {
        Ok(match self {
            Root::Local(root) => local_builder(root, rel)?.metadata().clone(),
            Root::Object(o) => o.builder(rel)?.metadata().clone(),
        })
    }
}

fn local_builder(root: &Path, rel: &str) -> Result<ParquetRecordBatchReaderBuilder<std::fs::File>> {
    let path = root.join(rel);
    let file = std::fs::File::open(&path).map_err(|e| missing_or_io(e, &path))?;
    ParquetRecordBatchReaderBuilder::try_new(file).map_err(Error::parquet(&path))
}

/// Only `columns` (all if `None`), in batches of [`BATCH_ROWS`].
fn projected<T>(b: ArrowReaderBuilder<T>, columns: Option<&[String]>) -> ArrowReaderBuilder<T> {
    let mask = columns.map(|c| ProjectionMask::columns(b.parquet_schema(), c.iter().map(String::as_str)));
    match mask {
        Some(m) => b.with_projection(m),
        None => b,
    }
    .with_batch_size(BATCH_ROWS)
}

impl std::fmt::Debug for Root {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.label().display())
    }
}

impl ObjectRoot {
    fn s3(text: &str) -> Result<ObjectRoot> {
        check_safe_s3_settings()?;
        let mut url = url::Url::parse(text).map_err(|e| bad_location(text, e.to_string()))?;
        if url.host_str().is_none_or(str::is_empty) {
            return Err(bad_location(
                text,
                "no bucket (expected s3://bucket/prefix)".into(),
            ));
        }
        if !url.username().is_empty()
            || url.password().is_some()
            || url.query().is_some()
            || url.fragment().is_some()
        {
            // Credentials come from the environment only; a URL carrying them would be
            // printed in every message that names the dataset.
            return Err(bad_location(
                "s3://…",
                "an s3:// location takes no user, password, query or fragment; set AWS_* variables instead"
                    .into(),
            ));
        }
        let trimmed = url.path().trim_end_matches('/').to_string();
        url.set_path(&format!("{trimmed}/"));
        let label = PathBuf::from(format!("s3://{}{trimmed}", url.host_str().unwrap_or_default()));
        deltalake::aws::register_handlers(None);
        let no_options: [(&str, &str); 0] = [];
        let store = deltalake::logstore::store_for(&url, no_options).map_err(|e| Error::Delta {
            table: label.display().to_string(),
            source: Box::new(e),
        })?;
        let staging = std::env::temp_dir()
            .join("milv-staging")
            .join(crate::log::run_id(&[url.as_str()]));
        Ok(ObjectRoot {
            url,
            store,
            label,
            staging,
        })
    }

    fn err(&self, op: &'static str, rel: &str) -> impl FnOnce(os::Error) -> Error {
        let uri = format!("{}/{rel}", self.label.display());
        move |source| Error::Store {
            op,
            source: Box::new(source),
            uri,
        }
    }

    fn builder(&self, rel: &str) -> Result<ParquetRecordBatchStreamBuilder<RemoteFile>> {
        let reader = self.parquet_reader(rel)?;
        block_on(ParquetRecordBatchStreamBuilder::new(reader))
            .map_err(Error::parquet(format!("{}/{rel}", self.label.display())))
    }

    fn parquet_reader(&self, rel: &str) -> Result<RemoteFile> {
        let key = Key::from(rel);
        // A missing file gets the same clear message as locally (vacuumed, most likely).
        let meta = match block_on(self.store.head(&key)) {
            Ok(m) => m,
            Err(os::Error::NotFound { .. }) => {
                return Err(missing(&PathBuf::from(format!("{}/{rel}", self.label.display()))));
            }
            Err(e) => return Err(self.err("open", rel)(e)),
        };
        Ok(RemoteFile {
            store: self.store.clone(),
            key,
            size: meta.size,
        })
    }
}

/// A Parquet file in an object store, read with ranged `GET`s: the footer (one request
/// with a 64 KiB prefetch), then the column chunks a projection needs.
struct RemoteFile {
    store: Arc<dyn ObjectStore>,
    key: Key,
    size: u64,
}

/// Footer bytes fetched speculatively with the metadata length (saves a request).
const FOOTER_PREFETCH: usize = 64 << 10;

impl AsyncFileReader for RemoteFile {
    fn get_bytes(
        &mut self,
        range: std::ops::Range<u64>,
    ) -> BoxFuture<'_, Result<bytes::Bytes, ParquetError>> {
        async move {
            self.store
                .get_range(&self.key, range)
                .await
                .map_err(|e| ParquetError::External(Box::new(e)))
        }
        .boxed()
    }

    fn get_byte_ranges(
        &mut self,
        ranges: Vec<std::ops::Range<u64>>,
    ) -> BoxFuture<'_, Result<Vec<bytes::Bytes>, ParquetError>> {
        async move {
            self.store
                .get_ranges(&self.key, &ranges)
                .await
                .map_err(|e| ParquetError::External(Box::new(e)))
        }
        .boxed()
    }

    fn get_metadata<'a>(
        &'a mut self,
        _options: Option<&'a ArrowReaderOptions>,
    ) -> BoxFuture<'a, Result<Arc<ParquetMetaData>, ParquetError>> {
        async move {
            let size = self.size;
            let meta = ParquetMetaDataReader::new()
                .with_prefetch_hint(Some(FOOTER_PREFETCH))
                .load_and_finish(self, size)
                .await?;
            Ok(Arc::new(meta))
        }
        .boxed()
    }
}

fn bad_location(uri: &str, msg: String) -> Error {
    Error::Location {
        uri: uri.to_string(),
        msg,
    }
}

fn missing(path: &Path) -> Error {
    Error::Invalid(format!(
        "data file missing (removed by `milv-ds vacuum`? versions older than its retention \
         are no longer readable): {}",
        path.display()
    ))
}

fn missing_or_io(e: std::io::Error, path: &Path) -> Error {
    match e.kind() {
        std::io::ErrorKind::NotFound => missing(path),
        _ => Error::io("open shard", path)(e),
    }
}

fn read_full(f: &mut impl std::io::Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// Creates `target` with `bytes` unless it exists: written to a temp file, synced, then
/// hard-linked, which fails if a concurrent writer took the name first.
fn create_new_local(target: &Path, bytes: &[u8]) -> Result<bool> {
    let dir = target.parent().unwrap_or(Path::new("."));
    let tmp = dir.join(format!(".tmp-{}.json", uuid::Uuid::new_v4()));
    write_synced(&tmp, bytes)?;
    let created = match std::fs::hard_link(&tmp, target) {
        Ok(()) => true,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => false,
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            return Err(Error::io("create version entry", target)(e));
        }
    };
    std::fs::remove_file(&tmp).map_err(Error::io("remove temp file", &tmp))?;
    if created {
        sync_dir(dir)?;
    }
    Ok(created)
}

/// Writes a file and flushes it to disk, so a crash never leaves a named, partial file.
pub(crate) fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let mut f = std::fs::File::create(path).map_err(Error::io("create", path))?;
    f.write_all(bytes).map_err(Error::io("write", path))?;
    f.sync_all().map_err(Error::io("sync", path))
}

pub(crate) fn sync_dir(dir: &Path) -> Result<()> {
    std::fs::File::open(dir)
        .and_then(|f| f.sync_all())
        .map_err(Error::io("sync folder", dir))
}

/// The local folder mirroring fetched `s3://` inputs: `s3://bucket/key` is stored at
/// `<cache>/s3/bucket/key` (`$MILV_INPUT_CACHE`, else a folder in the temp dir).
pub fn input_cache() -> PathBuf {
    std::env::var_os("MILV_INPUT_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("milv-inputs"))
}

/// `s3://bucket/key` of a path inside [`input_cache`], if it is one.
pub fn cached_url(path: &Path) -> Option<String> {
    let rel = path.strip_prefix(input_cache().join("s3")).ok()?;
    Some(format!("s3://{}", rel.to_str()?))
}

/// Where `s3://bucket/key` is (or will be) stored in [`input_cache`].
pub fn cache_path(url: &str) -> Result<PathBuf> {
    let (bucket, key) = split_s3(url)?;
    let mut p = input_cache().join("s3").join(bucket);
    for part in key.split('/').filter(|s| !s.is_empty()) {
        // Keys are untrusted text: never let one climb out of the cache.
        if part == ".." || part == "." {
            return Err(bad_location(url, "a key with `.` or `..` segments".into()));
        }
        p.push(part);
    }
    Ok(p)
}

fn split_s3(url: &str) -> Result<(&str, &str)> {
    let rest = url
        .strip_prefix("s3://")
        .ok_or_else(|| bad_location(url, "not an s3:// URL".into()))?;
    let (bucket, key) = rest.split_once('/').unwrap_or((rest, ""));
    if bucket.is_empty() {
        return Err(bad_location(url, "no bucket".into()));
    }
    Ok((bucket, key))
}

/// Downloads an input from object storage into [`input_cache`] and returns its local path:
/// `s3://bucket/key` names an object, or (when no such object exists) every object under
/// `key/` — a folder such as a LeRobot dataset or a folder of frames. With `siblings`,
/// objects beside the file sharing its stem (`clip.json`, `clip.csv`: sidecars) come too.
/// Objects already cached with the same size are not downloaded again. A local path is
/// returned as it is; any other URL scheme is refused.
pub fn fetch_input(path: &Path, siblings: bool) -> Result<PathBuf> {
    let Some(text) = path.to_str() else {
        return Ok(path.to_path_buf());
    };
    if let Some(url) = cached_url(path) {
        // A path inside the cache that is not there yet: a relative path resolved
        // against a fetched manifest. Fetch what it stands for.
        if !path.exists() {
            return fetch_input(Path::new(&url), siblings);
        }
    }
    match url_scheme(text) {
        None => return Ok(path.to_path_buf()),
        Some("s3") => {}
        Some(other) => {
            return Err(bad_location(
                text,
                format!("the URL scheme `{other}` is not supported for inputs (use a local path or s3://)"),
            ));
        }
    }
    check_safe_s3_settings()?;
    let (bucket, key) = split_s3(text)?;
    let key = key.trim_end_matches('/');
    let bucket_url =
        url::Url::parse(&format!("s3://{bucket}/")).map_err(|e| bad_location(text, e.to_string()))?;
    deltalake::aws::register_handlers(None);
    let no_options: [(&str, &str); 0] = [];
    let store = deltalake::logstore::store_for(&bucket_url, no_options).map_err(|e| Error::Delta {
        table: text.to_string(),
        source: Box::new(e),
    })?;
    let err = |op: &'static str| {
        let uri = text.to_string();
        move |source: os::Error| Error::Store {
            op,
            source: Box::new(source),
            uri,
        }
    };
    let local = cache_path(text)?;
    // Objects under `key/` make it a folder (some servers also answer HEAD for a folder,
    // or hold an empty marker object under its name).
    let under: Vec<_> = block_on(store.list(Some(&Key::from(key))).try_collect::<Vec<_>>())
        .map_err(err("list"))?
        .into_iter()
        .filter(|m| m.location.as_ref() != key)
        .collect();
    let mut wanted = under;
    if wanted.is_empty() {
        match block_on(store.head(&Key::from(key))) {
            Ok(meta) => wanted.push(meta),
            Err(os::Error::NotFound { path, .. }) => {
                return Err(Error::Store {
                    op: "fetch input",
                    source: Box::new(os::Error::NotFound {
                        path,
                        source: "no such object, and no objects under this prefix".into(),
                    }),
                    uri: text.to_string(),
                });
            }
            Err(e) => return Err(err("fetch input")(e)),
        }
        if siblings {
            // Sidecars: `<stem>.<ext>` beside the file.
            let (dir, name) = key.rsplit_once('/').unwrap_or(("", key));
            let stem = name.rsplit_once('.').map_or(name, |(s, _)| s);
            let dir = (!dir.is_empty()).then(|| Key::from(dir));
            let listing = block_on(store.list_with_delimiter(dir.as_ref())).map_err(err("list"))?;
            wanted.extend(listing.objects.into_iter().filter(|m| {
                let f = m.location.filename().unwrap_or_default();
                f != name && f.strip_prefix(stem).is_some_and(|r| r.starts_with('.'))
            }));
        }
    }
    for meta in wanted {
        let dest = cache_path(&format!("s3://{bucket}/{}", meta.location))?;
        if std::fs::metadata(&dest).is_ok_and(|m| m.len() == meta.size) {
            continue;
        }
        if let Some(dir) = dest.parent() {
            std::fs::create_dir_all(dir).map_err(Error::io("create cache folder", dir))?;
        }
        let tmp = dest.with_extension(format!("part-{}", uuid::Uuid::new_v4()));
        let loc = meta.location.clone();
        block_on(async {
            use std::io::Write as _;
            let mut out = std::fs::File::create(&tmp).map_err(Error::io("create", &tmp))?;
            let mut body = store.get(&loc).await.map_err(err("download"))?.into_stream();
            while let Some(chunk) = body.next().await {
                out.write_all(&chunk.map_err(err("download"))?)
                    .map_err(Error::io("write", &tmp))?;
            }
            out.sync_all().map_err(Error::io("sync", &tmp))
        })
        .inspect_err(|_| {
            let _ = std::fs::remove_file(&tmp);
        })?;
        std::fs::rename(&tmp, &dest).map_err(Error::io("rename", &dest))?;
    }
    Ok(local)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn locations_parse() {
        assert!(Root::parse(Path::new("data/ds")).unwrap().is_local());
        assert!(Root::parse(Path::new("data/user@host:x/ds")).unwrap().is_local());
        let r = Root::parse(Path::new("file:///tmp/ds")).unwrap();
        assert_eq!(r.label(), Path::new("/tmp/ds"));
        for bad in ["gs://bucket/ds", "http://host/ds", "s3:///ds"] {
            let e = Root::parse(Path::new(bad)).unwrap_err().to_string();
            assert!(e.contains(bad) || e.contains("bucket"), "{e}");
        }
        let e = Root::parse(Path::new("s3://key:secret@bucket/ds"))
            .unwrap_err()
            .to_string();
        assert!(!e.contains("secret"), "{e}");
    }

    #[test]
    fn schemes_are_recognised() {
        assert_eq!(url_scheme("s3://b/p"), Some("s3"));
        assert_eq!(url_scheme("a/b://c"), None);
        assert_eq!(url_scheme("/abs/path"), None);
        assert_eq!(url_scheme("gs+x://b"), Some("gs+x"));
    }

    #[test]
    fn local_create_new_is_once() {
        let dir = tempfile::tempdir().unwrap();
        let root = Root::Local(dir.path().to_path_buf());
        assert!(root.create_new("a.json", b"1").unwrap());
        assert!(!root.create_new("a.json", b"2").unwrap());
        assert_eq!(root.read("a.json").unwrap(), b"1");
        assert_eq!(root.list("").unwrap().unwrap(), vec!["a.json".to_string()]);
        assert_eq!(root.list("nope").unwrap(), None);
    }
}
