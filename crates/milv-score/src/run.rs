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

use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::read::stream_images;
use milv_data::{CommitMeta, Dataset, Domain, Episode, Partition, ScoreRow, ShardOptions, TableKind, ops};
use milv_quality::{ClipScorer, FrameScore, Rgb, set_weight};
use serde::Serialize;

use crate::{EpisodeError, Error, Result, digest};

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
    /// Only episodes of this domain.
    pub domain: Option<Domain>,
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
            let (m, eps) = milv_data::resolve_model(ds, v, opts.model_id.as_deref())?.ok_or_else(|| {
                Error::EmptySelection(format!("{}@{v} has no imagined rows", ds.root().display()))
            })?;
            (Some(m), Some(eps))
        }
        Source::Frames => (None, None),
    };
    let selected: BTreeSet<String> = episodes
        .values()
        .filter(|e| opts.episodes.as_ref().is_none_or(|s| s.contains(&e.episode_id)))
        .filter(|e| opts.domain.is_none_or(|d| d == e.domain))
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
    let done = milv_data::run_groups(ds, ds.latest_version()?, TableKind::Scores, &run_id)?;
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
    let norm = report.weights_written.then_some((bmin, bmax));
    report.version =
        ds.begin(meta)?
            .write_and_commit(TableKind::Scores, Some(&run_id), shard, |w| -> Result<()> {
                for (id, scores) in &scored {
                    w.group(
                        id,
                        &score_rows(id, scores, table, model_id.as_deref(), &run_id, norm),
                    )?;
                }
                Ok(())
            })?;
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
    let mut decoders = BTreeMap::new();
    for id in todo {
        let d = match opts.source {
            Source::Imagined => Decode::AnyPng,
            Source::Frames => {
                let e = &episodes[id];
                Decode::Stored {
                    enc: e.frame_encoding,
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
        for row in stream_images(ds, v, table, model_id, &|id| todo.contains(id))? {
            let row = row?;
            let id = row.episode_id.as_str();
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
                c.frames.push((row.frame_index, row.image));
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

/// The `scores` rows of one scored episode; weights set-normalised over the run when the
/// run is not partitioned (`norm`: its Brenner minimum and maximum).
fn score_rows(
    id: &str,
    s: &[FrameScore],
    table: TableKind,
    model_id: Option<&str>,
    run_id: &str,
    norm: Option<(f64, f64)>,
) -> Vec<ScoreRow> {
    s.iter()
        .enumerate()
        .map(|(k, f)| ScoreRow {
            episode_id: id.to_string(),
            frame_index: k as i32,
            source_table: table.name().to_string(),
            model_id: model_id.map(str::to_string),
            run_id: run_id.to_string(),
            brenner_raw: f.brenner.raw,
            brenner: f.brenner.normalized,
            ssim: f.ssim,
            beta: f.beta,
            weight: norm.map(|(lo, hi)| set_weight(f.brenner.normalized, f.ssim, lo, hi)),
        })
        .collect()
}
