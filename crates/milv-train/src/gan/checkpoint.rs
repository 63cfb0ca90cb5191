//! Checkpoints: a folder per step with the networks (`G`, `F`, `DX`, `DY`, `IDM`
//! `.safetensors`), the optimizer moments and image pools (`state.safetensors`) and
//! `checkpoint.json` (configs, step, the dataset version and data digest it trained on,
//! and the model id). Written to a temporary folder and renamed, so a crash never leaves
//! a half checkpoint that looks whole.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use tch::{Device, Tensor};

use crate::gan::config::{ModelConfig, TrainConfig};
use crate::gan::cyclegan::{ACycleGan, NET_FILES};
use crate::run::DataRef;
use crate::run::folder::{latest_with, read_json_format, write_dir, write_json};
use crate::{Error, Result};

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CheckpointMeta {
    pub format: String,
    pub step: u64,
    pub model: ModelConfig,
    pub train: TrainConfig,
    pub data: DataRef,
    /// Digest of the translation networks (G, F, IDM): names the rows `translate` writes.
    pub model_id: String,
    pub tool_version: String,
}

const FORMAT: &str = "milv-acyclegan/1";

/// The model id of a checkpoint folder: sha256 of G, F and IDM's files (16 hex chars).
pub fn model_id(dir: &Path) -> Result<String> {
    let mut h = Sha256::new();
    for name in ["G", "F", "IDM"] {
        let path = dir.join(format!("{name}.safetensors"));
        let bytes = std::fs::read(&path).map_err(Error::io("read", &path))?;
        h.update(&bytes);
    }
    let d = h.finalize();
    Ok(format!(
        "acg-{}",
        d.iter().take(8).map(|b| format!("{b:02x}")).collect::<String>()
    ))
}

/// Writes `run`'s checkpoint as `dir/step-NNNNNNNN` and returns that folder.
pub fn save(run: &ACycleGan, data: &DataRef, dir: &Path) -> Result<PathBuf> {
    write_dir(dir, &format!("step-{:08}", run.step), &mut |tmp| {
        run.nets.save(tmp)?;
        let state = run.state();
        Tensor::write_safetensors(&state, tmp.join("state.safetensors"))?;
        let meta = CheckpointMeta {
            format: FORMAT.into(),
            step: run.step,
            model: run.model.clone(),
            train: run.train.clone(),
            data: data.clone(),
            model_id: model_id(tmp)?,
            tool_version: milv_data::TOOL_VERSION.into(),
        };
        write_json(&tmp.join("checkpoint.json"), &meta)
    })
}

/// Reads a checkpoint's metadata, checking that every file it needs is there.
pub fn read_meta(dir: &Path) -> Result<CheckpointMeta> {
    let meta: CheckpointMeta = read_json_format(
        &dir.join("checkpoint.json"),
        "a checkpoint",
        FORMAT,
        |m: &CheckpointMeta| &m.format,
    )?;
    for n in NET_FILES
        .iter()
        .map(|n| format!("{n}.safetensors"))
        .chain(["state.safetensors".into()])
    {
        if !dir.join(&n).is_file() {
            return Err(Error::checkpoint(format!("{n} is missing"), dir));
        }
    }
    Ok(meta)
}

/// Loads a checkpoint into a run on `device`; its model id must match its files.
pub fn load(dir: &Path, device: Device) -> Result<(ACycleGan, CheckpointMeta)> {
    let meta = read_meta(dir)?;
    let actual = model_id(dir)?;
    if actual != meta.model_id {
        return Err(Error::checkpoint(
            format!(
                "the network files do not match checkpoint.json (model id {actual}, recorded {}): \
                 the checkpoint is corrupt or was edited",
                meta.model_id
            ),
            dir,
        ));
    }
    let mut run = ACycleGan::new(meta.model.clone(), meta.train.clone(), device)?;
    run.nets.load(dir)?;
    let sp = dir.join("state.safetensors");
    let state = Tensor::read_safetensors(&sp).map_err(Error::tensors(&sp))?;
    run.load_state(state)?;
    run.step = meta.step;
    Ok((run, meta))
}

/// The newest complete checkpoint under `dir` (a run's `checkpoints/`), if any.
pub fn latest(dir: &Path) -> Result<Option<PathBuf>> {
    latest_with(dir, "checkpoint.json")
}
