//! Writing a dataset version as a LeRobot v3.0 dataset ([`export`]) and computing the
//! statistics such an export would carry ([`stats`]) — both from one pass over the rows,
//! in storage order, one episode in memory at a time.
//!
//! The export is built in a temporary folder beside the target and renamed onto it only
//! when complete; every video file is decoded back first and each frame's timestamp
//! checked against LeRobot's tolerance.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use milv_data::arrow::array::{
    Array, ArrayRef, BinaryArray, FixedSizeListArray, Float32Array, Int32Array, Int64Array, ListArray,
    ListBuilder, RecordBatch, StringArray, StringBuilder, StructArray,
};
use milv_data::arrow::datatypes::{DataType, Field, Fields, Schema, SchemaRef};
use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::parquet::arrow::ArrowWriter;
use milv_data::parquet::basic::Compression;
use milv_data::parquet::file::properties::WriterProperties;
use milv_data::{CuratedRow, Dataset, Episode, TableKind};
use milv_video::{Codec, DecodeOptions, VideoReader, VideoWriter};
use rayon::prelude::*;
use serde::Serialize;
use serde_json::{Value, json};

use crate::error::{Error, Result};
use crate::format::{
    self, Arg, CODEBASE_VERSION, DATA_PATH, EPISODES_PATH, TOLERANCE_S, VIDEO_PATH, fill_template,
};
use crate::stats::{DatasetStats, sample_indices};

/// The camera feature MILV exports.
pub const IMAGE_KEY: &str = "observation.image";
/// Files per chunk folder, and LeRobot's file size targets.
const CHUNKS_SIZE: i64 = 1000;
const DATA_FILE_MB: u64 = 100;
const VIDEO_FILE_MB: u64 = 200;
/// LeRobot's keyframe interval: random access decodes at most one frame before the target.
pub const DEFAULT_GOP: u32 = 2;

/// Which rows become the LeRobot frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// Recorded frames with their actions and states.
    Frames,
    /// One model's imagined frames with the inverse-dynamics actions.
    Imagined,
    /// The curated view: its episodes, every frame, with the curated loss weight (0 for
    /// frames the curation dropped).
    Curated,
}

impl std::str::FromStr for Source {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "frames" => Ok(Source::Frames),
            "imagined" => Ok(Source::Imagined),
            "curated" => Ok(Source::Curated),
            o => Err(format!("unknown table {o:?} (frames | imagined | curated)")),
        }
    }
}

/// How to export.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    pub source: Source,
    /// AV1 video (LeRobot's default) or inline PNG images.
    pub video: bool,
    /// Keyframe interval of the video ([`DEFAULT_GOP`], LeRobot's): longer encodes faster
    /// and smaller, but LeRobot decodes up to `gop - 1` extra frames per random access.
    pub gop: u32,
    /// Translation model for `imagined` (default: the only one).
    pub model_id: Option<String>,
}

/// Progress hooks; the library prints nothing.
pub trait Progress: Sync {
    fn planned(&self, _episodes: usize, _frames: u64) {}
    fn episode_done(&self, _frames: u64) {}
    fn verifying(&self) {}
}

pub struct NoProgress;
impl Progress for NoProgress {}

/// What an export wrote (the `--json` output).
#[derive(Clone, Debug, Serialize)]
pub struct ExportReport {
    pub dataset: String,
    pub version: u64,
    pub source: Source,
    pub out: String,
    pub episodes: usize,
    pub frames: u64,
    pub fps: u32,
    pub width: u32,
    pub height: u32,
    pub video: bool,
    pub video_encoder: Option<String>,
    pub video_files: usize,
    pub data_files: usize,
    /// Largest |decoded pts − expected| over every exported video frame, seconds.
    pub max_timestamp_error_s: Option<f64>,
    pub tasks: usize,
    pub model_id: Option<String>,
    pub curation_id: Option<String>,
}

/// One episode's rows as exported.
struct EpisodeData {
    ep: Episode,
    images: Vec<Vec<u8>>,
    actions: Option<Vec<Vec<f32>>>,
    states: Option<Vec<Vec<f32>>>,
    weights: Option<Vec<f32>>,
}

/// The selection: episodes in export order and how to read their rows.
struct Plan {
    version: u64,
    table: TableKind,
    episodes: BTreeMap<String, Episode>,
    model_id: Option<String>,
    curation_id: Option<String>,
    weights: Option<HashMap<(String, i32), f64>>,
    fps: u32,
    width: u32,
    height: u32,
    action_dim: Option<usize>,
    state_dim: Option<usize>,
    action_names: Option<Vec<String>>,
    state_names: Option<Vec<String>>,
}

fn invalid(ds: &Dataset, msg: impl Into<String>) -> Error {
    Error::format(ds.root(), msg)
}

