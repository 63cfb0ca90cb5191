//! `milv-score`: frame-quality scores (Brenner × SSIM = β_qua, `shared/spec/quality.md`).

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::{Parser, Subcommand};
use milv::cli;
use milv::data::{CommitMeta, Dataset, DatasetRef, Partition};
use milv::quality::{Rgb, SsimMode, beta_video, ssim};
use milv::score::{CurateOptions, Rule, RunOptions, Source, curate, score_dataset, summarize};
use milv::video::DecodeOptions;

/// Score video frames by sharpness (Brenner) and temporal consistency (SSIM with the next
/// frame), the paper's β_qua.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Scores every frame of a dataset version (recorded `frames`, or the `imagined`
    /// translations of one model) and commits the `scores` table as a new version:
    /// brenner_raw, brenner, ssim (with the next frame), beta, and the weight normalised
    /// over the run (parameters in each file's `milv.scores` metadata and the commit).
    /// Episodes are scored in parallel while the table streams. Any episode that cannot
    /// be scored (undecodable frame, one frame, mixed sizes) fails the run with nothing
    /// committed, unless --skip-bad. Re-running a finished run is a no-op.
    Run {
        /// DATASET or DATASET@VERSION to read (the new version is added on top of the latest).
        dataset: DatasetRef,
        /// frames: recorded frames; imagined: translated human frames.
        #[arg(long, value_enum, default_value_t = SourceArg::Frames)]
        table: SourceArg,
        /// Translation model to score (needed when the imagined table holds several).
        #[arg(long)]
        model_id: Option<String>,
        /// Only these episode ids (comma-separated or repeated).
        #[arg(long, value_delimiter = ',')]
        episodes: Vec<String>,
        /// Only this domain: human or robot (default: both).
        #[arg(long)]
        domain: Option<milv::data::Domain>,
        /// Episodes scored at once (default: all cores).
        #[arg(long)]
        jobs: Option<usize>,
        /// Score only share i of n of the episodes (array jobs): i/n. Workers share one
        /// run id; weights are then computed by `curate` over all of them.
        #[arg(long)]
        partition: Option<Partition>,
        /// Commit the episodes that scored, list the others, exit 3.
        #[arg(long)]
        skip_bad: bool,
        #[arg(long)]
        json: bool,
    },
    /// Commits the curated view the trainer reads: the frames of a scoring run whose
    /// set-normalised weight passes a rule, with their weights. Replaces the previous view.
    Curate {
        /// DATASET (curation applies to the latest version).
        dataset: DatasetRef,
        /// Keep frames with weight >= X.
        #[arg(
            long,
            conflicts_with = "top_fraction",
            required_unless_present = "top_fraction"
        )]
        min_weight: Option<f64>,
        /// Keep the best fraction F of the frames by weight.
        #[arg(long)]
        top_fraction: Option<f64>,
        /// Drop an episode keeping fewer than this fraction of its frames.
        #[arg(long, default_value_t = 0.5)]
        min_episode_fraction: f64,
        /// Scoring run to curate (default: the newest).
        #[arg(long)]
        run: Option<String>,
        #[arg(long)]
        json: bool,
    },
    /// Summarises a scoring run: per-episode mean/min beta (worst first), the worst
    /// frames, and with --out a beta histogram and per-episode beta curves as PNG.
    Report {
        dataset: DatasetRef,
        /// Scoring run (default: the newest).
        #[arg(long)]
        run: Option<String>,
        /// How many worst frames and episodes to list.
        #[arg(long, default_value_t = 10)]
        worst: usize,
        /// Folder for beta_hist.png and beta_curves.png.
        #[arg(long, short)]
        out: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Times one frame's β (Brenner of A + gray SSIM of A and B) on one thread, in process;
    /// used by tools/bench/score.py.
    Bench {
        a: PathBuf,
        b: PathBuf,
        #[arg(long, default_value_t = 200)]
        iters: usize,
        #[arg(long)]
        json: bool,
    },
    /// Scores one clip without any dataset: a folder of numbered PNG/JPEG frames or a video
    /// file. Prints one line per frame: frame, brenner_raw, brenner, brenner_h, ssim (gray,
    /// with the next frame; the last frame reuses the last pair), ssim_rgb, beta; with
    /// --json as JSON lines with full f64 precision.
    Frames {
        /// Frame folders or video files.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        #[arg(long)]
        json: bool,
    },
}

