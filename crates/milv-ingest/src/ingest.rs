//! The ingest pipeline: plan (sidecars, metadata, content ids), decode + encode in
//! parallel across episodes, stream rows into shards, commit one version.

use std::cell::Cell;
use std::collections::{BTreeMap, BTreeSet};
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use milv_data::RowBuffer as _;
use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::{
    CommitMeta, Dataset, Domain, Episode, FileAdd, FrameRows, InputDigest, Kind, ShardOptions, ShardWriter,
    Split, TableKind,
};
use milv_lerobot::{EpisodePlan, LeRobotDataset};
use milv_video::{DecodeOptions, Frame, Resize};
use rayon::prelude::*;
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::error::{Error, Result};
use crate::journal::Journal;
use crate::manifest::InputSpec;
use crate::sidecar::{self, EpisodeMeta, Sidecar};

/// Frame rates accepted for folders and resampling.
pub const MIN_FPS: f64 = 0.001;
pub const MAX_FPS: f64 = 10_000.0;

pub use milv_data::Partition;

/// How to ingest.
#[derive(Clone, Debug)]
pub struct IngestOptions {
    /// Metadata for inputs whose sidecar/manifest line doesn't say.
    pub defaults: EpisodeMeta,
    pub resize: Option<Resize>,
    /// Resample to this frame rate.
    pub fps: Option<f64>,
    pub encoding: FrameEncoding,
    /// Episodes decoded at once (and threads encoding frames).
    pub jobs: usize,
    pub require_actions: bool,
    pub shard: ShardOptions,
    pub partition: Option<Partition>,
}

impl Default for IngestOptions {
    fn default() -> Self {
        IngestOptions {
            defaults: EpisodeMeta::default(),
            resize: None,
            fps: None,
            encoding: FrameEncoding::Png,
            jobs: std::thread::available_parallelism().map_or(1, |n| n.get()),
            require_actions: false,
            shard: ShardOptions::default(),
            partition: None,
        }
    }
}

/// Hooks for a progress display; the library prints nothing itself.
pub trait Progress: Sync {
    /// The run will decode `episodes` episodes, about `frames` frames (0 if unknown).
    fn planned(&self, _episodes: usize, _frames: u64) {}
    fn frames_done(&self, _n: u64) {}
    fn episode_done(&self, _source: &Path, _ok: bool) {}
}

/// A [`Progress`] that shows nothing.
pub struct NoProgress;
impl Progress for NoProgress {}

#[derive(Clone, Debug, Serialize)]
pub struct Ingested {
    pub episode_id: String,
    pub source: String,
    pub n_frames: i64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Skipped {
    pub source: String,
    pub episode_id: String,
    pub reason: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct Failed {
    pub source: String,
    pub error: String,
}

/// What an ingest run did (the `--json` output).
#[derive(Clone, Debug, Serialize)]
pub struct IngestReport {
    pub dataset: String,
    /// The dataset version after the run (unchanged if nothing new landed).
    pub version: u64,
    pub base_version: u64,
    pub ingested: Vec<Ingested>,
    pub skipped: Vec<Skipped>,
    pub failed: Vec<Failed>,
    pub frames: u64,
    /// Episodes taken over from an interrupted earlier run of the same batch (also listed
    /// in `ingested`).
    pub resumed: usize,
    /// Problems that did not stop the run.
    pub warnings: Vec<String>,
}

impl IngestReport {
    pub fn all_ok(&self) -> bool {
        self.failed.is_empty()
    }
}

/// Metadata of an episode after layering and validation.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Resolved {
    domain: Domain,
    kind: Kind,
    task_id: Option<String>,
    task_family: Option<String>,
    pair_id: Option<String>,
    split: Split,
    /// Frame rate of a frame folder.
    folder_fps: Option<f64>,
}

pub(crate) struct Planned {
    pub(crate) source: PathBuf,
    pub(crate) sidecar: Option<Sidecar>,
    pub(crate) meta: Resolved,
    pub(crate) source_sha256: String,
    pub(crate) episode_id: String,
    /// The files this episode was made from, for the version's input digests.
    pub(crate) inputs: Vec<InputDigest>,
    /// An episode of a LeRobot dataset (its frames come from there, not from `source`).
    pub(crate) lerobot: Option<Arc<(Arc<LeRobotDataset>, EpisodePlan)>>,
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn sha256_file(path: &Path, h: &mut Sha256) -> Result<()> {
    let mut f = std::fs::File::open(path).map_err(|e| Error::Io {
        op: "open",
        source: e,
        path: path.to_path_buf(),
    })?;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).map_err(|e| Error::Io {
            op: "read",
            source: e,
            path: path.to_path_buf(),
        })?;
        if n == 0 {
            return Ok(());
        }
        h.update(&buf[..n]);
    }
}

