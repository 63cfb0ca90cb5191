//! `milv-train`: trains A-CycleGAN (with inverse dynamics) on a pinned dataset version,
//! translates human episodes into the `imagined` table, evaluates translations, trains
//! DAML / MILV meta-policies and evaluates them one-shot in milv-sim.

mod gan;
mod meta;

use clap::{Parser, Subcommand};
use milv_cli as cli;
use milv_train::ModelConfig;
use milv_train::run::{Start, device};

#[derive(Parser, Debug)]
#[command(
    name = "milv-train",
    version,
    about = "A-CycleGAN, imagined robot data, DAML/MILV meta-policies and their one-shot evaluation",
    long_about = "Trains the paper's A-CycleGAN (G: human→robot, F: robot→human, PatchGAN \
discriminators, the auxiliary loss on aligned pairs and the inverse-dynamics model π_I on F's \
encoder) from a pinned dataset version; `translate` writes the imagined table (ŷ^r, ẑ^r, â^r) \
that milv-score and the meta-learner read. `meta` trains a meta-policy (DAML, MILV or an \
ablation) from a pinned version; `eval` adapts it to ONE human video per trial of each held-out \
task and runs it closed loop in milv-sim; `table` prints the paper's Tables 1 and 2.\n\nExamples:\n  \
milv-train cyclegan ds@3 --out runs/acg --steps 5000\n  milv-train cyclegan ds@3 --out runs/acg --resume --steps 8000\n  \
milv-train translate ds --checkpoint runs/acg/checkpoints/step-00005000\n  \
milv-train eval-translation ds --checkpoint runs/acg/checkpoints/step-00005000 --truth sim/ground_truth.jsonl\n  \
milv-train meta ds@7 --variant milv --translator runs/acg/checkpoints/step-00005000 --out runs/milv\n  \
milv-train eval runs/milv --trials 10 --seeds 0,1 -o results/milv.json\n  \
milv-train table results/*.json\n  \
milv-train pack runs/milv --out samples/policies/milv --half"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(clap::Args, Debug)]
pub(crate) struct Runtime {
    /// cpu | cuda | auto (CUDA when libtorch sees a GPU).
    #[arg(long, default_value = "cpu")]
    device: String,
    /// libtorch intra-op threads (default: libtorch's choice, usually all cores).
    #[arg(long)]
    threads: Option<i32>,
    /// Print the result as JSON on stdout.
    #[arg(long)]
    json: bool,
}

impl Runtime {
    pub(crate) fn apply(&self) -> anyhow::Result<tch::Device> {
        if let Some(t) = self.threads {
            tch::set_num_threads(t);
        }
        Ok(device::parse(&self.device)?)
    }
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Train A-CycleGAN (writes RUN/losses.jsonl, RUN/grids/, RUN/checkpoints/).
    Cyclegan(Box<gan::TrainArgs>),
    /// Translate human episodes with a checkpoint and commit the imagined table.
    Translate(gan::TranslateArgs),
    /// SSIM of translations against ground-truth robot renderings, π_I's action error.
    EvalTranslation(gan::EvalTranslationArgs),
    /// Meta-train a DAML / MILV / ablation policy (writes RUN/losses.jsonl, RUN/checkpoints/).
    Meta(Box<meta::MetaArgs>),
    /// One-shot success of a policy in milv-sim: one human video per trial, 50 robot steps.
    Eval(meta::EvalArgs),
    /// The paper's Tables 1 and 2 (Markdown) from `eval --out` reports.
    Table(meta::TableArgs),
    /// Pack a policy for sharing: its weights and the translator's G and F (f16 with
    /// --half), evaluated with `milv-train eval PACK` like a checkpoint.
    Pack(meta::PackArgs),
    /// Time second-order meta steps on random data: the tool side of tools/bench/meta_step.py.
    BenchMeta(meta::BenchMetaArgs),
    /// Time A-CycleGAN steps on random data (no dataset): the tool side of
    /// tools/bench/train_step.py.
    BenchStep(gan::BenchArgs),
    /// The data loader's decode throughput on a dataset, against a step's consumption.
    BenchLoader(gan::LoaderArgs),
    /// Learning curves (SSIM, action error) of runs' eval.jsonl as PNG charts.
    Report(gan::ReportArgs),
}

/// The paper's networks at `size`, or the tiny ones of tests.
pub(crate) fn model_config(tiny: bool, size: i64) -> ModelConfig {
    if tiny {
        ModelConfig::tiny(size)
    } else {
        ModelConfig {
            image_size: size,
            ..ModelConfig::default()
        }
    }
}

/// Where a training run writing checkpoints to `checkpoints` starts
/// ([`Start::resolve`]); says so on stderr when `--resume` finds nothing to resume.
pub(crate) fn start_run(
    tool: &str,
    ds: &milv_data::Dataset,
    checkpoints: &std::path::Path,
    resume: bool,
    version: Option<u64>,
    latest: impl Fn(&std::path::Path) -> milv_train::Result<Option<std::path::PathBuf>>,
    recorded: impl Fn(&std::path::Path) -> milv_train::Result<milv_train::run::DataRef>,
) -> anyhow::Result<Start> {
    let start = Start::resolve(ds, checkpoints, resume, version, latest, recorded)?;
    if start.nothing_to_resume {
        eprintln!(
            "{tool}: no checkpoint in {} yet; starting fresh",
            checkpoints.display()
        );
    }
    Ok(start)
}

fn main() -> std::process::ExitCode {
    cli::finish("milv-train", run(Cli::parse()))
}

fn run(c: Cli) -> anyhow::Result<u8> {
    match c.cmd {
        Cmd::Cyclegan(a) => gan::cmd_train_cyclegan(*a),
        Cmd::Translate(a) => gan::cmd_translate(a),
        Cmd::EvalTranslation(a) => gan::cmd_eval_translation(a),
        Cmd::Meta(a) => meta::cmd_meta(*a),
        Cmd::Eval(a) => meta::cmd_eval_one_shot(a),
        Cmd::Table(a) => meta::cmd_table(a),
        Cmd::Pack(a) => meta::cmd_pack(a),
        Cmd::BenchMeta(a) => meta::cmd_bench_meta(a),
        Cmd::BenchStep(a) => gan::cmd_bench_step(a),
        Cmd::BenchLoader(a) => gan::cmd_bench_loader(a),
        Cmd::Report(a) => gan::cmd_report(a),
    }
}
