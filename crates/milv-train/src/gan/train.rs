//! The training loop around [`ACycleGan::step`]: prefetched batches, JSON-lines losses,
//! translation grids, periodic evaluation, checkpoints and resume.
//!
//! A run folder holds `losses.jsonl` (one line per step), `eval.jsonl` (one line per
//! evaluation), `grids/step-N.png` (rows of human | G(human) | F(G(human))) and
//! `checkpoints/step-N/`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;
use tch::nn::Module;

use crate::gan::checkpoint;
use crate::gan::cyclegan::{ACycleGan, Losses};
use crate::gan::data::{Loader, TrainingSet};
use crate::gan::eval::{EvalReport, EvalSet, evaluate_translation};
use crate::run::DataRef;
use crate::run::image::to_rgb;
use crate::run::log::{append_json, truncate_after};
use crate::run::time_steps;
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Translation grid every N steps (0: never).
    pub grid_every: u64,
    pub checkpoint_every: u64,
    pub eval_every: u64,
    /// Decoding threads and batches decoded ahead.
    pub workers: usize,
    pub prefetch: usize,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            out: PathBuf::from("run"),
            grid_every: 500,
            checkpoint_every: 1000,
            eval_every: 0,
            workers: 2,
            prefetch: 8,
        }
    }
}