/// sha256 of a video file, or of a frame folder's files (names and bytes, in frame order).
pub fn source_digest(path: &Path) -> Result<String> {
    let mut h = Sha256::new();
    if path.is_dir() {
        for f in milv_video::list_numbered_frames(path)? {
            h.update(f.file_name().map(|n| n.as_encoded_bytes()).unwrap_or_default());
            h.update([0]);
            sha256_file(&f, &mut h)?;
        }
    } else {
        let meta = std::fs::metadata(path).map_err(|e| Error::Io {
            op: "read",
            source: e,
            path: path.to_path_buf(),
        })?;
        if meta.len() == 0 {
            return Err(Error::input(path, "empty file (0 bytes)"));
        }
        sha256_file(path, &mut h)?;
    }
    Ok(hex(&h.finalize()))
}

/// A metadata value of a closed set (domain, kind, split), or an error naming the input.
fn parse_choice<T: std::str::FromStr<Err = String>>(path: &Path, v: &str) -> Result<T> {
    v.parse().map_err(|msg: String| Error::input(path, msg))
}

pub(crate) fn resolve_meta(
    spec: &InputSpec,
    sidecar: Option<&Sidecar>,
    defaults: &EpisodeMeta,
) -> Result<Resolved> {
    let side = sidecar.map(|s| s.meta.clone()).unwrap_or_default();
    let m = spec.meta.clone().over(&side.over(defaults));
    let p = &spec.path;
    let domain = m
        .domain
        .ok_or_else(|| Error::input(p, "no domain (give --domain, a sidecar or a manifest column)"))?;
    let domain: Domain = parse_choice(p, &domain)?;
    let kind: Kind = m.kind.as_deref().map_or(Ok(Kind::Demo), |k| parse_choice(p, k))?;
    let split: Split = m
        .split
        .as_deref()
        .map_or(Ok(Split::Train), |k| parse_choice(p, k))?;
    if let Some(f) = m.fps
        && !(MIN_FPS..=MAX_FPS).contains(&f)
    {
        return Err(Error::input(
            p,
            format!("fps {f} is outside {MIN_FPS}..={MAX_FPS}"),
        ));
    }
    Ok(Resolved {
        domain,
        kind,
        task_id: m.task_id,
        task_family: m.task_family,
        pair_id: m.pair_id,
        split,
        folder_fps: m.fps,
    })
}

fn plan_one(spec: &InputSpec, opts: &IngestOptions) -> Result<Planned> {
    let path = &spec.path;
    // symlink_metadata first so a dangling link is reported as such.
    std::fs::metadata(path).map_err(|e| Error::Io {
        op: "cannot read input",
        source: e,
        path: path.clone(),
    })?;
    let sidecar_path = spec.sidecar.clone().or_else(|| sidecar::discover(path));
    let (sidecar, sidecar_sha256) = match &sidecar_path {
        Some(sp) => {
            let s = sidecar::read(sp)?;
            (Some(s), Some(source_digest(sp)?))
        }
        None => (None, None),
    };
    if opts.require_actions && sidecar.as_ref().and_then(|s| s.actions.as_ref()).is_none() {
        return Err(Error::input(
            path,
            "--require-actions: no sidecar with actions (looked for <stem>.json / <stem>.csv)",
        ));
    }
    let meta = resolve_meta(spec, sidecar.as_ref(), &opts.defaults)?;
    if path.is_dir() && meta.folder_fps.is_none() {
        return Err(Error::input(
            path,
            "a frame folder needs --fps or an fps in its sidecar",
        ));
    }
    let source_sha256 = source_digest(path)?;
    let episode_id = episode_id(&source_sha256, sidecar_sha256.as_deref(), &meta, opts, None);
    let mut inputs = vec![InputDigest {
        uri: source_name(path),
        sha256: source_sha256.clone(),
    }];
    if let (Some(s), Some(sha)) = (&sidecar, &sidecar_sha256) {
        inputs.push(InputDigest {
            uri: source_name(&s.path),
            sha256: sha.clone(),
        });
    }
    Ok(Planned {
        source: path.clone(),
        sidecar,
        meta,
        source_sha256,
        episode_id,
        inputs,
        lerobot: None,
    })
}