fn plan(ds: &Dataset, version: u64, opts: &ExportOptions) -> Result<Plan> {
    let all: BTreeMap<String, Episode> = milv_data::read::rows::<Episode>(ds, version)?
        .into_iter()
        .map(|e| (e.episode_id.clone(), e))
        .collect();
    let (table, episodes, model_id, curation_id, weights) = match opts.source {
        Source::Frames => (TableKind::Frames, all, None, None, None),
        Source::Imagined => {
            let Some((model, eps)) = milv_data::resolve_model(ds, version, opts.model_id.as_deref())? else {
                return Err(invalid(
                    ds,
                    format!("@{version} has no imagined frames; run `milv-train translate` first"),
                ));
            };
            let episodes = all.into_iter().filter(|(id, _)| eps.contains(id)).collect();
            (TableKind::Imagined, episodes, Some(model), None, None)
        }
        Source::Curated => {
            let ids = milv_data::read::curations(ds, version)?;
            let Some(curation) = ids.iter().next_back().cloned() else {
                return Err(invalid(
                    ds,
                    format!("@{version} has no curated view; run `milv-score curate` first"),
                ));
            };
            let rows: Vec<CuratedRow> = milv_data::read::rows::<CuratedRow>(ds, version)?
                .into_iter()
                .filter(|r| r.curation_id == curation)
                .collect();
            let table = match rows.first().map(|r| r.source_table.as_str()) {
                Some("imagined") => TableKind::Imagined,
                _ => TableKind::Frames,
            };
            let model = rows.first().and_then(|r| r.model_id.clone());
            let keep: std::collections::BTreeSet<&str> = rows.iter().map(|r| r.episode_id.as_str()).collect();
            let episodes = all
                .into_iter()
                .filter(|(id, _)| keep.contains(id.as_str()))
                .collect();
            let weights = rows
                .iter()
                .map(|r| ((r.episode_id.clone(), r.frame_index), r.weight))
                .collect();
            (table, episodes, model, Some(curation), Some(weights))
        }
    };
    if episodes.is_empty() {
        return Err(invalid(ds, format!("@{version}: no episodes to export")));
    }
    // LeRobot has one fps and one frame size per dataset.
    let fpss: std::collections::BTreeSet<String> = episodes.values().map(|e| format!("{}", e.fps)).collect();
    if fpss.len() > 1 {
        return Err(invalid(
            ds,
            format!(
                "episodes differ in fps ({}); LeRobot datasets have one: re-ingest with --fps N",
                fpss.into_iter().collect::<Vec<_>>().join(", ")
            ),
        ));
    }
    let first = episodes
        .values()
        .next()
        .cloned()
        .ok_or_else(|| invalid(ds, "no episodes"))?;
    if (first.fps - first.fps.round()).abs() > 1e-6 || first.fps < 1.0 {
        return Err(invalid(
            ds,
            format!(
                "fps {} is not an integer; LeRobot needs one: re-ingest with --fps N",
                first.fps
            ),
        ));
    }
    // Imagined frames have the translator's size, whatever the human clips' were.
    let (width, height) = match table {
        TableKind::Imagined => imagined_size(ds, version, model_id.as_deref())?,
        _ => {
            let sizes: std::collections::BTreeSet<(i32, i32)> =
                episodes.values().map(|e| (e.width, e.height)).collect();
            if sizes.len() > 1 {
                let s: Vec<String> = sizes.iter().map(|(w, h)| format!("{w}x{h}")).collect();
                return Err(invalid(
                    ds,
                    format!(
                        "episodes differ in frame size ({}); re-ingest with --resize WxH",
                        s.join(", ")
                    ),
                ));
            }
            (first.width as u32, first.height as u32)
        }
    };
    let dims = |f: &dyn Fn(&Episode) -> Option<i32>, what: &str| -> Result<Option<usize>> {
        let d: std::collections::BTreeSet<Option<i32>> = episodes.values().map(f).collect();
        match d.len() {
            1 => Ok(d.into_iter().next().flatten().map(|x| x as usize)),
            _ => Err(invalid(
                ds,
                format!("episodes differ in {what} width ({d:?}); export them separately"),
            )),
        }
    };
    let (action_dim, state_dim) = match table {
        // Imagined actions are the robot's (their width is in the rows, checked there).
        TableKind::Imagined => (None, None),
        _ => (
            dims(&|e| e.action_dim, "action")?,
            dims(&|e| e.state_dim, "state")?,
        ),
    };
    Ok(Plan {
        version,
        table,
        model_id,
        curation_id,
        weights,
        fps: first.fps.round() as u32,
        width,
        height,
        action_dim,
        state_dim,
        action_names: first.action_names.clone().filter(|_| table == TableKind::Frames),
        state_names: first.state_names.clone(),
        episodes,
    })
}

/// The size of `model`'s imagined frames (read from the first one; every frame is checked
/// against it when decoded).
fn imagined_size(ds: &Dataset, version: u64, model: Option<&str>) -> Result<(u32, u32)> {
    let path = ds.table_root(TableKind::Imagined);
    for b in ds.scan(TableKind::Imagined, version, Some(&["model_id", "image"]))? {
        let b = b?;
        let models = str_col(&path, &b, "model_id")?;
        let imgs = b
            .column_by_name("image")
            .and_then(|c| c.as_any().downcast_ref::<BinaryArray>())
            .ok_or_else(|| Error::format(&path, "no image"))?;
        if let Some(i) = (0..b.num_rows()).find(|&i| model.is_none_or(|m| models.value(i) == m)) {
            let dims = image::ImageReader::new(std::io::Cursor::new(imgs.value(i)))
                .with_guessed_format()
                .map_err(Error::io("cannot read an imagined frame of", &path))?
                .into_dimensions()
                .map_err(|e| Error::format(&path, format!("an imagined frame does not decode: {e}")))?;
            return Ok(dims);
        }
    }
    Err(Error::format(&path, "no imagined frames of the model"))
}

