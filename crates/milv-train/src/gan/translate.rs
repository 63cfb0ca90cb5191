//! Human episodes into imagined robot data (paper section 4.1): for every frame x^h,
//! the imagined frame ŷ^r = G(x^h), its latent ẑ^r = E_F(ŷ^r) from F's encoder and the
//! imagined action â^r_t = π_I(ŷ^r_t, ŷ^r_t+1) read through π_I's encoder (F's when
//! coupled, its own when decoupled; the last frame gets π_I(ŷ_T, ŷ_T), the model's action
//! for "no change"), committed as the `imagined` table of one model.
//!
//! Episodes stream one at a time through chunks of frames, so memory stays bounded by
//! one episode's encoded frames and one chunk of tensors.

use std::collections::{BTreeMap, BTreeSet};

use milv_data::{
    CommitMeta, Dataset, Episode, ImaginedRow, ImaginedRows, Partition, ShardOptions, TableKind, ops,
};
use serde::Serialize;
use tch::nn::Module;
use tch::{Kind, Tensor};

use crate::gan::config::ModelConfig;
use crate::gan::cyclegan::{ACycleGan, Nets};
use crate::run::image::load_clips;
use crate::run::image::to_rgb;
use crate::{Error, Result};

/// How latents are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LatentDtype {
    F16,
    F32,
}

impl std::str::FromStr for LatentDtype {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "f16" => Ok(LatentDtype::F16),
            "f32" => Ok(LatentDtype::F32),
            _ => Err(format!("unknown latent dtype {s:?} (f16 | f32)")),
        }
    }
}

impl LatentDtype {
    pub fn name(self) -> &'static str {
        match self {
            LatentDtype::F16 => "f16",
            LatentDtype::F32 => "f32",
        }
    }

    fn kind(self) -> Kind {
        match self {
            LatentDtype::F16 => Kind::Half,
            LatentDtype::F32 => Kind::Float,
        }
    }
}

#[derive(Clone, Debug)]
pub struct TranslateOptions {
    /// Frames per forward pass.
    pub chunk: usize,
    pub latent: LatentDtype,
    /// Only these episodes (default: every human episode).
    pub episodes: Option<BTreeSet<String>>,
    pub partition: Option<Partition>,
}

