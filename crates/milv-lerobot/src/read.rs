//! Reading a LeRobot v3.0 dataset episode by episode: [`LeRobotDataset::open`] checks the
//! metadata and plans every episode (its rows, task, actions and where its frames are);
//! [`LeRobotDataset::frames`] then streams one episode's frames, decoded from the shared
//! video file at `from_timestamp + timestamp` (LeRobot's own rule) or from inline images.
//!
//! Memory: planning holds the vector features of every episode (not the images); decoding
//! holds a frame or two.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use milv_data::arrow::array::{Array, AsArray as _, BinaryArray, RecordBatch, StringArray};
use milv_video::{DecodeOptions, Frame, FrameSource, VideoInfo, VideoReader};

use crate::error::{Error, Result};
use crate::format::{
    self, Arg, Feature, Info, TOLERANCE_S, fill_template, float_values, inside, int_values, read_parquet,
    vector_values,
};

/// Where an episode's frames are.
#[derive(Clone, Debug)]
pub enum FrameLocation {
    /// In a video file shared with other episodes, starting at `from_timestamp` seconds.
    Video { path: PathBuf, from_timestamp: f64 },
    /// Inline images of the data file, rows `row_offset..row_offset + length`.
    Images { path: PathBuf, row_offset: usize },
}

/// One episode, planned.
#[derive(Clone, Debug)]
pub struct EpisodePlan {
    pub index: i64,
    pub length: usize,
    pub task: String,
    pub split: String,
    /// The data file holding its rows.
    pub data_file: PathBuf,
    /// Frame timestamps relative to the episode start, seconds (the `timestamp` column).
    pub timestamps: Vec<f64>,
    pub actions: Option<Vec<Vec<f32>>>,
    pub states: Option<Vec<Vec<f32>>>,
    pub frames: FrameLocation,
}

/// An opened dataset: its metadata, the chosen camera and every episode's plan (or why
/// that episode cannot be read).
#[derive(Debug)]
pub struct LeRobotDataset {
    pub root: PathBuf,
    pub info: Info,
    pub camera: Feature,
    /// The other camera keys (kept in each episode's metadata).
    pub other_cameras: Vec<String>,
    pub tasks: Vec<String>,
    pub action: Option<Feature>,
    pub state: Option<Feature>,
    pub episodes: Vec<Result<EpisodePlan>>,
}

/// The row range an episode occupies in one data file, with its vector features.
#[derive(Default)]
struct DataRows {
    offset: usize,
    frame_index: Vec<i64>,
    timestamps: Vec<f64>,
    task_index: Vec<i64>,
    actions: Vec<Vec<f32>>,
    states: Vec<Vec<f32>>,
    contiguous: bool,
}

/// A row of `meta/episodes/*/*.parquet`.
struct EpisodeMeta {
    file: PathBuf,
    index: i64,
    length: Option<i64>,
    data: (i64, i64),
    video: Option<(i64, i64, f64)>,
    tasks: Vec<String>,
}

impl LeRobotDataset {
    /// Reads the metadata of the dataset at `root` and plans its episodes. `camera` picks
    /// the camera feature; it may be left out when there is exactly one.
    pub fn open(root: &Path, camera: Option<&str>) -> Result<LeRobotDataset> {
        let info = Info::read(root)?;
        let cams = info.cameras();
        let keys: Vec<String> = cams.iter().map(|f| f.key.clone()).collect();
        let camera = match camera {
            Some(k) => cams
                .iter()
                .find(|f| f.key == k)
                .copied()
                .cloned()
                .ok_or_else(|| {
                    Error::format(
                        &info.path,
                        format!("no camera {k:?}; the cameras are: {}", keys.join(", ")),
                    )
                })?,
            None if cams.len() == 1 => cams[0].clone(),
            None if cams.is_empty() => {
                return Err(Error::format(
                    &info.path,
                    "no image or video feature (nothing to ingest)",
                ));
            }
            None => {
                return Err(Error::format(
                    &info.path,
                    format!(
                        "{} cameras; pick one with --camera KEY: {}",
                        cams.len(),
                        keys.join(", ")
                    ),
                ));
            }
        };
        if camera.dtype == "video" && info.video_path.is_none() {
            return Err(Error::format(&info.path, "video features but no video_path"));
        }
        // A template that leaves the folder is refused before anything is read.
        let probe = [
            ("chunk_index", Arg::Int(0)),
            ("file_index", Arg::Int(0)),
            ("video_key", Arg::Str(&camera.key)),
        ];
        fill_template(&info.data_path, &probe[..2], &info.path)?;
        if let Some(v) = &info.video_path {
            fill_template(v, &probe, &info.path)?;
        }
        let other_cameras = keys.into_iter().filter(|k| *k != camera.key).collect();
        let tasks = format::read_tasks(root)?;
        let action = info.feature("action").cloned();
        let state = info.feature("observation.state").cloned();
        let metas = read_episode_metas(root, &info, &camera)?;
        let mut ds = LeRobotDataset {
            root: root.to_path_buf(),
            info,
            camera,
            other_cameras,
            tasks,
            action,
            state,
            episodes: Vec::new(),
        };
        ds.episodes = ds.plan(metas);
        Ok(ds)
    }

