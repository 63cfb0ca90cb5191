//! `milv-align`: frame correspondences of loosely paired human/robot clips (banded DTW).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::{Parser, Subcommand};
use milv::align::{AlignOptions, StepPattern, align_dataset, features, load_pair};
use milv::cli;
use milv::data::{CommitMeta, Dataset, DatasetRef, Partition};

/// Aligns every pair of a dataset version (episodes sharing a pair_id: one human, one
/// robot clip of the same motion) by dynamic time warping inside a Sakoe-Chiba band, and
/// commits the `alignments` table (each frame of both clips with its partner and their cost) as a
/// new version. A pair whose path runs along the band's edge is aligned again in a wider
/// band (up to --max-band). Prints a per-pair summary: normalised cost, path length, the
/// band used, and a trust flag for pairs whose cost is high or whose path runs along the
/// widest band's edge.
///
///   milv-align DATASET[@V] [--features auto|motion|motion-hand|track|state|translated] [--band F] [--max-band F] [--jobs N]
///
///   milv-align show DATASET[@V] PAIR -o cost.png
#[derive(Parser, Debug)]
#[command(version, args_conflicts_with_subcommands = true)]
struct Args {
    #[command(subcommand)]
    cmd: Option<Cmd>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// DATASET or DATASET@VERSION to read (the new version is added on top of the latest).
    dataset: Option<DatasetRef>,
    #[command(flatten)]
    common: Common,
    /// Only these pair ids (comma-separated or repeated).
    #[arg(long, value_delimiter = ',')]
    pairs: Vec<String>,
    /// Pairs aligned at once (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Align only share i of n of the pairs (array jobs): i/n.
    #[arg(long)]
    partition: Option<Partition>,
    /// Ground-truth correspondences (JSON lines {pair_id, human_to_robot}, e.g. the
    /// warps.jsonl of `milv-sim gen` or tools/mujoco/paired_arms.py): report the frame
    /// error of each pair beside the proportional warp's (the baseline to beat).
    #[arg(long)]
    truth: Option<PathBuf>,
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args, Debug, Clone)]
struct Common {
    /// auto (default): motion for each pair whose motion cost says the table-plane model
    /// fits (milv-sim-like scenes), else track (robot clips with states), unless only
    /// motion's cost is within its trust bound or the human clip's tracked points travel
    /// less than a tenth as far as motion's tip (a pushed object, not the hand: motion's
    /// cost decides, flagged if untrusted, and motion-hand aligns where trusted); where
    /// motion fits, track instead when its path stays off the band's edge and its points
    /// travel as far as motion's tip (on the hand; points seeded through the clip or in its first frame, whichever fit costs
    /// less), else motion-hand (motion's features from the hand region, deeper than the
    /// tip, nearer the end effector); the report names the kind used per pair;
    /// motion: progress and heading of the arm's tip, tracked from frame differences and
    /// mapped onto the table plane (any clip); motion-hand: the same from the hand region,
    /// deeper in the moving pixels than the tip, measured from where the arm enters the
    /// picture (nearer the end effector); track: the human's hand followed by image
    /// feature points, against the robot's end-effector states mapped into the human's
    /// view by an affine camera fitted per pair (robot clips need states; no scene
    /// assumption); state: the episodes' state vectors (e.g.
    /// end-effector position); translated: the human clip translated to the robot domain
    /// (imagined table) against the robot frames.
    #[arg(long, default_value = "auto")]
    features: String,
    /// Band half-width as a fraction of the longer clip.
    #[arg(long, default_value_t = 0.2)]
    band: f64,
    /// A pair whose path runs along the band's edge (the band may have cut it short) is
    /// aligned again in a band 0.1 wider, up to this width; a path still on the edge of
    /// the widest is flagged untrusted. Default 0.4 (or --band, if wider); at most --band:
    /// never widen.
    #[arg(long)]
    max_band: Option<f64>,
    /// symmetric1 | symmetric2 | asymmetric (each human frame gets one robot frame).
    #[arg(long, default_value = "symmetric2")]
    step: StepPattern,
    /// Translation model for --features translated (default: the only one).
    #[arg(long)]
    model_id: Option<String>,
    /// Pairs above this normalised cost per feature dimension are flagged untrusted
    /// (default per feature kind: motion 0.002, track 0.01, state 0.002, translated 0.5;
    /// auto: that of the kind it picked for the pair, and none for track where it replaced
    /// motion, whose cost vouched for the pair).
    #[arg(long)]
    max_cost: Option<f64>,
    /// Each frame's partner is its median over all warping paths in the band, weighted
    /// by exp(−cost / T) with T this many times the best path's mean local cost: where
    /// several paths explain the clips almost equally, the median lies between them
    /// (0: the best path's own cells, classic DTW). Costs and trust always rate the best
    /// path.
    #[arg(long, default_value_t = milv::align::POSTERIOR_TEMPERATURE)]
    temperature: f64,
    /// Take the proportional warp, round(i·(m−1)/(n−1)) for human frame i of n and m
    /// robot frames, for a pair whose partners (the posterior medians, see --temperature)
    /// lie on average within K posterior standard deviations of it: where the features
    /// cannot tell the two apart, a pair that switches scores exactly as stretching one
    /// clip onto the other does. Costs mean accuracy: at 1.3, on the evaluation sets of
    /// BENCHMARKS.md, trusted pairs worse than the proportional warp fall 4 → 2, but 40 of
    /// the 44 pairs it switches get worse. The report marks such pairs (proportional:
    /// true); every pair's mean posterior spread is reported as posterior_sd. 0 (default):
    /// never; no effect with --temperature 0.
    #[arg(long, value_name = "K", default_value_t = 0.0)]
    proportional_within: f64,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Times banded DTW (symmetric1, squared Euclidean local cost, |i − j| < WINDOW as
    /// dtaidistance's `window`) on two feature files of raw little-endian f64 (frames ×
    /// DIM); used by tools/bench/align.py.
    Bench {
        a: PathBuf,
        b: PathBuf,
        #[arg(long)]
        dim: usize,
        #[arg(long)]
        window: usize,
        #[arg(long, default_value_t = 10)]
        iters: usize,
    },
    /// Writes a PNG of one pair's cost matrix (human frames down, robot frames across)
    /// with each frame's partner (the cells the run writes to the alignments table), to
    /// see whether an alignment can be trusted.
    Show {
        dataset: DatasetRef,
        pair: String,
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        common: Common,
    },
}

fn options(c: &Common) -> AlignOptions {
    AlignOptions {
        band: c.band,
        max_band: c.max_band.unwrap_or(milv_align::align::MAX_BAND),
        step: c.step,
        model_id: c.model_id.clone(),
        max_cost: c.max_cost,
        temperature: c.temperature,
        proportional_within: c.proportional_within,
        ..AlignOptions::default()
    }
}

fn read_truth(path: &std::path::Path) -> anyhow::Result<BTreeMap<String, Vec<usize>>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = BTreeMap::new();
    for (k, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let v: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("{}:{}: not JSON", path.display(), k + 1))?;
        let (Some(p), Some(m)) = (v["pair_id"].as_str(), v["human_to_robot"].as_array()) else {
            bail!("{}:{}: needs pair_id and human_to_robot", path.display(), k + 1);
        };
        let m: Option<Vec<usize>> = m.iter().map(|x| x.as_u64().map(|x| x as usize)).collect();
        out.insert(
            p.to_string(),
            m.with_context(|| format!("{}:{}: bad frame numbers", path.display(), k + 1))?,
        );
    }
    Ok(out)
}

