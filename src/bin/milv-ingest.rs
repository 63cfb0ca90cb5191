//! `milv-ingest`: turn human and robot videos (+ action sidecars) into dataset episodes.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{Context as _, bail};
use clap::{Parser, ValueEnum};
use indicatif::ProgressBar;
use milv::cli;
use milv::data::frame_codec::FrameEncoding;
use milv::data::{CommitMeta, Dataset, ShardOptions};
use milv::ingest::{EpisodeMeta, IngestOptions, InputSpec, Partition, Progress};
use milv::video::{AspectPolicy, Resize};

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Encoding {
    Png,
    Jpeg,
    Raw,
}

/// Ingest videos or frame folders into a versioned MILV dataset.
///
/// Every input becomes one episode: its frames (decoded with FFmpeg, stored PNG by default)
/// go to the `frames` table, one row per episode to `episodes`. Actions and states come
/// from a sidecar beside each input (`<stem>.json` or `<stem>.csv`, see
/// schemas/sidecar.md). The whole run is one new dataset version; inputs that fail are
/// reported and skipped (exit code 3), the rest still land. Running the same command again
/// changes nothing: episode ids are content hashes of the inputs and options.
#[derive(Parser, Debug)]
#[command(
    version,
    after_help = "Examples:\n  milv-ingest data/ds clips/*.mp4 --domain human --task draw/circle\n  milv-ingest data/ds --from-lerobot ~/lerobot/pusht --camera observation.image\n  milv-ingest data/ds --manifest samples/manifest.jsonl --json\n  milv-ingest data/ds frames_dir/ --fps 10 --domain robot --kind random"
)]
struct Args {
    /// Dataset folder or s3://bucket/prefix (created if missing).
    dataset: PathBuf,
    /// Video files or folders of numbered PNG/JPEG frames (local, or s3:// URLs: fetched
    /// with their sidecars into $MILV_INPUT_CACHE first).
    inputs: Vec<PathBuf>,
    /// Import every episode of a local LeRobot v3.0 dataset (frames decoded from its
    /// videos at `from_timestamp + timestamp`, or from its inline images; `action` and
    /// `observation.state` with their names; the task text as task id). Defaults:
    /// --domain robot, --task-family <the folder's name>.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["inputs", "manifest", "sidecar", "task", "fps"])]
    from_lerobot: Option<PathBuf>,
    /// With --from-lerobot: the camera feature to take frames from (needed when the
    /// dataset has several; the others are named in each episode's source_uri).
    #[arg(long, value_name = "KEY", requires = "from_lerobot")]
    camera: Option<String>,
    /// A manifest listing many inputs (JSON lines or CSV; keys: path, sidecar, domain, kind,
    /// task_id, task_family, pair_id, split, fps). Repeatable.
    #[arg(long)]
    manifest: Vec<PathBuf>,
    /// Sidecar for the (single) input, instead of looking beside it.
    #[arg(long)]
    sidecar: Option<PathBuf>,
    /// Embodiment, for inputs whose sidecar/manifest doesn't say.
    #[arg(long, value_parser = ["human", "robot"])]
    domain: Option<String>,
    /// Episode kind (default: demo).
    #[arg(long, value_parser = ["demo", "random", "paired"])]
    kind: Option<String>,
    /// Task id, e.g. draw/circle.
    #[arg(long)]
    task: Option<String>,
    /// Task family, e.g. drawing or pushing.
    #[arg(long)]
    task_family: Option<String>,
    /// Pair id linking a human and a robot clip of the same motion.
    #[arg(long)]
    pair_id: Option<String>,
    /// Split (default: train).
    #[arg(long, value_parser = ["train", "val", "test"])]
    split: Option<String>,
    /// Frame rate: required for frame folders; for videos, resample to this rate
    /// (frames are dropped or repeated; each keeps its source frame's action).
    #[arg(long)]
    fps: Option<f64>,
    /// Resize every frame to WxH (see --aspect).
    #[arg(long, value_name = "WxH")]
    resize: Option<Resize>,
    /// Aspect-ratio policy for --resize: pad (letterbox, keeps everything), crop (fill,
    /// centre crop) or stretch.
    #[arg(long, default_value = "pad")]
    aspect: AspectPolicy,
    /// How frames are stored.
    #[arg(long, value_enum, default_value = "png")]
    frame_encoding: Encoding,
    /// JPEG quality for --frame-encoding jpeg.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    jpeg_quality: u8,
    /// Parallel episodes and encoder threads (default: all cores).
    #[arg(long, short)]
    jobs: Option<usize>,
    /// Fail inputs that have no sidecar with actions.
    #[arg(long)]
    require_actions: bool,
    /// Target Parquet shard size in MiB.
    #[arg(long, default_value_t = 128)]
    shard_mb: u64,
    /// Take only every n-th input starting at i (for array jobs): i/n.
    #[arg(long)]
    partition: Option<Partition>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    json: bool,
}

/// One bar of episodes; its message counts frames, so a single long clip shows progress too.
struct Bars {
    episodes: ProgressBar,
    frames: AtomicU64,
}

