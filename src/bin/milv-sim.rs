//! `milv-sim`: generate human/robot tabletop videos with action sidecars, render a contact
//! sheet, and run the scripted experts through the evaluator.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand, ValueEnum};
use milv::cli;
use milv::ingest::{EpisodeMeta, Sidecar};
use milv::sim::env::{
    Rollout, Sim, SmoothRandom, Task, blind_expert_action, evaluate, expert_action, paired_clips, rollout,
};
use milv::sim::render::{Domain, Randomization};
use milv::sim::shapes::{self, Shape};
use milv::video::{Codec, VideoWriter};
use rand::{Rng, SeedableRng};

/// The MILV tabletop: a human (camera A) and a robot (camera B) drawing on a table.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Split {
    /// The 11 training shapes.
    Train,
    /// The 12 held-out test shapes.
    Test,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Family {
    /// Trace a red guide shape (11 train / 12 test shapes).
    Drawing,
    /// Push the target object into a 12×12 cm square past a distractor (10 / 8 objects).
    Pushing,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Writes episodes as MP4 (H.264) + `milv-sidecar/1` JSON + a manifest.jsonl that
    /// `milv-ingest DATASET --manifest OUT/manifest.jsonl` reads: per task instance a
    /// human expert demo, a robot expert demo and a robot random-motion clip, and a loosely
    /// paired human/robot pair (same motion, random monotone time warps, different
    /// lengths), all with actions and states; deterministic by seed. Also writes
    /// `warps.jsonl` (ground-truth frame correspondence of each pair) and
    /// `ground_truth.jsonl` (robot demo = ground-truth robot rendering of each human demo)
    /// and `instances.jsonl` (each task instance, for `milv-train eval --instances`).
    Gen {
        /// Task family.
        #[arg(long, value_enum, default_value = "drawing")]
        task: Family,
        /// Episodes per kind (human demos, robot random).
        #[arg(long, default_value_t = 4)]
        episodes: usize,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long, value_enum, default_value = "train")]
        split: Split,
        /// Frame size in pixels (square).
        #[arg(long, default_value_t = 128)]
        size: u32,
        /// Randomise lighting, table texture, camera pose and clutter per episode
        /// (demo and random clips).
        #[arg(long)]
        randomize: bool,
        #[arg(long)]
        out: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Renders a PNG grid: rows of human and robot frames of the same expert motion.
    ContactSheet {
        #[arg(long, default_value_t = 96)]
        size: u32,
        #[arg(long)]
        out: PathBuf,
    },
    /// Measures rendering + stepping speed on one thread (expert drawing episodes).
    Bench {
        #[arg(long, default_value_t = 128)]
        size: u32,
        /// Episodes per domain.
        #[arg(long, default_value_t = 100)]
        episodes: usize,
        #[arg(long)]
        json: bool,
    },
    /// Runs the scripted expert (upper bound) and a random policy (lower bound) on every
    /// shape of a split and prints the success table. Pushing adds the "blind" baseline:
    /// both objects' experts averaged, where behaviour cloning that cannot tell the target
    /// from the distractor lands.
    EvalExpert {
        #[arg(long, value_enum, default_value = "drawing")]
        task: Family,
        #[arg(long, value_enum, default_value = "test")]
        split: Split,
        /// Random-policy trials per shape.
        #[arg(long, default_value_t = 5)]
        trials: usize,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long)]
        json: bool,
    },
}

fn shapes_of(split: Split) -> Vec<Shape> {
    match split {
        Split::Train => shapes::training_shapes(),
        Split::Test => shapes::test_shapes(),
    }
}

fn write_episode(out: &Path, name: &str, r: &Rollout, size: u32, meta: EpisodeMeta) -> anyhow::Result<()> {
    let video = out.join(format!("{name}.mp4"));
    let mut w = VideoWriter::create(&video, size, size, 10, Codec::H264)?;
    for f in &r.frames {
        w.write(f)?;
    }
    w.finish()?;
    let rows = |v: &[[f32; 2]]| Some(v.iter().map(|a| a.to_vec()).collect());
    let sidecar = Sidecar {
        path: out.join(format!("{name}.json")),
        meta,
        action_names: Some(vec!["dx".into(), "dy".into()]),
        state_names: Some(vec!["x".into(), "y".into()]),
        actions: rows(&r.actions),
        states: rows(&r.states),
    };
    sidecar
        .write(&sidecar.path)
        .with_context(|| format!("writing the sidecar of {}", video.display()))?;
    Ok(())
}