fn run_align(a: RunArgs) -> anyhow::Result<u8> {
    let Some(dataset) = a.dataset else {
        bail!("give a DATASET (see --help)");
    };
    if let Some(j) = a.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(j.max(1))
            .build_global()?;
    }
    let kind = features::by_name(&a.common.features)?;
    let mut opts = options(&a.common);
    opts.pairs = (!a.pairs.is_empty()).then(|| a.pairs.into_iter().collect());
    opts.partition = a.partition;
    if let Some(t) = &a.truth {
        opts.truth = read_truth(t)?;
    }
    let ds = Dataset::open(&dataset.root).with_context(|| format!("opening {dataset}"))?;
    let bar = cli::bar(0, "pairs aligned");
    let rep = align_dataset(
        &ds,
        dataset.version,
        kind,
        &opts,
        CommitMeta::for_this_process("milv-align", "align"),
        &|| bar.inc(1),
    );
    bar.finish_and_clear();
    let rep = rep?;
    for f in &rep.failed {
        eprintln!("milv-align: error: pair {}: {}", f.pair_id, f.message);
    }
    if a.json {
        cli::print_json(&rep)?;
    } else if rep.pairs.is_empty() && rep.failed.is_empty() && rep.already_aligned > 0 {
        println!(
            "{}@{}: run {} already aligned all {} selected pairs; nothing to do",
            ds.root().display(),
            rep.version,
            rep.run_id,
            rep.already_aligned
        );
    } else {
        println!(
            "{}@{}: aligned {} pairs on {} features ({} rows, run {}, read @{})",
            ds.root().display(),
            rep.version,
            rep.pairs.len(),
            rep.features,
            rep.rows,
            rep.run_id,
            rep.read_version
        );
        let num = |e: Option<f64>| e.map_or("-".into(), |e| format!("{e:.2}"));
        println!(
            "{:<28} {:>6} {:>6} {:>16} {:>10} {:>6} {:>5} {:>7} {:>9} {:>9}",
            "pair",
            "human",
            "robot",
            "features",
            "cost/dim",
            "path",
            "band",
            "trusted",
            "err mean",
            "prop mean"
        );
        for p in &rep.pairs {
            println!(
                "{:<28} {:>6} {:>6} {:>16} {:>10.4} {:>6} {:>5.2} {:>7} {:>9} {:>9}",
                p.pair_id,
                p.human_frames,
                p.robot_frames,
                if p.proportional {
                    format!("{}>prop", p.features)
                } else {
                    p.features.clone()
                },
                p.cost_per_dim,
                p.path_length,
                p.band,
                if p.trusted { "yes" } else { "NO" },
                num(p.mean_frame_error),
                num(p.proportional_mean_error),
            );
        }
        let widened = rep.pairs.iter().filter(|p| p.band > opts.band).count();
        let untrusted = rep.pairs.iter().filter(|p| !p.trusted).count();
        println!(
            "{untrusted} of {} pairs untrusted; {widened} aligned in a band wider than --band {} (their path ran along its edge)",
            rep.pairs.len(),
            opts.band
        );
        if opts.proportional_within > 0.0 {
            println!(
                "{} took the proportional warp (>prop: their partners within --proportional-within {} posterior sd of it)",
                rep.pairs.iter().filter(|p| p.proportional).count(),
                opts.proportional_within
            );
        }
        if let (Some(m), Some(x), Some(pm)) = (
            rep.mean_frame_error,
            rep.max_frame_error,
            rep.proportional_mean_error,
        ) {
            println!(
                "frame error against ground truth: mean {m:.3}, max {x}; proportional warp: mean {pm:.3} ({:.2}x)",
                m / pm.max(1e-9)
            );
            if !rep.trusted_worse_than_proportional.is_empty() {
                println!(
                    "trusted but worse than the proportional warp: {}",
                    rep.trusted_worse_than_proportional.join(", ")
                );
            }
        }
    }
    Ok(match (rep.pairs.is_empty(), rep.failed.is_empty()) {
        (_, true) => cli::EXIT_OK,
        (true, false) => cli::EXIT_FATAL,
        (false, false) => cli::EXIT_PARTIAL,
    })
}