/// The id covers everything that changes the rows: source, sidecar, metadata, options,
/// and for an episode out of a larger file, which part of it (`origin`).
pub(crate) fn episode_id(
    source_sha256: &str,
    sidecar_sha256: Option<&str>,
    meta: &Resolved,
    opts: &IngestOptions,
    origin: Option<&serde_json::Value>,
) -> String {
    let mut h = Sha256::new();
    h.update(b"milv-episode/1\0");
    h.update(source_sha256.as_bytes());
    h.update(sidecar_sha256.unwrap_or("-").as_bytes());
    let mut options = serde_json::json!({
        "meta": meta,
        "resize": opts.resize.map(|r| format!("{}x{}:{}", r.width, r.height, r.policy)),
        "fps": opts.fps,
        "encoding": opts.encoding.name(),
        "jpeg_quality": match opts.encoding { FrameEncoding::Jpeg { quality } => Some(quality), _ => None },
    });
    if let Some(o) = origin {
        options["origin"] = o.clone();
    }
    h.update(options.to_string().as_bytes());
    hex(&h.finalize())[..32].to_string()
}

const ENCODE_CHUNK: usize = 16;
const BATCH_BYTES: usize = 8 << 20;

struct EpisodeState<'a> {
    p: &'a Planned,
    enc: FrameEncoding,
    rows: FrameRows,
    n: i64,
    size: Option<(u32, u32)>,
    last_ts: i64,
}

/// Decodes (and resamples) `source`, sending frames in chunks; returns the number of
/// source frames decoded. Stops early when the receiver is gone (the episode failed).
fn decode_chunks(
    source: Box<dyn milv_video::FrameSource>,
    fps: Option<f64>,
    tx: &crossbeam_channel::Sender<Result<Vec<Frame>, milv_video::Error>>,
) -> u64 {
    let decoded = Cell::new(0u64);
    let counted = source.inspect(|f| {
        if let Ok(f) = f {
            decoded.set(decoded.get().max(f.source_index + 1));
        }
    });
    let frames: Box<dyn Iterator<Item = Result<Frame, milv_video::Error>>> = match fps {
        Some(fps) => match milv_video::Resample::new(counted, fps) {
            Ok(r) => Box::new(r),
            Err(e) => {
                let _ = tx.send(Err(e));
                return 0;
            }
        },
        None => Box::new(counted),
    };
    let mut chunk = Vec::with_capacity(ENCODE_CHUNK);
    for f in frames {
        match f {
            Ok(f) => {
                chunk.push(f);
                if chunk.len() == ENCODE_CHUNK {
                    let full = std::mem::replace(&mut chunk, Vec::with_capacity(ENCODE_CHUNK));
                    if tx.send(Ok(full)).is_err() {
                        break;
                    }
                }
            }
            Err(e) => {
                let _ = tx.send(Err(e));
                return decoded.get();
            }
        }
    }
    if !chunk.is_empty() {
        let _ = tx.send(Ok(chunk));
    }
    decoded.get()
}

