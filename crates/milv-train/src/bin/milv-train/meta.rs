//! The meta-learning subcommands: `meta` (train a DAML / MILV policy), `eval` (one-shot
//! success in milv-sim), `table` (the paper's Tables 1 and 2 from eval reports) and
//! `bench-meta`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use milv_cli as cli;
use milv_data::{Dataset, DatasetRef};
use milv_train::gan::checkpoint;
use milv_train::meta::check;
use milv_train::meta::oneshot::{
    self, DemoSource, EvalOptions, EvalRecord, EvalSplit, Family, PolicyLearner,
};
use milv_train::meta::policy::{Input, MetaConfig, MetaRun, PolicyConfig, Variant};
use milv_train::meta::tasks::{MetaDataOptions, MetaSet};
use milv_train::meta::train::{self as meta_train, MetaRunOptions, PolicyMeta, Translator};
use milv_train::run::DataRef;

use crate::{Runtime, start_run};

#[derive(clap::Args, Debug)]
pub struct MetaArgs {
    /// DATASET or DATASET@VERSION (default: the latest version).
    dataset: DatasetRef,
    /// daml | milv | wstable | feedimg | degi.
    #[arg(long)]
    variant: Variant,
    /// A-CycleGAN checkpoint whose imagined rows the policy trains on (all variants but
    /// daml; degi needs a --decoupled one).
    #[arg(long)]
    translator: Option<PathBuf>,
    /// Run folder.
    #[arg(long)]
    out: PathBuf,
    /// Continue from the newest checkpoint in RUN/checkpoints.
    #[arg(long)]
    resume: bool,
    /// Meta-train until this many steps in all.
    #[arg(long, default_value_t = 1000)]
    steps: u64,
    /// Tasks per meta-batch.
    #[arg(long, default_value_t = 4)]
    meta_batch: usize,
    /// Inner step size α.
    #[arg(long, default_value_t = 0.01)]
    alpha: f64,
    /// Outer Adam learning rate.
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    /// First-order meta-gradient (ψ then learns nothing; for comparison only).
    #[arg(long)]
    first_order: bool,
    /// Image size for daml without a translator (default: the dataset's frames).
    #[arg(long)]
    size: Option<u32>,
    /// Scoring run whose curated weights to use (default: the newest over the model).
    #[arg(long)]
    score_run: Option<String>,
    /// DAML's loss multiplier, inside the square of the adaptation loss: L_ψ = mean((m·out)²).
    #[arg(long, default_value_t = 50.0)]
    loss_multiplier: f64,
    /// Clip each inner-gradient entry to ±this (DAML: 10); 0 turns clipping off.
    #[arg(long, default_value_t = 10.0)]
    inner_clip: f64,
    /// Width of the learned context vector after the spatial softmax (DAML's bias
    /// transformation, adapted in the inner step); 0 turns it off.
    #[arg(long, default_value_t = 20)]
    bias_dim: i64,
    /// No layer norm after the convolutions (DAML has it, with a learned offset).
    #[arg(long)]
    no_layer_norm: bool,
    /// No learned temperature before the spatial softmax (DAML learns one, from 1).
    #[arg(long)]
    fixed_temperature: bool,
    /// Width of the fully connected layers (paper: 100; DAML's push: 200).
    #[arg(long)]
    hidden: Option<i64>,
    /// Whose video the inner step watches: human (the paper), or robot (DAML only: another
    /// robot demo's frames, no actions — DAML's video-only robot → robot).
    #[arg(long, default_value = "human")]
    inner: milv_data::Domain,
    /// Also feed the robot's end-effector state (the sidecar's `state`, standardised) to
    /// the policy after the spatial softmax (DAML only; off by default: the paper's policy
    /// is image-only, and a row trained with it says so).
    #[arg(long)]
    state: bool,
    /// Ground-truth human/robot demo pairs (milv-sim's ground_truth.jsonl): an imagined-data
    /// variant is refused when the translator's imagined actions correlate < 0.5 with the
    /// true robot actions. Without it, a warning when their spread is under a quarter of
    /// the robot random videos'.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Train on imagined actions even when --truth says they do not follow the true ones.
    #[arg(long)]
    allow_weak_translator: bool,
    /// Imagined-data variants: imitate the TRUE robot actions of each human demo's pair in
    /// --truth instead of π_I's imagined ones (a diagnostic, the ladder's R6: it separates
    /// the imagined inputs from the imagined actions; a row trained with it says so).
    #[arg(long, requires = "truth")]
    true_actions: bool,
    /// Small networks (tests).
    #[arg(long)]
    tiny: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long, default_value_t = 500)]
    checkpoint_every: u64,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Policy checkpoint folder, or a meta run folder (its newest checkpoint).
    policy: PathBuf,
    /// drawing | pushing (default: the family the policy trained on).
    #[arg(long)]
    family: Option<Family>,
    /// Trials per held-out task and seed.
    #[arg(long, default_value_t = 10)]
    trials: usize,
    /// Evaluation seeds (comma-separated): each draws its own trial instances.
    #[arg(long, value_delimiter = ',', default_value = "0")]
    seeds: Vec<u64>,
    /// test: the held-out shapes / objects (the paper's protocol); train: the training
    /// ones at new positions (does the policy fit what it was trained on?).
    #[arg(long, default_value = "test")]
    split: EvalSplit,
    /// own: adapt on a demo of the task executed; swap: on a demo of another task (the
    /// drop in success measures how much the policy uses the demo).
    #[arg(long, default_value = "own")]
    demo: DemoSource,
    /// Whose video the learner adapts on (default: the domain the policy's inner step
    /// trained on).
    #[arg(long)]
    demo_domain: Option<milv_data::Domain>,
    /// Evaluate on these task instances instead (milv-sim gen's instances.jsonl), each from
    /// --trials other start positions per seed, adapting on the instance's own demo: does
    /// the policy reproduce what it trained on? (the ladder's R0; overrides --split)
    #[arg(long, value_name = "FILE")]
    instances: Option<PathBuf>,
    /// h264: the demo and every camera frame pass through the codec of the training videos
    /// (H.264, CRF 18, 4:2:0: milv-sim gen's) before the learner sees them; raw: as rendered.
    #[arg(long, default_value = "h264")]
    frames: oneshot::EvalFrames,
    /// Use this A-CycleGAN checkpoint instead of the one recorded in the policy.
    #[arg(long)]
    translator: Option<PathBuf>,
    /// Also write the report (JSON) here.
    #[arg(long, short)]
    out: Option<PathBuf>,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub struct TableArgs {
    /// Reports written by `milv-train eval --out`.
    #[arg(required = true)]
    reports: Vec<PathBuf>,
    /// Write the Markdown here too.
    #[arg(long, short)]
    out: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
pub struct PackArgs {
    /// A policy checkpoint folder, or a run folder (its newest checkpoint).
    policy: PathBuf,
    /// The pack's folder (replaced if it exists; written to a temporary folder first).
    #[arg(long, short)]
    out: PathBuf,
    /// Store the translator's G and F as f16 (half the size; the policy stays f32).
    #[arg(long)]
    half: bool,
    /// Keep the translator in DIR/<model id>[-f16]/, written once and shared by every
    /// pack that names the same DIR, instead of inside the pack (policies trained on one
    /// A-CycleGAN then ship it once).
    #[arg(long, value_name = "DIR")]
    translators: Option<PathBuf>,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub struct BenchMetaArgs {
    /// latent (64×S/4×S/4, the MILV variants) | image (3×S×S, DAML and FeedImg).
    #[arg(long, default_value = "latent")]
    input: Input,
    #[arg(long, default_value_t = 128)]
    size: i64,
    #[arg(long, default_value_t = 4)]
    tasks: usize,
    #[arg(long, default_value_t = 50)]
    frames: i64,
    #[arg(long, default_value_t = 10)]
    steps: u64,
    #[arg(long, default_value_t = 2)]
    warmup: u64,
    #[command(flatten)]
    rt: Runtime,
}

fn translator_for(
    variant: Variant,
    path: Option<&PathBuf>,
) -> anyhow::Result<Option<checkpoint::CheckpointMeta>> {
    let Some(p) = path else {
        if variant != Variant::Daml {
            bail!(
                "--variant {} trains on a translator's imagined rows: pass --translator RUN/checkpoints/step-N",
                variant.name()
            );
        }
        return Ok(None);
    };
    let m = checkpoint::read_meta(p).with_context(|| format!("reading translator {}", p.display()))?;
    match (variant, m.train.decoupled) {
        (Variant::Degi, false) => bail!(
            "--variant degi needs a decoupled A-CycleGAN (trained with --decoupled); {} is coupled",
            p.display()
        ),
        (Variant::Milv | Variant::Wstable | Variant::Feedimg, true) => bail!(
            "--variant {} needs the coupled A-CycleGAN; {} was trained --decoupled (that is degi)",
            variant.name(),
            p.display()
        ),
        _ => Ok(Some(m)),
    }
}

pub fn cmd_meta(a: MetaArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let ds = Dataset::open(&a.dataset.root)?;
    let ckpts = a.out.join("checkpoints");
    let start = start_run(
        "milv-train meta",
        &ds,
        &ckpts,
        a.resume,
        a.dataset.version,
        meta_train::latest,
        |d| Ok(meta_train::read_meta(d)?.1.data),
    )?;
    let tr = translator_for(a.variant, a.translator.as_ref())?;
    let version = start.version;
    let image_size = match (&tr, a.size) {
        (Some(m), _) => m.model.image_size as u32,
        (None, Some(s)) => s,
        (None, None) => milv_data::ops::episodes(&ds, version)?
            .iter()
            .find(|e| e.domain == milv_data::Domain::Robot && e.kind == milv_data::Kind::Demo)
            .map(|e| e.width as u32)
            .context("the dataset has no robot demonstrations")?,
    };
    let set = MetaSet::load(
        &ds,
        version,
        &MetaDataOptions {
            variant: a.variant,
            model_id: tr.as_ref().map(|m| m.model_id.clone()),
            image_size,
            score_run: a.score_run.clone(),
            inner_domain: a.inner,
            with_state: a.state,
            true_actions: if a.true_actions {
                Some(
                    a.truth
                        .clone()
                        .context("--true-actions reads the true actions from --truth FILE")?,
                )
            } else {
                None
            },
        },
    )?;
    let (seqs, frames) = set.size();
    eprintln!(
        "milv-train meta: {} on version {version}: {} tasks, {seqs} sequences, {frames} frames of {:?}{}",
        a.variant.name(),
        set.tasks.len(),
        set.input_shape,
        if set.variant.weighted() {
            format!(", {} frames weighted 0 by curation", set.zero_weight_frames)
        } else {
            String::new()
        }
    );
    let std: Vec<String> = set.action_std.iter().map(|x| format!("{x:.3}")).collect();
    eprintln!(
        "milv-train meta: target actions' standard deviation (cm): [{}]",
        std.join(", ")
    );
    if set.action_std.iter().all(|&x| x < 0.05) {
        eprintln!(
            "milv-train meta: warning: the target actions are nearly constant; the policy has nothing \
             to imitate. With imagined data this means the translator's inverse-dynamics model does not \
             tell the translated frames apart: train the A-CycleGAN longer (check `milv-train eval-translation`)."
        );
    }
    if a.true_actions {
        eprintln!(
            "milv-train meta: --true-actions: the targets are the true robot actions of each human demo's \
             pair in --truth, not the translator's (a diagnostic; the translator check is skipped)"
        );
    } else if a.variant != Variant::Daml {
        let check = check::check_imagined(&ds, version, &set, a.truth.as_deref())?;
        if let Some(fit) = &check.fit {
            eprintln!(
                "milv-train meta: imagined vs true robot actions: {}",
                fit.summary()
            );
        }
        match check.problem() {
            Some(check::Problem::Uncorrelated(why)) if !a.allow_weak_translator => bail!(
                "refusing to train {} on translator {}: {why}; train the A-CycleGAN further \
                 (`milv-train eval-translation --truth` shows π_I on translated demos), or pass \
                 --allow-weak-translator",
                a.variant.name(),
                a.translator
                    .as_ref()
                    .map(|p| p.display().to_string())
                    .unwrap_or_default()
            ),
            Some(check::Problem::Uncorrelated(why) | check::Problem::NarrowSpread(why)) => {
                eprintln!("milv-train meta: warning: {why}")
            }
            None => {}
        }
    }
    start.check_digest(&set.digest)?;
    let (mut run, info) = match &start.checkpoint {
        Some(dir) => {
            let (mut run, info) = meta_train::load(dir, dev)?;
            run.cfg.steps = a.steps;
            eprintln!("milv-train meta: resuming {} at step {}", dir.display(), run.step);
            (run, info)
        }
        None => {
            let shape = set.input_shape;
            let ad = set.action_dim.max(1);
            let base = if a.tiny {
                PolicyConfig::tiny(a.variant.input(), shape, ad)
            } else {
                PolicyConfig::paper(a.variant.input(), shape, ad)
            };
            let policy = PolicyConfig {
                loss_multiplier: a.loss_multiplier,
                inner_clip: a.inner_clip,
                bias_dim: if a.tiny {
                    a.bias_dim.min(base.bias_dim)
                } else {
                    a.bias_dim
                },
                layer_norm: !a.no_layer_norm,
                learned_temperature: !a.fixed_temperature,
                hidden: a.hidden.unwrap_or(base.hidden),
                state_dim: set.state_norm.len() as i64,
                state_norm: set.state_norm.clone(),
                ..base
            };
            policy.validate()?;
            let cfg = MetaConfig {
                variant: a.variant,
                steps: a.steps,
                meta_batch: a.meta_batch,
                alpha: a.alpha,
                lr: a.lr,
                second_order: !a.first_order,
                seed: a.seed,
                inner_domain: a.inner,
                true_actions: a.true_actions,
            };
            let info = PolicyMeta {
                format: String::new(),
                step: 0,
                policy: policy.clone(),
                meta: cfg.clone(),
                data: DataRef {
                    uri: ds.root().display().to_string(),
                    version,
                    digest: set.digest.clone(),
                    alignment_run: None,
                },
                translator: match (&tr, &a.translator) {
                    (Some(m), Some(p)) => Some(Translator {
                        checkpoint: std::fs::canonicalize(p).unwrap_or_else(|_| p.clone()),
                        model_id: m.model_id.clone(),
                    }),
                    _ => None,
                },
                families: set.families.clone(),
                image_size,
                tool_version: milv_data::TOOL_VERSION.into(),
            };
            (MetaRun::new(policy, cfg, dev)?, info)
        }
    };
    let min = run.net.cfg.min_frames() as i64;
    if let Some(s) = set.seqs.iter().find(|s| s.frames.size()[0] < min) {
        bail!(
            "episode {} has {} frames; the adaptation loss needs sequences of at least {min}",
            s.episode_id,
            s.frames.size()[0]
        );
    }
    let bar = cli::bar(run.cfg.steps, "meta steps");
    bar.set_position(run.step);
    let report = meta_train::train_meta(
        &mut run,
        &set,
        &info,
        &MetaRunOptions {
            out: a.out.clone(),
            checkpoint_every: a.checkpoint_every,
        },
        &mut |l| {
            bar.set_position(l.step);
            bar.set_message(format!(
                "inner {:.4} outer {:.4} (before adaptation {:.4})",
                l.losses.inner, l.losses.outer, l.losses.outer_pre
            ));
        },
    )?;
    bar.finish_and_clear();
    if a.rt.json {
        cli::print_json(&report)?;
    } else {
        println!(
            "{} meta-trained to step {} ({} steps, {:.0} ms/step); outer loss {:.4} → {:.4} \
             (before adaptation {:.4})",
            a.variant.name(),
            report.step,
            report.steps_run,
            report.mean_step_ms,
            report.outer_first,
            report.outer_last,
            report.outer_pre_last
        );
        if let Some(c) = &report.checkpoint {
            println!("checkpoint {}", c.display());
        }
        println!("losses {}", a.out.join("losses.jsonl").display());
    }
    Ok(cli::EXIT_OK)
}

impl EvalArgs {
    fn split_name(&self) -> &'static str {
        if self.instances.is_some() {
            return "listed instances, other start positions";
        }
        match self.split {
            EvalSplit::Train => "training",
            EvalSplit::Test => "held-out",
        }
    }

    fn demo_name(&self) -> &'static str {
        match self.demo {
            DemoSource::Own => "own",
            DemoSource::Swap => "swapped",
        }
    }
}

