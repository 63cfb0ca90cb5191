//! Writing a [`ViewPlan`] as MCAP: one file for the whole selection (episodes laid end to
//! end in log time) or one file per episode. Files are written under a temporary name in
//! the target folder and renamed when complete, so a failed export leaves nothing behind.

use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};
use mcap::{Attachment, WriteOptions};
use milv_data::Dataset;
use milv_data::view::{EpisodeView, Image, ViewPlan};
use prost::Message;
use serde::Serialize;
use serde_json::{Value, json};

use crate::schema::{self, Tensor};
use crate::{Error, Result};

/// Where a recording comes from, for its metadata record.
#[derive(Clone, Debug)]
pub struct RecordingInfo {
    pub dataset_uri: String,
    pub tool_version: String,
    pub command: Vec<String>,
}

/// Chunking and compression: the `mcap` crate's defaults (zstd at its default level, 1 MiB
/// chunks, all indexes, statistics and summary), except that zstd runs on the writing
/// thread — that thread already overlaps with the table reads, and on two cores extra
/// zstd workers measured no faster.
#[derive(Clone, Debug)]
pub struct McapOptions {
    pub compression: Option<mcap::Compression>,
    pub chunk_size: Option<u64>,
    /// zstd level (0: zstd's default, 3).
    pub compression_level: u32,
    /// zstd worker threads (0: compress on the writing thread).
    pub compression_threads: u32,
}

impl Default for McapOptions {
    fn default() -> Self {
        McapOptions {
            compression: Some(mcap::Compression::Zstd),
            chunk_size: Some(WriteOptions::DEFAULT_CHUNK_SIZE),
            compression_level: 0,
            compression_threads: 0,
        }
    }
}

/// One written file.
#[derive(Clone, Debug, Serialize)]
pub struct Written {
    pub path: PathBuf,
    pub episodes: usize,
    pub messages: u64,
    /// Messages per topic.
    pub topics: BTreeMap<String, u64>,
    pub bytes: u64,
    pub start_ns: u64,
    pub end_ns: u64,
}

struct Channels {
    image: BTreeMap<&'static str, u16>,
    action: BTreeMap<&'static str, u16>,
    quality: u16,
    latent: u16,
}

/// What every file of an export says about its source (copied out of the plan, which the
/// episode stream borrows).
struct Head {
    version: u64,
    model_id: Option<String>,
    model_config: Option<Value>,
    action_names: Vec<String>,
    score_run: Option<String>,
    alignment: Option<milv_data::AlignmentRun>,
}

impl Head {
    fn of(p: &ViewPlan) -> Head {
        Head {
            version: p.version,
            model_id: p.model_id.clone(),
            model_config: p.model_config.clone(),
            action_names: p.action_names.clone(),
            score_run: p.score_run.clone(),
            alignment: p.alignment.clone(),
        }
    }
}

/// An open MCAP writer with the MILV channels.
struct Recorder<W: Write + Seek> {
    w: mcap::Writer<W>,
    ch: Channels,
    seq: u32,
    action_names: Vec<String>,
    model_id: String,
    end_ns: u64,
    start_ns: Option<u64>,
    episodes: usize,
}

fn mcap_err(path: &Path) -> impl Fn(mcap::McapError) -> Error + '_ {
    move |source| Error::Mcap {
        source,
        path: path.to_path_buf(),
    }
}

