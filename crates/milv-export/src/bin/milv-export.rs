//! `milv-export`: MCAP and Rerun recordings of a dataset version, to look at what the
//! translation did before trusting it for training; LeRobot v3.0 datasets for the policies
//! people already train.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use milv_cli as cli;
use milv_data::view::{ViewOptions, ViewPlan};
use milv_data::{Dataset, DatasetRef};
use milv_mcap::{McapOptions, RecordingInfo};
use milv_rerun::Sink;

#[derive(Parser, Debug)]
#[command(
    name = "milv-export",
    version,
    about = "MCAP and Rerun recordings of a dataset version (human, imagined and robot frames, latents, actions, quality), and LeRobot v3.0 datasets",
    long_about = "Exports a pinned dataset version for visual inspection: each human frame, its \
translation by one model (imagined frame, latent ẑ^r, predicted action â^r), its quality \
(Brenner, SSIM, β, curated weight) and the robot frame it was aligned to, with that frame's \
true action. Robot episodes named with --episodes are exported with their own frames and \
actions.\n\nExamples:\n  milv-export mcap ds@7 -o translations.mcap\n  milv-export mcap ds --per-episode -o mcap/\n  \
milv-export rerun ds --sort beta -o translations.rrd\n  milv-export rerun ds --spawn\n  \
milv-export lerobot ds@7 -o lerobot/ds\n  milv-export schemas schemas/mcap"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Args, Debug)]
struct Select {
    /// DATASET or DATASET@VERSION (default: the latest version).
    dataset: DatasetRef,
    /// Only these episodes (comma-separated or repeated; human or robot). Default: every
    /// human episode the model translated.
    #[arg(long, value_delimiter = ',')]
    episodes: Vec<String>,
    /// Translation model (needed when the imagined table holds several).
    #[arg(long)]
    model_id: Option<String>,
    /// Scoring run for the quality channels (default: the newest over this model).
    #[arg(long)]
    score_run: Option<String>,
    /// Alignment run id or feature kind for the aligned robot frames (default: the newest).
    #[arg(long)]
    alignment: Option<String>,
    /// Episode order: as stored, or the lowest mean β first (what needs looking at).
    #[arg(long, value_enum, default_value_t = Sort::Id)]
    sort: Sort,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Sort {
    Id,
    Beta,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Writes MCAP (zstd chunks, message and chunk indexes, statistics, summary): topics
    /// /human/image, /imagined/image, /robot/image (foxglove.CompressedImage, protobuf),
    /// /imagined/action, /robot/action, /quality (JSON schema), /imagined/latent
    /// (milv.Tensor, protobuf); metadata `milv` (dataset, version, model, tool, command
    /// line) and one `episode` record per episode; the model config attached. Log time is
    /// the frame timestamps with episodes laid end to end. Schemas: schemas/mcap/.
    Mcap {
        #[command(flatten)]
        select: Select,
        /// Output file (a folder with --per-episode).
        #[arg(short, long)]
        out: PathBuf,
        /// One file per episode, `OUT/<episode_id>.mcap`, each with its own timestamps.
        #[arg(long)]
        per_episode: bool,
        /// Write uncompressed chunks instead of zstd.
        #[arg(long)]
        no_compression: bool,
        /// zstd level (1 fastest … 19; 0 is zstd's default, 3).
        #[arg(long, default_value_t = 0)]
        zstd_level: u32,
        /// zstd worker threads (0: compress on the writing thread, which already overlaps
        /// with reading the tables).
        #[arg(long, default_value_t = 0)]
        zstd_threads: u32,
    },
    /// Writes a Rerun recording (.rrd), or streams it to a new or running viewer, with a
    /// layout that opens on the images side by side and the quality and action plots below.
    Rerun {
        #[command(flatten)]
        select: Select,
        /// Output .rrd file.
        #[arg(short, long, required_unless_present_any = ["spawn", "connect"], conflicts_with_all = ["spawn", "connect"])]
        out: Option<PathBuf>,
        /// Start a viewer (the `rerun` executable on PATH: `pip install rerun-sdk==0.36.3`).
        #[arg(long, conflicts_with = "connect")]
        spawn: bool,
        /// Stream to a running viewer: HOST:PORT or rerun+http://HOST:PORT/proxy.
        #[arg(long)]
        connect: Option<String>,
    },
    /// Writes a LeRobot v3.0 dataset that `LeRobotDataset(repo_id, root=OUT)` loads offline:
    /// `observation.image` (AV1 video, every frame decoded back and its timestamp checked
    /// within LeRobot's 1e-4 s before the export is finalised; or lossless inline images
    /// with --images), `action`, `observation.state`, the task text (the MILV task id),
    /// meta/stats.json and tasks.parquet. Imagined and curated exports add `milv.model_id`
    /// and `milv.weight` features. Built in a temporary folder and renamed to OUT at the end.
    #[command(
        after_help = "Examples:\n  milv-export lerobot data/robot@3 -o ~/lerobot/robot\n  milv-export lerobot data/human --table imagined --images -o out/imagined"
    )]
    Lerobot {
        /// DATASET or DATASET@VERSION (default: the latest version).
        dataset: DatasetRef,
        /// Output folder (must not exist, or be empty).
        #[arg(short, long)]
        out: PathBuf,
        /// Which rows: frames (recorded), imagined (one model's translations with their
        /// inverse-dynamics actions) or curated (the curated view with its loss weights).
        #[arg(long, default_value = "frames", value_parser = ["frames", "imagined", "curated"])]
        table: String,
        /// AV1 video, concatenated per file as LeRobot writes it (the default).
        #[arg(long, conflicts_with = "images")]
        video: bool,
        /// Inline images instead of video (stored PNG/JPEG bytes, copied losslessly).
        #[arg(long)]
        images: bool,
        /// Keyframe interval of the video. 2 is LeRobot's: random access (training) decodes
        /// at most one extra frame. Longer encodes several times faster and smaller, but
        /// LeRobot then decodes up to N-1 extra frames per item.
        #[arg(long, default_value_t = milv_lerobot::write::DEFAULT_GOP, value_parser = clap::value_parser!(u32).range(1..))]
        gop: u32,
        /// Translation model for --table imagined (default: the only one).
        #[arg(long)]
        model_id: Option<String>,
        /// Print a JSON summary on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Writes the documented schema files of the MCAP channels into a folder.
    Schemas {
        /// Folder (e.g. schemas/mcap).
        dir: PathBuf,
    },
}