impl EpisodeState<'_> {
    fn check_frame(&mut self, f: &Frame, n_actions: Option<usize>, n_states: Option<usize>) -> Result<()> {
        let p = self.p;
        let size = (f.width, f.height);
        if *self.size.get_or_insert(size) != size {
            return Err(Error::Frame {
                index: f.source_index,
                msg: format!(
                    "frame size changed from {}x{} to {}x{} (use --resize)",
                    self.size.map_or(0, |s| s.0),
                    self.size.map_or(0, |s| s.1),
                    size.0,
                    size.1
                ),
                path: p.source.clone(),
            });
        }
        // Fail early rather than after decoding a long clip.
        for (what, n) in [("action", n_actions), ("state", n_states)] {
            if let Some(n) = n
                && f.source_index as usize >= n
            {
                return Err(Error::input(
                    p.sidecar.as_ref().map_or(&p.source, |s| &s.path),
                    format!(
                        "{n} {what} rows for at least {} video frames (need one row per frame of {})",
                        f.source_index + 1,
                        p.source.display()
                    ),
                ));
            }
        }
        Ok(())
    }

    fn row(table: Option<&Vec<Vec<f32>>>, i: u64) -> Option<&[f32]> {
        table.and_then(|t| t.get(i as usize)).map(Vec::as_slice)
    }

    fn flush_chunk(
        &mut self,
        chunk: &mut Vec<Frame>,
        w: &mut ShardWriter,
        progress: &dyn Progress,
    ) -> Result<()> {
        let enc = self.enc;
        let encoded: Vec<std::result::Result<Vec<u8>, frame_codec::CodecError>> = chunk
            .par_iter()
            .map(|f| {
                let mut buf = Vec::new();
                frame_codec::encode(enc, &f.data, f.width, f.height, &mut buf).map(|()| buf)
            })
            .collect();
        let side = self.p.sidecar.as_ref();
        let count = chunk.len() as u64;
        for (f, bytes) in chunk.drain(..).zip(encoded) {
            let bytes = bytes.map_err(|e| Error::Frame {
                index: f.source_index,
                msg: format!("encode: {e}"),
                path: self.p.source.clone(),
            })?;
            let action = Self::row(side.and_then(|s| s.actions.as_ref()), f.source_index);
            let state = Self::row(side.and_then(|s| s.states.as_ref()), f.source_index);
            self.rows
                .push(&self.p.episode_id, self.n as i32, f.pts_ns, &bytes, action, state);
            self.n += 1;
            self.last_ts = f.pts_ns;
            if self.rows.buffered_bytes() >= BATCH_BYTES {
                w.push(self.rows.finish()?)?;
            }
        }
        progress.frames_done(count);
        Ok(())
    }
}

fn count_check(p: &Planned, what: &str, rows: Option<usize>, frames: u64) -> Result<()> {
    match rows {
        Some(r) if r as u64 != frames => Err(Error::input(
            p.sidecar.as_ref().map_or(&p.source, |s| &s.path),
            format!(
                "{r} {what} rows for {frames} video frames (need one row per frame of {})",
                p.source.display()
            ),
        )),
        _ => Ok(()),
    }
}

