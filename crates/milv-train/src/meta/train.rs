//! Meta-training runs: the loop around [`MetaRun::step`] (task sampling per meta-batch,
//! JSON-lines losses, checkpoints, resume) and policy checkpoints.
//!
//! A run folder holds `losses.jsonl` (one line per step) and `checkpoints/step-N/` with
//! `policy.safetensors` (θ and ψ), `state.safetensors` (Adam's moments) and
//! `policy.json` ([`PolicyMeta`]: configs, the data and the translator it trained on).
//!
//! [`pack`] writes a policy for sharing: `policy.json` (format `milv-meta-pack/1`),
//! `policy.safetensors` and, for the variants that read translated frames, `translator/`
//! (G and F, [`crate::gan::checkpoint::pack_translator`]), which `policy.json` names by
//! a path relative to the pack. A pack evaluates like a checkpoint; it cannot resume.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use tch::{Device, Kind, Tensor};

use crate::meta::policy::{Input, MetaConfig, MetaLosses, MetaRun, MetaTask, PolicyConfig, Variant};
use crate::meta::tasks::MetaSet;
use crate::run::folder::{DataRef, write_dir, write_json};
use crate::run::log::{append_json, truncate_after};
use crate::{Error, Result};

const FORMAT: &str = "milv-meta/1";
const PACK_FORMAT: &str = "milv-meta-pack/1";

/// The A-CycleGAN a policy's inputs come from (all variants but DAML).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Translator {
    pub checkpoint: PathBuf,
    pub model_id: String,
}

/// `policy.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyMeta {
    pub format: String,
    pub step: u64,
    pub policy: PolicyConfig,
    pub meta: MetaConfig,
    pub data: DataRef,
    pub translator: Option<Translator>,
    /// Task families trained on.
    pub families: Vec<String>,
    /// Camera frame size the policy (or its translator) takes.
    pub image_size: u32,
    pub tool_version: String,
}

impl PolicyMeta {
    pub fn variant(&self) -> Variant {
        self.meta.variant
    }
}

/// Writes `run` as `dir/step-NNNNNNNN`.
pub fn save(run: &MetaRun, meta: &PolicyMeta, dir: &Path) -> Result<PathBuf> {
    write_dir(dir, &format!("step-{:08}", run.step), &mut |tmp| {
        run.net.save(&tmp.join("policy.safetensors"))?;
        Tensor::write_safetensors(&run.adam.state(), tmp.join("state.safetensors"))?;
        let m = PolicyMeta {
            format: FORMAT.into(),
            step: run.step,
            policy: run.net.cfg.clone(),
            meta: run.cfg.clone(),
            ..meta.clone()
        };
        write_json(&tmp.join("policy.json"), &m)
    })
}

/// The newest policy checkpoint in a run's `checkpoints/`.
pub fn latest(dir: &Path) -> Result<Option<PathBuf>> {
    crate::run::folder::latest_with(dir, "policy.json")
}

/// Reads `policy.json` of a checkpoint folder, or of the newest checkpoint of a run
/// folder; returns the checkpoint folder with it.
pub fn read_meta(path: &Path) -> Result<(PathBuf, PolicyMeta)> {
    let dir = if path.join("policy.json").is_file() {
        path.to_path_buf()
    } else {
        latest(&path.join("checkpoints"))?.ok_or_else(|| {
            Error::checkpoint(
                "neither a policy checkpoint (policy.json) nor a run folder with checkpoints",
                path,
            )
        })?
    };
    let mut meta: PolicyMeta = crate::run::folder::read_json_formats(
        &dir.join("policy.json"),
        "a policy checkpoint",
        &[FORMAT, PACK_FORMAT],
        |m: &PolicyMeta| &m.format,
    )?;
    let packed = meta.format == PACK_FORMAT;
    // A pack has no optimizer state: it is for evaluating, not for resuming.
    let needed: &[&str] = if packed {
        &["policy.safetensors"]
    } else {
        &["policy.safetensors", "state.safetensors"]
    };
    for f in needed {
        if !dir.join(f).is_file() {
            return Err(Error::checkpoint(format!("{f} is missing"), &dir));
        }
    }
    if packed && let Some(t) = meta.translator.as_mut() {
        t.checkpoint = dir.join(&t.checkpoint);
    }
    Ok((dir, meta))
}