/// A task: a shape placed somewhere on the table, or a pushing layout.
fn sample_task(family: Family, split: Split, rng: &mut rand::rngs::StdRng) -> anyhow::Result<Task> {
    match family {
        Family::Drawing => {
            let pool = shapes_of(split);
            let mut shape = pool[rng.random_range(0..pool.len())].clone();
            // Each episode places the shape elsewhere on the table, so demos of one task differ.
            let offset = milv::sim::Vec2::new(rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0));
            for p in &mut shape.path {
                *p += offset;
            }
            Ok(Task::Drawing { shape })
        }
        Family::Pushing => {
            let (train, test) = milv::sim::push::object_catalog();
            let objs = match split {
                Split::Train => train,
                Split::Test => test,
            };
            milv::sim::env::pushing_task(&objs, rng).context("object catalogue too small")
        }
    }
}

fn generate(
    family: Family,
    split: Split,
    episodes: usize,
    seed: u64,
    size: u32,
    randomize: bool,
    out: &Path,
) -> anyhow::Result<Vec<serde_json::Value>> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let split_name = match split {
        Split::Train => "train",
        Split::Test => "test",
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut manifest = Vec::new();
    let mut ground_truth = Vec::new();
    let mut instances = Vec::new();
    let mut warps = Vec::new();
    let pb = cli::bar(4 * episodes as u64, "episodes");
    for i in 0..episodes {
        let task = sample_task(family, split, &mut rng)?;
        // Human demos (MILV's training data), robot demos (only the DAML baseline uses
        // them) and robot random motion (A-CycleGAN's inverse dynamics).
        for (domain, kind) in [
            (Domain::Human, "demo"),
            (Domain::Robot, "demo"),
            (Domain::Robot, "random"),
        ] {
            let look = if randomize {
                Randomization::all(seed.wrapping_mul(7919).wrapping_add(i as u64))
            } else {
                Randomization::default()
            };
            let sim = Sim::reset_with(task.clone(), domain, size, &look).context("empty shape")?;
            let r = if kind == "demo" {
                rollout(sim, expert_action)
            } else {
                let mut policy = SmoothRandom::new(seed.wrapping_mul(1_000_003).wrapping_add(i as u64));
                rollout(sim, |s| policy.act(s))
            };
            let name = format!("{}_{}_{kind}_{i:04}", task.family(), domain.name());
            let meta = EpisodeMeta {
                domain: Some(domain.name().into()),
                kind: Some(kind.into()),
                task_id: Some(task.id()),
                task_family: Some(task.family().into()),
                split: Some(split_name.into()),
                ..EpisodeMeta::default()
            };
            write_episode(out, &name, &r, size, meta)?;
            manifest.push(
                serde_json::json!({"path": format!("{name}.mp4"), "sidecar": format!("{name}.json"),
                "success": r.success, "score": r.score}),
            );
            pb.inc(1);
        }
        // The human demo and the robot demo of one instance share every state: frame k of
        // the robot demo is the ground-truth robot rendering of frame k of the human demo.
        let stem = format!("{}_{{}}_demo_{i:04}", task.family());
        ground_truth.push(serde_json::json!({
            "human": format!("{}.mp4", stem.replace("{}", "human")),
            "robot": format!("{}.mp4", stem.replace("{}", "robot")),
        }));
        // The instance itself, so a policy can be evaluated on exactly what it trained on
        // (`milv-train eval --instances`).
        instances.push(serde_json::json!({
            "index": i,
            "robot": format!("{}.mp4", stem.replace("{}", "robot")),
            "task": serde_json::to_value(&task)?,
        }));
        // Loosely paired clips: the same motion at different speeds and lengths.
        let robot_len = rng.random_range(36..=51);
        let pair = paired_clips(&task, size, 51, robot_len, &mut rng).context("empty task")?;
        let pair_id = format!("{}-{seed}-{i:04}", task.family());
        for (domain, r) in [(Domain::Human, &pair.human), (Domain::Robot, &pair.robot)] {
            let name = format!("{}_{}_paired_{i:04}", task.family(), domain.name());
            let meta = EpisodeMeta {
                domain: Some(domain.name().into()),
                kind: Some("paired".into()),
                task_id: Some(task.id()),
                task_family: Some(task.family().into()),
                split: Some(split_name.into()),
                pair_id: Some(pair_id.clone()),
                ..EpisodeMeta::default()
            };
            write_episode(out, &name, r, size, meta)?;
            manifest.push(
                serde_json::json!({"path": format!("{name}.mp4"), "sidecar": format!("{name}.json"),
                "success": r.success, "score": r.score}),
            );
        }
        warps.push(
            serde_json::json!({"pair_id": pair_id, "human_frames": pair.human.frames.len(),
            "robot_frames": pair.robot.frames.len(), "human_to_robot": pair.human_to_robot}),
        );
        pb.inc(1);
    }
    pb.finish_and_clear();
    let jsonl = |rows: &[serde_json::Value]| rows.iter().map(|r| r.to_string() + "\n").collect::<String>();
    std::fs::write(out.join("ground_truth.jsonl"), jsonl(&ground_truth))?;
    std::fs::write(out.join("warps.jsonl"), jsonl(&warps))?;
    std::fs::write(out.join("instances.jsonl"), jsonl(&instances))?;
    let lines: Vec<String> = manifest
        .iter()
        .map(|m| serde_json::json!({"path": m["path"], "sidecar": m["sidecar"]}).to_string())
        .collect();
    std::fs::write(out.join("manifest.jsonl"), lines.join("\n") + "\n")?;
    Ok(manifest)
}

