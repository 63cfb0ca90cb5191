//! How good a translation model is, on data it did not train on:
//! - SSIM (grey, `shared/spec/quality.md`) of G(x^h) against the ground-truth robot
//!   rendering of the same human frame (milv-sim's `ground_truth.jsonl` pairs each human
//!   demo with the robot demo of the same states, frame by frame);
//! - π_I's action error on held-out robot random videos (`split ≠ train`), next to the
//!   error of always predicting no motion, so the number has a scale.

use std::collections::BTreeMap;
use std::path::Path;

use milv_data::{Dataset, Domain, Episode, Kind as EpisodeKind, Split, ops};
use milv_quality::{Rgb, SsimMode, ssim};
use serde::Serialize;
use tch::nn::Module;
use tch::{Kind, Tensor};

use crate::gan::config::ModelConfig;
use crate::gan::cyclegan::Nets;
use crate::run::fit::{ActionFit, FitAccumulator};
use crate::run::image::to_rgb;
use crate::run::image::{Clip, load_clips, to_chw};
use crate::{Error, Result};

/// Frames translated per forward pass.
const CHUNK: usize = 8;

pub struct EvalSet {
    /// (human demo, its ground-truth robot rendering).
    pub pairs: Vec<(Clip, Clip)>,
    /// Robot random videos with actions, held out of training.
    pub held_out: Vec<Clip>,
}

fn file_name(uri: &str) -> &str {
    uri.rsplit(['/', '\\']).next().unwrap_or(uri)
}

/// The (human demo, ground-truth robot demo) episode pairs a truth file names:
/// JSON lines `{"human": FILE, "robot": FILE}` naming source videos, relative to the truth
/// file's folder (as milv-sim writes them), matched against the episodes' `source_uri`; the
/// bare file name is enough when only one episode has it. Entries naming no episode of
/// `eps` are skipped (a truth file may cover several datasets).
pub fn truth_pairs(eps: &[Episode], path: &Path) -> Result<Vec<(String, String)>> {
    let by_uri: BTreeMap<&str, &Episode> = eps.iter().map(|e| (e.source_uri.as_str(), e)).collect();
    let mut by_file: BTreeMap<&str, Vec<&Episode>> = BTreeMap::new();
    for e in eps {
        by_file.entry(file_name(&e.source_uri)).or_default().push(e);
    }
    let find = |base: &Path, f: &str| -> Option<&Episode> {
        let full = base.join(f);
        let canon = std::fs::canonicalize(&full).unwrap_or_else(|_| full.clone());
        let uri = |p: &Path| by_uri.get(p.to_string_lossy().as_ref()).copied();
        uri(&full)
            .or_else(|| uri(&canon))
            .or_else(|| match by_file.get(file_name(f)) {
                Some(v) if v.len() == 1 => Some(v[0]),
                _ => None,
            })
    };
    let text = std::fs::read_to_string(path).map_err(Error::io("read", path))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut pairs = Vec::new();
    for (k, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let j: serde_json::Value = serde_json::from_str(line)
            .map_err(|e| Error::Data(format!("{}:{}: {e}", path.display(), k + 1)))?;
        let (Some(h), Some(r)) = (j["human"].as_str(), j["robot"].as_str()) else {
            return Err(Error::Data(format!(
                "{}:{}: expected {{\"human\": FILE, \"robot\": FILE}}",
                path.display(),
                k + 1
            )));
        };
        if let (Some(he), Some(re)) = (find(base, h), find(base, r)) {
            pairs.push((he.episode_id.clone(), re.episode_id.clone()));
        }
    }
    Ok(pairs)
}