    fn plan(&self, metas: Vec<Result<EpisodeMeta>>) -> Vec<Result<EpisodePlan>> {
        // Each data file is read once (vector columns only) for all its episodes.
        let mut by_file: BTreeMap<(i64, i64), Result<BTreeMap<i64, DataRows>>> = BTreeMap::new();
        let mut out = Vec::with_capacity(metas.len());
        for m in metas {
            out.push(m.and_then(|m| {
                let rows = by_file
                    .entry(m.data)
                    .or_insert_with(|| self.read_data_file(m.data))
                    .as_mut()
                    .map_err(|e| Error::episode(&m.file, m.index, e.to_string()))?;
                let r = rows.remove(&m.index).unwrap_or_default();
                self.plan_one(m, r)
            }));
        }
        out
    }

    fn data_path(&self, (chunk, file): (i64, i64)) -> Result<PathBuf> {
        let rel = fill_template(
            &self.info.data_path,
            &[("chunk_index", Arg::Int(chunk)), ("file_index", Arg::Int(file))],
            &self.info.path,
        )?;
        inside(&self.root, &rel)
    }

    fn read_data_file(&self, at: (i64, i64)) -> Result<BTreeMap<i64, DataRows>> {
        let path = self.data_path(at)?;
        let mut cols = vec!["episode_index", "frame_index", "timestamp", "task_index"];
        let (a, s) = (
            self.action.as_ref().map(|f| f.key.as_str()),
            self.state.as_ref().map(|f| f.key.as_str()),
        );
        cols.extend(a);
        cols.extend(s);
        let mut out: BTreeMap<i64, DataRows> = BTreeMap::new();
        let mut row = 0usize;
        let mut last: Option<i64> = None;
        for b in read_parquet(&path, Some(&cols))? {
            let ep = int_values(&path, &b, "episode_index")?;
            let fi = int_values(&path, &b, "frame_index")?;
            let ts = float_values(&path, &b, "timestamp")?;
            let ti = int_values(&path, &b, "task_index")?;
            let acts = a.map(|k| vector_values(&path, &b, k)).transpose()?;
            let sts = s.map(|k| vector_values(&path, &b, k)).transpose()?;
            for i in 0..b.num_rows() {
                let e = ep[i];
                let r = out.entry(e).or_insert_with(|| DataRows {
                    offset: row,
                    contiguous: true,
                    ..Default::default()
                });
                if last != Some(e) && !r.frame_index.is_empty() {
                    r.contiguous = false;
                }
                last = Some(e);
                r.frame_index.push(fi[i]);
                r.timestamps.push(ts[i]);
                r.task_index.push(ti[i]);
                if let Some(v) = &acts {
                    r.actions.push(v[i].clone());
                }
                if let Some(v) = &sts {
                    r.states.push(v[i].clone());
                }
                row += 1;
            }
        }
        Ok(out)
    }

