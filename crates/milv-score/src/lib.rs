//! # milv-score — β_qua over a dataset
//!
//! The paper weights every imagined robot frame by `β_qua = Brenner × SSIM(y_t, y_{t+1})`
//! (section 4.2, eq. 10–11; exact definitions in `shared/spec/quality.md`, kernels in
//! `milv-quality`). This crate applies it to a dataset version:
//!
//! | module | what |
//! |---|---|
//! | [`run`] | [`score_dataset`]: decode and score every selected episode of `frames` or `imagined` in parallel, commit a `scores` table version |
//! | [`curate`] | [`curate`](curate::curate): the set-normalised weights of a scoring run, thresholded into the `curated` view the trainer reads |
//! | [`report`] | [`summarize`]: per-episode mean/min β, worst frames, the values for plots |
//!
//! Every stage reads a pinned dataset version and appends one version; a run can be split
//! across stateless workers with `--partition i/n` (they share one `run_id`, and curation
//! normalises over all of the run's rows).

pub mod curate;
pub mod report;
pub mod run;

pub use curate::{CurateOptions, CurateReport, Rule, curate};
pub use report::{EpisodeSummary, Summary, WorstFrame, summarize};
pub use run::{RunOptions, RunReport, Source, score_dataset};

/// Why an episode or a run could not be scored or curated.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Data(#[from] milv_data::Error),
    #[error("{0}")]
    Invalid(String),
    #[error("the selection is empty: {0}")]
    EmptySelection(String),
    /// Some episodes could not be scored; nothing was committed.
    #[error("{} episode(s) could not be scored, nothing committed (use --skip-bad to commit the others):\n  {}", .0.len(), .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n  "))]
    Episodes(Vec<EpisodeError>),
}

pub type Result<T> = std::result::Result<T, Error>;

/// One episode that failed, and why.
#[derive(Clone, Debug, serde::Serialize, thiserror::Error)]
#[error("episode {episode_id}: {message}")]
pub struct EpisodeError {
    pub episode_id: String,
    pub message: String,
}

pub(crate) use milv_data::run_id as digest;