/// Loads a policy checkpoint (or a run folder's newest, or a pack) onto `device`.
pub fn load(path: &Path, device: Device) -> Result<(MetaRun, PolicyMeta)> {
    let (dir, meta) = read_meta(path)?;
    let mut run = MetaRun::new(meta.policy.clone(), meta.meta.clone(), device)?;
    run.net.load(&dir.join("policy.safetensors"))?;
    if meta.format == FORMAT {
        let sp = dir.join("state.safetensors");
        let state = Tensor::read_safetensors(&sp).map_err(Error::tensors(&sp))?;
        run.adam.load_state(state)?;
    }
    run.step = meta.step;
    Ok((run, meta))
}

/// What [`pack`] wrote.
#[derive(Clone, Debug, Serialize)]
pub struct PackReport {
    pub out: PathBuf,
    pub variant: String,
    pub step: u64,
    pub translator_model: Option<String>,
    /// The shared translator folder it references (`--translators`), if any.
    pub translator_dir: Option<PathBuf>,
    /// Whether the translator's weights were stored as f16.
    pub half_translator: bool,
    pub bytes: u64,
}

/// Packs the policy checkpoint at `policy` (or a run folder's newest) into the folder
/// `out` (replaced atomically): θ and ψ as trained (f32: the inner step differentiates
/// through them, and they are small), and the translator's G and F, in f16 when `half`.
/// With `translators`, the translator goes to `translators/<model id>[-f16]/` instead,
/// written once and shared by every pack naming that folder.
pub fn pack(policy: &Path, out: &Path, half: bool, translators: Option<&Path>) -> Result<PackReport> {
    let (dir, meta) = read_meta(policy)?;
    let name = out
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| Error::Config(format!("{} has no folder name to pack into", out.display())))?;
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let shared = match (&meta.translator, translators) {
        (Some(t), Some(root)) => Some(shared_translator(t, root, half)?),
        _ => None,
    };
    std::fs::create_dir_all(parent).map_err(Error::io("create folder", parent))?;
    let canonical = |p: &Path| p.canonicalize().map_err(Error::io("resolve", p));
    let shared_rel = match &shared {
        Some(s) => Some(relative_to(&canonical(parent)?.join(name), &canonical(s)?)),
        None => None,
    };
    let fin = write_dir(parent, name, &mut |tmp| {
        std::fs::copy(dir.join("policy.safetensors"), tmp.join("policy.safetensors"))
            .map_err(Error::io("copy", tmp.join("policy.safetensors")))?;
        let mut m = PolicyMeta {
            format: PACK_FORMAT.into(),
            ..meta.clone()
        };
        if let Some(t) = m.translator.as_mut() {
            t.checkpoint = match &shared_rel {
                Some(rel) => rel.clone(),
                None => {
                    let p = crate::gan::checkpoint::pack_translator(
                        &t.checkpoint,
                        &tmp.join("translator"),
                        half,
                    )?;
                    check_model(&p.model_id, t)?;
                    PathBuf::from("translator")
                }
            };
        }
        write_json(&tmp.join("policy.json"), &m)
    })?;
    Ok(PackReport {
        bytes: folder_bytes(&fin)?,
        out: fin,
        translator_dir: shared,
        variant: meta.variant().name().into(),
        step: meta.step,
        half_translator: half && meta.translator.is_some(),
        translator_model: meta.translator.map(|t| t.model_id),
    })
}

