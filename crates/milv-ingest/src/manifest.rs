//! Manifests: many episodes at once, as JSON lines or CSV with a header.
//!
//! Keys: `path` (required; relative paths are relative to the manifest's folder),
//! `sidecar` (optional, same rule), and any [`EpisodeMeta`] key.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::sidecar::EpisodeMeta;

/// One input of an ingest run.
#[derive(Clone, Debug, PartialEq)]
pub struct InputSpec {
    pub path: PathBuf,
    /// Explicit sidecar; `None` means look beside the input.
    pub sidecar: Option<PathBuf>,
    /// Metadata given for this input specifically (manifest line).
    pub meta: EpisodeMeta,
}

impl InputSpec {
    pub fn new(path: impl Into<PathBuf>) -> Self {
        InputSpec {
            path: path.into(),
            sidecar: None,
            meta: EpisodeMeta::default(),
        }
    }
}

fn resolve(base: &Path, p: &str) -> PathBuf {
    let p = Path::new(p.trim());
    // URLs (`s3://…`) stand as they are; relative paths are relative to the manifest.
    if p.is_absolute() || p.to_str().and_then(milv_data::store::url_scheme).is_some() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}

/// Reads a manifest (`.csv` by extension, otherwise JSON lines).
pub fn read(path: &Path) -> Result<Vec<InputSpec>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        op: "read manifest",
        source: e,
        path: path.to_path_buf(),
    })?;
    let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let err = |line: usize, msg: String| Error::Manifest {
        line,
        msg,
        path: path.to_path_buf(),
    };
    let mut out = Vec::new();
    let is_csv = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv {
        let mut rdr = csv::Reader::from_reader(text.as_bytes());
        let headers = rdr.headers().map_err(|e| err(1, e.to_string()))?.clone();
        for (i, rec) in rdr.records().enumerate() {
            let line = i + 2;
            let rec = rec.map_err(|e| err(line, e.to_string()))?;
            let mut spec = InputSpec::new(PathBuf::new());
            let mut has_path = false;
            for (k, v) in headers.iter().zip(rec.iter()) {
                match k.trim() {
                    "path" => {
                        spec.path = resolve(&base, v);
                        has_path = !v.trim().is_empty();
                    }
                    "sidecar" if !v.trim().is_empty() => spec.sidecar = Some(resolve(&base, v)),
                    "sidecar" => {}
                    key => spec.meta.set(key, v).map_err(|m| err(line, m))?,
                }
            }
            if !has_path {
                return Err(err(line, "no path".into()));
            }
            out.push(spec);
        }
    } else {
        for (i, l) in text.lines().enumerate() {
            let line = i + 1;
            if l.trim().is_empty() {
                continue;
            }
            let v: serde_json::Map<String, serde_json::Value> =
                serde_json::from_str(l).map_err(|e| err(line, format!("invalid JSON: {e}")))?;
            let mut spec = InputSpec::new(PathBuf::new());
            let mut has_path = false;
            for (k, val) in &v {
                let s = match val {
                    serde_json::Value::Null => String::new(),
                    serde_json::Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                match k.as_str() {
                    "path" => {
                        spec.path = resolve(&base, &s);
                        has_path = !s.is_empty();
                    }
                    "sidecar" if !s.is_empty() => spec.sidecar = Some(resolve(&base, &s)),
                    "sidecar" => {}
                    key => spec.meta.set(key, &s).map_err(|m| err(line, m))?,
                }
            }
            if !has_path {
                return Err(err(line, "no path".into()));
            }
            out.push(spec);
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn jsonl_and_csv_manifests_agree() {
        let dir = tempfile::tempdir().unwrap();
        let j = dir.path().join("m.jsonl");
        std::fs::write(
            &j,
            "{\"path\":\"a.mp4\",\"domain\":\"human\",\"fps\":10}\n\n{\"path\":\"/x/b\",\"sidecar\":\"b.json\",\"pair_id\":null}\n",
        )
        .unwrap();
        let c = dir.path().join("m.csv");
        std::fs::write(
            &c,
            "path,sidecar,domain,fps,pair_id\na.mp4,,human,10,\n/x/b,b.json,,,\n",
        )
        .unwrap();
        let a = read(&j).unwrap();
        let b = read(&c).unwrap();
        assert_eq!(a, b);
        assert_eq!(a[0].path, dir.path().join("a.mp4"));
        assert_eq!(a[0].meta.fps, Some(10.0));
        assert_eq!(a[1].sidecar, Some(dir.path().join("b.json")));
    }

    #[test]
    fn bad_lines_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let j = dir.path().join("m.jsonl");
        std::fs::write(&j, "{\"path\":\"a\"}\n{\"colour\":\"red\",\"path\":\"b\"}\n").unwrap();
        let e = read(&j).unwrap_err().to_string();
        assert!(
            e.contains("line 2") && e.contains("colour") && e.contains("m.jsonl"),
            "{e}"
        );
    }
}
