//! Checkpoints: a folder per step with the networks (`G`, `F`, `DX`, `DY`, `IDM`
//! `.safetensors`), the optimizer moments and image pools (`state.safetensors`) and
//! `checkpoint.json` (configs, step, the dataset version and data digest it trained on,
//! and the model id). Written to a temporary folder and renamed, so a crash never leaves
//! a half checkpoint that looks whole.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use tch::{Device, Tensor};

use crate::config::{ModelConfig, TrainConfig};
use crate::cyclegan::{ACycleGan, NET_FILES};
use crate::{Error, Result};

/// What a checkpoint was trained on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataRef {
    pub uri: String,
    pub version: u64,
    pub digest: String,
    pub alignment_run: Option<String>,
}

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
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
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

/// Pretty JSON to `path`.
pub fn write_json(path: &Path, v: &impl Serialize) -> Result<()> {
    let json = serde_json::to_vec_pretty(v).map_err(|e| Error::Checkpoint(e.to_string()))?;
    std::fs::write(path, json).map_err(|e| Error::io(path, e))
}

/// Fills `dir/.NAME.tmp` with `fill`, syncs its files and renames it to `dir/NAME`
/// (replacing an older one), so a crash never leaves a half folder that looks whole.
pub fn write_dir(dir: &Path, name: &str, fill: &mut dyn FnMut(&Path) -> Result<()>) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let tmp = dir.join(format!(".{name}.tmp"));
    let fin = dir.join(name);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    fill(&tmp)?;
    for f in std::fs::read_dir(&tmp).map_err(|e| Error::io(&tmp, e))?.flatten() {
        std::fs::File::open(f.path())
            .and_then(|h| h.sync_all())
            .map_err(|e| Error::io(&f.path(), e))?;
    }
    if fin.exists() {
        std::fs::remove_dir_all(&fin).map_err(|e| Error::io(&fin, e))?;
    }
    std::fs::rename(&tmp, &fin).map_err(|e| Error::io(&fin, e))?;
    Ok(fin)
}

/// Reads a checkpoint's JSON metadata (`what` names it in errors) and checks that its
/// `format` field is `expected`.
pub fn read_json_format<T: serde::de::DeserializeOwned>(
    path: &Path,
    what: &str,
    expected: &str,
    format: impl Fn(&T) -> &str,
) -> Result<T> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let meta: T = serde_json::from_slice(&bytes)
        .map_err(|e| Error::Checkpoint(format!("{}: not {what}: {e}", path.display())))?;
    if format(&meta) != expected {
        return Err(Error::Checkpoint(format!(
            "{}: format {:?}, expected {expected:?}",
            path.display(),
            format(&meta)
        )));
    }
    Ok(meta)
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
            return Err(Error::Checkpoint(format!("{}: {n} is missing", dir.display())));
        }
    }
    Ok(meta)
}

/// Loads a checkpoint into a run on `device`; its model id must match its files.
pub fn load(dir: &Path, device: Device) -> Result<(ACycleGan, CheckpointMeta)> {
    let meta = read_meta(dir)?;
    let actual = model_id(dir)?;
    if actual != meta.model_id {
        return Err(Error::Checkpoint(format!(
            "{}: the network files do not match checkpoint.json (model id {actual}, recorded {}): \
             the checkpoint is corrupt or was edited",
            dir.display(),
            meta.model_id
        )));
    }
    let mut run = ACycleGan::new(meta.model.clone(), meta.train.clone(), device)?;
    run.nets.load(dir)?;
    let sp = dir.join("state.safetensors");
    let state =
        Tensor::read_safetensors(&sp).map_err(|e| Error::Checkpoint(format!("{}: {e}", sp.display())))?;
    run.load_state(state)?;
    run.step = meta.step;
    Ok((run, meta))
}

/// The newest complete checkpoint under `dir` (a run's `checkpoints/`), if any.
pub fn latest(dir: &Path) -> Result<Option<PathBuf>> {
    latest_with(dir, "checkpoint.json")
}

/// The newest `step-N` folder under `dir` that holds `marker` (written last, so its
/// presence means the folder is complete).
pub fn latest_with(dir: &Path, marker: &str) -> Result<Option<PathBuf>> {
    if !dir.is_dir() {
        return Ok(None);
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .flatten()
        .filter(|e| e.path().join(marker).is_file())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("step-"))
        .collect();
    // Zero-padded step numbers sort as text.
    names.sort();
    let best = names.pop().map(|n| dir.join(n));
    Ok(best)
}
