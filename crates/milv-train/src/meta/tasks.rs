//! What a meta-policy trains on, from one pinned dataset version, grouped by task.
//!
//! | variant | inner sequence (no actions) | outer sequence (actions, weights) |
//! |---|---|---|
//! | `daml` | a human demo's frames | a robot demo of the same task: frames, true actions, weight 1 |
//! | `milv`, `degi` | a human demo's imagined latents ẑ^r | another human demo of the task: latents, predicted actions â^r, curated weights |
//! | `wstable` | as `milv` | as `milv`, weight 1 |
//! | `feedimg` | a human demo's translated frames ŷ^r | another human demo: translated frames, â^r, curated weights |
//!
//! With [`MetaDataOptions::true_actions`] an imagined-data variant's outer actions are the
//! true robot actions of each human demo's ground-truth robot demo instead of π_I's â^r
//! (the ladder's R6: imagined inputs, true targets, so the translation's images and its
//! inverse dynamics are measured apart).
//!
//! Only `split = train`, `kind = demo` episodes are read. A task with a single human demo
//! uses it for both sides. Sequences are held in memory as f32 tensors on the CPU and
//! moved to the device per meta-batch.

use std::collections::{BTreeMap, BTreeSet};

use milv_data::view::{EpisodeView, Image, ViewOptions, ViewPlan};
use milv_data::{Dataset, Domain, Episode, Kind as EpisodeKind, Split, ops};
use rand::{Rng, SeedableRng, rngs::StdRng};
use tch::{Device, Tensor};

use crate::gan::eval::truth_pairs;
use crate::meta::policy::{Input, MetaTask, Variant, standardised_states};
use crate::run::image::{load_clips, to_chw};
use crate::{Error, Result};

/// One episode as the policy sees it.
pub struct Sequence {
    pub episode_id: String,
    /// `[T, C, H, W]` f32.
    pub frames: Tensor,
    /// `[T, A]` in cm (outer sequences).
    pub actions: Option<Tensor>,
    /// `[T]` loss weights.
    pub weights: Tensor,
    /// `[T, S]` robot state, standardised with [`MetaSet::state_norm`] (outer sequences,
    /// `--state` only).
    pub states: Option<Tensor>,
}

/// The sequences of one task: indices into [`MetaSet::seqs`].
#[derive(Clone, Debug, Default)]
pub struct TaskSeqs {
    pub inner: Vec<usize>,
    pub outer: Vec<usize>,
}

pub struct MetaSet {
    pub version: u64,
    pub variant: Variant,
    pub seqs: Vec<Sequence>,
    pub tasks: BTreeMap<String, TaskSeqs>,
    /// One observation's shape.
    pub input_shape: [i64; 3],
    pub action_dim: i64,
    /// Task families present (`drawing`, `pushing`).
    pub families: Vec<String>,
    /// Hash of the files and selection read: a resumed run checks it.
    pub digest: String,
    /// Frames with weight 0 (dropped by curation) among the outer sequences.
    pub zero_weight_frames: usize,
    /// Standard deviation (cm) of each action component over the outer sequences' frames:
    /// near 0 means the targets are constant (e.g. an inverse-dynamics model that has not
    /// learned to tell imagined frames apart) and there is nothing to imitate.
    pub action_std: Vec<f64>,
    /// `--state`: mean and standard deviation (cm) of each state component over the outer
    /// sequences, the standardisation the policy's state input gets; empty without.
    pub state_norm: Vec<[f64; 2]>,
}

/// What to read.
#[derive(Clone, Debug)]
pub struct MetaDataOptions {
    pub variant: Variant,
    /// The translation model whose imagined rows to read (all variants but `daml`).
    pub model_id: Option<String>,
    /// Frame size for image variants (frames are resized to it).
    pub image_size: u32,
    /// Scoring run for the weights (default: the newest over the model).
    pub score_run: Option<String>,
    /// Whose demos feed the inner step: human (every variant) or robot (DAML only).
    pub inner_domain: Domain,
    /// Also read the robot's state along the outer (robot demo) sequences (DAML only).
    pub with_state: bool,
    /// Ground-truth human/robot demo pairs (milv-sim's `ground_truth.jsonl`): the outer
    /// actions become the true robot actions of each human demo's pair (imagined-data
    /// variants only).
    pub true_actions: Option<std::path::PathBuf>,
}