/// Streams the plan's episodes, complete and in storage order.
fn for_each_episode(ds: &Dataset, plan: &Plan, mut f: impl FnMut(EpisodeData) -> Result<()>) -> Result<()> {
    let mut cols = vec!["episode_id", "frame_index", "image", "action"];
    if plan.table == TableKind::Frames {
        cols.push("state");
    } else {
        cols.push("model_id");
    }
    // Rows of episodes not yet complete: (frame_index, image, action, state).
    type Rows = Vec<(i32, Vec<u8>, Option<Vec<f32>>, Option<Vec<f32>>)>;
    let mut open: HashMap<String, Rows> = HashMap::new();
    for b in ds.scan(plan.table, plan.version, Some(&cols))? {
        let b = b?;
        let path = ds.table_root(plan.table);
        let ids = str_col(&path, &b, "episode_id")?;
        let idx = b
            .column_by_name("frame_index")
            .and_then(|c| c.as_any().downcast_ref::<Int32Array>())
            .ok_or_else(|| Error::format(&path, "no frame_index"))?;
        let imgs = b
            .column_by_name("image")
            .and_then(|c| c.as_any().downcast_ref::<BinaryArray>())
            .ok_or_else(|| Error::format(&path, "no image"))?;
        let acts = b
            .column_by_name("action")
            .and_then(|c| c.as_any().downcast_ref::<ListArray>());
        let sts = b
            .column_by_name("state")
            .and_then(|c| c.as_any().downcast_ref::<ListArray>());
        let models = if plan.table == TableKind::Imagined {
            Some(str_col(&path, &b, "model_id")?)
        } else {
            None
        };
        let vec_at = |l: Option<&ListArray>, i: usize| -> Option<Vec<f32>> {
            let l = l?;
            if l.is_null(i) {
                return None;
            }
            let v = l.value(i);
            v.as_any()
                .downcast_ref::<Float32Array>()
                .map(|a| a.values().to_vec())
        };
        for i in 0..b.num_rows() {
            let id = ids.value(i);
            let Some(ep) = plan.episodes.get(id) else { continue };
            if models.is_some_and(|m| Some(m.value(i)) != plan.model_id.as_deref()) {
                continue;
            }
            let rows = open.entry(id.to_string()).or_default();
            rows.push((
                idx.value(i),
                imgs.value(i).to_vec(),
                vec_at(acts, i),
                vec_at(sts, i),
            ));
            if rows.len() as i64 == ep.n_frames {
                let mut rows = open.remove(id).unwrap_or_default();
                rows.sort_by_key(|r| r.0);
                f(episode_data(plan, ep, rows)?)?;
            }
        }
    }
    if let Some((id, rows)) = open.into_iter().next() {
        let n = plan.episodes.get(&id).map_or(0, |e| e.n_frames);
        return Err(Error::format(
            ds.table_root(plan.table),
            format!(
                "episode {id} has {} of its {n} rows in @{} (run `milv-ds verify`)",
                rows.len(),
                plan.version
            ),
        ));
    }
    Ok(())
}

fn str_col<'a>(path: &Path, b: &'a RecordBatch, name: &str) -> Result<&'a StringArray> {
    b.column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<StringArray>())
        .ok_or_else(|| Error::format(path, format!("no string column {name}")))
}

#[allow(clippy::type_complexity)]
fn episode_data(
    plan: &Plan,
    ep: &Episode,
    rows: Vec<(i32, Vec<u8>, Option<Vec<f32>>, Option<Vec<f32>>)>,
) -> Result<EpisodeData> {
    let n = rows.len();
    let mut images = Vec::with_capacity(n);
    let mut actions = Vec::with_capacity(n);
    let mut states = Vec::with_capacity(n);
    for (_, img, a, s) in rows {
        images.push(img);
        actions.push(a);
        states.push(s);
    }
    let all = |v: Vec<Option<Vec<f32>>>| -> Option<Vec<Vec<f32>>> { v.into_iter().collect() };
    let weights = plan.weights.as_ref().map(|w| {
        (0..n as i32)
            .map(|i| w.get(&(ep.episode_id.clone(), i)).copied().unwrap_or(0.0) as f32)
            .collect()
    });
    Ok(EpisodeData {
        ep: ep.clone(),
        images,
        actions: all(actions),
        states: if plan.table == TableKind::Frames {
            all(states)
        } else {
            None
        },
        weights,
    })
}

/// The frames of one episode as RGB24 (decoded in parallel).
fn decode_all(e: &EpisodeData, enc: FrameEncoding, w: u32, h: u32) -> Result<Vec<Vec<u8>>> {
    (0..e.images.len())
        .into_par_iter()
        .map(|i| decode_frame(e, enc, i, w, h))
        .collect()
}