impl<W: Write + Seek> Recorder<W> {
    fn new(out: W, path: &Path, plan: &Head, info: &RecordingInfo, opts: &McapOptions) -> Result<Self> {
        let e = mcap_err(path);
        let mut w = WriteOptions::new()
            .compression(opts.compression)
            .chunk_size(opts.chunk_size)
            .compression_level(opts.compression_level)
            .compression_threads(opts.compression_threads)
            .profile("")
            .library(format!("milv-mcap {}", info.tool_version))
            .create(out)
            .map_err(&e)?;
        let (name, enc, data) = schema::image_schema();
        let img = w.add_schema(&name, &enc, &data).map_err(&e)?;
        let act_schema = serde_json::to_vec(&schema::action_schema(&plan.action_names))?;
        let act = w
            .add_schema(schema::ACTION_SCHEMA, "jsonschema", &act_schema)
            .map_err(&e)?;
        let q_schema = serde_json::to_vec(&schema::quality_schema())?;
        let q = w
            .add_schema(schema::QUALITY_SCHEMA, "jsonschema", &q_schema)
            .map_err(&e)?;
        let t = w
            .add_schema(schema::TENSOR_SCHEMA, "protobuf", &schema::tensor_descriptor())
            .map_err(&e)?;
        let none = BTreeMap::new();
        let mut image = BTreeMap::new();
        for topic in [schema::HUMAN_IMAGE, schema::IMAGINED_IMAGE, schema::ROBOT_IMAGE] {
            image.insert(topic, w.add_channel(img, topic, "protobuf", &none).map_err(&e)?);
        }
        let mut action = BTreeMap::new();
        for topic in [schema::IMAGINED_ACTION, schema::ROBOT_ACTION] {
            action.insert(topic, w.add_channel(act, topic, "json", &none).map_err(&e)?);
        }
        let quality = w.add_channel(q, schema::QUALITY, "json", &none).map_err(&e)?;
        let latent = w
            .add_channel(t, schema::IMAGINED_LATENT, "protobuf", &none)
            .map_err(&e)?;
        let model_id = plan.model_id.clone().unwrap_or_default();
        let mut meta = BTreeMap::from([
            ("dataset_uri".to_string(), info.dataset_uri.clone()),
            ("dataset_version".to_string(), plan.version.to_string()),
            ("model_id".to_string(), model_id.clone()),
            ("tool".to_string(), "milv-export".to_string()),
            ("tool_version".to_string(), info.tool_version.clone()),
            ("command_line".to_string(), serde_json::to_string(&info.command)?),
            (
                "action_names".to_string(),
                serde_json::to_string(&plan.action_names)?,
            ),
        ]);
        if let Some(r) = &plan.score_run {
            meta.insert("score_run".into(), r.clone());
        }
        if let Some(a) = &plan.alignment {
            meta.insert("alignment_run".into(), format!("{} ({})", a.run_id, a.features));
        }
        w.write_metadata(&Metadata {
            name: "milv".into(),
            metadata: meta,
        })
        .map_err(&e)?;
        if let Some(cfg) = &plan.model_config {
            w.attach(&Attachment {
                log_time: 0,
                create_time: 0,
                name: "model_config.json".into(),
                media_type: "application/json".into(),
                data: serde_json::to_vec_pretty(cfg)?.into(),
            })
            .map_err(&e)?;
        }
        Ok(Recorder {
            w,
            ch: Channels {
                image,
                action,
                quality,
                latent,
            },
            seq: 0,
            action_names: plan.action_names.clone(),
            model_id,
            end_ns: 0,
            start_ns: None,
            episodes: 0,
        })
    }

    fn put(&mut self, channel_id: u16, t: u64, data: &[u8], path: &Path) -> Result<()> {
        self.seq = self.seq.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.seq,
            log_time: t,
            publish_time: t,
        };
        self.w
            .write_to_known_channel(&header, data)
            .map_err(mcap_err(path))
    }

    fn image(&mut self, topic: &'static str, t: u64, img: &Image, path: &Path) -> Result<()> {
        let msg = foxglove::messages::CompressedImage {
            timestamp: Some(foxglove::messages::Timestamp::new(
                (t / 1_000_000_000) as u32,
                (t % 1_000_000_000) as u32,
            )),
            frame_id: topic.trim_start_matches('/').trim_end_matches("/image").into(),
            data: img.data.clone().into(),
            format: img.format.into(),
        };
        let ch = self.ch.image[topic];
        self.put(ch, t, &msg.encode_to_vec(), path)
    }

    fn action(
        &mut self,
        topic: &'static str,
        t: u64,
        ep: &str,
        frame: i32,
        a: &[f32],
        path: &Path,
    ) -> Result<()> {
        let mut m = serde_json::Map::new();
        m.insert("episode_id".into(), ep.into());
        m.insert("frame_index".into(), frame.into());
        for (i, v) in a.iter().enumerate() {
            let name = milv_data::view::component_name(&self.action_names, i);
            // f32 → JSON number: the shortest text that parses back to the same f32.
            m.insert(name, json!(v));
        }
        let ch = self.ch.action[topic];
        self.put(ch, t, &serde_json::to_vec(&Value::Object(m))?, path)
    }

    /// Writes one episode with its timestamps shifted by `offset_ns`.
    fn episode(&mut self, ev: &EpisodeView, offset_ns: u64, path: &Path) -> Result<()> {
        let e = &ev.episode;
        let id = e.episode_id.as_str();
        let own = if e.domain == milv_data::Domain::Robot {
            schema::ROBOT_IMAGE
        } else {
            schema::HUMAN_IMAGE
        };
        let start = offset_ns;
        for f in &ev.frames {
            let t = offset_ns + f.timestamp_ns.max(0) as u64;
            self.image(own, t, &f.image, path)?;
            if e.domain == milv_data::Domain::Robot
                && let Some(a) = &f.action
            {
                self.action(schema::ROBOT_ACTION, t, id, f.frame_index, a, path)?;
            }
            if let Some(im) = &f.imagined {
                self.image(schema::IMAGINED_IMAGE, t, &im.image, path)?;
                if let Some(l) = &im.latent {
                    let msg = Tensor {
                        timestamp_ns: f.timestamp_ns,
                        episode_id: id.into(),
                        frame_index: f.frame_index,
                        model_id: self.model_id.clone(),
                        dtype: l.dtype.clone(),
                        shape: l.shape.iter().map(|d| *d as u32).collect(),
                        data: l.data.clone(),
                    };
                    let ch = self.ch.latent;
                    self.put(ch, t, &msg.encode_to_vec(), path)?;
                }
                if let Some(a) = &im.action {
                    self.action(schema::IMAGINED_ACTION, t, id, f.frame_index, a, path)?;
                }
            }
            if let Some(q) = &f.quality {
                let m = json!({
                    "episode_id": id, "frame_index": f.frame_index,
                    "brenner": q.brenner, "ssim": q.ssim, "beta": q.beta, "weight": q.weight,
                });
                let ch = self.ch.quality;
                self.put(ch, t, &serde_json::to_vec(&m)?, path)?;
            }
            if let Some(r) = &f.aligned {
                self.image(schema::ROBOT_IMAGE, t, &r.image, path)?;
                if let Some(a) = &r.action {
                    self.action(schema::ROBOT_ACTION, t, &r.episode_id, r.frame_index, a, path)?;
                }
            }
        }
        let end = offset_ns + ev.duration_ns();
        let meta = BTreeMap::from([
            ("episode_id".to_string(), id.to_string()),
            ("domain".to_string(), e.domain.to_string()),
            ("kind".to_string(), e.kind.to_string()),
            ("task_id".to_string(), e.task_id.clone().unwrap_or_default()),
            ("frames".to_string(), ev.frames.len().to_string()),
            ("start_ns".to_string(), start.to_string()),
            ("end_ns".to_string(), end.to_string()),
            (
                "mean_beta".to_string(),
                ev.mean_beta().map(|b| format!("{b:.6}")).unwrap_or_default(),
            ),
        ]);
        self.w
            .write_metadata(&Metadata {
                name: "episode".into(),
                metadata: meta,
            })
            .map_err(mcap_err(path))?;
        self.start_ns.get_or_insert(start);
        self.end_ns = end;
        self.episodes += 1;
        Ok(())
    }

    fn finish(mut self, path: &Path) -> Result<(W, Written)> {
        let summary = self.w.finish().map_err(mcap_err(path))?;
        let stats = summary.stats.unwrap_or_default();
        let topics = summary
            .channels
            .values()
            .map(|c| {
                let n = stats.channel_message_counts.get(&c.id).copied().unwrap_or(0);
                (c.topic.clone(), n)
            })
            .collect();
        let written = Written {
            path: path.to_path_buf(),
            episodes: self.episodes,
            messages: stats.message_count,
            topics,
            bytes: 0,
            start_ns: self.start_ns.unwrap_or(0),
            end_ns: self.end_ns,
        };
        Ok((self.w.into_inner(), written))
    }
}

