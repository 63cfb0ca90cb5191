//! `milv-score run`: score every frame of a selection and commit a `scores` version.
//!
//! One reader thread streams the table (only the id, index and image columns), cuts it
//! into episodes and hands them to `jobs` workers over a bounded channel, so memory holds
//! at most a few episodes' encoded frames. Each worker decodes its episode frame by frame
//! into a [`ClipScorer`] (no per-frame allocation after the first). The scores themselves
//! (a few numbers per frame) are kept until the end, because the set-normalised weight
//! needs the Brenner minimum and maximum over the whole run.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::sync::Mutex;

use milv_data::arrow::array::{ArrayRef, BinaryArray, Float64Array, Int32Array, RecordBatch, StringArray};
use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::{CommitMeta, Dataset, Episode, Partition, ShardOptions, TableKind, ops};
use milv_quality::{ClipScorer, FrameScore, Rgb};
use serde::Serialize;

use crate::{EpisodeError, Error, Result, column, digest};

/// Which frames to score.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// Recorded frames (human and/or robot).
    Frames,
    /// Translated human frames of one model (`milv-train translate`).
    Imagined,
}

impl Source {
    pub fn table(self) -> TableKind {
        match self {
            Source::Frames => TableKind::Frames,
            Source::Imagined => TableKind::Imagined,
        }
    }
}

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub source: Source,
    /// Required when the imagined table holds several models.
    pub model_id: Option<String>,
    /// Only these episodes.
    pub episodes: Option<BTreeSet<String>>,
    /// Only episodes of this domain (human | robot).
    pub domain: Option<String>,
    pub jobs: usize,
    pub partition: Option<Partition>,
    /// Commit the episodes that scored and report the others (otherwise commit nothing).
    pub skip_bad: bool,
}

/// What a run did.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    /// The version read.
    pub read_version: u64,
    /// The version committed (equal to the latest one when there was nothing to do).
    pub version: u64,
    pub run_id: String,
    pub source: Source,
    pub model_id: Option<String>,
    pub episodes_scored: usize,
    pub frames_scored: u64,
    /// Episodes this run had already scored (a re-run after success is a no-op).
    pub episodes_already_scored: usize,
    pub brenner_min: Option<f64>,
    pub brenner_max: Option<f64>,
    pub beta_mean: Option<f64>,
    pub failed: Vec<EpisodeError>,
    /// Weights are left null when the run is split into partitions; curation computes them.
    pub weights_written: bool,
}

struct Job {
    episode_id: String,
    frames: Vec<(i32, Vec<u8>)>,
}

type Scored = (String, Vec<FrameScore>);

/// How a stored image is decoded.
#[derive(Clone, Copy)]
enum Decode {
    Stored {
        enc: FrameEncoding,
        w: u32,
        h: u32,
    },
    /// Imagined frames are PNGs of the model's size.
    AnyPng,
}

fn decode(d: Decode, bytes: &[u8]) -> std::result::Result<(Vec<u8>, usize, usize), String> {
    match d {
        Decode::Stored { enc, w, h } => frame_codec::decode(enc, bytes, w, h)
            .map(|v| (v, w as usize, h as usize))
            .map_err(|e| e.to_string()),
        Decode::AnyPng => image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
            .map(|i| {
                let i = i.into_rgb8();
                let (w, h) = (i.width() as usize, i.height() as usize);
                (i.into_raw(), w, h)
            })
            .map_err(|e| e.to_string()),
    }
}

fn score_episode(
    job: &Job,
    dec: Decode,
    scorer: &mut ClipScorer,
) -> std::result::Result<Vec<FrameScore>, String> {
    let mut out = Vec::with_capacity(job.frames.len());
    let mut first: Option<(usize, usize)> = None;
    for (k, (idx, bytes)) in job.frames.iter().enumerate() {
        if *idx != k as i32 {
            return Err(format!(
                "frame_index {idx} where {k} was expected (rows missing or out of order)"
            ));
        }
        let (rgb, w, h) = decode(dec, bytes).map_err(|e| format!("frame {idx}: undecodable image: {e}"))?;
        if let Some((w0, h0)) = first
            && (w, h) != (w0, h0)
        {
            return Err(format!("frame {idx} is {w}x{h}, frame 0 is {w0}x{h0}"));
        }
        first = Some((w, h));
        let img = Rgb::new(&rgb, w, h).map_err(|e| format!("frame {idx}: {e}"))?;
        out.extend(scorer.push(img).map_err(|e| format!("frame {idx}: {e}"))?);
    }
    let n = job.frames.len();
    let last = scorer.finish().map_err(|_| {
        format!("{n} frame(s): a clip needs at least 2 to score (the SSIM pairs a frame with the next)")
    })?;
    out.push(last);
    Ok(out)
}