/// Stored frame `i` of an episode as RGB24; the error names the episode and the frame.
fn decode_frame(e: &EpisodeData, enc: FrameEncoding, i: usize, w: u32, h: u32) -> Result<Vec<u8>> {
    frame_codec::decode(enc, &e.images[i], w, h).map_err(|err| {
        Error::format(
            &e.ep.source_uri,
            format!("episode {}: stored frame {i}: {err}", e.ep.episode_id),
        )
    })
}

/// The encoding of a table's images (imagined frames are PNG).
fn encoding_of(plan: &Plan, ep: &Episode) -> FrameEncoding {
    if plan.table == TableKind::Frames {
        ep.frame_encoding
    } else {
        FrameEncoding::Png
    }
}

/// Accumulates the statistics of one episode (frames sampled as LeRobot samples them).
fn add_stats(
    stats: &mut DatasetStats,
    plan: &Plan,
    e: &EpisodeData,
    first_row: i64,
    ep_index: i64,
    task: i64,
    rgb: Option<&[Vec<u8>]>,
) -> Result<()> {
    let n = e.images.len();
    for i in 0..n {
        if let Some(a) = &e.actions {
            stats.vector("action").push(&a[i]);
        }
        if let Some(s) = &e.states {
            stats.vector("observation.state").push(&s[i]);
        }
        if let Some(w) = &e.weights {
            stats.vector("milv.weight").push(&[w[i]]);
        }
        stats
            .vector("timestamp")
            .push(&[(i as f64 / f64::from(plan.fps)) as f32]);
        stats.vector("frame_index").push(&[i as f32]);
        stats.vector("episode_index").push(&[ep_index as f32]);
        stats.vector("index").push(&[(first_row + i as i64) as f32]);
        stats.vector("task_index").push(&[task as f32]);
    }
    let idx = sample_indices(n);
    let enc = encoding_of(plan, &e.ep);
    let img = stats.image(IMAGE_KEY);
    match rgb {
        // Already decoded for the video: no second decode, no copies.
        Some(all) => idx.iter().for_each(|&i| img.push(&all[i])),
        None => {
            let sampled: Vec<Vec<u8>> = idx
                .par_iter()
                .map(|&i| decode_frame(e, enc, i, plan.width, plan.height))
                .collect::<Result<_>>()?;
            sampled.iter().for_each(|f| img.push(f));
        }
    }
    Ok(())
}

/// Task text of an episode: its task id, or its family, or "unspecified".
fn task_text(ep: &Episode) -> String {
    ep.task_id
        .clone()
        .or_else(|| ep.task_family.clone())
        .unwrap_or_else(|| "unspecified".into())
}

/// The statistics an export of `version` would write to `meta/stats.json`.
pub fn stats(ds: &Dataset, version: u64, opts: &ExportOptions) -> Result<Value> {
    let plan = plan(ds, version, opts)?;
    let mut stats = DatasetStats::default();
    let mut tasks: Vec<String> = Vec::new();
    let (mut row, mut ep_index) = (0i64, 0i64);
    for_each_episode(ds, &plan, |e| {
        let task = task_index(&mut tasks, task_text(&e.ep));
        add_stats(&mut stats, &plan, &e, row, ep_index, task, None)?;
        row += e.images.len() as i64;
        ep_index += 1;
        Ok(())
    })?;
    Ok(stats.to_json())
}

fn task_index(tasks: &mut Vec<String>, t: String) -> i64 {
    match tasks.iter().position(|x| *x == t) {
        Some(i) => i as i64,
        None => {
            tasks.push(t);
            tasks.len() as i64 - 1
        }
    }
}

/// A Parquet file of the `data/` folder being written, rolled over at LeRobot's size.
struct DataFiles {
    root: PathBuf,
    schema: SchemaRef,
    current: Option<(ArrowWriter<File>, PathBuf)>,
    at: (i64, i64),
    written: usize,
}

fn next_file((chunk, file): (i64, i64)) -> (i64, i64) {
    if file + 1 >= CHUNKS_SIZE {
        (chunk + 1, 0)
    } else {
        (chunk, file + 1)
    }
}

impl DataFiles {
    /// The (chunk, file) the next episode goes to; rolls over when the current file is full.
    fn place(&mut self) -> Result<(i64, i64)> {
        if let Some((w, _)) = &self.current
            && w.bytes_written() as u64 >= DATA_FILE_MB << 20
        {
            self.close()?;
            self.at = next_file(self.at);
        }
        if self.current.is_none() {
            let rel = fill_template(
                DATA_PATH,
                &[
                    ("chunk_index", Arg::Int(self.at.0)),
                    ("file_index", Arg::Int(self.at.1)),
                ],
                &self.root,
            )?;
            let path = self.root.join(rel);
            create_parent(&path)?;
            let f = File::create(&path).map_err(Error::io("cannot create", &path))?;
            let props = WriterProperties::builder()
                .set_compression(Compression::SNAPPY)
                .build();
            let w =
                ArrowWriter::try_new(f, self.schema.clone(), Some(props)).map_err(Error::parquet(&path))?;
            self.current = Some((w, path));
            self.written += 1;
        }
        Ok(self.at)
    }

