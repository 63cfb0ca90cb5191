//! The A-CycleGAN subcommands: `cyclegan` (train / resume), `translate` (→ `imagined`),
//! `eval-translation`, `bench-step`, `bench-loader` and `report`.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, bail};
use milv_cli as cli;
use milv_data::{CommitMeta, Dataset, DatasetRef, Partition};
use milv_train::ModelConfig;
use milv_train::gan::checkpoint;
use milv_train::gan::data::{DataOptions, TrainingSet};
use milv_train::gan::eval::{EvalSet, evaluate_translation};
use milv_train::gan::train::{RunOptions, train_cyclegan};
use milv_train::gan::translate::{LatentDtype, TranslateOptions, translate};
use milv_train::run::DataRef;
use milv_train::{ACycleGan, GanLoss, TrainConfig};

use crate::{Runtime, model_config, start_run};

#[derive(clap::Args, Debug)]
pub(crate) struct TrainArgs {
    /// DATASET or DATASET@VERSION to train on (default: the latest version).
    dataset: DatasetRef,
    /// Run folder.
    #[arg(long)]
    out: PathBuf,
    /// Continue from the newest checkpoint in RUN/checkpoints (same data digest).
    #[arg(long)]
    resume: bool,
    /// Train until this many steps in all.
    #[arg(long, default_value_t = 10_000)]
    steps: u64,
    /// Image size (pixels, square; frames are resized to it).
    #[arg(long, default_value_t = 128)]
    size: i64,
    /// Small networks (tests and quick looks), not the paper's widths.
    #[arg(long)]
    tiny: bool,
    #[arg(long, default_value_t = 1)]
    batch: i64,
    /// Robot transitions per step for the inverse-dynamics loss.
    #[arg(long, default_value_t = 1)]
    idm_batch: i64,
    /// Generators' and discriminators' Adam learning rate.
    #[arg(long, default_value_t = 2e-4)]
    lr: f64,
    /// Inverse-dynamics learning rate.
    #[arg(long, default_value_t = 0.01)]
    lr_idm: f64,
    /// Negative slope of π_I's conv activations (0: a ReLU, the paper's). With a ReLU π_I
    /// can die and predict a constant for good; 0.2 keeps a gradient (RESULTS.md, ladder R5).
    #[arg(long, default_value_t = 0.0)]
    idm_slope: f64,
    /// Cycle-consistency weight λ.
    #[arg(long, default_value_t = 10.0)]
    lambda_cyc: f64,
    /// Auxiliary (aligned pairs, eq. 7) weight; 0 trains without alignments.
    #[arg(long, default_value_t = 1.0)]
    lambda_aux: f64,
    /// Inverse-dynamics loss weight in the generators' objective.
    #[arg(long, default_value_t = 1.0)]
    lambda_idm: f64,
    /// lsgan (least squares) | log (the paper's eq. 1).
    #[arg(long, default_value = "lsgan")]
    gan: GanLoss,
    /// Discriminators' image-history size.
    #[arg(long, default_value_t = 50)]
    pool: usize,
    /// π_I on its own encoder (the DeGI ablation) instead of F's.
    #[arg(long)]
    decoupled: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Alignment run (id or feature kind) for the auxiliary loss, when the table has several.
    #[arg(long)]
    alignment: Option<String>,
    #[arg(long, default_value_t = 500)]
    grid_every: u64,
    #[arg(long, default_value_t = 1000)]
    checkpoint_every: u64,
    /// Evaluate every N steps (needs --truth for SSIM; held-out random videos for π_I).
    #[arg(long, default_value_t = 0)]
    eval_every: u64,
    /// Ground-truth human/robot pairs (milv-sim's ground_truth.jsonl).
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Ground-truth pairs evaluated (held-out tasks first).
    #[arg(long, default_value_t = 8)]
    eval_pairs: usize,
    /// Decoding threads of the loader.
    #[arg(long, default_value_t = 2)]
    workers: usize,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub(crate) struct TranslateArgs {
    dataset: DatasetRef,
    /// Checkpoint folder (RUN/checkpoints/step-N).
    #[arg(long)]
    checkpoint: PathBuf,
    /// Frames per forward pass.
    #[arg(long, default_value_t = 8)]
    chunk: usize,
    /// f16 | f32.
    #[arg(long, default_value = "f16")]
    latent: LatentDtype,
    /// Only these human episodes (comma-separated or repeated).
    #[arg(long, value_delimiter = ',')]
    episodes: Vec<String>,
    /// Translate only share i of n of the episodes (array jobs): i/n.
    #[arg(long)]
    partition: Option<Partition>,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub(crate) struct EvalTranslationArgs {
    dataset: DatasetRef,
    #[arg(long)]
    checkpoint: PathBuf,
    #[arg(long)]
    truth: Option<PathBuf>,
    #[arg(long, default_value_t = 8)]
    pairs: usize,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub(crate) struct BenchArgs {
    #[arg(long, default_value_t = 128)]
    size: i64,
    #[arg(long, default_value_t = 10)]
    steps: u64,
    #[arg(long, default_value_t = 2)]
    warmup: u64,
    #[arg(long)]
    tiny: bool,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub(crate) struct LoaderArgs {
    dataset: DatasetRef,
    #[arg(long, default_value_t = 128)]
    size: u32,
    #[arg(long, default_value_t = 200)]
    batches: u64,
    #[arg(long, default_value_t = 2)]
    workers: usize,
    #[arg(long, default_value_t = 1)]
    batch: usize,
    /// A step time (ms) to compare with, e.g. from `bench-step`.
    #[arg(long)]
    step_ms: Option<f64>,
    /// Alignment run (id or feature kind), when the table has several.
    #[arg(long)]
    alignment: Option<String>,
    #[command(flatten)]
    rt: Runtime,
}

#[derive(clap::Args, Debug)]
pub(crate) struct ReportArgs {
    /// Run folders: A-CycleGAN runs (with an eval.jsonl) get SSIM and action-error
    /// curves; meta runs (losses.jsonl only) the outer loss after and before adaptation.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Folder for the charts.
    #[arg(long, short)]
    out: PathBuf,
    /// Moving-average window of the meta-loss curves (steps).
    #[arg(long, default_value_t = 25)]
    window: usize,
}

pub(crate) fn cmd_report(a: ReportArgs) -> anyhow::Result<u8> {
    let (gan, meta): (Vec<PathBuf>, Vec<PathBuf>) = a
        .runs
        .iter()
        .cloned()
        .partition(|r| r.join("eval.jsonl").is_file());
    if !gan.is_empty() {
        for f in milv_train::gan::train::plot_runs(&gan, &a.out)? {
            println!("{}", f.display());
        }
    }
    if !meta.is_empty() {
        let f = milv_train::meta::train::plot_meta_runs(&meta, &a.out, a.window)?;
        println!("{}", f.display());
    }
    Ok(cli::EXIT_OK)
}

pub(crate) fn cmd_train_cyclegan(a: TrainArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let ds = Dataset::open(&a.dataset.root)?;
    let ckpts = a.out.join("checkpoints");
    let start = start_run(
        "milv-train",
        &ds,
        &ckpts,
        a.resume,
        a.dataset.version,
        checkpoint::latest,
        |d| Ok(checkpoint::read_meta(d)?.data),
    )?;
    let version = start.version;
    let resumed = match &start.checkpoint {
        Some(dir) => {
            let (mut run, _) = checkpoint::load(dir, dev)?;
            run.train.steps = a.steps;
            eprintln!("milv-train: resuming {} at step {}", dir.display(), run.step);
            Some(run)
        }
        None => None,
    };
    let lambda_aux = resumed.as_ref().map_or(a.lambda_aux, |r| r.train.lambda_aux);
    let set = TrainingSet::load(
        &ds,
        version,
        &DataOptions {
            alignment: a.alignment.clone(),
            no_alignments: lambda_aux == 0.0,
        },
    )?;
    let mut run = match resumed {
        Some(run) => {
            if run.model.action_dim != set.action_dim as i64 {
                anyhow::bail!(
                    "{}: the checkpoint's π_I predicts {} action values, the robot videos of version {version} have {}",
                    ckpts.display(),
                    run.model.action_dim,
                    set.action_dim
                );
            }
            run
        }
        None => {
            let model = ModelConfig {
                idm_slope: a.idm_slope,
                action_dim: set.action_dim as i64,
                ..model_config(a.tiny, a.size)
            };
            let train_cfg = TrainConfig {
                steps: a.steps,
                batch: a.batch,
                idm_batch: a.idm_batch,
                lr: a.lr,
                lr_idm: a.lr_idm,
                lambda_cyc: a.lambda_cyc,
                lambda_aux: a.lambda_aux,
                lambda_idm: a.lambda_idm,
                gan: a.gan,
                pool_size: a.pool,
                decoupled: a.decoupled,
                seed: a.seed,
                ..TrainConfig::default()
            };
            ACycleGan::new(model, train_cfg, dev)?
        }
    };
    start.check_digest(&set.digest)?;
    let data = DataRef {
        uri: ds.root().display().to_string(),
        version,
        digest: set.digest.clone(),
        alignment_run: set.alignment.as_ref().map(|r| r.run_id.clone()),
    };
    let (hf, rf) = set.frames();
    eprintln!(
        "milv-train: version {version}: {} human demos ({hf} frames), {} robot random videos ({rf} frames), {} aligned pairs{}",
        set.human.len(),
        set.robot.len(),
        set.pairs.len(),
        set.alignment
            .as_ref()
            .map(|r| format!(" (run {}, {})", r.run_id, r.features))
            .unwrap_or_default()
    );
    let eval = if a.eval_every > 0 {
        Some(EvalSet::load(&ds, version, a.truth.as_deref(), a.eval_pairs)?)
    } else {
        None
    };
    let opts = RunOptions {
        out: a.out.clone(),
        grid_every: a.grid_every,
        checkpoint_every: a.checkpoint_every,
        eval_every: a.eval_every,
        workers: a.workers,
        ..RunOptions::default()
    };
    let bar = cli::bar(run.train.steps, "steps");
    bar.set_position(run.step);
    let report = train_cyclegan(&mut run, Arc::new(set), &data, eval.as_ref(), &opts, &mut |l| {
        bar.set_position(l.step);
        bar.set_message(format!(
            "G {:.3} cyc {:.3} aux {:.3} idm {:.3} D {:.3}",
            l.losses.generators,
            l.losses.cycle,
            l.losses.aux,
            l.losses.idm,
            l.losses.d_x + l.losses.d_y
        ));
    })?;
    bar.finish_and_clear();
    if a.rt.json {
        cli::print_json(&report)?;
    } else {
        println!(
            "trained to step {} ({} steps, {:.0} ms/step, {} waited for data)",
            report.step, report.steps_run, report.mean_step_ms, report.waited_steps
        );
        if let Some(c) = &report.checkpoint {
            println!(
                "checkpoint {} (model {})",
                c.display(),
                report.model_id.clone().unwrap_or_default()
            );
        }
        println!("losses {}", a.out.join("losses.jsonl").display());
        println!("grids  {}", a.out.join("grids").display());
    }
    Ok(cli::EXIT_OK)
}

pub(crate) fn cmd_translate(a: TranslateArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let ds = Dataset::open(&a.dataset.root)?;
    let (run, meta) = checkpoint::load(&a.checkpoint, dev)
        .with_context(|| format!("loading checkpoint {}", a.checkpoint.display()))?;
    let opts = TranslateOptions {
        chunk: a.chunk,
        latent: a.latent,
        episodes: (!a.episodes.is_empty()).then(|| a.episodes.iter().cloned().collect::<BTreeSet<_>>()),
        partition: a.partition,
    };
    let bar = cli::bar(0, "episodes translated");
    let report = translate(
        &ds,
        a.dataset.version,
        &run,
        &meta.model_id,
        &opts,
        CommitMeta::for_this_process("milv-train", "translate"),
        &mut |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )?;
    bar.finish_and_clear();
    if a.rt.json {
        cli::print_json(&report)?;
    } else if report.episodes == 0 {
        println!(
            "nothing to do: model {} already translated the {} selected episode(s) at version {}",
            report.model_id, report.already_done, report.read_version
        );
    } else {
        println!(
            "version {}: translated {} episode(s), {} frames with model {} (latents {} {:?})",
            report.version,
            report.episodes,
            report.frames,
            report.model_id,
            report.latent_dtype.name(),
            report.latent_shape
        );
    }
    Ok(cli::EXIT_OK)
}

pub(crate) fn cmd_eval_translation(a: EvalTranslationArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let ds = Dataset::open(&a.dataset.root)?;
    let (run, meta) = checkpoint::load(&a.checkpoint, dev)?;
    let v = ds.resolve(a.dataset.version)?;
    let set = EvalSet::load(&ds, v, a.truth.as_deref(), a.pairs)?;
    if set.pairs.is_empty() && set.held_out.is_empty() {
        bail!(
            "nothing to evaluate at version {v}: no ground-truth pairs{} and no held-out robot random videos (split ≠ train)",
            if a.truth.is_none() {
                " (pass --truth)"
            } else {
                " matched"
            }
        );
    }
    let mut rep = evaluate_translation(&run.nets, &set, &run.model)?;
    rep.step = meta.step;
    if a.rt.json {
        cli::print_json(&rep)?;
    } else {
        let f = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.4}"));
        println!("model {} (step {}), version {v}", meta.model_id, meta.step);
        println!(
            "SSIM(G(x), ground truth) {} over {} frames of {} episodes (untranslated human frames: {})",
            f(rep.ssim),
            rep.ssim_frames,
            rep.ssim_episodes,
            f(rep.ssim_untranslated)
        );
        println!(
            "π_I action MAE {} RMSE {} over {} held-out transitions (predicting 0: MAE {})",
            f(rep.action_mae),
            f(rep.action_rmse),
            rep.action_frames,
            f(rep.action_mae_zero)
        );
        if let Some(fit) = &rep.robot_demo_fit {
            println!("π_I on the ground-truth robot demos: {}", fit.summary());
        }
        if let Some(fit) = &rep.translated_fit {
            println!(
                "π_I on translated human demos (the imagined actions) vs the true robot actions: {}",
                fit.summary()
            );
        }
    }
    Ok(cli::EXIT_OK)
}

pub(crate) fn cmd_bench_step(a: BenchArgs) -> anyhow::Result<u8> {
    let dev = a.rt.apply()?;
    let model = model_config(a.tiny, a.size);
    let r = milv_train::gan::train::bench_steps(model, dev, a.warmup, a.steps)?;
    if a.rt.json {
        cli::print_json(&r)?;
    } else {
        println!(
            "A-CycleGAN step at {0}x{0} on {1}: median {2:.1} ms, mean {3:.1} ms over {4} steps ({5} threads)",
            a.size, a.rt.device, r.median_ms, r.mean_ms, r.steps, r.threads
        );
    }
    Ok(cli::EXIT_OK)
}

pub(crate) fn cmd_bench_loader(a: LoaderArgs) -> anyhow::Result<u8> {
    let ds = Dataset::open(&a.dataset.root)?;
    let v = ds.resolve(a.dataset.version)?;
    let set = TrainingSet::load(
        &ds,
        v,
        &DataOptions {
            alignment: a.alignment.clone(),
            no_alignments: false,
        },
    )?;
    let r = milv_train::gan::train::bench_loader(Arc::new(set), a.size, a.batch, a.workers, a.batches)?;
    // A step consumes six images per sample (x, y, an aligned pair, a transition).
    let needed = a.step_ms.map(|ms| (6 * a.batch) as f64 / (ms / 1e3));
    if a.rt.json {
        cli::print_json(
            &serde_json::json!({"loader": r, "step_ms": a.step_ms, "consumed_frames_per_s": needed,
            "ratio": needed.map(|n| r.frames_per_s / n)}),
        )?;
    } else {
        println!(
            "loader: {:.0} frames/s ({:.1} batches/s) on {} workers at {}x{}",
            r.frames_per_s, r.batches_per_s, r.workers, a.size, a.size
        );
        if let Some(n) = needed {
            println!(
                "a {:.0} ms step consumes {n:.0} frames/s: the loader is {:.1}x ahead",
                a.step_ms.unwrap_or(0.0),
                r.frames_per_s / n
            );
        }
    }
    Ok(cli::EXIT_OK)
}
