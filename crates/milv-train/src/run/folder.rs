//! Checkpoint folders: written whole under a temporary name and renamed, found again by
//! their step number, with format-checked JSON metadata and the data they trained on.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// What a checkpoint was trained on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataRef {
    pub uri: String,
    pub version: u64,
    pub digest: String,
    pub alignment_run: Option<String>,
}

/// Pretty JSON to `path`.
pub fn write_json(path: &Path, v: &impl Serialize) -> Result<()> {
    let json = serde_json::to_vec_pretty(v).map_err(|source| Error::Json {
        op: "serialise",
        source,
        path: path.to_path_buf(),
    })?;
    std::fs::write(path, json).map_err(Error::io("write", path))
}

/// Fills `dir/.NAME.tmp` with `fill`, syncs its files and renames it to `dir/NAME`
/// (replacing an older one), so a crash never leaves a half folder that looks whole.
pub fn write_dir(dir: &Path, name: &str, fill: &mut dyn FnMut(&Path) -> Result<()>) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(Error::io("create folder", dir))?;
    let tmp = dir.join(format!(".{name}.tmp"));
    let fin = dir.join(name);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(Error::io("remove", &tmp))?;
    }
    std::fs::create_dir_all(&tmp).map_err(Error::io("create folder", &tmp))?;
    fill(&tmp)?;
    for f in std::fs::read_dir(&tmp)
        .map_err(Error::io("list", &tmp))?
        .flatten()
    {
        std::fs::File::open(f.path())
            .and_then(|h| h.sync_all())
            .map_err(Error::io("sync", &f.path()))?;
    }
    if fin.exists() {
        std::fs::remove_dir_all(&fin).map_err(Error::io("remove", &fin))?;
    }
    std::fs::rename(&tmp, &fin).map_err(Error::io("rename into place", &fin))?;
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
    read_json_formats(path, what, &[expected], format)
}

/// [`read_json_format`] for a file that may be in any of the `expected` formats.
pub fn read_json_formats<T: serde::de::DeserializeOwned>(
    path: &Path,
    what: &str,
    expected: &[&str],
    format: impl Fn(&T) -> &str,
) -> Result<T> {
    let bytes = std::fs::read(path).map_err(Error::io("read", path))?;
    let meta: T =
        serde_json::from_slice(&bytes).map_err(|e| Error::checkpoint(format!("not {what}: {e}"), path))?;
    if !expected.contains(&format(&meta)) {
        let want = expected
            .iter()
            .map(|e| format!("{e:?}"))
            .collect::<Vec<_>>()
            .join(" or ");
        return Err(Error::checkpoint(
            format!("format {:?}, expected {want}", format(&meta)),
            path,
        ));
    }
    Ok(meta)
}

/// The newest `step-N` folder under `dir` that holds `marker` (written last, so its
/// presence means the folder is complete).
pub fn latest_with(dir: &Path, marker: &str) -> Result<Option<PathBuf>> {
    if !dir.is_dir() {
        return Ok(None);
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(Error::io("list", dir))?
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