fn decode(img: &Image, size: u32, what: &str) -> Result<Vec<f32>> {
    let rgb = image::load_from_memory(&img.data)
        .map_err(|e| Error::Data(format!("{what}: cannot decode the {} frame: {e}", img.format)))?
        .to_rgb8();
    let (w, h) = rgb.dimensions();
    Ok(to_chw(rgb.as_raw(), w, h, size))
}

/// A clip's frames as `[T, 3, size, size]`.
fn clip_tensor(clip: &crate::run::Clip, size: u32) -> Result<Tensor> {
    let mut data = Vec::new();
    for t in 0..clip.frames.len() {
        data.extend(clip.tensor_data(t, size)?);
    }
    Ok(Tensor::from_slice(&data).view([clip.frames.len() as i64, 3, size as i64, size as i64]))
}

fn task_of(e: &Episode) -> String {
    e.task_id.clone().unwrap_or_else(|| e.episode_id.clone())
}

impl MetaSet {
    pub fn load(ds: &Dataset, v: u64, opts: &MetaDataOptions) -> Result<MetaSet> {
        let eps = ops::episodes(ds, v)?;
        let demos = |domain: Domain| -> BTreeMap<String, Episode> {
            eps.iter()
                .filter(|e| e.domain == domain && e.kind == EpisodeKind::Demo && e.split == Split::Train)
                .map(|e| (e.episode_id.clone(), e.clone()))
                .collect()
        };
        let humans = demos(Domain::Human);
        if humans.is_empty() {
            return Err(Error::Data(format!(
                "version {v} has no human demonstrations (domain=human, kind=demo, split=train)"
            )));
        }
        let mut families: Vec<String> = humans.values().filter_map(|e| e.task_family.clone()).collect();
        families.sort();
        families.dedup();
        let mut set = MetaSet {
            version: v,
            variant: opts.variant,
            seqs: Vec::new(),
            tasks: BTreeMap::new(),
            input_shape: [0; 3],
            action_dim: 0,
            families,
            digest: String::new(),
            zero_weight_frames: 0,
            action_std: Vec::new(),
            state_norm: Vec::new(),
        };
        let mut parts: Vec<String> = vec!["milv-train/meta-data/1".into(), opts.variant.name().into()];
        if opts.inner_domain == Domain::Robot {
            if opts.variant != Variant::Daml {
                return Err(Error::Config(format!(
                    "--inner robot is DAML's robot → robot setting; variant {} adapts on human videos",
                    opts.variant.name()
                )));
            }
            parts.push("inner=robot".into());
        }
        if opts.with_state {
            if opts.variant != Variant::Daml {
                return Err(Error::Config(format!(
                    "--state feeds the robot's state along robot demos; variant {} trains on human \
                     videos, which have none (DAML only)",
                    opts.variant.name()
                )));
            }
            parts.push("state".into());
        }
        match opts.variant {
            Variant::Daml if opts.inner_domain == Domain::Robot => {
                set.load_daml_robot(ds, v, &demos(Domain::Robot), opts.image_size)?
            }
            Variant::Daml => set.load_daml(ds, v, &humans, &demos(Domain::Robot), opts.image_size)?,
            _ => {
                let model = opts.model_id.clone().ok_or_else(|| {
                    Error::Config(format!(
                        "variant {} needs a translation model",
                        opts.variant.name()
                    ))
                })?;
                parts.push(model.clone());
                set.load_imagined(ds, v, &humans, &model, opts)?;
            }
        }
        if set.tasks.is_empty() {
            return Err(Error::Data(format!(
                "version {v}: no task has usable demonstrations"
            )));
        }
        if let Some(path) = &opts.true_actions {
            if opts.variant == Variant::Daml {
                return Err(Error::Config(
                    "--true-actions replaces imagined actions; daml trains on the true robot actions already"
                        .into(),
                ));
            }
            let pairs = set.use_true_actions(ds, v, &eps, path)?;
            parts.push("true-actions".into());
            parts.extend(pairs);
        }
        if opts.with_state {
            set.attach_states(ds, v)?;
        }
        parts.extend(
            ds.files(milv_data::TableKind::Frames, v)?
                .into_iter()
                .map(|f| f.info.path),
        );
        parts.extend(
            ds.files(milv_data::TableKind::Imagined, v)?
                .into_iter()
                .map(|f| f.info.path),
        );
        parts.extend(set.seqs.iter().map(|s| s.episode_id.clone()));
        set.digest = milv_data::run_id(&parts);
        set.action_std = set.outer_action_std();
        Ok(set)
    }