fn check_model(packed: &str, t: &Translator) -> Result<()> {
    if packed != t.model_id {
        return Err(Error::checkpoint(
            format!(
                "the translator there is model {packed}, but the policy trained on rows of model {}",
                t.model_id
            ),
            &t.checkpoint,
        ));
    }
    Ok(())
}

/// `root/<model id>[-f16]`, packed from `t`'s checkpoint unless a pack of it is there.
fn shared_translator(t: &Translator, root: &Path, half: bool) -> Result<PathBuf> {
    let name = format!("{}{}", t.model_id, if half { "-f16" } else { "" });
    let dir = root.join(&name);
    if dir.join("translator.json").is_file() {
        check_model(&crate::gan::checkpoint::read_packed(&dir)?.model_id, t)?;
        return Ok(dir);
    }
    write_dir(root, &name, &mut |tmp| {
        let p = crate::gan::checkpoint::pack_translator(&t.checkpoint, tmp, half)?;
        check_model(&p.model_id, t)
    })
}

/// `to` as a path relative to the folder `from` (both absolute): what a pack records
/// so that it can move together with its translators.
fn relative_to(from: &Path, to: &Path) -> PathBuf {
    let common = from
        .components()
        .zip(to.components())
        .take_while(|(a, b)| a == b)
        .count();
    let mut rel = PathBuf::new();
    for _ in from.components().skip(common) {
        rel.push("..");
    }
    for c in to.components().skip(common) {
        rel.push(c);
    }
    rel
}

fn folder_bytes(dir: &Path) -> Result<u64> {
    let mut n = 0;
    for e in std::fs::read_dir(dir).map_err(Error::io("list", dir))? {
        let e = e.map_err(Error::io("list", dir))?;
        let md = e.metadata().map_err(Error::io("stat", e.path()))?;
        n += if md.is_dir() {
            folder_bytes(&e.path())?
        } else {
            md.len()
        };
    }
    Ok(n)
}

#[derive(Clone, Debug)]
pub struct MetaRunOptions {
    pub out: PathBuf,
    pub checkpoint_every: u64,
}