fn ingest_one(
    p: &Planned,
    opts: &IngestOptions,
    w: &mut ShardWriter,
    progress: &dyn Progress,
) -> Result<Episode> {
    let dopts = DecodeOptions {
        resize: opts.resize,
        fps: None,
        // One decoder thread per episode: it runs beside the encoder pool, and measured
        // faster on 2 cores than FFmpeg frame threads competing with the encoders.
        threads: 1,
    };
    let source = match &p.lerobot {
        Some(lr) => lr.0.frames(&lr.1, &dopts)?,
        None => milv_video::open_frames(&p.source, p.meta.folder_fps, &dopts)?,
    };
    let info = source.info().clone();
    let side = p.sidecar.as_ref();
    let n_actions = side.and_then(|s| s.actions.as_ref()).map(Vec::len);
    let n_states = side.and_then(|s| s.states.as_ref()).map(Vec::len);
    let mut st = EpisodeState {
        p,
        enc: opts.encoding,
        rows: FrameRows::new(),
        n: 0,
        size: None,
        last_ts: 0,
    };
    w.begin_episode()?;
    // --fps resamples videos; a frame folder's rate is its own (folder_fps).
    let resample = if p.source.is_dir() || p.lerobot.is_some() {
        None
    } else {
        opts.fps
    };
    // Decoding runs on its own thread, up to two chunks ahead of encoding and writing.
    let frames_decoded = std::thread::scope(|s| -> Result<u64> {
        let (tx, rx) = crossbeam_channel::bounded(2);
        let decoder = s.spawn(move || decode_chunks(source, resample, &tx));
        for chunk in rx.iter() {
            let mut chunk: Vec<Frame> = chunk?;
            for f in &chunk {
                st.check_frame(f, n_actions, n_states)?;
            }
            st.flush_chunk(&mut chunk, w, progress)?;
        }
        decoder
            .join()
            .map_err(|_| Error::input(&p.source, "the decoder thread panicked"))
    })?;
    if st.n == 0 {
        return Err(Error::input(&p.source, "no decodable frames"));
    }
    // A faststart MP4 cut short still opens and decodes its first part: the frame count
    // the container declares tells.
    if let Some(declared) = info.frames_declared
        && frames_decoded < declared
    {
        return Err(Error::input(
            &p.source,
            format!(
                "decoded {frames_decoded} of the {declared} frames the container declares (truncated or corrupt)"
            ),
        ));
    }
    count_check(p, "action", n_actions, frames_decoded)?;
    count_check(p, "state", n_states, frames_decoded)?;
    if !st.rows.is_empty() {
        w.push(st.rows.finish()?)?;
    }
    w.end_episode()?;
    let (width, height) = st.size.unwrap_or((0, 0));
    let fps = opts
        .fps
        .filter(|_| p.lerobot.is_none())
        .or(p.meta.folder_fps.filter(|_| p.source.is_dir()))
        .filter(|f| *f > 0.0)
        .unwrap_or_else(|| {
            if info.fps > 0.0 {
                info.fps
            } else if st.n > 1 && st.last_ts > 0 {
                (st.n - 1) as f64 * 1e9 / st.last_ts as f64
            } else {
                0.0
            }
        });
    let period = if fps > 0.0 { (1e9 / fps).round() as i64 } else { 0 };
    Ok(Episode {
        episode_id: p.episode_id.clone(),
        domain: p.meta.domain,
        kind: p.meta.kind,
        task_id: p.meta.task_id.clone(),
        task_family: p.meta.task_family.clone(),
        pair_id: p.meta.pair_id.clone(),
        split: p.meta.split,
        n_frames: st.n,
        fps,
        width: width as i32,
        height: height as i32,
        frame_encoding: opts.encoding,
        action_dim: side
            .and_then(|s| s.actions.as_ref())
            .and_then(|a| a.first())
            .map(|r| r.len() as i32),
        state_dim: side
            .and_then(|s| s.states.as_ref())
            .and_then(|a| a.first())
            .map(|r| r.len() as i32),
        action_names: side.and_then(|s| s.action_names.clone()),
        state_names: side.and_then(|s| s.state_names.clone()),
        source_uri: source_name(&p.source),
        source_sha256: p.source_sha256.clone(),
        sidecar_uri: side.map(|s| source_name(&s.path)),
        duration_ns: st.last_ts + period,
        ingested_at_us: now_us(),
    })
}

fn now_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

/// How the version log names an input: its path, or the `s3://` URL it was fetched from.
fn source_name(p: &Path) -> String {
    milv_data::store::cached_url(p).unwrap_or_else(|| p.display().to_string())
}

/// Ingests `inputs` into `ds` as one new version. Bad inputs are reported in the result and
/// skipped; the others land. Errors only for problems with the dataset itself.
pub fn ingest(
    ds: &Dataset,
    inputs: &[InputSpec],
    opts: &IngestOptions,
    meta: CommitMeta,
    progress: &dyn Progress,
) -> Result<IngestReport> {
    let sources: Vec<String> = inputs.iter().map(|s| source_name(&s.path)).collect();
    ingest_planned(
        ds,
        &sources,
        &|i| plan_one(&inputs[i], opts),
        opts,
        meta,
        progress,
    )
}

/// Ingests every episode of the LeRobot v3.0 dataset at `dir` (frames of `camera`, which
/// may be left out when there is only one) as one new version, with the guarantees of
/// [`ingest`]. Each episode's task text becomes its task id; `opts.defaults` give the
/// domain, kind and task family.
pub fn ingest_lerobot(
    ds: &Dataset,
    dir: &Path,
    camera: Option<&str>,
    opts: &IngestOptions,
    meta: CommitMeta,
    progress: &dyn Progress,
) -> Result<IngestReport> {
    let lr = Arc::new(LeRobotDataset::open(dir, camera)?);
    let digests = crate::lerobot::file_digests(&lr)?;
    let sources: Vec<String> = (0..lr.episodes.len())
        .map(|i| format!("{}#episode={i}", lr.root.display()))
        .collect();
    let plan = |i: usize| crate::lerobot::plan_episode(&lr, i, &digests, opts);
    ingest_planned(ds, &sources, &plan, opts, meta, progress)
}