/// One line of `losses.jsonl`.
#[derive(Clone, Debug, Serialize)]
pub struct StepLog {
    pub step: u64,
    #[serde(flatten)]
    pub losses: Losses,
    /// Wall time of the optimisation step.
    pub step_ms: f64,
    /// Time the step waited for its batch (0 when the loader kept ahead).
    pub wait_ms: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct TrainReport {
    pub steps_run: u64,
    pub step: u64,
    pub mean_step_ms: f64,
    /// Steps whose batch was not ready when asked for.
    pub waited_steps: u64,
    pub last: Option<Losses>,
    pub checkpoint: Option<PathBuf>,
    pub model_id: Option<String>,
    pub eval: Option<EvalReport>,
}

/// Trains `run` up to `run.train.steps`, from wherever it stands (a resumed run starts
/// at its checkpoint's step and draws the same batches an uninterrupted run would).
pub fn train_cyclegan(
    run: &mut ACycleGan,
    set: Arc<TrainingSet>,
    data: &DataRef,
    eval: Option<&EvalSet>,
    opts: &RunOptions,
    on_step: &mut dyn FnMut(&StepLog),
) -> Result<TrainReport> {
    for d in [opts.out.clone(), opts.out.join("grids")] {
        std::fs::create_dir_all(&d).map_err(Error::io("create folder", &d))?;
    }
    let losses_path = opts.out.join("losses.jsonl");
    let eval_path = opts.out.join("eval.jsonl");
    for log in [&losses_path, &eval_path] {
        truncate_after(log, run.step)?;
    }
    let ckpt_dir = opts.out.join("checkpoints");
    let size = run.model.image_size as u32;
    let grid_src = grid_inputs(&set, size)?;
    let mut loader = Loader::start(
        set.clone(),
        run.train.seed,
        run.step,
        crate::gan::data::BatchShape {
            images: run.train.batch as usize,
            transitions: run.train.idm_batch as usize,
        },
        size,
        opts.workers,
        opts.prefetch,
    );
    let mut report = TrainReport {
        steps_run: 0,
        step: run.step,
        mean_step_ms: 0.0,
        waited_steps: 0,
        last: None,
        checkpoint: None,
        model_id: None,
        eval: None,
    };
    let mut total_ms = 0.0;
    while run.step < run.train.steps {
        let t0 = Instant::now();
        let (batch, waited) = loader.next_batch()?;
        let wait_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let losses = run.step(&batch);
        let step_ms = t1.elapsed().as_secs_f64() * 1e3;
        if !losses.generators.is_finite() {
            return Err(Error::Data(format!(
                "step {}: the generators' loss is {} (diverged); lower --lr or --lr-idm",
                run.step, losses.generators
            )));
        }
        total_ms += step_ms;
        report.steps_run += 1;
        report.waited_steps += u64::from(waited);
        let line = StepLog {
            step: run.step,
            losses,
            step_ms,
            wait_ms,
        };
        append_json(&losses_path, &line)?;
        on_step(&line);
        let at = |every: u64| every > 0 && run.step.is_multiple_of(every);
        if at(opts.grid_every) || run.step == run.train.steps {
            write_grid(
                run,
                &grid_src,
                &opts.out.join("grids").join(format!("step-{:08}.png", run.step)),
            )?;
        }
        if let Some(e) = eval
            && (at(opts.eval_every) || (opts.eval_every > 0 && run.step == run.train.steps))
        {
            let mut r = evaluate_translation(&run.nets, e, &run.model)?;
            r.step = run.step;
            append_json(&eval_path, &r)?;
            report.eval = Some(r);
        }
        if at(opts.checkpoint_every) || run.step == run.train.steps {
            let dir = checkpoint::save(run, data, &ckpt_dir)?;
            report.model_id = Some(checkpoint::read_meta(&dir)?.model_id);
            report.checkpoint = Some(dir);
        }
        report.last = Some(line.losses);
    }
    report.step = run.step;
    report.mean_step_ms = total_ms / report.steps_run.max(1) as f64;
    Ok(report)
}

/// Four human frames spread over the training set, as one batch tensor's data.
fn grid_inputs(set: &TrainingSet, size: u32) -> Result<Vec<f32>> {
    let n = set.human.len();
    let mut out = Vec::new();
    for k in 0..4usize.min(n.max(1)) {
        let c = &set.human[k * n / 4.min(n).max(1)];
        out.extend(c.tensor_data(c.frames.len() / 2, size)?);
    }
    Ok(out)
}

/// Rows of human | G(human) | F(G(human)).
pub fn write_grid(run: &ACycleGan, src: &[f32], path: &Path) -> Result<()> {
    let s = run.model.image_size;
    let x = run.images(src);
    let (fake, back) = tch::no_grad(|| {
        let f = run.nets.g.forward(&x);
        let b = run.nets.f.forward(&f);
        (f, b)
    });
    let rows = x.size()[0];
    let (w, h) = (3 * s as u32, rows as u32 * s as u32);
    let mut img = image::RgbImage::new(w, h);
    for r in 0..rows {
        for (col, t) in [&x, &fake, &back].iter().enumerate() {
            let rgb = to_rgb(&t.get(r))?;
            let tile = image::RgbImage::from_raw(s as u32, s as u32, rgb).unwrap_or_default();
            image::imageops::replace(&mut img, &tile, col as i64 * s, r * s);
        }
    }
    img.save(path).map_err(|e| Error::Write {
        what: "translation grid",
        source: Box::new(e),
        path: path.to_path_buf(),
    })
}

/// Timings of [`bench_steps`].
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub steps: u64,
    pub median_ms: f64,
    pub mean_ms: f64,
    pub min_ms: f64,
    pub threads: i32,
    pub image_size: i64,
}

/// Times full A-CycleGAN steps (batch 1, every loss) on fixed random images, after
/// `warmup` untimed steps.
pub fn bench_steps(
    model: crate::ModelConfig,
    device: tch::Device,
    warmup: u64,
    steps: u64,
) -> Result<BenchReport> {
    let s = model.image_size;
    let mut run = ACycleGan::new(model.clone(), crate::TrainConfig::default(), device)?;
    let img = |seed: u64| -> Vec<f32> {
        // A cheap deterministic pattern in [-1, 1].
        (0..3 * s * s)
            .map(|i| (((i as u64).wrapping_mul(2_654_435_761) ^ seed) % 2001) as f32 / 1000.0 - 1.0)
            .collect()
    };
    let b = crate::gan::data::Batch {
        step: 0,
        x: img(1),
        y: img(2),
        ph: img(3),
        pr: img(4),
        yt: img(5),
        yt1: img(6),
        actions: vec![0.5; model.action_dim as usize],
    };
    let t = time_steps(warmup, steps, &mut || {
        run.step(&b);
    });
    Ok(BenchReport {
        steps: t.steps,
        median_ms: t.median_ms,
        mean_ms: t.mean_ms,
        min_ms: t.min_ms,
        threads: tch::get_num_threads(),
        image_size: s,
    })
}