fn score_clip(path: &std::path::Path, json: bool) -> anyhow::Result<()> {
    // Folders need a rate to be read as a clip; it does not affect the scores.
    let source = milv::video::open_frames(path, Some(10.0), &DecodeOptions::default())
        .with_context(|| format!("opening {}", path.display()))?;
    let frames: Vec<milv::video::Frame> = source.collect::<Result<_, _>>()?;
    if frames.len() < 2 {
        bail!(
            "{} frame(s): a clip needs at least 2 to score: {}",
            frames.len(),
            path.display()
        );
    }
    let imgs: Vec<Rgb<'_>> = frames
        .iter()
        .map(|f| Rgb::new(&f.data, f.width as usize, f.height as usize))
        .collect::<Result<_, _>>()
        .with_context(|| format!("frame sizes differ in {}", path.display()))?;
    let scores = beta_video(&imgs).with_context(|| format!("scoring {}", path.display()))?;
    let mut out = std::io::stdout().lock();
    for (t, s) in scores.iter().enumerate() {
        let (a, b) = if t + 1 < imgs.len() {
            (imgs[t], imgs[t + 1])
        } else {
            (imgs[t - 1], imgs[t])
        };
        let ssim_rgb = ssim(a, b, SsimMode::Rgb)?;
        if json {
            writeln!(
                out,
                "{}",
                serde_json::json!({
                    "source": path.display().to_string(), "frame": t,
                    "brenner_raw": s.brenner.raw, "brenner": s.brenner.normalized,
                    "brenner_h": s.brenner.horizontal, "ssim": s.ssim, "ssim_rgb": ssim_rgb, "beta": s.beta,
                })
            )?;
        } else {
            writeln!(
                out,
                "{}\t{t}\t{:.6e}\t{:.9}\t{:.9}\t{:.9}\t{:.9}\t{:.9}",
                path.display(),
                s.brenner.raw,
                s.brenner.normalized,
                s.brenner.horizontal,
                s.ssim,
                ssim_rgb,
                s.beta
            )?;
        }
    }
    Ok(())
}