fn read_f64(path: &std::path::Path, dim: usize) -> anyhow::Result<milv::align::Features> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let data: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect();
    if dim == 0 || !data.len().is_multiple_of(dim) {
        bail!(
            "{}: {} values are not frames of {dim}",
            path.display(),
            data.len()
        );
    }
    Ok(milv::align::Features::new(data.len() / dim, dim, data)?)
}

fn bench(
    a: &std::path::Path,
    b: &std::path::Path,
    dim: usize,
    window: usize,
    iters: usize,
) -> anyhow::Result<u8> {
    use milv::align::{Band, dtw};
    let (fa, fb) = (read_f64(a, dim)?, read_f64(b, dim)?);
    let band = Band::absolute(fa.n, fb.n, window.saturating_sub(1));
    let time = |keep_path: bool| -> anyhow::Result<(f64, f64)> {
        let first = dtw(&fa, &fb, &band, StepPattern::Symmetric1, keep_path)?;
        let t0 = std::time::Instant::now();
        for _ in 0..iters.max(1) {
            std::hint::black_box(dtw(&fa, &fb, &band, StepPattern::Symmetric1, keep_path)?);
        }
        Ok((
            t0.elapsed().as_secs_f64() / iters.max(1) as f64,
            first.total.sqrt(),
        ))
    };
    let (t_dist, d) = time(false)?;
    let (t_path, _) = time(true)?;
    cli::print_json(&serde_json::json!({
        "n": fa.n, "m": fb.n, "dim": dim, "window": window, "cells": band.cells(),
        "seconds_distance": t_dist, "seconds_with_path": t_path, "distance": d,
        // What the DP keeps: two cost rows, plus one byte per band cell for the path.
        "bytes_distance": 2 * fb.n * 8, "bytes_with_path": band.cells() + 2 * fb.n * 8,
    }))?;
    Ok(cli::EXIT_OK)
}

fn run(args: Args) -> anyhow::Result<u8> {
    match args.cmd {
        None => run_align(args.run),
        Some(Cmd::Bench {
            a,
            b,
            dim,
            window,
            iters,
        }) => bench(&a, &b, dim, window, iters),
        Some(Cmd::Show {
            dataset,
            pair,
            out,
            common,
        }) => {
            let ds = Dataset::open(&dataset.root).with_context(|| format!("opening {dataset}"))?;
            let kind = features::by_name(&common.features)?;
            let opts = options(&common);
            let fit = load_pair(&ds, dataset.version, &pair, kind, &opts)?;
            let corr = fit.correspondence(&opts)?;
            let (h, r, al) = (&fit.human, &fit.robot, &fit.alignment);
            let cost: Vec<f64> = (0..h.n)
                .flat_map(|i| (0..r.n).map(move |j| (i, j)))
                .map(|(i, j)| milv::align::dtw::sq_dist(h.row(i), r.row(j)))
                .collect();
            milv::plot::heatmap_png(
                &out,
                &cost,
                h.n,
                r.n,
                &format!(
                    "pair {pair}: {} cost, normalised {:.4}, band {}",
                    if fit.kind.name() == kind.name() {
                        kind.name().to_string()
                    } else {
                        format!("{} → {}", kind.name(), fit.kind.name())
                    },
                    al.normalized,
                    fit.band
                ),
                "robot frame",
                "human frame",
                Some(&corr.cells.iter().map(|&(i, j, _)| (i, j)).collect::<Vec<_>>()),
            )?;
            println!("wrote {}", out.display());
            Ok(cli::EXIT_OK)
        }
    }
}

fn main() -> ExitCode {
    cli::finish("milv-align", run(Args::parse()))
}