/// Runs an ingest of `sources.len()` inputs, input `i` planned by `plan(i)`.
fn ingest_planned(
    ds: &Dataset,
    sources: &[String],
    plan: &(dyn Fn(usize) -> Result<Planned> + Sync),
    opts: &IngestOptions,
    meta: CommitMeta,
    progress: &dyn Progress,
) -> Result<IngestReport> {
    // A concurrent writer adding the same episode makes our commit conflict; the retry
    // then sees that episode as present and skips it.
    let mut attempt = 0;
    loop {
        match ingest_attempt(ds, sources, plan, opts, meta.clone(), progress) {
            Err(Error::Data(milv_data::Error::Conflict(_))) if attempt < 3 => attempt += 1,
            other => return other,
        }
    }
}

fn ingest_attempt(
    ds: &Dataset,
    sources: &[String],
    plan: &(dyn Fn(usize) -> Result<Planned> + Sync),
    opts: &IngestOptions,
    meta: CommitMeta,
    progress: &dyn Progress,
) -> Result<IngestReport> {
    let mut txn = ds.begin(meta)?;
    let base = txn.base_version();
    let mut report = IngestReport {
        dataset: ds.root().display().to_string(),
        version: base,
        base_version: base,
        ingested: Vec::new(),
        skipped: Vec::new(),
        failed: Vec::new(),
        frames: 0,
        resumed: 0,
        warnings: Vec::new(),
    };
    let todo = plan_batch(ds, base, sources, plan, opts, &mut report)?;
    // Reuse what an interrupted run of this same batch already finished.
    let pending: BTreeSet<String> = todo.iter().map(|p| p.episode_id.clone()).collect();
    let (journal, adopted) = Journal::open(ds, &pending)?;
    let adopted_ids: BTreeSet<&str> = adopted.episodes.iter().map(|e| e.episode_id.as_str()).collect();
    let (resumed, todo): (Vec<Planned>, Vec<Planned>) = todo
        .into_iter()
        .partition(|p| adopted_ids.contains(p.episode_id.as_str()));
    progress.planned(todo.len(), 0);

    let results = write_frames(ds, &txn, &todo, opts, &journal, progress)?;
    let (frame_files, mut episodes, mut digests, fatal) = collect_outcomes(results, &mut report);
    for p in &resumed {
        let n_frames = adopted
            .episodes
            .iter()
            .find(|e| e.episode_id == p.episode_id)
            .map_or(0, |e| e.n_frames);
        report.frames += n_frames as u64;
        report.ingested.push(Ingested {
            episode_id: p.episode_id.clone(),
            source: source_name(&p.source),
            n_frames,
        });
        digests.extend(input_digests(p));
    }
    report.resumed = resumed.len();
    let new_ids: Vec<String> = episodes.iter().map(|e| e.episode_id.clone()).collect();
    txn.add_files(TableKind::Frames, frame_files, new_ids);
    let adopted_ids: Vec<String> = adopted.episodes.iter().map(|e| e.episode_id.clone()).collect();
    txn.adopt_files(TableKind::Frames, adopted.files, adopted_ids);
    episodes.extend(adopted.episodes);
    if let Some(e) = fatal {
        txn.abort();
        return Err(e);
    }
    if episodes.is_empty() {
        txn.abort();
        journal.remove();
        return Ok(report);
    }
    if let Err(e) = txn.add_episode_rows(&episodes) {
        txn.abort();
        return Err(e.into());
    }
    report.version = commit_batch(txn, digests, opts, &mut report)?;
    journal.remove();
    Ok(report)
}

