//! The floor both rooms stand on: what any training run needs, whatever it trains.
//!
//! | module | what |
//! |---|---|
//! | [`folder`] | checkpoint folders (temp + rename, newest by step), format-checked JSON metadata, [`DataRef`] |
//! | [`log`] | JSON-lines logs (`losses.jsonl`, `eval.jsonl`) |
//! | [`image`] | tensor ↔ RGB, [`Clip`]: a pinned version's frames decoded into tensors |
//! | [`layers`] | layers both networks use (spatial softmax) |
//! | [`adam`] | Adam with its moments in named tensors (exact resume) |
//! | [`device`] | `cpu` / `cuda` / `auto` |
//! | [`fit`] | predicted vs true actions: error, correlation, spread ([`fit::ActionFit`]) |
//!
//! and [`Start`]: where a run begins — fresh, or resumed from its newest checkpoint on the
//! version and data it trained on — for both training commands.

pub mod adam;
pub mod device;
pub mod fit;
pub mod folder;
pub mod image;
pub mod layers;
pub mod log;

use std::path::{Path, PathBuf};
use std::time::Instant;

use milv_data::Dataset;

pub use folder::DataRef;
pub use image::Clip;

use crate::{Error, Result};

/// Where a training run begins.
#[derive(Clone, Debug)]
pub struct Start {
    /// The checkpoint to resume from (None: a fresh run).
    pub checkpoint: Option<PathBuf>,
    /// What that checkpoint trained on.
    pub recorded: Option<DataRef>,
    /// The dataset version to read: the checkpoint's, or the requested (default latest).
    pub version: u64,
    /// `--resume` was asked for, but the run folder holds no checkpoint yet.
    pub nothing_to_resume: bool,
}

impl Start {
    /// Resolves the start of a run writing checkpoints to `checkpoints`: with `resume`,
    /// the newest one there (found by `latest`, its data read by `recorded`), whose
    /// version must be `requested` if one is given; without, the folder must hold none.
    pub fn resolve(
        ds: &Dataset,
        checkpoints: &Path,
        resume: bool,
        requested: Option<u64>,
        latest: impl Fn(&Path) -> Result<Option<PathBuf>>,
        recorded: impl Fn(&Path) -> Result<DataRef>,
    ) -> Result<Start> {
        let found = latest(checkpoints)?;
        if !resume && found.is_some() {
            return Err(Error::Config(format!(
                "{} already holds checkpoints: pass --resume to continue, or choose another --out",
                checkpoints.display()
            )));
        }
        let Some(dir) = found else {
            return Ok(Start {
                checkpoint: None,
                recorded: None,
                version: ds.resolve(requested)?,
                nothing_to_resume: resume,
            });
        };
        let data = recorded(&dir)?;
        if let Some(v) = requested.filter(|v| *v != data.version) {
            return Err(Error::Config(format!(
                "{} trained on version {}, not {v}",
                dir.display(),
                data.version
            )));
        }
        Ok(Start {
            version: data.version,
            checkpoint: Some(dir),
            recorded: Some(data),
            nothing_to_resume: false,
        })
    }

    /// A resumed run must read the same data: `digest` is what the version reads as now.
    pub fn check_digest(&self, digest: &str) -> Result<()> {
        match (&self.checkpoint, &self.recorded) {
            (Some(dir), Some(r)) if r.digest != digest => Err(Error::Config(format!(
                "{} trained on data digest {}, but version {} now reads as {digest}: the data changed",
                dir.display(),
                r.digest,
                self.version
            ))),
            _ => Ok(()),
        }
    }
}

/// Step timings: `warmup` untimed calls of `step`, then `steps` (at least 1) timed ones.
#[derive(Clone, Copy, Debug)]
pub struct Timings {
    pub steps: u64,
    pub median_ms: f64,
    pub mean_ms: f64,
    pub min_ms: f64,
}

/// Times `step` (benchmarks).
pub fn time_steps(warmup: u64, steps: u64, step: &mut dyn FnMut()) -> Timings {
    for _ in 0..warmup {
        step();
    }
    let mut ms: Vec<f64> = (0..steps.max(1))
        .map(|_| {
            let t = Instant::now();
            step();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let mean_ms = ms.iter().sum::<f64>() / ms.len() as f64;
    ms.sort_by(f64::total_cmp);
    Timings {
        steps: ms.len() as u64,
        median_ms: ms[ms.len() / 2],
        mean_ms,
        min_ms: ms[0],
    }
}
