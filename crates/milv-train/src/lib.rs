//! # milv-train — A-CycleGAN, imagined data, DAML/MILV meta-policies, one-shot evaluation
//!
//! The learning half of MILV (paper sections 4.1 and 4.2, Appendix A.2), on `tch`
//! (libtorch from the PyPI `torch` wheel). Only this crate links libtorch. Two rooms and a
//! floor; the meta room may use the translator the GAN room trained, never the reverse.
//!
//! | module | what |
//! |---|---|
//! | [`gan`] | A-CycleGAN with inverse dynamics: [`gan::config`], [`gan::nets`], [`gan::cyclegan`] (losses, step), [`gan::pool`], [`gan::data`] (training set, loader), [`gan::train`] (loop, grids, benches), [`gan::checkpoint`], [`gan::translate`] (→ `imagined`), [`gan::eval`] (translation quality) |
//! | [`meta`] | DAML / MILV meta-policies: [`meta::policy`] (θ, ψ, the second-order meta step, [`meta::policy::Variant`]), [`meta::tasks`] (per-task sequences of each variant), [`meta::train`] (loop, policy checkpoints), [`meta::oneshot`] (one-shot evaluation in milv-sim, success tables) |
//! | [`run`] | the floor: checkpoint folders, JSON-lines logs, tensor ↔ image and decoded clips, shared layers, Adam, devices, where a run starts ([`run::Start`]) |

pub mod gan;
pub mod meta;
pub mod run;

pub use gan::config::{GanLoss, ModelConfig, TrainConfig};
pub use gan::cyclegan::{ACycleGan, Losses};
pub use gan::data::{Loader, TrainingSet};

use std::path::PathBuf;

/// Why training, translation or evaluation failed. Paths come last in messages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Dataset(#[from] milv_data::Error),
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    /// Encoding or decoding evaluation frames.
    #[error(transparent)]
    Video(#[from] milv_video::Error),
    /// The data cannot be trained on or evaluated as asked.
    #[error("{0}")]
    Data(String),
    /// Options or configurations that do not fit together.
    #[error("config: {0}")]
    Config(String),
    #[error("{op}: {source}: {path}")]
    Io {
        op: &'static str,
        #[source]
        source: std::io::Error,
        path: PathBuf,
    },
    #[error("{op}: {source}: {path}")]
    Json {
        op: &'static str,
        #[source]
        source: serde_json::Error,
        path: PathBuf,
    },
    /// A tensor file (safetensors) that cannot be read or written.
    #[error("checkpoint: {source}: {path}")]
    Tensors {
        #[source]
        source: tch::TchError,
        path: PathBuf,
    },
    /// A checkpoint that is incomplete, corrupt or of another kind.
    #[error("checkpoint: {msg}: {path}")]
    Checkpoint { msg: String, path: PathBuf },
    /// Saved training state (optimizer moments, image pools) that does not fit the run.
    #[error("checkpoint: {0}")]
    State(String),
    #[error("cannot write the {what}: {source}: {path}")]
    Write {
        what: &'static str,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
        path: PathBuf,
    },
    #[error("{what}: {source}")]
    Frame {
        what: String,
        #[source]
        source: milv_data::frame_codec::CodecError,
    },
}

impl Error {
    /// Maps an I/O error on `path` (what was being done: `op`).
    pub fn io(op: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
        let path = path.into();
        move |source| Error::Io { op, source, path }
    }

    /// Maps a safetensors read or write error of `path`.
    pub fn tensors(path: impl Into<PathBuf>) -> impl FnOnce(tch::TchError) -> Error {
        let path = path.into();
        move |source| Error::Tensors { source, path }
    }

    pub fn checkpoint(msg: impl Into<String>, path: impl Into<PathBuf>) -> Error {
        Error::Checkpoint {
            msg: msg.into(),
            path: path.into(),
        }
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