/// Phase 1: plans the selected inputs (this worker's partition): metadata, digests and
/// episode ids; inputs already in the dataset are skipped, duplicates within the batch
/// and unplannable ones fail. Returns the episodes to ingest.
fn plan_batch(
    ds: &Dataset,
    base: u64,
    sources: &[String],
    plan: &(dyn Fn(usize) -> Result<Planned> + Sync),
    opts: &IngestOptions,
    report: &mut IngestReport,
) -> Result<Vec<Planned>> {
    let existing: BTreeSet<String> = milv_data::ops::episodes(ds, base)?
        .into_iter()
        .map(|e| e.episode_id)
        .collect();
    let selected: Vec<usize> = (0..sources.len())
        .filter(|i| opts.partition.is_none_or(|p| p.contains_index(*i as u64)))
        .collect();
    let plans: Vec<Result<Planned>> = selected.par_iter().map(|&i| plan(i)).collect();
    let mut todo = Vec::new();
    let mut in_batch: BTreeMap<String, PathBuf> = BTreeMap::new();
    for (&i, plan) in selected.iter().zip(plans) {
        match plan {
            Err(e) => report.failed.push(Failed {
                source: sources[i].clone(),
                error: e.to_string(),
            }),
            Ok(p) if existing.contains(&p.episode_id) => report.skipped.push(Skipped {
                source: source_name(&p.source),
                episode_id: p.episode_id,
                reason: format!("already in the dataset at version {base}"),
            }),
            Ok(p) => {
                if let Some(first) = in_batch.get(&p.episode_id) {
                    report.failed.push(Failed {
                        source: source_name(&p.source),
                        error: format!(
                            "duplicate episode {} (same content and options as {}): {}",
                            p.episode_id,
                            first.display(),
                            p.source.display()
                        ),
                    });
                } else {
                    in_batch.insert(p.episode_id.clone(), p.source.clone());
                    todo.push(p);
                }
            }
        }
    }
    Ok(todo)
}

type Outcome<'p> = (&'p Planned, Result<Episode>);
/// What one writer thread produced: its files (or the error that stopped it), and each
/// episode's outcome.
type WorkerResult<'p> = (Result<Vec<FileAdd>>, Vec<Outcome<'p>>);

/// Phase 2: decodes and writes the episodes' frames on `opts.jobs` threads, one shard
/// writer each, journaling every closed file so an interrupted run can adopt it.
fn write_frames<'p>(
    ds: &Dataset,
    txn: &milv_data::Transaction<'_>,
    todo: &'p [Planned],
    opts: &IngestOptions,
    journal: &Journal,
    progress: &dyn Progress,
) -> Result<Vec<WorkerResult<'p>>> {
    let jobs = opts.jobs.max(1);
    let workers = jobs.min(todo.len()).max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .map_err(|e| Error::input(ds.root(), format!("thread pool: {e}")))?;
    let mut shard = opts.shard.clone();
    // PNG/JPEG frames are compressed already; raw frames get fast zstd.
    let image_zstd = (opts.encoding == FrameEncoding::Raw).then_some(1);
    shard.column_zstd.push(("image".into(), image_zstd));
    let mut writers = Vec::with_capacity(workers);
    for _ in 0..workers {
        writers.push(txn.shard_writer(TableKind::Frames, shard.clone())?);
    }
    let (tx, rx) = crossbeam_channel::unbounded::<&Planned>();
    for p in todo {
        // Unbounded is fine: the channel holds references, not frames.
        let _ = tx.send(p);
    }
    drop(tx);
    let results: Vec<WorkerResult<'p>> = std::thread::scope(|s| {
        let handles: Vec<_> = writers
            .into_iter()
            .map(|mut w| {
                let rx = rx.clone();
                let pool = &pool;
                s.spawn(move || {
                    let mut outcomes = Vec::new();
                    let mut unjournaled: BTreeMap<String, Episode> = BTreeMap::new();
                    let mut fatal = None;
                    for p in rx.iter() {
                        let mut r = pool.install(|| ingest_one(p, opts, &mut w, progress));
                        match &r {
                            Ok(ep) => {
                                unjournaled.insert(ep.episode_id.clone(), ep.clone());
                            }
                            // The shard writer itself failed (disk full, ...): its open
                            // file is lost, so nothing more may be written through it.
                            Err(Error::Data(_)) => {
                                if let Err(e) = std::mem::replace(
                                    &mut r,
                                    Err(Error::input(&p.source, "not ingested: the shard writer failed")),
                                ) {
                                    fatal = Some(e);
                                }
                            }
                            Err(_) => w.abort_episode(),
                        }
                        for c in w.take_closed() {
                            let eps = c
                                .episodes
                                .iter()
                                .filter_map(|id| unjournaled.remove(id))
                                .collect();
                            if let Err(e) = journal.record(c.file, eps) {
                                fatal = Some(e);
                            }
                        }
                        progress.episode_done(&p.source, r.is_ok());
                        outcomes.push((p, r));
                        if fatal.is_some() {
                            break;
                        }
                    }
                    let files = match fatal {
                        Some(e) => {
                            w.abort();
                            Err(e)
                        }
                        None => w.finish().map_err(Error::from),
                    };
                    (files, outcomes)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    (
                        Err(Error::input(ds.root(), "an ingest worker panicked")),
                        Vec::new(),
                    )
                })
            })
            .collect()
    });

    Ok(results)
}