fn load(p: &std::path::Path) -> anyhow::Result<image::RgbImage> {
    Ok(image::open(p)
        .with_context(|| format!("reading {}", p.display()))?
        .into_rgb8())
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum SourceArg {
    Frames,
    Imagined,
}

fn writable(r: &DatasetRef) -> anyhow::Result<Dataset> {
    if r.version.is_some() {
        bail!("{r}: curation applies to the latest version; drop the @N");
    }
    Dataset::open(&r.root).with_context(|| format!("opening {r}"))
}

#[allow(clippy::too_many_arguments)]
fn score_run(
    dataset: DatasetRef,
    table: SourceArg,
    model_id: Option<String>,
    episodes: Vec<String>,
    domain: Option<milv::data::Domain>,
    jobs: Option<usize>,
    partition: Option<Partition>,
    skip_bad: bool,
    json: bool,
) -> anyhow::Result<u8> {
    let ds = Dataset::open(&dataset.root).with_context(|| format!("opening {dataset}"))?;
    let opts = RunOptions {
        source: match table {
            SourceArg::Frames => Source::Frames,
            SourceArg::Imagined => Source::Imagined,
        },
        model_id,
        episodes: (!episodes.is_empty()).then(|| episodes.into_iter().collect()),
        domain,
        jobs: jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        partition,
        skip_bad,
    };
    let bar = cli::bar(0, "frames scored");
    let rep = score_dataset(
        &ds,
        dataset.version,
        &opts,
        CommitMeta::for_this_process("milv-score", "score"),
        &|n| bar.inc(n),
    );
    bar.finish_and_clear();
    let rep = rep?;
    for f in &rep.failed {
        eprintln!("milv-score: error: {f}");
    }
    if json {
        cli::print_json(&rep)?;
    } else if rep.frames_scored == 0 {
        println!(
            "{}@{}: run {} already scored all {} selected episodes; nothing to do",
            ds.root().display(),
            rep.version,
            rep.run_id,
            rep.episodes_already_scored
        );
    } else {
        println!(
            "{}@{}: scored {} frames of {} episodes (run {}, read @{}); brenner in [{:.6}, {:.6}], mean beta {:.6}",
            ds.root().display(),
            rep.version,
            rep.frames_scored,
            rep.episodes_scored,
            rep.run_id,
            rep.read_version,
            rep.brenner_min.unwrap_or(f64::NAN),
            rep.brenner_max.unwrap_or(f64::NAN),
            rep.beta_mean.unwrap_or(f64::NAN),
        );
    }
    Ok(if rep.failed.is_empty() {
        cli::EXIT_OK
    } else {
        cli::EXIT_PARTIAL
    })
}

fn report(
    dataset: DatasetRef,
    run: Option<String>,
    worst: usize,
    out: Option<PathBuf>,
    json: bool,
) -> anyhow::Result<u8> {
    let ds = Dataset::open(&dataset.root).with_context(|| format!("opening {dataset}"))?;
    let s = summarize(&ds, dataset.version, run.as_deref(), worst)?;
    let mut plots = Vec::new();
    if let Some(dir) = &out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        plots = write_plots(&s, dir)?;
    }
    if json {
        let mut v = serde_json::to_value(&s)?;
        v["episodes"] = serde_json::to_value(s.episodes.iter().take(worst).collect::<Vec<_>>())?;
        v["episodes_total"] = s.episodes.len().into();
        v["plots"] = serde_json::to_value(&plots)?;
        cli::print_json(&v)?;
        return Ok(cli::EXIT_OK);
    }
    println!(
        "{}@{}  run {}  ({}{})",
        ds.root().display(),
        s.version,
        s.run_id,
        s.source_table,
        s.model_id
            .as_deref()
            .map(|m| format!(", model {m}"))
            .unwrap_or_default()
    );
    println!(
        "{} frames in {} episodes; beta mean {:.6}, min {:.6}, max {:.6}; brenner in [{:.6}, {:.6}]",
        s.frames,
        s.episodes.len(),
        s.beta_mean,
        s.beta_min,
        s.beta_max,
        s.brenner_min,
        s.brenner_max
    );
    println!("\nworst episodes (by mean beta):");
    println!(
        "{:<34} {:>6} {:>10} {:>10} {:>6}",
        "episode", "frames", "mean beta", "min beta", "at"
    );
    for e in s.episodes.iter().take(worst) {
        println!(
            "{:<34} {:>6} {:>10.6} {:>10.6} {:>6}",
            e.episode_id, e.frames, e.beta_mean, e.beta_min, e.worst_frame
        );
    }
    println!("\nworst frames:");
    println!(
        "{:<34} {:>6} {:>10} {:>10} {:>10}",
        "episode", "frame", "beta", "brenner", "ssim"
    );
    for f in &s.worst_frames {
        println!(
            "{:<34} {:>6} {:>10.6} {:>10.6} {:>10.6}",
            f.episode_id, f.frame_index, f.beta, f.brenner, f.ssim
        );
    }
    for p in &plots {
        println!("wrote {}", p.display());
    }
    Ok(cli::EXIT_OK)
}