    fn plan_one(&self, m: EpisodeMeta, r: DataRows) -> Result<EpisodePlan> {
        let data_file = self.data_path(m.data)?;
        let ep_err = |msg: String| Error::episode(&data_file, m.index, msg);
        let n = r.frame_index.len();
        if n == 0 {
            return Err(ep_err("no rows in its data file".into()));
        }
        if let Some(len) = m.length
            && len as usize != n
        {
            return Err(Error::episode(
                &m.file,
                m.index,
                format!(
                    "length {len} in the episodes table, but {n} rows in {}",
                    data_file.display()
                ),
            ));
        }
        if !r.contiguous {
            return Err(ep_err("its rows are not contiguous in the data file".into()));
        }
        if let Some(bad) = r.frame_index.iter().enumerate().find(|(i, f)| **f != *i as i64) {
            return Err(ep_err(format!(
                "frame_index {} at row {} (expected 0..{n} in order)",
                bad.1, bad.0
            )));
        }
        let task = match r.task_index.first().and_then(|&t| self.tasks.get(t as usize)) {
            Some(t) => t.clone(),
            None => m.tasks.first().cloned().ok_or_else(|| {
                ep_err(format!(
                    "task_index {:?} is not in meta/tasks.parquet",
                    r.task_index.first()
                ))
            })?,
        };
        let frames = match (&self.camera.dtype[..], m.video) {
            ("video", Some((chunk, file, from))) => {
                let template = self.info.video_path.as_deref().unwrap_or_default();
                let rel = fill_template(
                    template,
                    &[
                        ("video_key", Arg::Str(&self.camera.key)),
                        ("chunk_index", Arg::Int(chunk)),
                        ("file_index", Arg::Int(file)),
                    ],
                    &self.info.path,
                )?;
                let path =
                    inside(&self.root, &rel).map_err(|e| Error::episode(&m.file, m.index, e.to_string()))?;
                FrameLocation::Video {
                    path,
                    from_timestamp: from,
                }
            }
            ("video", None) => {
                return Err(Error::episode(
                    &m.file,
                    m.index,
                    format!("no videos/{}/… columns for this episode", self.camera.key),
                ));
            }
            _ => FrameLocation::Images {
                path: data_file.clone(),
                row_offset: r.offset,
            },
        };
        Ok(EpisodePlan {
            index: m.index,
            length: n,
            task,
            split: self.info.split_of(m.index as u64).to_string(),
            timestamps: r.timestamps,
            actions: self.action.as_ref().map(|_| r.actions),
            states: self.state.as_ref().map(|_| r.states),
            frames,
            data_file,
        })
    }

    /// Streams the frames of `ep` in order, `DecodeOptions::resize` applied. Each yields
    /// `source_index` = frame index and `pts_ns` = the frame's timestamp in the episode.
    pub fn frames(&self, ep: &EpisodePlan, opts: &DecodeOptions) -> Result<Box<dyn FrameSource>> {
        let fps = f64::from(self.info.fps);
        let opts = DecodeOptions {
            fps: None,
            ..opts.clone()
        };
        match &ep.frames {
            FrameLocation::Video { path, from_timestamp } => {
                let mut reader = VideoReader::open(path, &opts)?;
                let start = ((from_timestamp + ep.timestamps[0]) * 1e9).round() as i64;
                reader.seek_to(start)?;
                let mut info = reader.info().clone();
                info.fps = fps;
                info.frames_declared = None;
                info.frames_hint = Some(ep.length as u64);
                Ok(Box::new(VideoSegment {
                    reader,
                    path: path.clone(),
                    episode: ep.index,
                    from: *from_timestamp,
                    timestamps: ep.timestamps.clone(),
                    next: 0,
                    prev: None,
                    ahead: None,
                    done: false,
                    info,
                }))
            }
            FrameLocation::Images { path, row_offset } => {
                let images = read_images(path, &self.camera.key, *row_offset, ep.length)
                    .map_err(|e| Error::episode(path, ep.index, e.to_string()))?;
                let info = VideoInfo {
                    width: self.camera.shape.get(1).copied().unwrap_or(0) as u32,
                    height: self.camera.shape.first().copied().unwrap_or(0) as u32,
                    fps,
                    duration_ns: None,
                    frames_hint: Some(ep.length as u64),
                    frames_declared: None,
                    codec: "image".into(),
                    container: "parquet".into(),
                };
                Ok(Box::new(InlineImages {
                    images: images.into_iter(),
                    timestamps: ep.timestamps.clone(),
                    next: 0,
                    path: path.clone(),
                    resize: opts.resize,
                    info,
                }))
            }
        }
    }

    /// A URI naming one episode and camera of this dataset (the MILV episode's source).
    pub fn episode_uri(&self, ep: &EpisodePlan) -> String {
        let mut s = format!(
            "{}#episode={}&camera={}",
            self.root.display(),
            ep.index,
            self.camera.key
        );
        if !self.other_cameras.is_empty() {
            s.push_str(&format!("&other_cameras={}", self.other_cameras.join(",")));
        }
        s
    }
}