impl Progress for Bars {
    fn planned(&self, episodes: usize, _frames: u64) {
        self.episodes.set_length(episodes as u64);
        self.episodes.set_message("episodes");
    }
    fn frames_done(&self, n: u64) {
        let total = self.frames.fetch_add(n, Ordering::Relaxed) + n;
        self.episodes.set_message(format!("{total} frames"));
    }
    fn episode_done(&self, _source: &std::path::Path, _ok: bool) {
        self.episodes.inc(1);
    }
}

/// The local copy of an `s3://` input (with its sidecars); a failed download leaves the
/// input as given, so ingest reports it among the failed inputs and the others land.
fn fetched(p: &std::path::Path, siblings: bool) -> PathBuf {
    match milv::data::store::fetch_input(p, siblings) {
        Ok(local) => local,
        Err(e) => {
            eprintln!("warning: {e}");
            p.to_path_buf()
        }
    }
}

fn run(mut args: Args) -> anyhow::Result<u8> {
    let mut inputs: Vec<InputSpec> = args.inputs.iter().map(InputSpec::new).collect();
    for m in &args.manifest {
        let local =
            milv::data::store::fetch_input(m, false).with_context(|| format!("manifest {}", m.display()))?;
        inputs.extend(milv::ingest::manifest::read(&local)?);
    }
    // Only this worker's share is fetched (ingest partitions inputs by their index).
    for (i, spec) in inputs.iter_mut().enumerate() {
        if args.partition.is_some_and(|p| !p.contains_index(i as u64)) {
            continue;
        }
        spec.path = fetched(&spec.path, spec.sidecar.is_none());
        spec.sidecar = spec.sidecar.as_deref().map(|s| fetched(s, false));
    }
    if let Some(dir) = &args.from_lerobot {
        args.from_lerobot = Some(
            milv::data::store::fetch_input(dir, false)
                .with_context(|| format!("LeRobot dataset {}", dir.display()))?,
        );
    }
    if inputs.is_empty() && args.from_lerobot.is_none() {
        bail!("no inputs: give video files / frame folders, --manifest or --from-lerobot");
    }
    if let Some(s) = &args.sidecar {
        if inputs.len() != 1 {
            bail!("--sidecar needs exactly one input, got {}", inputs.len());
        }
        inputs[0].sidecar = Some(fetched(s, false));
    }
    let encoding = match args.frame_encoding {
        Encoding::Png => FrameEncoding::Png,
        Encoding::Jpeg => FrameEncoding::Jpeg {
            quality: args.jpeg_quality,
        },
        Encoding::Raw => FrameEncoding::Raw,
    };
    let (mut domain, mut task_family) = (args.domain, args.task_family);
    if let Some(dir) = &args.from_lerobot {
        domain.get_or_insert_with(|| "robot".into());
        if task_family.is_none() {
            let name = dir.canonicalize().unwrap_or_else(|_| dir.clone());
            task_family = name.file_name().map(|n| n.to_string_lossy().into_owned());
        }
    }
    let opts = IngestOptions {
        defaults: EpisodeMeta {
            domain,
            kind: args.kind,
            task_id: args.task,
            task_family,
            pair_id: args.pair_id,
            split: args.split,
            // For frame folders --fps is their rate; videos are resampled to it.
            fps: args.fps,
        },
        resize: args.resize.map(|r| Resize {
            policy: args.aspect,
            ..r
        }),
        fps: args.fps,
        encoding,
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        require_actions: args.require_actions,
        shard: ShardOptions {
            target_file_bytes: args.shard_mb << 20,
            ..ShardOptions::default()
        },
        partition: args.partition,
    };
    let ds = Dataset::open_or_create(
        &args.dataset,
        CommitMeta::for_this_process("milv-ingest", "create"),
    )
    .with_context(|| format!("opening dataset {}", args.dataset.display()))?;
    let bars = Bars {
        episodes: cli::bar(0, "planning"),
        frames: AtomicU64::new(0),
    };
    let meta = CommitMeta::for_this_process("milv-ingest", "ingest");
    let report = match &args.from_lerobot {
        Some(dir) => milv::ingest::ingest_lerobot(&ds, dir, args.camera.as_deref(), &opts, meta, &bars),
        None => milv::ingest::ingest(&ds, &inputs, &opts, meta, &bars),
    }?;
    bars.episodes.finish_and_clear();
    if args.json {
        cli::print_json(&report)?;
    } else {
        for f in &report.failed {
            eprintln!("error: {}", f.error);
        }
        println!(
            "{}@{}: ingested {} episodes ({} frames), skipped {} already present, {} failed",
            report.dataset,
            report.version,
            report.ingested.len(),
            report.frames,
            report.skipped.len(),
            report.failed.len()
        );
    }
    Ok(if report.all_ok() {
        cli::EXIT_OK
    } else {
        cli::EXIT_PARTIAL
    })
}

fn main() -> ExitCode {
    cli::finish("milv-ingest", run(Args::parse()))
}