/// The export's progress: a bar over episodes.
struct ExportBar(indicatif::ProgressBar);

impl milv_lerobot::write::Progress for ExportBar {
    fn planned(&self, episodes: usize, _frames: u64) {
        self.0.set_length(episodes as u64);
    }
    fn episode_done(&self, _frames: u64) {
        self.0.inc(1);
    }
    fn verifying(&self) {
        self.0.set_message("checking video timestamps");
    }
}

fn plan(s: &Select) -> anyhow::Result<(Dataset, ViewPlan)> {
    let ds = Dataset::open(&s.dataset.root).with_context(|| format!("opening {}", s.dataset))?;
    let v = ds.resolve(s.dataset.version)?;
    let opts = ViewOptions {
        episodes: (!s.episodes.is_empty()).then(|| s.episodes.clone()),
        model_id: s.model_id.clone(),
        score_run: s.score_run.clone(),
        alignment: s.alignment.clone(),
        ..ViewOptions::default()
    };
    let mut plan = ViewPlan::new(&ds, v, &opts)
        .with_context(|| format!("selecting from {}@{v}", s.dataset.root.display()))?;
    if s.sort == Sort::Beta {
        plan.sort_by_beta();
    }
    Ok((ds, plan))
}

fn run(cli: Cli) -> anyhow::Result<u8> {
    match cli.cmd {
        Cmd::Mcap {
            select,
            out,
            per_episode,
            no_compression,
            zstd_level,
            zstd_threads,
        } => {
            let (ds, mut plan) = plan(&select)?;
            let info = RecordingInfo {
                dataset_uri: ds.root().display().to_string(),
                tool_version: milv_data::TOOL_VERSION.into(),
                command: std::env::args().collect(),
            };
            let opts = McapOptions {
                compression: (!no_compression).then_some(milv_mcap::mcap::Compression::Zstd),
                compression_level: zstd_level,
                compression_threads: zstd_threads,
                ..McapOptions::default()
            };
            let pb = cli::bar(plan.episodes.len() as u64, "episodes");
            let written = if per_episode {
                milv_mcap::write_per_episode(&mut plan, &ds, &info, &out, &opts, &mut |k| {
                    pb.set_position(k as u64)
                })?
            } else {
                vec![milv_mcap::write_recording(
                    &mut plan,
                    &ds,
                    &info,
                    &out,
                    &opts,
                    &mut |k| pb.set_position(k as u64),
                )?]
            };
            pb.finish_and_clear();
            if select.json {
                cli::print_json(&serde_json::json!({
                    "version": plan.version, "model_id": plan.model_id,
                    "score_run": plan.score_run, "alignment": plan.alignment,
                    "files": written,
                }))?;
            } else {
                for w in &written {
                    println!(
                        "{}: {} episode(s), {} messages, {}",
                        w.path.display(),
                        w.episodes,
                        w.messages,
                        cli::human_bytes(w.bytes)
                    );
                }
            }
        }
        Cmd::Rerun {
            select,
            out,
            spawn,
            connect,
        } => {
            let sink = match (out, spawn, connect) {
                (Some(o), _, _) => Sink::File(o),
                (None, true, _) => Sink::Spawn,
                (None, false, Some(a)) => Sink::Connect(a),
                (None, false, None) => bail!("give -o FILE.rrd, --spawn or --connect ADDR"),
            };
            let (ds, mut plan) = plan(&select)?;
            let name = format!("{}@{}", ds.root().display(), plan.version);
            let pb = cli::bar(plan.episodes.len() as u64, "episodes");
            let logged =
                milv_rerun::log_recording(&mut plan, &ds, &name, &sink, &mut |k| pb.set_position(k as u64))?;
            pb.finish_and_clear();
            if select.json {
                cli::print_json(&serde_json::json!({
                    "version": plan.version, "model_id": plan.model_id, "logged": logged,
                }))?;
            } else {
                let to = logged
                    .path
                    .as_ref()
                    .map(|p| p.display().to_string())
                    .unwrap_or_else(|| "the viewer".into());
                println!("{}: {} episode(s), {} frames", to, logged.episodes, logged.frames);
            }
        }
        Cmd::Lerobot {
            dataset,
            out,
            table,
            video: _,
            images,
            gop,
            model_id,
            json,
        } => {
            let ds = Dataset::open(&dataset.root).with_context(|| format!("opening {dataset}"))?;
            let v = ds.resolve(dataset.version)?;
            let opts = milv_lerobot::ExportOptions {
                source: table.parse().map_err(anyhow::Error::msg)?,
                video: !images,
                gop,
                model_id,
            };
            let bars = ExportBar(cli::bar(0, "episodes"));
            let report = milv_lerobot::export(&ds, v, &out, &opts, &bars)
                .with_context(|| format!("exporting {}@{v} to {}", ds.root().display(), out.display()))?;
            bars.0.finish_and_clear();
            if json {
                cli::print_json(&report)?;
            } else {
                println!(
                    "{}: {} episodes, {} frames at {} fps, {}x{}, {}{}",
                    report.out,
                    report.episodes,
                    report.frames,
                    report.fps,
                    report.width,
                    report.height,
                    if report.video {
                        "AV1 video"
                    } else {
                        "inline images"
                    },
                    report
                        .max_timestamp_error_s
                        .map(|e| format!(" (timestamps checked, worst error {e:.1e} s)"))
                        .unwrap_or_default()
                );
            }
        }
        Cmd::Schemas { dir } => {
            for (rel, text) in milv_mcap::schema::schema_files() {
                let p = dir.join(rel);
                if let Some(parent) = p.parent() {
                    std::fs::create_dir_all(parent)
                        .with_context(|| format!("creating {}", parent.display()))?;
                }
                std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
                println!("{}", p.display());
            }
        }
    }
    Ok(cli::EXIT_OK)
}

fn main() -> ExitCode {
    quiet_svt_av1();
    cli::finish("milv-export", run(Cli::parse()))
}

/// SVT-AV1 (the LeRobot export's encoder) prints a 16-line banner per video file unless
/// `SVT_LOG` asks for errors only; it reads the variable itself, so set it before any
/// encoder exists.
#[allow(unsafe_code)]
fn quiet_svt_av1() {
    if std::env::var_os("SVT_LOG").is_none() {
        // SAFETY: first thing in main, before any thread is started, so nothing else can
        // be reading or writing the environment.
        unsafe { std::env::set_var("SVT_LOG", "1") };
    }
}