/// A file being written under a temporary name next to its destination.
struct Pending {
    file: BufWriter<std::fs::File>,
    tmp: tempfile::TempPath,
}

fn pending(out: &Path) -> Result<Pending> {
    let (file, tmp) = milv_data::temp_file_beside(out)?.into_parts();
    Ok(Pending {
        file: BufWriter::with_capacity(1 << 20, file),
        tmp,
    })
}

fn commit(
    w: BufWriter<std::fs::File>,
    tmp: tempfile::TempPath,
    out: &Path,
    mut written: Written,
) -> Result<Written> {
    let io = |op: &'static str| {
        move |source: std::io::Error| Error::Io {
            op,
            source,
            path: out.to_path_buf(),
        }
    };
    let file = w.into_inner().map_err(|e| io("write")(e.into_error()))?;
    file.sync_all().map_err(io("sync"))?;
    written.bytes = file.metadata().map_err(io("stat"))?.len();
    tmp.persist(out).map_err(|e| io("rename onto")(e.error))?;
    Ok(written)
}

/// Writes every episode of `plan` into one file, laid end to end in log time.
pub fn write_recording(
    plan: &mut ViewPlan,
    ds: &Dataset,
    info: &RecordingInfo,
    out: &Path,
    opts: &McapOptions,
    progress: &mut dyn FnMut(usize),
) -> Result<Written> {
    let p = pending(out)?;
    let mut rec = Recorder::new(p.file, out, &Head::of(plan), info, opts)?;
    let mut offset = 0u64;
    plan.for_each_prefetched(ds, |k, ev| {
        rec.episode(&ev, offset, out)?;
        offset = rec.end_ns;
        progress(k + 1);
        Ok::<(), Error>(())
    })?;
    let (w, written) = rec.finish(out)?;
    commit(w, p.tmp, out, written)
}

/// Writes each episode of `plan` into `dir/<episode_id>.mcap` with its own timestamps.
pub fn write_per_episode(
    plan: &mut ViewPlan,
    ds: &Dataset,
    info: &RecordingInfo,
    dir: &Path,
    opts: &McapOptions,
    progress: &mut dyn FnMut(usize),
) -> Result<Vec<Written>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        op: "create folder",
        source,
        path: dir.to_path_buf(),
    })?;
    let head = Head::of(plan);
    let mut done = Vec::new();
    plan.for_each_prefetched(ds, |k, ev| {
        let out = dir.join(format!("{}.mcap", ev.episode.episode_id));
        let p = pending(&out)?;
        let mut rec = Recorder::new(p.file, &out, &head, info, opts)?;
        rec.episode(&ev, 0, &out)?;
        let (w, written) = rec.finish(&out)?;
        done.push(commit(w, p.tmp, &out, written)?);
        progress(k + 1);
        Ok::<(), Error>(())
    })?;
    Ok(done)
}