/// The loader's throughput, against what training consumes.
#[derive(Clone, Debug, Serialize)]
pub struct LoaderBench {
    pub batches: u64,
    pub workers: usize,
    /// Images decoded per second (six per sample: x, y, an aligned pair, a transition).
    pub frames_per_s: f64,
    pub batches_per_s: f64,
}

/// Decodes `batches` batches through the prefetching [`Loader`] as fast as it goes.
pub fn bench_loader(
    set: Arc<TrainingSet>,
    size: u32,
    batch: usize,
    workers: usize,
    batches: u64,
) -> Result<LoaderBench> {
    let per_batch = batch * if set.pairs.is_empty() { 4 } else { 6 };
    let shape = crate::gan::data::BatchShape {
        images: batch,
        transitions: batch,
    };
    let mut loader = Loader::start(set, 0, 0, shape, size, workers, 16);
    // The first batch pays for thread start-up.
    loader.next_batch()?;
    let t = Instant::now();
    for _ in 0..batches {
        loader.next_batch()?;
    }
    let secs = t.elapsed().as_secs_f64().max(1e-9);
    Ok(LoaderBench {
        batches,
        workers,
        frames_per_s: (batches as usize * per_batch) as f64 / secs,
        batches_per_s: batches as f64 / secs,
    })
}

/// Learning curves of runs (their `eval.jsonl`) as PNG charts in `out`: SSIM of the
/// translations against ground truth, and π_I's action error. Returns the files written.
pub fn plot_runs(runs: &[PathBuf], out: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).map_err(Error::io("create folder", out))?;
    let mut ssim = Vec::new();
    let mut act = Vec::new();
    let mut baseline: Option<(f64, f64)> = None;
    for r in runs {
        let path = r.join("eval.jsonl");
        let text = std::fs::read_to_string(&path).map_err(Error::io("read", &path))?;
        let name = r
            .file_name()
            .map_or_else(|| r.display().to_string(), |n| n.to_string_lossy().into_owned());
        let (mut s, mut a) = (Vec::new(), Vec::new());
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let v: serde_json::Value =
                serde_json::from_str(line).map_err(|e| Error::Data(format!("{}: {e}", path.display())))?;
            let step = v["step"].as_f64().unwrap_or(0.0);
            if let Some(x) = v["ssim"].as_f64() {
                s.push((step, x));
            }
            if let Some(x) = v["action_mae"].as_f64() {
                a.push((step, x));
            }
            if let (Some(u), Some(z)) = (v["ssim_untranslated"].as_f64(), v["action_mae_zero"].as_f64()) {
                baseline = Some((u, z));
            }
        }
        ssim.push(milv_plot::Series {
            name: name.clone(),
            points: s,
        });
        act.push(milv_plot::Series { name, points: a });
    }
    let span = |series: &[milv_plot::Series]| {
        let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
        (
            xs.clone().fold(f64::INFINITY, f64::min),
            xs.fold(f64::NEG_INFINITY, f64::max),
        )
    };
    if let Some((u, z)) = baseline {
        let (lo, hi) = span(&ssim);
        ssim.push(milv_plot::Series {
            name: "untranslated human frame".into(),
            points: vec![(lo, u), (hi, u)],
        });
        act.push(milv_plot::Series {
            name: "always predict 0".into(),
            points: vec![(lo, z), (hi, z)],
        });
    }
    let files = [out.join("ssim.png"), out.join("action_mae.png")];
    let plot = |p: &Path, s: &[milv_plot::Series], title: &str, y: &str| {
        milv_plot::lines_png(p, s, title, "training step", y).map_err(|e| Error::Write {
            what: "chart",
            source: Box::new(e),
            path: p.to_path_buf(),
        })
    };
    plot(
        &files[0],
        &ssim,
        "SSIM(G(human), ground-truth robot frame), held-out tasks",
        "SSIM",
    )?;
    plot(
        &files[1],
        &act,
        "inverse dynamics on held-out robot random videos",
        "action MAE (cm)",
    )?;
    Ok(files.to_vec())
}
