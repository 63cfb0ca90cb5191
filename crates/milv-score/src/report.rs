//! `milv-score report`: what a scoring run says about the data, for people and scripts.

use std::collections::BTreeMap;

use milv_data::{Dataset, ScoreRow, score_run};
use serde::Serialize;

use crate::Result;

#[derive(Clone, Debug, Serialize)]
pub struct EpisodeSummary {
    pub episode_id: String,
    pub frames: usize,
    pub beta_mean: f64,
    pub beta_min: f64,
    /// Frame with the lowest β.
    pub worst_frame: i32,
    pub ssim_mean: f64,
    pub brenner_mean: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct WorstFrame {
    pub episode_id: String,
    pub frame_index: i32,
    pub beta: f64,
    pub brenner: f64,
    pub ssim: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub version: u64,
    pub run_id: String,
    pub source_table: String,
    pub model_id: Option<String>,
    pub frames: usize,
    pub beta_mean: f64,
    pub beta_min: f64,
    pub beta_max: f64,
    pub brenner_min: f64,
    pub brenner_max: f64,
    /// Worst episode (lowest mean β) first.
    pub episodes: Vec<EpisodeSummary>,
    pub worst_frames: Vec<WorstFrame>,
    /// Every frame's β, per episode in frame order (for the plots).
    #[serde(skip)]
    pub curves: BTreeMap<String, Vec<f64>>,
}

/// Summarises scoring run `run_id` (default: the newest) at `version` (default: latest).
pub fn summarize(ds: &Dataset, version: Option<u64>, run_id: Option<&str>, worst: usize) -> Result<Summary> {
    let v = ds.resolve(version)?;
    let (run_id, rows) = score_run(ds, v, run_id)?;
    let mut by_ep: BTreeMap<String, Vec<&ScoreRow>> = BTreeMap::new();
    for r in &rows {
        by_ep.entry(r.episode_id.clone()).or_default().push(r);
    }
    let mean = |it: &mut dyn Iterator<Item = f64>| {
        let (s, n) = it.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
        s / n.max(1) as f64
    };
    let mut episodes: Vec<EpisodeSummary> = by_ep
        .iter()
        .map(|(id, fr)| {
            let w = fr.iter().min_by(|a, b| a.beta.total_cmp(&b.beta));
            EpisodeSummary {
                episode_id: id.clone(),
                frames: fr.len(),
                beta_mean: mean(&mut fr.iter().map(|r| r.beta)),
                beta_min: w.map_or(f64::NAN, |r| r.beta),
                worst_frame: w.map_or(-1, |r| r.frame_index),
                ssim_mean: mean(&mut fr.iter().map(|r| r.ssim)),
                brenner_mean: mean(&mut fr.iter().map(|r| r.brenner)),
            }
        })
        .collect();
    episodes.sort_by(|a, b| a.beta_mean.total_cmp(&b.beta_mean));
    let mut sorted: Vec<&ScoreRow> = rows.iter().collect();
    sorted.sort_by(|a, b| a.beta.total_cmp(&b.beta));
    let worst_frames = sorted
        .iter()
        .take(worst)
        .map(|r| WorstFrame {
            episode_id: r.episode_id.clone(),
            frame_index: r.frame_index,
            beta: r.beta,
            brenner: r.brenner,
            ssim: r.ssim,
        })
        .collect();
    let fold =
        |f: fn(&ScoreRow) -> f64, init: f64, op: fn(f64, f64) -> f64| rows.iter().map(f).fold(init, op);
    Ok(Summary {
        version: v,
        run_id,
        source_table: rows[0].source_table.clone(),
        model_id: rows[0].model_id.clone(),
        frames: rows.len(),
        beta_mean: mean(&mut rows.iter().map(|r| r.beta)),
        beta_min: fold(|r| r.beta, f64::INFINITY, f64::min),
        beta_max: fold(|r| r.beta, f64::NEG_INFINITY, f64::max),
        brenner_min: fold(|r| r.brenner, f64::INFINITY, f64::min),
        brenner_max: fold(|r| r.brenner, f64::NEG_INFINITY, f64::max),
        episodes,
        worst_frames,
        curves: by_ep
            .into_iter()
            .map(|(id, fr)| (id, fr.iter().map(|r| r.beta).collect()))
            .collect(),
    })
}