/// Phase 3: the workers' files, the episodes that made it (with their input digests)
/// and the first fatal error; failed episodes go to the report.
fn collect_outcomes(
    results: Vec<WorkerResult<'_>>,
    report: &mut IngestReport,
) -> (Vec<FileAdd>, Vec<Episode>, Vec<InputDigest>, Option<Error>) {
    let mut frame_files = Vec::new();
    let mut episodes = Vec::new();
    let mut digests = Vec::new();
    let mut fatal = None;
    for (files, outcomes) in results {
        match files {
            Ok(f) => frame_files.extend(f),
            Err(e) => fatal = Some(e),
        }
        for (p, r) in outcomes {
            match r {
                Ok(ep) => {
                    digests.extend(input_digests(p));
                    report.frames += ep.n_frames as u64;
                    report.ingested.push(Ingested {
                        episode_id: ep.episode_id.clone(),
                        source: source_name(&p.source),
                        n_frames: ep.n_frames,
                    });
                    episodes.push(ep);
                }
                Err(e) => report.failed.push(Failed {
                    source: source_name(&p.source),
                    error: e.to_string(),
                }),
            }
        }
    }
    (frame_files, episodes, digests, fatal)
}

/// Phase 4: records what the version holds and commits it.
fn commit_batch(
    mut txn: milv_data::Transaction<'_>,
    digests: Vec<InputDigest>,
    opts: &IngestOptions,
    report: &mut IngestReport,
) -> Result<u64> {
    // Episodes of one LeRobot dataset share files: each is listed once.
    let mut seen = BTreeSet::new();
    let digests: Vec<InputDigest> = digests
        .into_iter()
        .filter(|d| seen.insert(d.uri.clone()))
        .collect();
    let m = txn.meta_mut();
    m.inputs = digests;
    m.summary = serde_json::json!({
        "ingested": report.ingested.len(),
        "skipped": report.skipped.len(),
        "failed": report.failed.len(),
        "frames": report.frames,
        "frame_encoding": opts.encoding.name(),
        "resize": opts.resize.map(|r| format!("{}x{}:{}", r.width, r.height, r.policy)),
        "fps": opts.fps,
        "partition": opts.partition.map(|p| format!("{}/{}", p.index, p.count)),
    });
    Ok(match txn.commit() {
        Ok(v) => v,
        Err(milv_data::Error::NotYetInDelta { version, source }) => {
            report.warnings.push(format!(
                "version {version} is committed but not yet in the Delta tables ({source}); \
                 the next write or `milv-ds verify --repair` completes it"
            ));
            version
        }
        Err(e) => return Err(e.into()),
    })
}

fn input_digests(p: &Planned) -> Vec<InputDigest> {
    p.inputs.clone()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn metadata_is_validated() {
        let spec = InputSpec::new("x.mp4");
        let mut d = EpisodeMeta {
            domain: Some("alien".into()),
            ..Default::default()
        };
        let e = resolve_meta(&spec, None, &d).unwrap_err().to_string();
        assert!(
            e.contains("unknown domain \"alien\"") && e.contains("x.mp4"),
            "{e}"
        );
        d.domain = None;
        assert!(
            resolve_meta(&spec, None, &d)
                .unwrap_err()
                .to_string()
                .contains("no domain")
        );
        d.domain = Some("human".into());
        let r = resolve_meta(&spec, None, &d).unwrap();
        assert_eq!((r.kind.as_str(), r.split.as_str()), ("demo", "train"));
    }
}