    fn push(&mut self, task: &str, seq: Sequence, inner: bool, outer: bool) {
        let i = self.seqs.len();
        let shape = seq.frames.size();
        self.input_shape = [shape[1], shape[2], shape[3]];
        if let Some(a) = &seq.actions {
            self.action_dim = a.size()[1];
        }
        self.seqs.push(seq);
        let t = self.tasks.entry(task.to_string()).or_default();
        if inner {
            t.inner.push(i);
        }
        if outer {
            t.outer.push(i);
        }
    }

    /// DAML robot → robot: every robot demo is both an inner sequence (its frames, no
    /// actions) and an outer one (frames and true actions); a task's inner and outer
    /// demos differ when it has more than one.
    fn load_daml_robot(
        &mut self,
        ds: &Dataset,
        v: u64,
        robots: &BTreeMap<String, Episode>,
        size: u32,
    ) -> Result<()> {
        if robots.is_empty() {
            return Err(Error::Data(format!(
                "version {v} has no robot demonstrations (domain=robot, kind=demo, split=train)"
            )));
        }
        for clip in load_clips(ds, v, robots, true)?.into_values() {
            let n = clip.frames.len() as i64;
            let acts: Vec<f32> = clip.actions.iter().flatten().flatten().copied().collect();
            let seq = Sequence {
                frames: clip_tensor(&clip, size)?,
                actions: Some(Tensor::from_slice(&acts).view([n, -1])),
                weights: Tensor::ones([n], (tch::Kind::Float, Device::Cpu)),
                states: None,
                episode_id: clip.episode_id.clone(),
            };
            self.push(&task_of(&robots[&clip.episode_id]), seq, true, true);
        }
        Ok(())
    }

    fn load_daml(
        &mut self,
        ds: &Dataset,
        v: u64,
        humans: &BTreeMap<String, Episode>,
        robots: &BTreeMap<String, Episode>,
        size: u32,
    ) -> Result<()> {
        if robots.is_empty() {
            return Err(Error::Data(format!(
                "version {v} has no robot demonstrations (domain=robot, kind=demo, split=train): \
                 DAML's outer loss needs them"
            )));
        }
        let tensor = |clip: &crate::run::Clip| clip_tensor(clip, size);
        for clip in load_clips(ds, v, humans, false)?.into_values() {
            let n = clip.frames.len() as i64;
            let seq = Sequence {
                frames: tensor(&clip)?,
                actions: None,
                weights: Tensor::ones([n], (tch::Kind::Float, Device::Cpu)),
                states: None,
                episode_id: clip.episode_id.clone(),
            };
            self.push(&task_of(&humans[&clip.episode_id]), seq, true, false);
        }
        for clip in load_clips(ds, v, robots, true)?.into_values() {
            let n = clip.frames.len() as i64;
            let acts: Vec<f32> = clip.actions.iter().flatten().flatten().copied().collect();
            let a = Tensor::from_slice(&acts).view([n, -1]);
            let seq = Sequence {
                frames: tensor(&clip)?,
                actions: Some(a),
                weights: Tensor::ones([n], (tch::Kind::Float, Device::Cpu)),
                states: None,
                episode_id: clip.episode_id.clone(),
            };
            let task = task_of(&robots[&clip.episode_id]);
            // Only tasks with a human demo can be meta-trained on.
            if self.tasks.contains_key(&task) {
                self.push(&task, seq, false, true);
            }
        }
        self.tasks
            .retain(|_, t| !t.inner.is_empty() && !t.outer.is_empty());
        Ok(())
    }