/// One line of `losses.jsonl`.
#[derive(Clone, Debug, Serialize)]
pub struct MetaStepLog {
    pub step: u64,
    #[serde(flatten)]
    pub losses: MetaLosses,
    pub step_ms: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct MetaReport {
    pub variant: Variant,
    pub steps_run: u64,
    pub step: u64,
    pub mean_step_ms: f64,
    /// Mean outer loss over the first and the last tenth of the steps run.
    pub outer_first: f64,
    pub outer_last: f64,
    /// The outer loss before adaptation (at θ) over the last tenth: near `outer_last`
    /// means the inner step does little.
    pub outer_pre_last: f64,
    pub checkpoint: Option<PathBuf>,
}

/// Trains `run` up to `run.cfg.steps` from wherever it stands.
pub fn train_meta(
    run: &mut MetaRun,
    set: &MetaSet,
    meta: &PolicyMeta,
    opts: &MetaRunOptions,
    on_step: &mut dyn FnMut(&MetaStepLog),
) -> Result<MetaReport> {
    std::fs::create_dir_all(&opts.out).map_err(Error::io("create folder", &opts.out))?;
    let losses_path = opts.out.join("losses.jsonl");
    truncate_after(&losses_path, run.step)?;
    let ckpt_dir = opts.out.join("checkpoints");
    let device = run.net.vs.device();
    let scale = run.net.cfg.action_scale;
    let mut outers = Vec::new();
    let mut total_ms = 0.0;
    let mut report = MetaReport {
        variant: run.cfg.variant,
        steps_run: 0,
        step: run.step,
        mean_step_ms: 0.0,
        outer_first: f64::NAN,
        outer_last: f64::NAN,
        outer_pre_last: f64::NAN,
        checkpoint: None,
    };
    let mut pres = Vec::new();
    while run.step < run.cfg.steps {
        let tasks = set.sample(run.cfg.seed, run.step, run.cfg.meta_batch, scale, device);
        let t = Instant::now();
        let losses = run.step(&tasks);
        let step_ms = t.elapsed().as_secs_f64() * 1e3;
        if !(losses.outer.is_finite() && losses.inner.is_finite()) {
            return Err(Error::Data(format!(
                "meta step {}: the loss is not finite (inner {}, outer {}): lower --lr or --alpha",
                run.step, losses.inner, losses.outer
            )));
        }
        total_ms += step_ms;
        outers.push(losses.outer);
        pres.push(losses.outer_pre);
        report.steps_run += 1;
        let line = MetaStepLog {
            step: run.step,
            losses,
            step_ms,
        };
        append_json(&losses_path, &line)?;
        on_step(&line);
        if (opts.checkpoint_every > 0 && run.step.is_multiple_of(opts.checkpoint_every))
            || run.step == run.cfg.steps
        {
            report.checkpoint = Some(save(run, meta, &ckpt_dir)?);
        }
    }
    let tenth = (outers.len() / 10).max(1).min(outers.len().max(1));
    let mean = |xs: &[f64]| xs.iter().sum::<f64>() / xs.len().max(1) as f64;
    if !outers.is_empty() {
        report.outer_first = mean(&outers[..tenth]);
        report.outer_last = mean(&outers[outers.len() - tenth..]);
        report.outer_pre_last = mean(&pres[pres.len() - tenth..]);
    }
    report.step = run.step;
    report.mean_step_ms = total_ms / report.steps_run.max(1) as f64;
    Ok(report)
}

/// Timings of [`bench_meta`].
#[derive(Clone, Debug, Serialize)]
pub struct MetaBench {
    pub input: Input,
    pub input_shape: [i64; 3],
    pub tasks: usize,
    pub frames: i64,
    pub steps: u64,
    pub median_ms: f64,
    pub mean_ms: f64,
    pub min_ms: f64,
    pub threads: i32,
}

/// Times second-order meta steps of the paper's policy on fixed random data: `tasks`
/// tasks of `frames` frames each, after `warmup` untimed steps.
pub fn bench_meta(
    input: Input,
    input_shape: [i64; 3],
    tasks: usize,
    frames: i64,
    warmup: u64,
    steps: u64,
    device: Device,
) -> Result<MetaBench> {
    let mut run = MetaRun::new(
        PolicyConfig::paper(input, input_shape, 2),
        MetaConfig::default(),
        device,
    )?;
    tch::manual_seed(0);
    let o = (Kind::Float, device);
    let [c, h, w] = input_shape;
    let batch: Vec<MetaTask> = (0..tasks)
        .map(|_| MetaTask {
            inner: Tensor::randn([frames, c, h, w], o),
            outer: Tensor::randn([frames, c, h, w], o),
            actions: Tensor::randn([frames, 2], o),
            weights: Tensor::rand([frames], o),
            outer_state: None,
        })
        .collect();
    let t = crate::run::time_steps(warmup, steps, &mut || {
        run.step(&batch);
    });
    Ok(MetaBench {
        input,
        input_shape,
        tasks,
        frames,
        steps: t.steps,
        median_ms: t.median_ms,
        mean_ms: t.mean_ms,
        min_ms: t.min_ms,
        threads: tch::get_num_threads(),
    })
}

/// Outer loss after adaptation (θ′) and before (θ) of meta runs (their `losses.jsonl`),
/// as one PNG chart `meta_losses.png` in `out`, each a moving average over `window`
/// steps: where the two curves lie on each other, the inner step does nothing.
pub fn plot_meta_runs(runs: &[PathBuf], out: &Path, window: usize) -> Result<PathBuf> {
    std::fs::create_dir_all(out).map_err(Error::io("create folder", out))?;
    let mut series = Vec::new();
    for r in runs {
        let path = r.join("losses.jsonl");
        let text = std::fs::read_to_string(&path).map_err(Error::io("read", &path))?;
        let name = r
            .file_name()
            .map_or_else(|| r.display().to_string(), |n| n.to_string_lossy().into_owned());
        let (mut post, mut pre) = (Vec::new(), Vec::new());
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let v: serde_json::Value = serde_json::from_str(line).map_err(|source| Error::Json {
                op: "parse a line of",
                source,
                path: path.clone(),
            })?;
            let step = v["step"].as_f64().unwrap_or(0.0);
            if let Some(x) = v["outer"].as_f64() {
                post.push((step, x));
            }
            if let Some(x) = v["outer_pre"].as_f64().filter(|x| *x > 0.0) {
                pre.push((step, x));
            }
        }
        for (label, pts) in [("after adaptation (θ′)", post), ("before adaptation (θ)", pre)] {
            if !pts.is_empty() {
                series.push(milv_plot::Series {
                    name: format!("{name}: {label}"),
                    points: moving_average(&pts, window),
                });
            }
        }
    }
    let file = out.join("meta_losses.png");
    milv_plot::lines_png(
        &file,
        &series,
        &format!("Outer loss, moving average of {window} steps"),
        "meta step",
        "weighted MSE (action units)",
    )
    .map_err(|e| Error::Write {
        what: "chart",
        source: Box::new(e),
        path: file.clone(),
    })?;
    Ok(file)
}