fn read_episode_metas(root: &Path, info: &Info, camera: &Feature) -> Result<Vec<Result<EpisodeMeta>>> {
    let dir = root.join("meta/episodes");
    let mut files = Vec::new();
    let chunks = std::fs::read_dir(&dir).map_err(Error::io("cannot list", &dir))?;
    for c in chunks {
        let c = c.map_err(Error::io("cannot list", &dir))?.path();
        if !c.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&c).map_err(Error::io("cannot list", &c))? {
            let f = f.map_err(Error::io("cannot list", &c))?.path();
            if f.extension().is_some_and(|e| e == "parquet") {
                files.push(f);
            }
        }
    }
    // LeRobot's own order: sorted glob("*/*.parquet").
    files.sort();
    let mut out = Vec::new();
    let key = &camera.key;
    let vcols = [
        format!("videos/{key}/chunk_index"),
        format!("videos/{key}/file_index"),
        format!("videos/{key}/from_timestamp"),
    ];
    for f in files {
        for b in read_parquet(&f, None)? {
            let idx = int_values(&f, &b, "episode_index")?;
            let length = int_values(&f, &b, "length").ok();
            let dc = int_values(&f, &b, "data/chunk_index")?;
            let df = int_values(&f, &b, "data/file_index")?;
            let video = if camera.dtype == "video" {
                match (
                    int_values(&f, &b, &vcols[0]),
                    int_values(&f, &b, &vcols[1]),
                    float_values(&f, &b, &vcols[2]),
                ) {
                    (Ok(c), Ok(fi), Ok(t)) => Some((c, fi, t)),
                    _ => None,
                }
            } else {
                None
            };
            let tasks = task_lists(&b);
            for i in 0..b.num_rows() {
                out.push(Ok(EpisodeMeta {
                    file: f.clone(),
                    index: idx[i],
                    length: length.as_ref().map(|l| l[i]),
                    data: (dc[i], df[i]),
                    video: video.as_ref().map(|(c, fi, t)| (c[i], fi[i], t[i])),
                    tasks: tasks.get(i).cloned().unwrap_or_default(),
                }));
            }
        }
    }
    // Rows must run 0..N-1: LeRobot looks episodes up by position.
    for (pos, m) in out.iter_mut().enumerate() {
        if let Ok(meta) = m
            && meta.index != pos as i64
        {
            *m = Err(Error::episode(
                &meta.file,
                meta.index,
                format!("found at row {pos} of the episodes tables (LeRobot reads episodes by position)"),
            ));
        }
    }
    if out.len() as u64 != info.total_episodes {
        return Err(Error::format(
            &info.path,
            format!(
                "total_episodes is {} but meta/episodes lists {}",
                info.total_episodes,
                out.len()
            ),
        ));
    }
    Ok(out)
}

fn task_lists(b: &RecordBatch) -> Vec<Vec<String>> {
    let Some(c) = b.column_by_name("tasks") else {
        return Vec::new();
    };
    let Some(l) = c.as_list_opt::<i32>() else {
        return Vec::new();
    };
    (0..l.len())
        .map(|i| {
            let v = l.value(i);
            v.as_any()
                .downcast_ref::<StringArray>()
                .map(|s| s.iter().flatten().map(str::to_string).collect())
                .unwrap_or_default()
        })
        .collect()
}

/// The encoded images of rows `offset..offset + n` of an image feature (`struct<bytes,
/// path>` as LeRobot writes it, or plain binary).
fn read_images(path: &Path, key: &str, offset: usize, n: usize) -> Result<Vec<Vec<u8>>> {
    use milv_data::parquet::arrow::ProjectionMask;
    use milv_data::parquet::arrow::arrow_reader::{
        ParquetRecordBatchReaderBuilder, RowSelection, RowSelector,
    };
    let f = std::fs::File::open(path).map_err(Error::io("cannot open", path))?;
    let b = ParquetRecordBatchReaderBuilder::try_new(f).map_err(Error::parquet(path))?;
    let root = b
        .schema()
        .fields()
        .iter()
        .position(|f| f.name() == key)
        .ok_or_else(|| Error::format(path, format!("no column {key:?}")))?;
    let mask = ProjectionMask::roots(b.parquet_schema(), [root]);
    let sel = RowSelection::from(vec![RowSelector::skip(offset), RowSelector::select(n)]);
    let reader = b
        .with_projection(mask)
        .with_row_selection(sel)
        .with_batch_size(256)
        .build()
        .map_err(Error::parquet(path))?;
    let mut out = Vec::with_capacity(n);
    for batch in reader {
        let batch = batch.map_err(Error::arrow(path))?;
        let col = batch.column(0);
        let bytes: &BinaryArray = match col.as_struct_opt() {
            Some(s) => s
                .column_by_name("bytes")
                .and_then(|c| c.as_binary_opt::<i32>())
                .ok_or_else(|| Error::format(path, format!("{key}: no binary 'bytes' field")))?,
            None => col
                .as_binary_opt::<i32>()
                .ok_or_else(|| Error::format(path, format!("{key} is {}, not an image", col.data_type())))?,
        };
        for i in 0..bytes.len() {
            if bytes.is_null(i) {
                return Err(Error::format(
                    path,
                    format!("{key}: row {} has no image bytes", offset + out.len()),
                ));
            }
            out.push(bytes.value(i).to_vec());
        }
    }
    if out.len() != n {
        return Err(Error::format(
            path,
            format!("{key}: {} image rows where {n} were expected", out.len()),
        ));
    }
    Ok(out)
}