fn contact_sheet(size: u32, out: &Path) -> anyhow::Result<()> {
    let train = shapes::training_shapes();
    let mut tasks: Vec<Task> = [0usize, 4, 9]
        .iter()
        .map(|&i| Task::Drawing {
            shape: train[i].clone(),
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    for _ in 0..2 {
        tasks.push(sample_task(Family::Pushing, Split::Train, &mut rng)?);
    }
    let times = [0usize, 12, 25, 37, 50];
    let cols = times.len() as u32;
    let rows = (tasks.len() * 2) as u32;
    let mut sheet = image::RgbImage::new(cols * size, rows * size);
    for (pi, task) in tasks.iter().enumerate() {
        for (di, domain) in [Domain::Human, Domain::Robot].into_iter().enumerate() {
            let r = rollout(
                Sim::reset(task.clone(), domain, size).context("empty task")?,
                expert_action,
            );
            for (ti, &t) in times.iter().enumerate() {
                let frame =
                    image::RgbImage::from_raw(size, size, r.frames[t].clone()).context("frame size")?;
                let y = (pi * 2 + di) as u32 * size;
                image::imageops::replace(&mut sheet, &frame, i64::from(ti as u32 * size), i64::from(y));
            }
        }
    }
    sheet
        .save(out)
        .with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}

fn run(args: Args) -> anyhow::Result<u8> {
    match args.cmd {
        Cmd::Gen {
            task,
            episodes,
            seed,
            split,
            size,
            randomize,
            out,
            json,
        } => {
            let m = generate(task, split, episodes, seed, size, randomize, &out)?;
            if json {
                cli::print_json(&serde_json::json!({"out": out, "episodes": m}))?;
            } else {
                println!(
                    "{}: {} episodes, manifest {}",
                    out.display(),
                    m.len(),
                    out.join("manifest.jsonl").display()
                );
            }
        }
        Cmd::Bench { size, episodes, json } => {
            let pool = shapes::training_shapes();
            let mut frames = 0usize;
            let t0 = std::time::Instant::now();
            for i in 0..episodes {
                for domain in [Domain::Human, Domain::Robot] {
                    let task = Task::Drawing {
                        shape: pool[i % pool.len()].clone(),
                    };
                    let r = rollout(
                        Sim::reset(task, domain, size).context("empty shape")?,
                        expert_action,
                    );
                    frames += r.frames.len();
                }
            }
            let secs = t0.elapsed().as_secs_f64();
            let fps = frames as f64 / secs;
            if json {
                cli::print_json(
                    &serde_json::json!({"size": size, "frames": frames, "seconds": secs, "frames_per_s": fps}),
                )?;
            } else {
                println!(
                    "{frames} frames of {size}x{size} rendered + stepped in {secs:.2} s on 1 thread: {fps:.0} frames/s"
                );
            }
        }
        Cmd::ContactSheet { size, out } => {
            contact_sheet(size, &out)?;
            println!("{}", out.display());
        }
        Cmd::EvalExpert {
            task: family,
            split,
            trials,
            seed,
            json,
        } => {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let mut rows = Vec::new();
            let tasks: Vec<Task> = match family {
                Family::Drawing => shapes_of(split)
                    .into_iter()
                    .map(|shape| Task::Drawing { shape })
                    .collect(),
                Family::Pushing => (0..16)
                    .map(|_| sample_task(family, split, &mut rng))
                    .collect::<anyhow::Result<_>>()?,
            };
            let expert =
                evaluate(&tasks, 1, Domain::Robot, 32, |_, _| expert_action).context("empty task")?;
            let random = evaluate(&tasks, trials, Domain::Robot, 32, |_, _| {
                let mut r = rand::rngs::StdRng::seed_from_u64(rng.random());
                move |_: &Sim| milv::sim::Vec2::new(r.random_range(-5.0..5.0), r.random_range(-5.0..5.0))
            })
            .context("empty task")?;
            // Pushing: the two targets' experts averaged, where a squared-loss policy that
            // cannot tell the objects apart lands. Success counts only the target; a blind
            // push that lands the distractor is reported apart.
            let blind = (family == Family::Pushing).then(|| {
                tasks
                    .iter()
                    .filter_map(|t| Sim::reset(t.clone(), Domain::Robot, 32))
                    .map(|mut sim| {
                        while !sim.done() {
                            let a = blind_expert_action(&sim);
                            sim.step(a);
                        }
                        (sim.success(), sim.distractor_moved())
                    })
                    .collect::<Vec<_>>()
            });
            for (i, (e, r)) in expert.per_task.iter().zip(&random.per_task).enumerate() {
                let mut row = serde_json::json!({"task": e.task, "expert_success": e.successes == e.trials,
                    "random_success": r.successes, "random_trials": r.trials});
                if let Some((ok, wrong)) = blind.as_ref().and_then(|b| b.get(i)) {
                    row["blind_success"] = (*ok).into();
                    row["blind_moved_distractor"] = (*wrong).into();
                }
                rows.push(row);
            }
            if json {
                cli::print_json(&rows)?;
            } else {
                println!("{:<28} {:>8} {:>10}", "task", "expert", "random");
                for r in &rows {
                    println!(
                        "{:<28} {:>8} {:>7}/{}",
                        r["task"].as_str().unwrap_or("?"),
                        r["expert_success"],
                        r["random_success"],
                        r["random_trials"]
                    );
                }
                println!(
                    "overall: expert {}/{} ({:.0} %), random {}/{} ({:.0} %)",
                    expert.successes,
                    expert.trials,
                    100.0 * expert.success_rate(),
                    random.successes,
                    random.trials,
                    100.0 * random.success_rate()
                );
                if let Some(b) = &blind {
                    println!(
                        "blind (both targets' experts averaged): target in the square {}/{}, distractor moved {}/{}",
                        b.iter().filter(|(ok, _)| *ok).count(),
                        b.len(),
                        b.iter().filter(|(_, wrong)| *wrong).count(),
                        b.len()
                    );
                }
            }
        }
    }
    Ok(cli::EXIT_OK)
}

fn main() -> ExitCode {
    cli::finish("milv-sim", run(Args::parse()))
}