    fn write(&mut self, b: &RecordBatch) -> Result<()> {
        if let Some((w, path)) = &mut self.current {
            w.write(b).map_err(Error::parquet(path.as_path()))?;
            // One row group per episode, as LeRobot writes them.
            w.flush().map_err(Error::parquet(path.as_path()))?;
        }
        Ok(())
    }

    fn close(&mut self) -> Result<()> {
        if let Some((w, path)) = self.current.take() {
            w.close().map_err(Error::parquet(&path))?;
        }
        Ok(())
    }
}

/// The video file being written.
struct VideoFiles {
    root: PathBuf,
    current: Option<(VideoWriter, PathBuf, u64)>,
    at: (i64, i64),
    gop: u32,
    /// Every finished file with its frame count, for the check.
    finished: Vec<(PathBuf, u64)>,
    encoder: Option<String>,
}

impl VideoFiles {
    fn place(&mut self, plan: &Plan) -> Result<((i64, i64), u64)> {
        if let Some((_, path, _)) = &self.current
            && std::fs::metadata(path).map(|m| m.len()).unwrap_or(0) >= VIDEO_FILE_MB << 20
        {
            self.close()?;
            self.at = next_file(self.at);
        }
        if self.current.is_none() {
            let rel = fill_template(
                VIDEO_PATH,
                &[
                    ("video_key", Arg::Str(IMAGE_KEY)),
                    ("chunk_index", Arg::Int(self.at.0)),
                    ("file_index", Arg::Int(self.at.1)),
                ],
                &self.root,
            )?;
            let path = self.root.join(rel);
            create_parent(&path)?;
            let w = VideoWriter::create_with_gop(
                &path,
                plan.width,
                plan.height,
                plan.fps,
                // LeRobot's own encoder and settings where SVT-AV1 can take the size.
                if plan.width >= 64 && plan.height >= 64 {
                    Codec::SvtAv1
                } else {
                    Codec::Av1
                },
                Some(self.gop),
            )?;
            self.encoder.get_or_insert_with(|| w.encoder_name());
            self.current = Some((w, path, 0));
        }
        Ok((self.at, self.current.as_ref().map_or(0, |c| c.2)))
    }

    fn write(&mut self, frames: &[Vec<u8>]) -> Result<()> {
        if let Some((w, _, n)) = &mut self.current {
            for f in frames {
                w.write(f)?;
            }
            *n += frames.len() as u64;
        }
        Ok(())
    }

    fn close(&mut self) -> Result<()> {
        if let Some((w, path, n)) = self.current.take() {
            w.finish()?;
            self.finished.push((path, n));
        }
        Ok(())
    }
}

fn create_parent(path: &Path) -> Result<()> {
    if let Some(p) = path.parent() {
        std::fs::create_dir_all(p).map_err(Error::io("cannot create", p))?;
    }
    Ok(())
}

/// Decodes `path` and checks frame k is at k/fps within LeRobot's tolerance (and that there
/// are exactly `n` frames). Returns the largest error in seconds.
pub fn check_video(path: &Path, n: u64, fps: u32) -> Result<f64> {
    let mut r = VideoReader::open(
        path,
        &DecodeOptions {
            threads: 0,
            ..Default::default()
        },
    )?;
    r.seek_to(0)?;
    let mut worst: f64 = 0.0;
    let mut k = 0u64;
    for f in r {
        let f = f?;
        let want = k as f64 / f64::from(fps);
        let err = (f.pts_ns as f64 / 1e9 - want).abs();
        if err >= TOLERANCE_S {
            return Err(Error::format(
                path,
                format!(
                    "frame {k} decodes at {:.6} s, not {want:.6} s (tolerance {TOLERANCE_S} s)",
                    f.pts_ns as f64 / 1e9
                ),
            ));
        }
        worst = worst.max(err);
        k += 1;
    }
    if k != n {
        return Err(Error::format(
            path,
            format!("decodes to {k} frames, {n} were written"),
        ));
    }
    Ok(worst)
}

fn schema(plan: &Plan, images: bool, action_dim: Option<usize>) -> SchemaRef {
    let mut fields = Vec::new();
    if images {
        let st = DataType::Struct(Fields::from(vec![
            Field::new("bytes", DataType::Binary, true),
            Field::new("path", DataType::Utf8, true),
        ]));
        fields.push(Field::new(IMAGE_KEY, st, true));
    }
    let fsl =
        |d: usize| DataType::FixedSizeList(Arc::new(Field::new("item", DataType::Float32, true)), d as i32);
    if let Some(d) = action_dim {
        fields.push(Field::new("action", fsl(d), true));
    }
    if let Some(d) = plan.state_dim {
        fields.push(Field::new("observation.state", fsl(d), true));
    }
    if plan.model_id.is_some() {
        fields.push(Field::new("milv.model_id", DataType::Utf8, true));
    }
    if plan.weights.is_some() {
        fields.push(Field::new("milv.weight", DataType::Float32, true));
    }
    fields.push(Field::new("timestamp", DataType::Float32, true));
    for k in ["frame_index", "episode_index", "index", "task_index"] {
        fields.push(Field::new(k, DataType::Int64, true));
    }
    Arc::new(Schema::new(fields))
}