fn moving_average(pts: &[(f64, f64)], window: usize) -> Vec<(f64, f64)> {
    let w = window.max(1);
    let mut sum = 0.0;
    let mut out = Vec::with_capacity(pts.len());
    for (i, &(x, y)) in pts.iter().enumerate() {
        sum += y;
        if i >= w {
            sum -= pts[i - w].1;
        }
        out.push((x, sum / (i + 1).min(w) as f64));
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_policy_checkpoint_round_trips() {
        let _serial = crate::testing::torch_rng();
        let cfg = PolicyConfig::tiny(Input::Image, [3, 16, 16], 2);
        let mut run = MetaRun::new(cfg.clone(), MetaConfig::default(), Device::Cpu).unwrap();
        let o = (Kind::Float, Device::Cpu);
        let task = MetaTask {
            inner: Tensor::randn([8, 3, 16, 16], o),
            outer: Tensor::randn([8, 3, 16, 16], o),
            actions: Tensor::randn([8, 2], o),
            weights: Tensor::ones([8], o),
            outer_state: None,
        };
        for _ in 0..3 {
            run.step(std::slice::from_ref(&task));
        }
        let meta = PolicyMeta {
            format: String::new(),
            step: 0,
            policy: cfg,
            meta: run.cfg.clone(),
            data: DataRef {
                uri: "ds".into(),
                version: 3,
                digest: "d".into(),
                alignment_run: None,
            },
            translator: None,
            families: vec!["drawing".into()],
            image_size: 16,
            tool_version: milv_data::TOOL_VERSION.into(),
        };
        let tmp = tempfile::tempdir().unwrap();
        let dir = save(&run, &meta, &tmp.path().join("checkpoints")).unwrap();
        // A run folder resolves to its newest checkpoint.
        let (mut back, m) = load(tmp.path(), Device::Cpu).unwrap();
        assert_eq!(m.step, 3);
        assert_eq!(m.data, meta.data);
        for (a, b) in run
            .net
            .theta
            .iter()
            .chain(&run.net.psi)
            .zip(back.net.theta.iter().chain(&back.net.psi))
        {
            assert!(a.equal(b));
        }
        // The optimizer state came back too: the next step is the same on both.
        let l1 = run.step(std::slice::from_ref(&task));
        let l2 = back.step(std::slice::from_ref(&task));
        assert_eq!(l1, l2);
        std::fs::remove_file(dir.join("state.safetensors")).unwrap();
        let err = load(&dir, Device::Cpu).err().unwrap().to_string();
        assert!(err.contains("state.safetensors is missing"), "{err}");
    }
}