impl Default for TranslateOptions {
    fn default() -> Self {
        TranslateOptions {
            chunk: 8,
            latent: LatentDtype::F16,
            episodes: None,
            partition: None,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct TranslateReport {
    pub read_version: u64,
    /// The new version, or the read one when there was nothing to do.
    pub version: u64,
    pub model_id: String,
    pub episodes: usize,
    pub frames: u64,
    /// Episodes this model had already translated at the read version.
    pub already_done: usize,
    pub latent_dtype: LatentDtype,
    pub latent_shape: [i64; 3],
}

/// Translates the selected human episodes of version `version` (default latest) and
/// commits their rows; a re-run with the same model is a no-op.
pub fn translate(
    ds: &Dataset,
    version: Option<u64>,
    run: &ACycleGan,
    model_id: &str,
    opts: &TranslateOptions,
    mut meta: CommitMeta,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<TranslateReport> {
    let (nets, cfg) = (&run.nets, &run.model);
    let v = ds.resolve(version)?;
    let eps = ops::episodes(ds, v)?;
    if let Some(want) = &opts.episodes
        && let Some(missing) = want.iter().find(|id| !eps.iter().any(|e| &e.episode_id == *id))
    {
        return Err(Error::Data(format!("no episode {missing} at version {v}")));
    }
    let done = milv_data::run_groups(ds, v, TableKind::Imagined, model_id)?;
    let todo: Vec<&Episode> = eps
        .iter()
        .filter(|e| e.domain == milv_data::Domain::Human)
        .filter(|e| opts.episodes.as_ref().is_none_or(|w| w.contains(&e.episode_id)))
        .filter(|e| opts.partition.is_none_or(|p| p.contains_key(&e.episode_id)))
        .collect();
    if todo.is_empty() {
        return Err(Error::Data(format!(
            "no human episodes to translate at version {v}"
        )));
    }
    let fresh: Vec<&Episode> = todo
        .iter()
        .copied()
        .filter(|e| !done.contains(&e.episode_id))
        .collect();
    let mut report = TranslateReport {
        read_version: v,
        version: v,
        model_id: model_id.into(),
        episodes: 0,
        frames: 0,
        already_done: todo.len() - fresh.len(),
        latent_dtype: opts.latent,
        latent_shape: cfg.latent_shape(),
    };
    if fresh.is_empty() {
        return Ok(report);
    }
    meta.summary = serde_json::json!({
        "model_id": model_id, "read_version": v, "episodes": fresh.len(),
        "latent_dtype": opts.latent.name(), "latent_shape": cfg.latent_shape(),
        // Exporters attach this, so a recording names the nets that made it.
        "model_config": cfg, "decoupled": run.train.decoupled,
    });
    report.version = ds.begin(meta)?.write_and_commit(
        TableKind::Imagined,
        Some(model_id),
        ShardOptions::default(),
        |w| -> Result<()> {
            for (k, e) in fresh.iter().enumerate() {
                let one: BTreeMap<String, Episode> = [(e.episode_id.clone(), (*e).clone())].into();
                let clip = load_clips(ds, v, &one, false)?
                    .remove(&e.episode_id)
                    .ok_or_else(|| {
                        Error::Data(format!("episode {} has no frames at version {v}", e.episode_id))
                    })?;
                if !w.begin(&e.episode_id)? {
                    continue; // translated meanwhile by another worker of this model
                }
                report.frames += translate_clip(nets, cfg, model_id, opts, &clip, &mut |rows| {
                    w.push(rows)?;
                    Ok(())
                })?;
                w.end()?;
                report.episodes += 1;
                progress(k + 1, fresh.len());
            }
            Ok(())
        },
    )?;
    Ok(report)
}

/// Translates one clip chunk by chunk, handing each chunk's rows to `emit`; returns the
/// number of frames.
fn translate_clip(
    nets: &Nets,
    cfg: &ModelConfig,
    model_id: &str,
    opts: &TranslateOptions,
    clip: &crate::run::Clip,
    emit: &mut dyn FnMut(&mut ImaginedRows) -> Result<()>,
) -> Result<u64> {
    let size = cfg.image_size as u32;
    let n = clip.frames.len();
    let dev = nets.vs_g.device();
    let shape: Vec<i32> = cfg.latent_shape().iter().map(|&d| d as i32).collect();
    // Each chunk needs the latent of the next chunk's first frame for its last action, so
    // chunks are translated one ahead.
    // π_I reads the latents of its own encoder: F's when coupled, its own when decoupled
    // (DeGI), exactly as in training ([`Nets::predict_action`]).
    let run_chunk = |range: std::ops::Range<usize>| -> Result<(Tensor, Tensor, Tensor)> {
        let mut data = Vec::with_capacity(range.len() * 3 * (size * size) as usize);
        for t in range.clone() {
            data.extend(clip.tensor_data(t, size)?);
        }
        let x = Tensor::from_slice(&data)
            .view([range.len() as i64, 3, cfg.image_size, cfg.image_size])
            .to_device(dev);
        Ok(tch::no_grad(|| {
            let y = nets.g.forward(&x);
            let z = nets.f.encode(&y);
            let zi = match &nets.idm_encoder {
                Some(e) => e.forward(&y),
                None => z.shallow_clone(),
            };
            (y, z, zi)
        }))
    };
    let chunk = opts.chunk.max(1);
    let starts: Vec<usize> = (0..n).step_by(chunk).collect();
    let mut cur = run_chunk(0..chunk.min(n))?;
    let mut rows = ImaginedRows::new();
    for (ci, &start) in starts.iter().enumerate() {
        let end = (start + chunk).min(n);
        let next = match starts.get(ci + 1) {
            Some(&s) => Some(run_chunk(s..(s + chunk).min(n))?),
            None => None,
        };
        let (y, z, zi) = &cur;
        // π_I's latent of t+1 for every frame of the chunk: the chunk shifted by one, then
        // the next chunk's first latent (or the last latent again at the end of the clip).
        let tail = match &next {
            Some((_, _, zn)) => zn.narrow(0, 0, 1),
            None => zi.narrow(0, zi.size()[0] - 1, 1),
        };
        let z_next = Tensor::cat(&[zi.narrow(0, 1, zi.size()[0] - 1), tail], 0);
        let actions = tch::no_grad(|| nets.idm.forward(zi, &z_next)).to_kind(Kind::Float);
        let actions: Vec<f32> = Vec::try_from(actions.to_device(tch::Device::Cpu).contiguous().view([-1]))?;
        let latents = z
            .to_kind(opts.latent.kind())
            .to_device(tch::Device::Cpu)
            .contiguous();
        let per = latents.numel() / (end - start);
        let elt = opts.latent.kind().elt_size_in_bytes();
        let mut bytes = vec![0u8; latents.numel() * elt];
        latents.f_copy_data_u8(&mut bytes, latents.numel())?;
        let d = cfg.action_dim as usize;
        for (k, t) in (start..end).enumerate() {
            let rgb = to_rgb(&y.get(k as i64))?;
            let mut png = Vec::new();
            milv_data::frame_codec::encode(
                milv_data::frame_codec::FrameEncoding::Png,
                &rgb,
                size,
                size,
                &mut png,
            )
            .map_err(|e| Error::Data(format!("episode {}: frame {t}: {e}", clip.episode_id)))?;
            rows.push(&ImaginedRow {
                episode_id: &clip.episode_id,
                frame_index: t as i32,
                timestamp_ns: clip.timestamps[t],
                model_id,
                image: &png,
                latent: Some((
                    &bytes[k * per * elt..(k + 1) * per * elt],
                    opts.latent.name(),
                    &shape,
                )),
                action: Some(&actions[k * d..(k + 1) * d]),
            });
        }
        emit(&mut rows)?;
        match next {
            Some(nx) => cur = nx,
            None => break,
        }
    }
    Ok(n as u64)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use milv_data::frame_codec::{FrameEncoding, encode};
    use milv_data::{ImaginedRecord, Row, RowBuffer as _};

    /// The stored actions are π_I's on consecutive translated frames, through the encoder
    /// π_I trained on — for a decoupled model its own, not F's.
    #[test]
    fn imagined_actions_are_pi_i_on_consecutive_translations_coupled_or_not() {
        let _serial = crate::testing::torch_rng();
        let cfg = ModelConfig::tiny(32);
        for decoupled in [false, true] {
            let nets = Nets::new(&cfg, decoupled, tch::Device::Cpu);
            let n = 5usize;
            let rgbs: Vec<Vec<u8>> = (0..n)
                .map(|i| (0..32 * 32 * 3).map(|k| ((k * 7 + i * 53) % 251) as u8).collect())
                .collect();
            let frames = rgbs
                .iter()
                .map(|f| {
                    let mut png = Vec::new();
                    encode(FrameEncoding::Png, f, 32, 32, &mut png).unwrap();
                    png
                })
                .collect();
            let clip = crate::run::Clip {
                episode_id: "e".into(),
                encoding: FrameEncoding::Png,
                width: 32,
                height: 32,
                frames,
                timestamps: (0..n as i64).collect(),
                actions: None,
            };
            let opts = TranslateOptions {
                chunk: 2,
                ..TranslateOptions::default()
            };
            let mut got: Vec<f32> = Vec::new();
            translate_clip(&nets, &cfg, "m", &opts, &clip, &mut |rows| {
                for r in ImaginedRecord::from_batch(&rows.finish()?)? {
                    got.extend(r.action.unwrap());
                }
                Ok(())
            })
            .unwrap();
            let data: Vec<f32> = (0..n).flat_map(|t| clip.tensor_data(t, 32).unwrap()).collect();
            let x = Tensor::from_slice(&data).view([n as i64, 3, 32, 32]);
            let want = tch::no_grad(|| {
                let y = nets.g.forward(&x);
                let next = Tensor::cat(&[y.narrow(0, 1, n as i64 - 1), y.narrow(0, n as i64 - 1, 1)], 0);
                nets.predict_action(&y, &next)
            });
            let want: Vec<f32> = Vec::try_from(want.contiguous().view([-1])).unwrap();
            assert_eq!(got.len(), want.len());
            let err = got
                .iter()
                .zip(&want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(err < 1e-5, "decoupled {decoupled}: actions differ by {err}");
        }
    }
}