fn fixed_list(rows: &[Vec<f32>], d: usize, path: &Path) -> Result<ArrayRef> {
    let mut flat = Vec::with_capacity(rows.len() * d);
    for (i, r) in rows.iter().enumerate() {
        if r.len() != d {
            return Err(Error::format(
                path,
                format!("row {i} has {} values where {d} were expected", r.len()),
            ));
        }
        flat.extend_from_slice(r);
    }
    let field = Arc::new(Field::new("item", DataType::Float32, true));
    Ok(Arc::new(
        FixedSizeListArray::try_new(field, d as i32, Arc::new(Float32Array::from(flat)), None)
            .map_err(Error::arrow(path))?,
    ))
}

/// Writes `version` of `ds` as a LeRobot v3.0 dataset at `out` (which must not exist or be
/// empty). Nothing appears at `out` unless the whole export succeeded.
pub fn export(
    ds: &Dataset,
    version: u64,
    out: &Path,
    opts: &ExportOptions,
    progress: &dyn Progress,
) -> Result<ExportReport> {
    if out.exists()
        && std::fs::read_dir(out)
            .map(|mut d| d.next().is_some())
            .unwrap_or(true)
    {
        return Err(Error::format(
            out,
            "exists and is not empty (export to a new folder)",
        ));
    }
    let plan = plan(ds, version, opts)?;
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(Error::io("cannot create", &parent))?;
    let tmp = tempfile::Builder::new()
        .prefix(&format!(
            ".{}.",
            out.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        ))
        .suffix(".tmp")
        .tempdir_in(&parent)
        .map_err(Error::io("cannot create a temporary folder in", &parent))?;
    let root = tmp.path().to_path_buf();
    let total: u64 = plan.episodes.values().map(|e| e.n_frames as u64).sum();
    progress.planned(plan.episodes.len(), total);

    // The imagined actions' width is only known from the rows.
    let mut action_dim = plan.action_dim;
    let mut data: Option<DataFiles> = None;
    let mut videos = VideoFiles {
        root: root.clone(),
        current: None,
        at: (0, 0),
        gop: opts.gop.max(1),
        finished: Vec::new(),
        encoder: None,
    };
    let mut stats = DatasetStats::default();
    let mut tasks: Vec<String> = Vec::new();
    let mut ep_rows: Vec<Value> = Vec::new();
    let (mut row, mut ep_index) = (0i64, 0i64);
    for_each_episode(ds, &plan, |e| {
        let n = e.images.len();
        let ep_path = PathBuf::from(&e.ep.source_uri);
        if plan.table == TableKind::Imagined
            && let Some(a) = e.actions.as_ref().and_then(|a| a.first())
        {
            action_dim.get_or_insert(a.len());
        }
        let data = data.get_or_insert_with(|| DataFiles {
            root: root.clone(),
            schema: schema(&plan, !opts.video, action_dim),
            current: None,
            at: (0, 0),
            written: 0,
        });
        let task = task_index(&mut tasks, task_text(&e.ep));
        let enc = encoding_of(&plan, &e.ep);
        let rgb = if opts.video {
            Some(decode_all(&e, enc, plan.width, plan.height)?)
        } else {
            None
        };
        add_stats(&mut stats, &plan, &e, row, ep_index, task, rgb.as_deref())?;

        let mut cols: Vec<ArrayRef> = Vec::new();
        if !opts.video {
            // PNG and JPEG bytes go in as stored (lossless); raw frames become PNG.
            let pngs: Option<Vec<Vec<u8>>> = if enc == FrameEncoding::Raw {
                Some(
                    e.images
                        .par_iter()
                        .map(|b| {
                            let mut out = Vec::new();
                            frame_codec::encode(FrameEncoding::Png, b, plan.width, plan.height, &mut out)
                                .map(|()| out)
                                .map_err(|err| Error::episode(ep_path.clone(), ep_index, err.to_string()))
                        })
                        .collect::<Result<_>>()?,
                )
            } else {
                None
            };
            let bytes = pngs.as_ref().unwrap_or(&e.images);
            let ext = if matches!(enc, FrameEncoding::Jpeg { .. }) {
                "jpg"
            } else {
                "png"
            };
            let names: Vec<String> = (0..n)
                .map(|i| format!("frame-{:06}.{ext}", row + i as i64))
                .collect();
            let bytes_arr: ArrayRef = Arc::new(BinaryArray::from_iter_values(bytes.iter()));
            let path_arr: ArrayRef = Arc::new(StringArray::from_iter_values(names));
            cols.push(Arc::new(StructArray::new(
                Fields::from(vec![
                    Field::new("bytes", DataType::Binary, true),
                    Field::new("path", DataType::Utf8, true),
                ]),
                vec![bytes_arr, path_arr],
                None,
            )));
        }
        // Every episode must have the vectors the dataset declares.
        for (dim, rows, what) in [
            (action_dim, &e.actions, "actions"),
            (plan.state_dim, &e.states, "states"),
        ] {
            if let Some(d) = dim {
                let rows = rows.as_ref().ok_or_else(|| {
                    Error::episode(
                        ep_path.clone(),
                        ep_index,
                        format!("{} has no {what} but others do", e.ep.episode_id),
                    )
                })?;
                cols.push(fixed_list(rows, d, &ep_path)?);
            }
        }
        if let Some(m) = &plan.model_id {
            cols.push(Arc::new(StringArray::from_iter_values(std::iter::repeat_n(m, n))));
        }
        if let Some(w) = &e.weights {
            cols.push(Arc::new(Float32Array::from(w.clone())));
        }
        let fps = f64::from(plan.fps);
        cols.push(Arc::new(Float32Array::from_iter_values(
            (0..n).map(|i| (i as f64 / fps) as f32),
        )));
        cols.push(Arc::new(Int64Array::from_iter_values(0..n as i64)));
        cols.push(Arc::new(Int64Array::from_iter_values(std::iter::repeat_n(
            ep_index, n,
        ))));
        cols.push(Arc::new(Int64Array::from_iter_values(row..row + n as i64)));
        cols.push(Arc::new(Int64Array::from_iter_values(std::iter::repeat_n(
            task, n,
        ))));
        let batch = RecordBatch::try_new(data.schema.clone(), cols).map_err(Error::arrow(&ep_path))?;
        let at = data.place()?;
        data.write(&batch)?;

        let mut meta = json!({
            "episode_index": ep_index,
            "tasks": [tasks[task as usize].clone()],
            "length": n as i64,
            "data/chunk_index": at.0,
            "data/file_index": at.1,
            "dataset_from_index": row,
            "dataset_to_index": row + n as i64,
            "milv/episode_id": e.ep.episode_id,
        });
        if let Some(rgb) = &rgb {
            let (vat, before) = videos.place(&plan)?;
            videos.write(rgb)?;
            meta["video"] = json!([
                vat.0,
                vat.1,
                before as f64 / fps,
                (before + n as u64) as f64 / fps
            ]);
        }
        ep_rows.push(meta);
        row += n as i64;
        ep_index += 1;
        progress.episode_done(n as u64);
        Ok(())
    })?;
    if let Some(d) = &mut data {
        d.close()?;
    }
    videos.close()?;
    progress.verifying();
    let mut worst = None;
    for (path, n) in &videos.finished {
        let w = check_video(path, *n, plan.fps)?;
        worst = Some(worst.map_or(w, |x: f64| x.max(w)));
    }
    write_episodes(&root, &ep_rows, opts.video)?;
    let tasks_path = root.join(format::TASKS_PATH);
    write_batch(
        &tasks_path,
        &format::tasks_batch(&tasks).map_err(Error::arrow(&tasks_path))?,
    )?;
    let stats_json = stats.to_json();
    write_json(&root.join(format::STATS_PATH), &stats_json)?;
    write_json(
        &root.join(format::INFO_PATH),
        &info_json(&plan, opts, action_dim, row, ep_index, tasks.len(), &videos),
    )?;

    // The commit point: the finished folder appears under its name, whole.
    let kept = tmp.keep();
    if out.exists() {
        std::fs::remove_dir(out).map_err(Error::io("cannot replace the empty folder", out))?;
    }
    std::fs::rename(&kept, out).map_err(|e| {
        let _ = std::fs::remove_dir_all(&kept);
        Error::Io {
            op: "cannot rename the finished export onto",
            path: out.to_path_buf(),
            source: e,
        }
    })?;
    Ok(ExportReport {
        dataset: ds.root().display().to_string(),
        version,
        source: opts.source,
        out: out.display().to_string(),
        episodes: ep_index as usize,
        frames: row as u64,
        fps: plan.fps,
        width: plan.width,
        height: plan.height,
        video: opts.video,
        video_encoder: videos.encoder.clone(),
        video_files: videos.finished.len(),
        data_files: data.map_or(0, |d| d.written),
        max_timestamp_error_s: worst,
        tasks: tasks.len(),
        model_id: plan.model_id.clone(),
        curation_id: plan.curation_id.clone(),
    })
}