pub fn cmd_eval_one_shot(a: EvalArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let (run, info) =
        meta_train::load(&a.policy, dev).with_context(|| format!("loading policy {}", a.policy.display()))?;
    let family = match a.family {
        Some(f) => f,
        None => match info.families.as_slice() {
            [f] => f.parse().map_err(anyhow::Error::msg)?,
            other => {
                bail!("the policy trained on families {other:?}: choose one with --family drawing|pushing")
            }
        },
    };
    let translator = match (a.translator.as_ref(), &info.translator) {
        (Some(p), _) => Some(p.clone()),
        (None, Some(t)) => Some(t.checkpoint.clone()),
        (None, None) => None,
    };
    let nets = match (&translator, info.variant()) {
        (_, Variant::Daml) => None,
        (Some(p), _) => {
            let (nets, model_id) = checkpoint::load_translation(p, dev)
                .with_context(|| format!("loading translator {}", p.display()))?;
            if let Some(t) = &info.translator
                && t.model_id != model_id
            {
                bail!(
                    "{} is model {model_id}, but the policy trained on rows of model {}",
                    p.display(),
                    t.model_id
                );
            }
            Some(nets)
        }
        (None, v) => bail!("variant {} needs its translator: pass --translator", v.name()),
    };
    let variant = info.variant();
    let alpha = run.cfg.alpha;
    let mut learner = PolicyLearner::new(run.net, variant, alpha, nets, info.image_size)?;
    let opts = EvalOptions {
        family,
        trials: a.trials,
        seeds: a.seeds.clone(),
        image_size: info.image_size,
        split: a.split,
        demo: a.demo,
        demo_domain: a.demo_domain.unwrap_or(info.meta.inner_domain),
        instances: a
            .instances
            .as_deref()
            .map(|p| oneshot::Instances::load(p, family))
            .transpose()?,
        frames: a.frames,
    };
    let bar = cli::bar(0, "trials");
    let result = oneshot::evaluate_one_shot(&mut learner, &opts, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let record = EvalRecord {
        variant,
        policy: a.policy.display().to_string(),
        dataset: info.data.uri.clone(),
        dataset_version: info.data.version,
        translator_model: info.translator.as_ref().map(|t| t.model_id.clone()),
        meta_steps: info.step,
        state_input: learner.net.cfg.state_dim > 0,
        true_actions: info.meta.true_actions,
        result,
    };
    if let Some(o) = &a.out {
        milv_train::run::folder::write_json(o, &record)?;
    }
    if a.rt.json {
        cli::print_json(&record)?;
    } else {
        let r = &record.result;
        println!(
            "{}{} on simulated {} ({} tasks, {} demos): {}/{} = {:.1} % (95 % CI {:.1}–{:.1} %) over {} tasks × {} trials, {} frames",
            variant.label(),
            record.setting_note(),
            family.name(),
            a.split_name(),
            a.demo_name(),
            r.successes,
            r.trials,
            100.0 * r.rate,
            100.0 * r.wilson95[0],
            100.0 * r.wilson95[1],
            r.per_task.len(),
            r.trials_per_task,
            r.frames.name()
        );
        if family == Family::Pushing {
            println!("failures: wrong object {}, control {}", r.wrong_object, r.control);
        }
        if let Some(p) = &r.pushing {
            println!(
                "objects: target moved in {} trials, distractor in {}, neither in {}; target to square \
                 {:.1} cm at the start, {:.1} cm at the end (mean)",
                p.target_moved, p.distractor_moved, p.untouched, p.mean_gap_start_cm, p.mean_gap_end_cm
            );
        }
        if let (Some(pre), Some(post)) = (r.loss_pre, r.loss_post) {
            println!(
                "imitation loss on the expert's rollouts of the evaluated instances: {pre:.4} before adapting, \
                 {post:.4} after ({:.2}×)",
                post / pre
            );
        }
        for t in &r.per_task {
            if t.scores.is_empty() {
                println!("  {:<24} {:>3}/{}", t.task, t.successes, t.trials);
            } else {
                // Drawing: the LCS scores say how near each miss came (success ≥ 30 of 50).
                println!(
                    "  {:<24} {:>3}/{}  LCS {:?}",
                    t.task, t.successes, t.trials, t.scores
                );
            }
        }
    }
    Ok(cli::EXIT_OK)
}

pub fn cmd_table(a: TableArgs) -> anyhow::Result<u8> {
    let mut records = Vec::new();
    for p in &a.reports {
        let bytes = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
        let r: EvalRecord =
            serde_json::from_slice(&bytes).with_context(|| format!("{}: not an eval report", p.display()))?;
        records.push(r);
    }
    let md = oneshot::tables_markdown(&records);
    if let Some(o) = &a.out {
        std::fs::write(o, &md).with_context(|| format!("writing {}", o.display()))?;
    }
    print!("{md}");
    Ok(cli::EXIT_OK)
}

pub fn cmd_pack(a: PackArgs) -> anyhow::Result<u8> {
    a.rt.apply()?;
    let r = meta_train::pack(&a.policy, &a.out, a.half, a.translators.as_deref())
        .with_context(|| format!("packing policy {}", a.policy.display()))?;
    if a.rt.json {
        cli::print_json(&r)?;
    } else {
        println!(
            "packed {} (step {}{}) into {}: {}{}",
            r.variant,
            r.step,
            r.translator_model
                .as_deref()
                .map(|m| format!(", translator {m}"))
                .unwrap_or_default(),
            r.out.display(),
            cli::human_bytes(r.bytes),
            if r.half_translator {
                " (translator in f16)"
            } else {
                ""
            }
        );
    }
    Ok(cli::EXIT_OK)
}

pub fn cmd_bench_meta(a: BenchMetaArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let shape = match a.input {
        Input::Latent => [64, a.size / 4, a.size / 4],
        Input::Image => [3, a.size, a.size],
    };
    let r = meta_train::bench_meta(a.input, shape, a.tasks, a.frames, a.warmup, a.steps, dev)?;
    if a.rt.json {
        cli::print_json(&r)?;
    } else {
        println!(
            "second-order meta step, {} tasks × {} frames of {:?}: median {:.1} ms, mean {:.1} ms over {} steps ({} threads)",
            r.tasks, r.frames, r.input_shape, r.median_ms, r.mean_ms, r.steps, r.threads
        );
    }
    Ok(cli::EXIT_OK)
}
