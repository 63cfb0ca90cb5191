//! # milv-train — A-CycleGAN, imagined data, DAML/MILV meta-policies, one-shot evaluation
//!
//! The learning half of MILV (paper sections 4.1 and 4.2, Appendix A.2), on `tch`
//! (libtorch from the PyPI `torch` wheel). Only this crate links libtorch.
//!
//! | module | what |
//! |---|---|
//! | [`config`] | [`ModelConfig`] (network shapes) and [`TrainConfig`] (losses, rates, pool, seed) |
//! | [`nets`] | generators (encoder + residual blocks + decoder), PatchGAN discriminators, inverse dynamics with spatial softmax |
//! | [`cyclegan`] | [`ACycleGan`]: the losses of eq. 1–3, 7, 8 and one optimisation step |
//! | [`adam`] | Adam with its moments in named tensors (exact resume) |
//! | [`pool`] | the discriminators' image history |
//! | [`data`] | [`TrainingSet`] from a pinned dataset version, the prefetching [`Loader`] |
//! | [`checkpoint`] | safetensors checkpoints with configs, data digest and model id |
//! | [`train`] | the training loop: progress, JSON-lines losses, translation grids, checkpoints, resume |
//! | [`translate`] | human episodes → the `imagined` table (frames, f16 latents, actions) |
//! | [`eval`] | SSIM of translations against ground-truth robot renderings, π_I's action error |
//! | [`meta`] | the meta-policy (θ with pre- and post-update heads, the learned loss L_ψ), the second-order meta step, [`meta::Variant`] |
//! | [`meta_data`] | per-task inner/outer sequences of each variant from a pinned version |
//! | [`meta_train`] | the meta-training loop, policy checkpoints, the meta-step benchmark |
//! | [`oneshot`] | one-shot evaluation in milv-sim, Wilson intervals, the success tables |
//! | [`device`] | `cpu` / `cuda` / `auto` |

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod cyclegan;
pub mod data;
pub mod device;
pub mod eval;
pub mod meta;
pub mod meta_data;
pub mod meta_train;
pub mod nets;
pub mod oneshot;
pub mod pool;
pub mod train;
pub mod translate;

pub use config::{GanLoss, ModelConfig, TrainConfig};
pub use cyclegan::{ACycleGan, Losses};
pub use data::{Loader, TrainingSet};

use std::path::Path;

/// Why training, translation or evaluation failed.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Dataset(#[from] milv_data::Error),
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    #[error("{0}")]
    Data(String),
    #[error("config: {0}")]
    Config(String),
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("{0}")]
    Io(String),
}

impl Error {
    pub fn io(path: &Path, e: std::io::Error) -> Error {
        Error::Io(format!("{e}: {}", path.display()))
    }
}

pub type Result<T> = std::result::Result<T, Error>;

#[cfg(test)]
pub(crate) mod testing {
    use std::sync::{Mutex, MutexGuard};

    static TORCH_RNG: Mutex<()> = Mutex::new(());

    /// libtorch's initialisation and `rand` draw from one global generator: unit tests
    /// that create networks or random tensors hold this, so a test comparing two runs
    /// sees no other test draw in between. It also pins libtorch to one intra-op thread
    /// (a global setting), so no test's numbers depend on the core count, on how a
    /// multi-threaded reduction split its work, or on which test ran before it.
    pub fn torch_rng() -> MutexGuard<'static, ()> {
        let guard = TORCH_RNG.lock().unwrap_or_else(|e| e.into_inner());
        tch::set_num_threads(1);
        guard
    }
}
