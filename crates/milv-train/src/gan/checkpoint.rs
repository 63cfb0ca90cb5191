//! Checkpoints: a folder per step with the networks (`G`, `F`, `DX`, `DY`, `IDM`
//! `.safetensors`), the optimizer moments and image pools (`state.safetensors`) and
//! `checkpoint.json` (configs, step, the dataset version and data digest it trained on,
//! and the model id). Written to a temporary folder and renamed, so a crash never leaves
//! a half checkpoint that looks whole.
//!
//! A *packed* translator ([`pack_translator`]) keeps only what a policy's one-shot
//! evaluation runs, G and F, optionally in f16, with `translator.json` naming the model
//! id of the checkpoint it came from; [`load_translation`] reads either kind.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use tch::{Device, Kind, Tensor};

use crate::gan::config::{ModelConfig, TrainConfig};
use crate::gan::cyclegan::{ACycleGan, NET_FILES, Nets};
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

const PACK_FORMAT: &str = "milv-translator-pack/1";

/// The networks a packed translator keeps: evaluation translates with G and encodes
/// with F's encoder; the discriminators, π_I and the optimizer state stay behind.
const PACK_NETS: [&str; 2] = ["G", "F"];

/// `translator.json` of a packed translator.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PackedTranslator {
    pub format: String,
    pub model: ModelConfig,
    pub decoupled: bool,
    /// The model id of the checkpoint it was packed from (what policies record).
    pub model_id: String,
    /// sha256 of the packed G and F files, checked on load.
    pub files_digest: String,
    /// Whether the weights are stored as f16 (they load back into f32 networks).
    pub half: bool,
    pub source_step: u64,
    pub tool_version: String,
}

fn digest_files(dir: &Path, names: &[&str]) -> Result<String> {
    let mut h = Sha256::new();
    for name in names {
        let path = dir.join(format!("{name}.safetensors"));
        h.update(std::fs::read(&path).map_err(Error::io("read", &path))?);
    }
    Ok(h.finalize().iter().take(8).map(|b| format!("{b:02x}")).collect())
}

/// Copies the safetensors file `src` to `dst`, converting floating tensors to f16 when
/// `half` ([`load_store`] casts them back).
pub fn copy_tensors(src: &Path, dst: &Path, half: bool) -> Result<()> {
    if !half {
        std::fs::copy(src, dst).map_err(Error::io("copy", dst))?;
        return Ok(());
    }
    let named = Tensor::read_safetensors(src).map_err(Error::tensors(src))?;
    let named: Vec<(String, Tensor)> = named
        .into_iter()
        .map(|(k, t)| {
            let t = if t.is_floating_point() {
                t.to_kind(Kind::Half)
            } else {
                t
            };
            (k, t)
        })
        .collect();
    Tensor::write_safetensors(&named, dst).map_err(Error::tensors(dst))
}

/// Writes the translation half of checkpoint `src` (G and F) into the folder `out`
/// (created if missing; callers pack into a temporary folder they rename).
pub fn pack_translator(src: &Path, out: &Path, half: bool) -> Result<PackedTranslator> {
    let meta = read_meta(src)?;
    let actual = model_id(src)?;
    if actual != meta.model_id {
        return Err(Error::checkpoint(
            format!(
                "the network files are model {actual}, checkpoint.json records {}",
                meta.model_id
            ),
            src,
        ));
    }
    std::fs::create_dir_all(out).map_err(Error::io("create folder", out))?;
    for name in PACK_NETS {
        let file = format!("{name}.safetensors");
        copy_tensors(&src.join(&file), &out.join(&file), half)?;
    }
    let packed = PackedTranslator {
        format: PACK_FORMAT.into(),
        model: meta.model,
        decoupled: meta.train.decoupled,
        model_id: meta.model_id,
        files_digest: digest_files(out, &PACK_NETS)?,
        half,
        source_step: meta.step,
        tool_version: milv_data::TOOL_VERSION.into(),
    };
    write_json(&out.join("translator.json"), &packed)?;
    Ok(packed)
}

/// Reads a packed translator's `translator.json`.
pub fn read_packed(dir: &Path) -> Result<PackedTranslator> {
    read_json_format(
        &dir.join("translator.json"),
        "a packed translator",
        PACK_FORMAT,
        |m: &PackedTranslator| &m.format,
    )
}

/// The networks of a translator for translating and encoding (G and F loaded; the
/// others at their initial values), and its model id: from a full checkpoint folder or
/// a packed one.
pub fn load_translation(dir: &Path, device: Device) -> Result<(Nets, String)> {
    if !dir.join("translator.json").is_file() {
        let (run, meta) = load(dir, device)?;
        return Ok((run.nets, meta.model_id));
    }
    let p = read_packed(dir)?;
    let actual = digest_files(dir, &PACK_NETS)?;
    if actual != p.files_digest {
        return Err(Error::checkpoint(
            format!(
                "G and F do not match translator.json (digest {actual}, recorded {}): the pack is \
                 corrupt or was edited",
                p.files_digest
            ),
            dir,
        ));
    }
    p.model.validate()?;
    let nets = Nets::new(&p.model, p.decoupled, device);
    for (vs, name) in [(&nets.vs_g, "G"), (&nets.vs_f, "F")] {
        load_store(vs, &dir.join(format!("{name}.safetensors")))?;
    }
    Ok((nets, p.model_id))
}

/// Loads a safetensors file into `vs` by copying into its variables, so f16 files fill
/// f32 networks (`VarStore::load` would swap in the f16 tensors); every variable must be
/// in the file and nothing else.
pub fn load_store(vs: &tch::nn::VarStore, path: &Path) -> Result<()> {
    let named = Tensor::read_safetensors(path).map_err(Error::tensors(path))?;
    let mut vars = vs.variables();
    if named.len() != vars.len() {
        return Err(Error::checkpoint(
            format!("{} tensors, the network has {}", named.len(), vars.len()),
            path,
        ));
    }
    tch::no_grad(|| {
        for (k, t) in &named {
            let v = vars
                .get_mut(k)
                .ok_or_else(|| Error::checkpoint(format!("tensor {k} is not in the network"), path))?;
            if v.size() != t.size() {
                return Err(Error::checkpoint(
                    format!(
                        "tensor {k} has shape {:?}, the network's {:?}",
                        t.size(),
                        v.size()
                    ),
                    path,
                ));
            }
            v.f_copy_(t).map_err(Error::tensors(path))?;
        }
        Ok(())
    })
}