    fn load_imagined(
        &mut self,
        ds: &Dataset,
        v: u64,
        humans: &BTreeMap<String, Episode>,
        model: &str,
        opts: &MetaDataOptions,
    ) -> Result<()> {
        let variant = opts.variant;
        let mut plan = ViewPlan::new(
            ds,
            v,
            &ViewOptions {
                model_id: Some(model.to_string()),
                score_run: opts.score_run.clone(),
                ..ViewOptions::default()
            },
        )?;
        plan.episodes.retain(|e| humans.contains_key(&e.episode_id));
        if plan.episodes.is_empty() {
            return Err(Error::Data(format!(
                "model {model} translated no training human demo at version {v}; run `milv-train translate`"
            )));
        }
        if variant.weighted() && plan.score_run.is_none() {
            return Err(Error::Data(format!(
                "variant {} weights frames by their curated β, but model {model} has no scores at \
                 version {v}: run `milv-score run` and `milv-score curate` (or train `wstable`)",
                variant.name()
            )));
        }
        let views: Vec<EpisodeView> = plan.views(ds).collect::<milv_data::Result<_>>()?;
        for view in views {
            let id = view.episode.episode_id.clone();
            let n = view.frames.len() as i64;
            let (mut frames, mut actions, mut weights) = (Vec::new(), Vec::new(), Vec::new());
            let mut shape = [0i64; 3];
            for f in &view.frames {
                let what = format!("episode {id} frame {}", f.frame_index);
                let im = f
                    .imagined
                    .as_ref()
                    .ok_or_else(|| Error::Data(format!("{what}: no imagined row for model {model}")))?;
                match variant.input() {
                    Input::Latent => {
                        let l = im
                            .latent
                            .as_ref()
                            .ok_or_else(|| Error::Data(format!("{what}: the imagined row has no latent")))?;
                        frames.extend(l.to_f32().map_err(|m| Error::Data(format!("{what}: {m}")))?);
                        if let [c, h, w] = l.shape[..] {
                            shape = [i64::from(c), i64::from(h), i64::from(w)];
                        } else {
                            return Err(Error::Data(format!(
                                "{what}: latent shape {:?} is not [C, H, W]",
                                l.shape
                            )));
                        }
                    }
                    Input::Image => {
                        frames.extend(decode(&im.image, opts.image_size, &what)?);
                        let s = i64::from(opts.image_size);
                        shape = [3, s, s];
                    }
                }
                actions.extend(
                    im.action
                        .clone()
                        .ok_or_else(|| Error::Data(format!("{what}: no predicted action")))?,
                );
                let w = if variant.weighted() {
                    let q = f
                        .quality
                        .ok_or_else(|| Error::Data(format!("{what}: not scored")))?;
                    q.weight.ok_or_else(|| {
                        Error::Data(format!(
                            "{what}: the scores have no curation; run `milv-score curate` (or train `wstable`)"
                        ))
                    })?
                } else {
                    1.0
                };
                if !(w.is_finite() && w >= 0.0) {
                    return Err(Error::Data(format!(
                        "{what}: weight {w} is not a finite non-negative number"
                    )));
                }
                self.zero_weight_frames += usize::from(w == 0.0);
                weights.push(w as f32);
            }
            if let Some(bad) = actions.iter().position(|a| !a.is_finite()) {
                return Err(Error::Data(format!(
                    "episode {id}: predicted action {} is not finite",
                    bad / (actions.len() / n.max(1) as usize).max(1)
                )));
            }
            let seq = Sequence {
                episode_id: id.clone(),
                frames: Tensor::from_slice(&frames).view([n, shape[0], shape[1], shape[2]]),
                actions: Some(Tensor::from_slice(&actions).view([n, -1])),
                weights: Tensor::from_slice(&weights),
                states: None,
            };
            self.push(&task_of(&view.episode), seq, true, true);
        }
        Ok(())
    }

