//! # milv-align — frame correspondences of loosely paired human/robot clips
//!
//! A-CycleGAN's auxiliary loss (paper eq. 7) needs, for a human clip and a robot clip of
//! the same motion (episodes sharing a `pair_id`), which robot frame goes with which
//! human frame. The clips differ in length, speed, embodiment and viewpoint.
//!
//! | module | what |
//! |---|---|
//! | [`mod@dtw`] | banded DTW (Sakoe–Chiba, O(n·band) memory), step patterns, [`Features`]; posterior decoding of the path ([`posterior`]) |
//! | [`features`] | the [`FeatureKind`] trait and its kinds: `motion`, `track`, `state`, `translated` |
//! | [`motion`] | tip tracking from frame differences, table-plane rectification, track filters |
//! | [`klt`] | feature-point tracking (Shi–Tomasi + pyramidal Lucas–Kanade) of the most travelled points |
//! | [`track`] | the `track` kind: the human's tracked hand vs the robot's states through a per-pair affine camera |
//! | [`align`] | [`align_dataset`]: every pair of a dataset version, in parallel, into the `alignments` table, each pair in a band widened while its path runs along the edge; per-pair summaries and ground-truth errors |

pub mod align;
pub mod dtw;
pub mod features;
pub mod klt;
pub mod motion;
pub mod track;

pub use align::{
    AlignOptions, AlignReport, Correspondence, POSTERIOR_TEMPERATURE, PairSummary, align_dataset, load_pair,
};
pub use dtw::{Alignment, Band, Features, Posterior, StepPattern, dtw, posterior, row_to_col, staircase};
pub use features::{Clip, FeatureKind};

/// Why a pair or a run could not be aligned.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Data(#[from] milv_data::Error),
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, Error>;