/// The model to score (the given one, checked, or the only one in the table) and the
/// episodes it translated.
fn resolve_model(ds: &Dataset, version: u64, wanted: Option<&str>) -> Result<(String, BTreeSet<String>)> {
    let mut models: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for b in ds.scan(TableKind::Imagined, version, Some(&["episode_id", "model_id"]))? {
        let b = b?;
        let (ids, m): (&StringArray, &StringArray) = (column(&b, "episode_id")?, column(&b, "model_id")?);
        for i in 0..b.num_rows() {
            models
                .entry(m.value(i).to_string())
                .or_default()
                .insert(ids.value(i).to_string());
        }
    }
    let names = || models.keys().cloned().collect::<Vec<_>>().join(", ");
    let model = match wanted {
        Some(w) if models.contains_key(w) => w.to_string(),
        Some(w) => {
            return Err(Error::Invalid(format!(
                "model {w} has no rows in the imagined table at version {version} (models: {})",
                names()
            )));
        }
        None if models.len() == 1 => models.keys().next().cloned().unwrap_or_default(),
        None => {
            return Err(Error::Invalid(format!(
                "the imagined table at version {version} holds {} models; choose one with --model-id: {}",
                models.len(),
                names()
            )));
        }
    };
    let eps = models.remove(&model).unwrap_or_default();
    Ok((model, eps))
}

/// Episodes of this run that earlier versions already scored.
fn already_scored(ds: &Dataset, version: u64, run_id: &str) -> Result<BTreeSet<String>> {
    let mut done = BTreeSet::new();
    for b in ds.scan(TableKind::Scores, version, Some(&["episode_id", "run_id"]))? {
        let b = b?;
        let (ids, runs): (&StringArray, &StringArray) = (column(&b, "episode_id")?, column(&b, "run_id")?);
        for i in 0..b.num_rows() {
            if runs.value(i) == run_id {
                done.insert(ids.value(i).to_string());
            }
        }
    }
    Ok(done)
}