    /// Replaces every sequence's imagined actions with the true actions of its human demo's
    /// ground-truth robot demo (`truth`, see [`truth_pairs`]). A demo without a pair, or
    /// whose pair differs in length, is an error naming both. Returns the pairs used, as
    /// `human=robot`, for the data digest.
    fn use_true_actions(
        &mut self,
        ds: &Dataset,
        v: u64,
        eps: &[Episode],
        truth: &std::path::Path,
    ) -> Result<Vec<String>> {
        let pairs: BTreeMap<String, String> = truth_pairs(eps, truth)?.into_iter().collect();
        let wanted: BTreeSet<&String> = self
            .seqs
            .iter()
            .filter_map(|s| pairs.get(&s.episode_id))
            .collect();
        let robots: BTreeMap<String, Episode> = eps
            .iter()
            .filter(|e| wanted.contains(&e.episode_id))
            .map(|e| (e.episode_id.clone(), e.clone()))
            .collect();
        let clips = load_clips(ds, v, &robots, true)?;
        let mut used = Vec::with_capacity(self.seqs.len());
        for seq in &mut self.seqs {
            let id = &seq.episode_id;
            let clip = pairs.get(id).and_then(|r| clips.get(r)).ok_or_else(|| {
                Error::Data(format!(
                    "{}: human demo {id} has no robot demo with actions at version {v}",
                    truth.display()
                ))
            })?;
            let n = seq.frames.size()[0];
            let acts = clip
                .actions
                .as_ref()
                .filter(|a| a.len() as i64 == n)
                .ok_or_else(|| {
                    Error::Data(format!(
                        "{}: robot demo {} has {} actions for the {n} frames of human demo {id}",
                        truth.display(),
                        clip.episode_id,
                        clip.actions.as_ref().map_or(0, Vec::len)
                    ))
                })?;
            let flat: Vec<f32> = acts.iter().flatten().copied().collect();
            seq.actions = Some(Tensor::from_slice(&flat).view([n, -1]));
            used.push(format!("{id}={}", clip.episode_id));
        }
        self.action_dim = self
            .seqs
            .first()
            .and_then(|s| s.actions.as_ref())
            .map_or(0, |a| a.size()[1]);
        Ok(used)
    }