/// One episode's frames out of a video file holding many: for each timestamp the decoded
/// frame nearest `from + timestamp`, which must be closer than LeRobot's tolerance.
struct VideoSegment {
    reader: VideoReader,
    path: PathBuf,
    episode: i64,
    from: f64,
    timestamps: Vec<f64>,
    next: usize,
    /// The last decoded frame before the current target.
    prev: Option<Frame>,
    /// A decoded frame at or after the current target, not yet used.
    ahead: Option<Frame>,
    done: bool,
    info: VideoInfo,
}

impl VideoSegment {
    fn fail(&mut self, msg: String) -> Option<Result<Frame, milv_video::Error>> {
        self.done = true;
        Some(Err(milv_video::Error::Decode {
            path: self.path.clone(),
            msg: format!("episode {}: {msg}", self.episode),
        }))
    }
}

impl Iterator for VideoSegment {
    type Item = Result<Frame, milv_video::Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done || self.next >= self.timestamps.len() {
            return None;
        }
        let rel = self.timestamps[self.next];
        let target = ((self.from + rel) * 1e9).round() as i64;
        let tol = (TOLERANCE_S * 1e9) as i64;
        // Decode until a frame at or past the target (minus the tolerance) is in hand.
        while self.ahead.as_ref().is_none_or(|f| f.pts_ns < target - tol) {
            if let Some(f) = self.ahead.take() {
                self.prev = Some(f);
            }
            match self.reader.next() {
                Some(Ok(f)) => self.ahead = Some(f),
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(e));
                }
                None => break,
            }
        }
        let dist = |f: &Frame| (f.pts_ns - target).abs();
        let best = [self.prev.as_ref(), self.ahead.as_ref()]
            .into_iter()
            .flatten()
            .min_by_key(|f| dist(f))
            .map(|f| (dist(f), f.pts_ns));
        match best {
            Some((d, _)) if d < tol => {}
            Some((_, pts)) => {
                let msg = format!(
                    "frame {} should be at {:.6} s (from_timestamp {:.6} + timestamp {:.6}) but the nearest decoded frame is at {:.6} s{}",
                    self.next,
                    target as f64 / 1e9,
                    self.from,
                    rel,
                    pts as f64 / 1e9,
                    if self.ahead.is_none() {
                        " (the video ends before the episode does)"
                    } else {
                        ""
                    }
                );
                return self.fail(msg);
            }
            None => {
                return self.fail(format!(
                    "no frame decoded at or after {:.6} s",
                    target as f64 / 1e9
                ));
            }
        }
        let use_ahead = self
            .ahead
            .as_ref()
            .is_some_and(|a| self.prev.as_ref().is_none_or(|p| dist(a) <= dist(p)));
        let src = if use_ahead {
            self.ahead.as_ref()
        } else {
            self.prev.as_ref()
        };
        let mut out = src.cloned()?;
        out.pts_ns = (rel * 1e9).round() as i64;
        out.source_index = self.next as u64;
        self.next += 1;
        Some(Ok(out))
    }
}

impl FrameSource for VideoSegment {
    fn info(&self) -> &VideoInfo {
        &self.info
    }
}

/// Inline images of one episode, decoded one at a time.
struct InlineImages {
    images: std::vec::IntoIter<Vec<u8>>,
    timestamps: Vec<f64>,
    next: usize,
    path: PathBuf,
    resize: Option<milv_video::Resize>,
    info: VideoInfo,
}

impl Iterator for InlineImages {
    type Item = Result<Frame, milv_video::Error>;

    fn next(&mut self) -> Option<Self::Item> {
        let bytes = self.images.next()?;
        let i = self.next;
        self.next += 1;
        let img_err = |msg: String| milv_video::Error::Image {
            path: self.path.clone(),
            msg: format!("row image {i}: {msg}"),
        };
        let rgb = match image::load_from_memory(&bytes) {
            Ok(img) => img.into_rgb8(),
            Err(e) => return Some(Err(img_err(e.to_string()))),
        };
        Some(
            milv_video::resize_rgb(rgb, self.resize.as_ref(), &self.path).map(|(width, height, data)| {
                Frame {
                    width,
                    height,
                    data,
                    pts_ns: (self.timestamps[i] * 1e9).round() as i64,
                    source_index: i as u64,
                }
            }),
        )
    }
}

impl FrameSource for InlineImages {
    fn info(&self) -> &VideoInfo {
        &self.info
    }
}