/// Scores the selected episodes of `version` (default: latest) and commits a `scores`
/// version. `progress` is called with the number of frames scored since the last call.
pub fn score_dataset(
    ds: &Dataset,
    version: Option<u64>,
    opts: &RunOptions,
    mut meta: CommitMeta,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<RunReport> {
    let v = ds.resolve(version)?;
    let table = opts.source.table();
    if ds.files(table, v)?.is_empty() {
        return Err(Error::EmptySelection(format!(
            "{}@{v} has no {table} rows{}",
            ds.root().display(),
            if opts.source == Source::Imagined {
                " (translate human episodes with `milv-train translate` first)"
            } else {
                ""
            }
        )));
    }
    let episodes: BTreeMap<String, Episode> = ops::episodes(ds, v)?
        .into_iter()
        .map(|e| (e.episode_id.clone(), e))
        .collect();
    if let Some(ids) = &opts.episodes
        && let Some(missing) = ids.iter().find(|id| !episodes.contains_key(*id))
    {
        return Err(Error::Invalid(format!(
            "episode {missing} is not in {}@{v}",
            ds.root().display()
        )));
    }
    let (model_id, translated) = match opts.source {
        Source::Imagined => {
            let (m, eps) = resolve_model(ds, v, opts.model_id.as_deref())?;
            (Some(m), Some(eps))
        }
        Source::Frames => (None, None),
    };
    let selected: BTreeSet<String> = episodes
        .values()
        .filter(|e| opts.episodes.as_ref().is_none_or(|s| s.contains(&e.episode_id)))
        .filter(|e| opts.domain.as_ref().is_none_or(|d| *d == e.domain))
        .filter(|e| translated.as_ref().is_none_or(|t| t.contains(&e.episode_id)))
        .map(|e| e.episode_id.clone())
        .collect();
    if selected.is_empty() {
        return Err(Error::EmptySelection(format!(
            "no episode of {}@{v} matches (domain {:?}, {} episode id(s) given{})",
            ds.root().display(),
            opts.domain,
            opts.episodes.as_ref().map_or(0, BTreeSet::len),
            model_id
                .as_deref()
                .map(|m| format!(", translated by {m}"))
                .unwrap_or_default()
        )));
    }
    // The run is named by what it reads (the source table's data files, the model, the
    // selection), not by the version number, so re-running it on a later version that
    // left those files alone (e.g. after its own commit) finds it done.
    let source_files: Vec<String> = ds.files(table, v)?.into_iter().map(|f| f.info.path).collect();
    let mut parts = vec![
        "milv-score/run/1",
        table.name(),
        model_id.as_deref().unwrap_or("-"),
    ];
    parts.extend(source_files.iter().map(String::as_str));
    parts.push("|");
    parts.extend(selected.iter().map(String::as_str));
    let run_id = digest(&parts);
    let done = already_scored(ds, ds.latest_version()?, &run_id)?;
    let todo: BTreeSet<String> = selected
        .iter()
        .filter(|id| opts.partition.is_none_or(|p| p.contains_key(id)))
        .filter(|id| !done.contains(*id))
        .cloned()
        .collect();
    let mut report = RunReport {
        read_version: v,
        version: ds.latest_version()?,
        run_id: run_id.clone(),
        source: opts.source,
        model_id: model_id.clone(),
        episodes_scored: 0,
        frames_scored: 0,
        episodes_already_scored: selected.iter().filter(|id| done.contains(*id)).count(),
        brenner_min: None,
        brenner_max: None,
        beta_mean: None,
        failed: Vec::new(),
        weights_written: opts.partition.is_none(),
    };
    if todo.is_empty() {
        return Ok(report);
    }

    let (scored, failed) = score_episodes(ds, v, opts, &episodes, &todo, model_id.as_deref(), progress)?;
    report.failed = failed;
    if !report.failed.is_empty() && !opts.skip_bad {
        return Err(Error::Episodes(report.failed));
    }
    if scored.is_empty() {
        return Err(Error::EmptySelection(format!(
            "none of the {} selected episode(s) could be scored",
            todo.len()
        )));
    }
    let all: Vec<&FrameScore> = scored.iter().flat_map(|(_, s)| s).collect();
    let bmin = all
        .iter()
        .map(|s| s.brenner.normalized)
        .fold(f64::INFINITY, f64::min);
    let bmax = all
        .iter()
        .map(|s| s.brenner.normalized)
        .fold(f64::NEG_INFINITY, f64::max);
    report.brenner_min = Some(bmin);
    report.brenner_max = Some(bmax);
    report.beta_mean = Some(all.iter().map(|s| s.beta).sum::<f64>() / all.len() as f64);
    report.episodes_scored = scored.len();
    report.frames_scored = all.len() as u64;

    let params = serde_json::json!({
        "run_id": run_id, "source_table": table.name(), "model_id": model_id,
        "read_version": v, "brenner_min": bmin, "brenner_max": bmax,
        "partition": opts.partition.map(|p| p.to_string()),
        "weights": if report.weights_written { "set-normalised over this run" } else { "null: partitioned run, computed by curate" },
        "spec": "shared/spec/quality.md: brenner h+v, ssim gray, last frame reuses the last pair",
    });
    let shard = ShardOptions {
        file_metadata: vec![("milv.scores".into(), params.to_string())],
        ..ShardOptions::default()
    };
    meta.summary = serde_json::json!({
        "scores": params, "episodes": report.episodes_scored, "frames": report.frames_scored,
        "failed": report.failed.len(),
    });
    let mut txn = ds.begin(meta)?;
    let mut w = txn.shard_writer(TableKind::Scores, shard)?;
    let norm = report.weights_written.then_some((bmin, bmax));
    let mut ids = Vec::new();
    let written = (|| -> Result<()> {
        for (id, scores) in &scored {
            w.begin_episode()?;
            w.push(scores_batch(
                id,
                scores,
                table.name(),
                model_id.as_deref(),
                &run_id,
                norm,
            )?)?;
            w.end_episode()?;
            ids.push(id.clone());
        }
        Ok(())
    })();
    if let Err(e) = written {
        w.abort();
        txn.abort();
        return Err(e);
    }
    let files = w.finish()?;
    txn.add_files(TableKind::Scores, files, ids);
    report.version = txn.commit()?;
    Ok(report)
}

/// Reads the selected episodes and scores them on `opts.jobs` threads.
fn score_episodes(
    ds: &Dataset,
    v: u64,
    opts: &RunOptions,
    episodes: &BTreeMap<String, Episode>,
    todo: &BTreeSet<String>,
    model_id: Option<&str>,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<(Vec<Scored>, Vec<EpisodeError>)> {
    let table = opts.source.table();
    let mut cols = vec!["episode_id", "frame_index", "image"];
    if model_id.is_some() {
        cols.push("model_id");
    }
    let mut decoders = BTreeMap::new();
    for id in todo {
        let d = match opts.source {
            Source::Imagined => Decode::AnyPng,
            Source::Frames => {
                let e = &episodes[id];
                let enc = FrameEncoding::from_name(&e.frame_encoding).ok_or_else(|| {
                    Error::Invalid(format!(
                        "episode {id}: unknown frame encoding {:?}",
                        e.frame_encoding
                    ))
                })?;
                Decode::Stored {
                    enc,
                    w: e.width as u32,
                    h: e.height as u32,
                }
            }
        };
        decoders.insert(id.clone(), d);
    }
    let decoders = Arc::new(decoders);
    let scored: Mutex<Vec<Scored>> = Mutex::new(Vec::new());
    let failed: Mutex<Vec<EpisodeError>> = Mutex::new(Vec::new());
    let fail = |id: &str, message: String| {
        if let Ok(mut f) = failed.lock() {
            f.push(EpisodeError {
                episode_id: id.to_string(),
                message,
            });
        }
    };
    let jobs = opts.jobs.max(1);
    let (tx, rx) = crossbeam_channel::bounded::<Job>(jobs * 2);
    let read = std::thread::scope(|scope| -> Result<()> {
        for _ in 0..jobs {
            let rx = rx.clone();
            let decoders = Arc::clone(&decoders);
            let (scored, fail) = (&scored, &fail);
            scope.spawn(move || {
                let mut scorer = ClipScorer::new();
                for job in rx {
                    match score_episode(&job, decoders[&job.episode_id], &mut scorer) {
                        Ok(s) => {
                            progress(s.len() as u64);
                            if let Ok(mut v) = scored.lock() {
                                v.push((job.episode_id, s));
                            }
                        }
                        Err(m) => {
                            // A failed clip leaves the scorer mid-clip; start the next clean.
                            scorer = ClipScorer::new();
                            fail(&job.episode_id, m);
                        }
                    }
                }
            });
        }
        drop(rx);
        let mut cur: Option<Job> = None;
        let mut seen: BTreeSet<String> = BTreeSet::new();
        let send = |job: Job| {
            tx.send(job)
                .map_err(|_| Error::Invalid("scoring workers stopped".into()))
        };
        for batch in ds.scan(table, v, Some(&cols))? {
            let b = batch?;
            let ids: &StringArray = column(&b, "episode_id")?;
            let idx: &Int32Array = column(&b, "frame_index")?;
            let img: &BinaryArray = column(&b, "image")?;
            let models: Option<&StringArray> = match model_id {
                Some(_) => Some(column(&b, "model_id")?),
                None => None,
            };
            for i in 0..b.num_rows() {
                let id = ids.value(i);
                if !todo.contains(id) || models.is_some_and(|m| Some(m.value(i)) != model_id) {
                    continue;
                }
                if cur.as_ref().is_none_or(|c| c.episode_id != id) {
                    if let Some(done) = cur.take() {
                        send(done)?;
                    }
                    if !seen.insert(id.to_string()) {
                        fail(id, "its rows are split across files or interleaved with other episodes; run `milv-ds compact`".into());
                        continue;
                    }
                    cur = Some(Job {
                        episode_id: id.to_string(),
                        frames: Vec::new(),
                    });
                }
                if let Some(c) = cur.as_mut() {
                    c.frames.push((idx.value(i), img.value(i).to_vec()));
                }
            }
        }
        if let Some(done) = cur.take() {
            send(done)?;
        }
        drop(tx);
        for id in todo.difference(&seen) {
            fail(id, format!("no rows in the {table} table at version {v}"));
        }
        Ok(())
    });
    read?;
    let mut scored = scored
        .into_inner()
        .map_err(|_| Error::Invalid("a scoring worker panicked".into()))?;
    let mut failed = failed
        .into_inner()
        .map_err(|_| Error::Invalid("a scoring worker panicked".into()))?;
    // A split episode may have been scored from its first part: drop it.
    let bad: BTreeSet<String> = failed.iter().map(|f| f.episode_id.clone()).collect();
    scored.retain(|(id, _)| !bad.contains(id));
    scored.sort_by(|a, b| a.0.cmp(&b.0));
    failed.sort_by(|a, b| a.episode_id.cmp(&b.episode_id));
    failed.dedup_by(|a, b| a.episode_id == b.episode_id);
    Ok((scored, failed))
}

fn scores_batch(
    id: &str,
    s: &[FrameScore],
    table: &str,
    model_id: Option<&str>,
    run_id: &str,
    norm: Option<(f64, f64)>,
) -> Result<RecordBatch> {
    let n = s.len();
    let f64s = |f: &dyn Fn(&FrameScore) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(s.iter().map(f)))
    };
    let weight: Float64Array = s
        .iter()
        .map(|f| norm.map(|(lo, hi)| crate::curate::weight(f.brenner.normalized, f.ssim, lo, hi)))
        .collect();
    let cols: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(vec![id; n])),
        Arc::new(Int32Array::from_iter_values(0..n as i32)),
        Arc::new(StringArray::from(vec![table; n])),
        Arc::new(StringArray::from(vec![model_id; n])),
        Arc::new(StringArray::from(vec![run_id; n])),
        f64s(&|f| f.brenner.raw),
        f64s(&|f| f.brenner.normalized),
        f64s(&|f| f.ssim),
        f64s(&|f| f.beta),
        Arc::new(weight),
    ];
    Ok(RecordBatch::try_new(TableKind::Scores.arrow_schema(), cols)?)
}

pub use milv_data::read::{ScoreRow, score_run as read_run};