fn run(args: Args) -> anyhow::Result<u8> {
    match args.cmd {
        Cmd::Run {
            dataset,
            table,
            model_id,
            episodes,
            domain,
            jobs,
            partition,
            skip_bad,
            json,
        } => {
            return score_run(
                dataset, table, model_id, episodes, domain, jobs, partition, skip_bad, json,
            );
        }
        Cmd::Curate {
            dataset,
            min_weight,
            top_fraction,
            min_episode_fraction,
            run,
            json,
        } => {
            let ds = writable(&dataset)?;
            let rule = match (min_weight, top_fraction) {
                (Some(x), _) => Rule::MinWeight(x),
                (None, Some(f)) => Rule::TopFraction(f),
                (None, None) => bail!("give --min-weight X or --top-fraction F"),
            };
            let opts = CurateOptions {
                run_id: run,
                rule,
                min_episode_fraction,
            };
            let r = curate(&ds, &opts, CommitMeta::for_this_process("milv-score", "curate"))?;
            if json {
                cli::print_json(&r)?;
            } else if r.unchanged {
                println!(
                    "{}@{}: the curated view already is curation {} (run {}); nothing to do",
                    ds.root().display(),
                    r.version,
                    r.curation_id,
                    r.run_id
                );
            } else {
                println!(
                    "{}@{}: curated {} of {} frames, {} of {} episodes (weight >= {:.6}, mean kept weight {:.4}; run {}, curation {})",
                    ds.root().display(),
                    r.version,
                    r.frames_kept,
                    r.frames_scored,
                    r.episodes_kept,
                    r.episodes_scored,
                    r.threshold,
                    r.mean_weight_kept,
                    r.run_id,
                    r.curation_id
                );
            }
        }
        Cmd::Report {
            dataset,
            run,
            worst,
            out,
            json,
        } => return report(dataset, run, worst, out, json),
        Cmd::Bench { a, b, iters, json } => {
            let (ia, ib) = (load(&a)?, load(&b)?);
            let (w, h) = (ia.width() as usize, ia.height() as usize);
            let ra = Rgb::new(ia.as_raw(), w, h)?;
            let rb = Rgb::new(ib.as_raw(), ib.width() as usize, ib.height() as usize)?;
            let mut scorer = milv::quality::Scorer::default();
            let first = scorer.beta_pair(ra, rb)?;
            let t0 = std::time::Instant::now();
            for _ in 0..iters.max(1) {
                std::hint::black_box(scorer.beta_pair(std::hint::black_box(ra), rb)?);
            }
            let per_frame = t0.elapsed().as_secs_f64() / iters.max(1) as f64;
            let v = serde_json::json!({"width": w, "height": h, "iters": iters, "seconds_per_frame": per_frame,
                "brenner": first.brenner.normalized, "ssim": first.ssim, "beta": first.beta});
            if json {
                println!("{v}")
            } else {
                println!(
                    "{w}x{h}: {:.1} µs per frame, beta {}",
                    per_frame * 1e6,
                    first.beta
                )
            }
        }
        Cmd::Frames { paths, json } => {
            if !json {
                writeln!(
                    std::io::stdout().lock(),
                    "source\tframe\tbrenner_raw\tbrenner\tbrenner_h\tssim\tssim_rgb\tbeta"
                )?;
            }
            let mut failed = 0;
            for p in &paths {
                match score_clip(p, json) {
                    Ok(()) => {}
                    Err(e) if e.downcast_ref::<std::io::Error>().is_some() => return Err(e),
                    Err(e) => {
                        eprintln!("milv-score: error: {e:#}");
                        failed += 1;
                    }
                }
            }
            if failed > 0 {
                return Ok(if failed == paths.len() {
                    cli::EXIT_FATAL
                } else {
                    cli::EXIT_PARTIAL
                });
            }
        }
    }
    Ok(cli::EXIT_OK)
}

/// β histogram and per-episode β curves (the worst 12 episodes by mean β) as PNG.
fn write_plots(s: &milv::score::Summary, dir: &std::path::Path) -> anyhow::Result<Vec<PathBuf>> {
    let hist = dir.join("beta_hist.png");
    let betas: Vec<f64> = s.curves.values().flatten().copied().collect();
    milv::plot::histogram_png(
        &hist,
        &betas,
        40,
        &format!("beta_qua of {} frames (run {})", betas.len(), s.run_id),
        "beta = brenner * (ssim + 1) / 2",
    )?;
    let curves = dir.join("beta_curves.png");
    let series: Vec<milv::plot::Series> = s
        .episodes
        .iter()
        .take(12)
        .filter_map(|e| {
            let c = s.curves.get(&e.episode_id)?;
            Some(milv::plot::Series {
                name: e.episode_id.chars().take(12).collect(),
                points: c.iter().enumerate().map(|(t, b)| (t as f64, *b)).collect(),
            })
        })
        .collect();
    milv::plot::lines_png(
        &curves,
        &series,
        &format!("beta per frame, worst {} episodes by mean beta", series.len()),
        "frame",
        "beta",
    )?;
    Ok(vec![hist, curves])
}

fn main() -> ExitCode {
    cli::finish("milv-score", run(Args::parse()))
}