fn write_json(path: &Path, v: &Value) -> Result<()> {
    create_parent(path)?;
    let text = serde_json::to_string_pretty(v).map_err(|source| Error::Json {
        path: path.to_path_buf(),
        source,
    })?;
    std::fs::write(path, text).map_err(Error::io("cannot write", path))
}

fn write_batch(path: &Path, b: &RecordBatch) -> Result<()> {
    create_parent(path)?;
    let f = File::create(path).map_err(Error::io("cannot create", path))?;
    let mut w = ArrowWriter::try_new(f, b.schema(), None).map_err(Error::parquet(path))?;
    w.write(b).map_err(Error::parquet(path))?;
    w.close().map_err(Error::parquet(path))?;
    Ok(())
}

/// `meta/episodes/chunk-000/file-000.parquet`: one row per episode, LeRobot's columns.
fn write_episodes(root: &Path, rows: &[Value], video: bool) -> Result<()> {
    let rel = fill_template(
        EPISODES_PATH,
        &[("chunk_index", Arg::Int(0)), ("file_index", Arg::Int(0))],
        root,
    )?;
    let path = root.join(rel);
    let int = |k: &str| -> ArrayRef {
        Arc::new(Int64Array::from_iter_values(
            rows.iter().map(|r| r[k].as_i64().unwrap_or(0)),
        ))
    };
    let mut tasks = ListBuilder::new(StringBuilder::new());
    for r in rows {
        for t in r["tasks"].as_array().into_iter().flatten() {
            tasks.values().append_value(t.as_str().unwrap_or_default());
        }
        tasks.append(true);
    }
    let mut fields = vec![
        Field::new("episode_index", DataType::Int64, true),
        Field::new(
            "tasks",
            DataType::List(Arc::new(Field::new("item", DataType::Utf8, true))),
            true,
        ),
        Field::new("length", DataType::Int64, true),
        Field::new("data/chunk_index", DataType::Int64, true),
        Field::new("data/file_index", DataType::Int64, true),
        Field::new("dataset_from_index", DataType::Int64, true),
        Field::new("dataset_to_index", DataType::Int64, true),
    ];
    let mut cols: Vec<ArrayRef> = vec![
        int("episode_index"),
        Arc::new(tasks.finish()),
        int("length"),
        int("data/chunk_index"),
        int("data/file_index"),
        int("dataset_from_index"),
        int("dataset_to_index"),
    ];
    if video {
        let v = |i: usize| rows.iter().map(move |r| r["video"][i].clone());
        for (i, name) in ["chunk_index", "file_index"].into_iter().enumerate() {
            fields.push(Field::new(
                format!("videos/{IMAGE_KEY}/{name}"),
                DataType::Int64,
                true,
            ));
            cols.push(Arc::new(Int64Array::from_iter_values(
                v(i).map(|x| x.as_i64().unwrap_or(0)),
            )));
        }
        for (i, name) in [(2, "from_timestamp"), (3, "to_timestamp")] {
            fields.push(Field::new(
                format!("videos/{IMAGE_KEY}/{name}"),
                DataType::Float64,
                true,
            ));
            cols.push(Arc::new(milv_data::arrow::array::Float64Array::from_iter_values(
                v(i).map(|x| x.as_f64().unwrap_or(0.0)),
            )));
        }
    }
    for k in ["meta/episodes/chunk_index", "meta/episodes/file_index"] {
        fields.push(Field::new(k, DataType::Int64, true));
        cols.push(Arc::new(Int64Array::from_iter_values(std::iter::repeat_n(
            0,
            rows.len(),
        ))));
    }
    fields.push(Field::new("milv/episode_id", DataType::Utf8, true));
    cols.push(Arc::new(StringArray::from_iter_values(rows.iter().map(|r| {
        r["milv/episode_id"].as_str().unwrap_or_default().to_string()
    }))));
    let b = RecordBatch::try_new(Arc::new(Schema::new(fields)), cols).map_err(Error::arrow(&path))?;
    write_batch(&path, &b)
}