    /// `--state`: the robot's state along every outer sequence, standardised over them all.
    fn attach_states(&mut self, ds: &Dataset, v: u64) -> Result<()> {
        let outer: BTreeSet<usize> = self
            .tasks
            .values()
            .flat_map(|t| t.outer.iter().copied())
            .collect();
        let ids: BTreeSet<String> = outer.iter().map(|&i| self.seqs[i].episode_id.clone()).collect();
        let rows = milv_data::episode_rows(
            ds,
            v,
            milv_data::TableKind::Frames,
            &|id| ids.contains(id),
            Some("state"),
            None,
        )?;
        let mut states = BTreeMap::new();
        for (id, r) in rows {
            if let Some(t) = r.vectors.iter().position(Option::is_none) {
                return Err(Error::Data(format!(
                    "episode {id}: frame {t} has no state (--state needs the robot's state in the sidecar)"
                )));
            }
            states.insert(id, r.all_vectors().unwrap_or_default());
        }
        let all: Vec<&Vec<f32>> = states.values().flatten().collect();
        let dim = all.first().map_or(0, |s| s.len());
        if dim == 0 || all.iter().any(|s| s.len() != dim) {
            return Err(Error::Data(format!(
                "version {v}: the robot demos' states are empty or of different widths"
            )));
        }
        let n = all.len() as f64;
        let norm: Vec<[f64; 2]> = (0..dim)
            .map(|d| {
                let mean = all.iter().map(|s| f64::from(s[d])).sum::<f64>() / n;
                let var = all.iter().map(|s| (f64::from(s[d]) - mean).powi(2)).sum::<f64>() / n;
                // A constant component carries nothing; keep it at 0 rather than divide by 0.
                [mean, if var > 1e-12 { var.sqrt() } else { 1.0 }]
            })
            .collect();
        for &i in &outer {
            let seq = &mut self.seqs[i];
            let rows = states
                .get(&seq.episode_id)
                .ok_or_else(|| Error::Data(format!("episode {}: no state rows", seq.episode_id)))?;
            let t = seq.frames.size()[0];
            if rows.len() as i64 != t {
                return Err(Error::Data(format!(
                    "episode {}: {} states for {t} frames",
                    seq.episode_id,
                    rows.len()
                )));
            }
            seq.states = Some(standardised_states(rows, &norm));
        }
        self.state_norm = norm;
        Ok(())
    }

    fn outer_action_std(&self) -> Vec<f64> {
        let mut idx: Vec<usize> = self
            .tasks
            .values()
            .flat_map(|t| t.outer.iter().copied())
            .collect();
        idx.sort_unstable();
        idx.dedup();
        let acts: Vec<Tensor> = idx
            .iter()
            .filter_map(|&i| self.seqs[i].actions.as_ref().map(Tensor::shallow_clone))
            .collect();
        if acts.is_empty() {
            return Vec::new();
        }
        let all = Tensor::cat(&acts, 0).to_kind(tch::Kind::Double);
        let std = all.std_dim([0i64].as_slice(), false, false);
        Vec::try_from(std).unwrap_or_default()
    }

    /// Sequences in all, and frames in all.
    pub fn size(&self) -> (usize, i64) {
        (
            self.seqs.len(),
            self.seqs.iter().map(|s| s.frames.size()[0]).sum(),
        )
    }

    /// Meta-batch `step`: `n` tasks (distinct while there are enough), each with an inner
    /// and an outer sequence, the outer one a different episode where the task has one.
    /// Deterministic in `(seed, step)`, so a resumed run draws what an uninterrupted one
    /// would.
    pub fn sample(&self, seed: u64, step: u64, n: usize, action_scale: f64, device: Device) -> Vec<MetaTask> {
        let mut rng = StdRng::seed_from_u64(seed ^ step.wrapping_mul(0xA24B_AED4_963E_E407));
        let mut names: Vec<&String> = self.tasks.keys().collect();
        let mut out = Vec::with_capacity(n);
        for k in 0..n {
            if k % names.len().max(1) == 0 {
                // A fresh shuffle per pass: tasks repeat only when n exceeds their number.
                for i in (1..names.len()).rev() {
                    names.swap(i, rng.random_range(0..=i));
                }
            }
            let t = &self.tasks[names[k % names.len()]];
            let i = t.inner[rng.random_range(0..t.inner.len())];
            let others: Vec<usize> = t.outer.iter().copied().filter(|&o| o != i).collect();
            let o = if others.is_empty() {
                i
            } else {
                others[rng.random_range(0..others.len())]
            };
            let (si, so) = (&self.seqs[i], &self.seqs[o]);
            let acts =
                so.actions.as_ref().map(|a| a / action_scale).unwrap_or_else(|| {
                    Tensor::zeros([so.frames.size()[0], 1], (tch::Kind::Float, Device::Cpu))
                });
            out.push(MetaTask {
                inner: si.frames.to_device(device),
                outer: so.frames.to_device(device),
                actions: acts.to_device(device),
                weights: so.weights.to_device(device),
                outer_state: so.states.as_ref().map(|x| x.to_device(device)),
            });
        }
        out
    }
}