impl EvalSet {
    /// `truth`: see [`truth_pairs`]; held-out pairs first, at most `max_pairs`.
    pub fn load(ds: &Dataset, v: u64, truth: Option<&Path>, max_pairs: usize) -> Result<EvalSet> {
        let eps = ops::episodes(ds, v)?;
        let mut wanted_pairs = match truth {
            Some(path) => truth_pairs(&eps, path)?,
            None => Vec::new(),
        };
        // Held-out tasks first: they say most about generalisation.
        wanted_pairs.sort_by_key(|(h, _)| eps.iter().any(|e| &e.episode_id == h && e.split == Split::Train));
        wanted_pairs.truncate(max_pairs);
        let pick = |ids: Vec<&String>| -> BTreeMap<String, Episode> {
            eps.iter()
                .filter(|e| ids.contains(&&e.episode_id))
                .map(|e| (e.episode_id.clone(), e.clone()))
                .collect()
        };
        let mut humans = load_clips(ds, v, &pick(wanted_pairs.iter().map(|(h, _)| h).collect()), false)?;
        // The robot demos with their actions: π_I is measured on them, and on the
        // translated human demos against them.
        let robots = load_clips(ds, v, &pick(wanted_pairs.iter().map(|(_, r)| r).collect()), true)?;
        let pairs = wanted_pairs
            .iter()
            .filter_map(|(h, r)| Some((humans.remove(h)?, robots.get(r)?.clone())))
            .collect();
        let held: BTreeMap<String, Episode> = eps
            .iter()
            .filter(|e| {
                e.domain == Domain::Robot
                    && e.kind == EpisodeKind::Random
                    && e.split != Split::Train
                    && e.action_dim.unwrap_or(0) > 0
            })
            .map(|e| (e.episode_id.clone(), e.clone()))
            .collect();
        let held_out = load_clips(ds, v, &held, true)?
            .into_values()
            .filter(|c| c.frames.len() >= 2)
            .collect();
        Ok(EvalSet { pairs, held_out })
    }
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct EvalReport {
    pub step: u64,
    /// Mean SSIM(G(x^h), ground truth) over all compared frames.
    pub ssim: Option<f64>,
    /// The same for the human frames themselves (the untranslated baseline).
    pub ssim_untranslated: Option<f64>,
    pub ssim_frames: usize,
    pub ssim_episodes: usize,
    /// Mean absolute error of π_I's actions (per component, action units).
    pub action_mae: Option<f64>,
    pub action_rmse: Option<f64>,
    /// Mean absolute action (the error of always predicting 0).
    pub action_mae_zero: Option<f64>,
    pub action_frames: usize,
    /// π_I on the ground-truth robot demos of the pairs (mostly held-out tasks).
    pub robot_demo_fit: Option<ActionFit>,
    /// π_I on consecutive translations G(x^h_t), G(x^h_t+1) of the human demos — the
    /// imagined actions the meta-policies train on — against the true robot actions.
    pub translated_fit: Option<ActionFit>,
}

/// Evaluates `nets` on `set` (no gradients).
pub fn evaluate_translation(nets: &Nets, set: &EvalSet, cfg: &ModelConfig) -> Result<EvalReport> {
    let size = cfg.image_size as u32;
    let dev = nets.vs_g.device();
    let batch = |c: &Clip, range: std::ops::Range<usize>| -> Result<Tensor> {
        let mut data = Vec::new();
        for t in range.clone() {
            data.extend(c.tensor_data(t, size)?);
        }
        Ok(Tensor::from_slice(&data)
            .view([range.len() as i64, 3, cfg.image_size, cfg.image_size])
            .to_device(dev))
    };
    let mut rep = EvalReport::default();
    let (mut sum, mut sum_raw) = (0.0, 0.0);
    let d = cfg.action_dim as usize;
    let predict = |a: &Tensor, b: &Tensor| -> Result<Vec<f32>> {
        let pred = tch::no_grad(|| nets.predict_action(a, b)).to_kind(Kind::Float);
        Ok(Vec::try_from(
            pred.to_device(tch::Device::Cpu).contiguous().view([-1]),
        )?)
    };
    let (mut on_robot, mut on_translated) = (FitAccumulator::new(d), FitAccumulator::new(d));
    for (h, r) in &set.pairs {
        let n = h.frames.len().min(r.frames.len());
        let mut fakes = Vec::new();
        for start in (0..n).step_by(CHUNK) {
            let range = start..(start + CHUNK).min(n);
            let x = batch(h, range.clone())?;
            let fake = tch::no_grad(|| nets.g.forward(&x));
            fakes.push(fake.shallow_clone());
            for (k, t) in range.enumerate() {
                let ours = to_rgb(&fake.get(k as i64))?;
                let truth = to_rgb(
                    &Tensor::from_slice(&to_chw(&r.rgb(t)?, r.width, r.height, size)).view([
                        3,
                        cfg.image_size,
                        cfg.image_size,
                    ]),
                )?;
                let raw = to_rgb(&x.get(k as i64))?;
                let s = size as usize;
                let score = |a: &[u8]| -> Result<f64> {
                    let bad = |e: milv_quality::Error| Error::Data(e.to_string());
                    ssim(
                        Rgb::new(a, s, s).map_err(bad)?,
                        Rgb::new(&truth, s, s).map_err(bad)?,
                        SsimMode::Gray,
                    )
                    .map_err(bad)
                };
                sum += score(&ours)?;
                sum_raw += score(&raw)?;
                rep.ssim_frames += 1;
            }
        }
        rep.ssim_episodes += 1;
        // Action t moves frame t to t+1: compare it with π_I on both kinds of frame pair.
        let Some(actions) = &r.actions else { continue };
        let translated = Tensor::cat(&fakes, 0);
        for start in (0..n.saturating_sub(1)).step_by(CHUNK) {
            let range = start..(start + CHUNK).min(n - 1);
            let len = range.len() as i64;
            let on_fakes = predict(
                &translated.narrow(0, start as i64, len),
                &translated.narrow(0, start as i64 + 1, len),
            )?;
            let on_real = predict(
                &batch(r, range.clone())?,
                &batch(r, range.start + 1..range.end + 1)?,
            )?;
            for (k, t) in range.enumerate() {
                on_translated.push(&on_fakes[k * d..(k + 1) * d], &actions[t]);
                on_robot.push(&on_real[k * d..(k + 1) * d], &actions[t]);
            }
        }
    }
    rep.robot_demo_fit = on_robot.finish();
    rep.translated_fit = on_translated.finish();
    if rep.ssim_frames > 0 {
        rep.ssim = Some(sum / rep.ssim_frames as f64);
        rep.ssim_untranslated = Some(sum_raw / rep.ssim_frames as f64);
    }
    let (mut abs, mut sq, mut zero, mut count) = (0.0, 0.0, 0.0, 0usize);
    for c in &set.held_out {
        let Some(actions) = &c.actions else { continue };
        let n = c.frames.len();
        for start in (0..n - 1).step_by(CHUNK) {
            let range = start..(start + CHUNK).min(n - 1);
            let p = predict(
                &batch(c, range.clone())?,
                &batch(c, range.start + 1..range.end + 1)?,
            )?;
            for (k, t) in range.enumerate() {
                for j in 0..d.min(actions[t].len()) {
                    let e = f64::from(p[k * d + j] - actions[t][j]);
                    abs += e.abs();
                    sq += e * e;
                    zero += f64::from(actions[t][j]).abs();
                    count += 1;
                }
            }
        }
        rep.action_frames += n - 1;
    }
    if count > 0 {
        rep.action_mae = Some(abs / count as f64);
        rep.action_rmse = Some((sq / count as f64).sqrt());
        rep.action_mae_zero = Some(zero / count as f64);
    }
    Ok(rep)
}