fn info_json(
    plan: &Plan,
    opts: &ExportOptions,
    action_dim: Option<usize>,
    frames: i64,
    episodes: i64,
    tasks: usize,
    videos: &VideoFiles,
) -> Value {
    let mut features = serde_json::Map::new();
    let (h, w) = (plan.height, plan.width);
    let mut image = json!({"dtype": if opts.video { "video" } else { "image" }, "shape": [h, w, 3], "names": ["height", "width", "channels"]});
    if opts.video {
        image["info"] = json!({
            "video.height": h, "video.width": w, "video.codec": "av1", "video.pix_fmt": "yuv420p",
            "video.is_depth_map": false, "video.fps": plan.fps, "video.channels": 3, "video.g": opts.gop,
            "video.encoder": videos.encoder, "has_audio": false
        });
    }
    features.insert(IMAGE_KEY.into(), image);
    let names = |n: &Option<Vec<String>>, d: usize| -> Value {
        match n {
            Some(n) if n.len() == d => json!(n),
            _ => json!((0..d).map(|i| format!("{i}")).collect::<Vec<_>>()),
        }
    };
    if let Some(d) = action_dim {
        features.insert(
            "action".into(),
            json!({"dtype": "float32", "shape": [d], "names": names(&plan.action_names, d)}),
        );
    }
    if let Some(d) = plan.state_dim {
        features.insert(
            "observation.state".into(),
            json!({"dtype": "float32", "shape": [d], "names": names(&plan.state_names, d)}),
        );
    }
    if plan.model_id.is_some() {
        features.insert(
            "milv.model_id".into(),
            json!({"dtype": "string", "shape": [1], "names": null}),
        );
    }
    if plan.weights.is_some() {
        features.insert(
            "milv.weight".into(),
            json!({"dtype": "float32", "shape": [1], "names": null}),
        );
    }
    features.insert(
        "timestamp".into(),
        json!({"dtype": "float32", "shape": [1], "names": null}),
    );
    for k in ["frame_index", "episode_index", "index", "task_index"] {
        features.insert(k.into(), json!({"dtype": "int64", "shape": [1], "names": null}));
    }
    json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": null,
        "total_episodes": episodes,
        "total_frames": frames,
        "total_tasks": tasks,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILE_MB,
        "video_files_size_in_mb": VIDEO_FILE_MB,
        "fps": plan.fps,
        "splits": {"train": format!("0:{episodes}")},
        "data_path": DATA_PATH,
        "video_path": if opts.video { json!(VIDEO_PATH) } else { Value::Null },
        "features": features,
    })
}
