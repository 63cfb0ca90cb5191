//! Per-episode sidecars (JSON `milv-sidecar/1` or CSV) and episode metadata.
//! The format is documented in `schemas/sidecar.md`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Episode metadata from flags, a sidecar or a manifest line; each field optional so the
/// three can be layered (manifest over sidecar over flags).
#[derive(Clone, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EpisodeMeta {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub domain: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub task_id: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub task_family: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pair_id: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub split: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
}

impl EpisodeMeta {
    /// `self` where set, else `under`.
    pub fn over(self, under: &EpisodeMeta) -> EpisodeMeta {
        EpisodeMeta {
            domain: self.domain.or_else(|| under.domain.clone()),
            kind: self.kind.or_else(|| under.kind.clone()),
            task_id: self.task_id.or_else(|| under.task_id.clone()),
            task_family: self.task_family.or_else(|| under.task_family.clone()),
            pair_id: self.pair_id.or_else(|| under.pair_id.clone()),
            split: self.split.or_else(|| under.split.clone()),
            fps: self.fps.or(under.fps),
        }
    }

    /// Sets one field from a `key: value` pair (CSV comments, manifest columns).
    pub fn set(&mut self, key: &str, value: &str) -> std::result::Result<(), String> {
        let v = value.trim();
        let opt = (!v.is_empty()).then(|| v.to_string());
        match key.trim() {
            "domain" => self.domain = opt,
            "kind" => self.kind = opt,
            "task_id" | "task" => self.task_id = opt,
            "task_family" => self.task_family = opt,
            "pair_id" => self.pair_id = opt,
            "split" => self.split = opt,
            "fps" => {
                self.fps = match opt {
                    Some(s) => Some(s.parse().map_err(|_| format!("fps {s:?} is not a number"))?),
                    None => None,
                }
            }
            other => return Err(format!("unknown metadata key {other:?}")),
        }
        Ok(())
    }
}

/// A parsed sidecar.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sidecar {
    pub path: PathBuf,
    pub meta: EpisodeMeta,
    pub action_names: Option<Vec<String>>,
    pub state_names: Option<Vec<String>>,
    /// One row per source frame.
    pub actions: Option<Vec<Vec<f32>>>,
    pub states: Option<Vec<Vec<f32>>>,
}

/// The JSON form, both ways (every key but `format` optional).
#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct JsonSidecar {
    format: Option<String>,
    #[serde(default)]
    episode: EpisodeMeta,
    #[serde(skip_serializing_if = "Option::is_none")]
    action_names: Option<Vec<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    state_names: Option<Vec<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    actions: Option<Vec<Vec<f64>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    states: Option<Vec<Vec<f64>>>,
}

impl Sidecar {
    /// The sidecar as `milv-sidecar/1` JSON (keys sorted, pretty-printed), as `read`
    /// reads it back.
    pub fn to_json(&self) -> String {
        let rows = |r: &Option<Vec<Vec<f32>>>| {
            r.as_ref().map(|r| {
                r.iter()
                    .map(|row| row.iter().map(|&v| f64::from(v)).collect())
                    .collect()
            })
        };
        let raw = JsonSidecar {
            format: Some(SIDECAR_FORMAT.into()),
            episode: self.meta.clone(),
            action_names: self.action_names.clone(),
            state_names: self.state_names.clone(),
            actions: rows(&self.actions),
            states: rows(&self.states),
        };
        // Through a Value: its maps sort their keys, so the text is canonical.
        let value = serde_json::to_value(&raw).unwrap_or_default();
        serde_json::to_string_pretty(&value).unwrap_or_default()
    }

    /// Writes [`Sidecar::to_json`] to `path`.
    pub fn write(&self, path: &Path) -> Result<()> {
        std::fs::write(path, self.to_json()).map_err(|e| Error::Io {
            op: "write sidecar",
            source: e,
            path: path.to_path_buf(),
        })
    }
}

pub const SIDECAR_FORMAT: &str = "milv-sidecar/1";

/// The sidecar next to an input: `<stem>.json` / `<stem>.csv` beside a video,
/// `<folder>.json` / `<folder>.csv` beside a frame folder.
pub fn discover(input: &Path) -> Option<PathBuf> {
    let base = if input.is_dir() {
        input.to_path_buf()
    } else {
        input.with_extension("")
    };
    ["json", "csv"].iter().find_map(|ext| {
        let mut p = base.clone().into_os_string();
        p.push(".");
        p.push(ext);
        let p = PathBuf::from(p);
        (p.is_file() && p != input).then_some(p)
    })
}

fn rows_to_f32(
    path: &Path,
    what: &str,
    names: Option<&[String]>,
    rows: Vec<Vec<f64>>,
) -> Result<Vec<Vec<f32>>> {
    let width = names.map_or_else(|| rows.first().map_or(0, Vec::len), <[String]>::len);
    let bad = |msg: String| Error::Sidecar {
        path: path.to_path_buf(),
        msg,
    };
    if width == 0 && !rows.is_empty() {
        return Err(bad(format!("{what} rows are empty")));
    }
    rows.into_iter()
        .enumerate()
        .map(|(i, row)| {
            if row.len() != width {
                return Err(bad(format!(
                    "{what} row {i} has {} values, expected {width} (rows must all have the same width)",
                    row.len()
                )));
            }
            row.iter()
                .enumerate()
                .map(|(j, &v)| {
                    let f = v as f32;
                    if f.is_finite() {
                        Ok(f)
                    } else {
                        let col = names
                            .and_then(|n| n.get(j))
                            .map_or_else(|| j.to_string(), Clone::clone);
                        Err(bad(format!("{what} row {i}, {col}: {v} is not a finite number")))
                    }
                })
                .collect()
        })
        .collect()
}

/// Reads a sidecar, JSON or CSV by extension.
pub fn read(path: &Path) -> Result<Sidecar> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        op: "read sidecar",
        source: e,
        path: path.to_path_buf(),
    })?;
    let is_csv = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv {
        parse_csv(path, &text)
    } else {
        parse_json(path, &text)
    }
}

fn parse_json(path: &Path, text: &str) -> Result<Sidecar> {
    let raw: JsonSidecar = serde_json::from_str(text).map_err(|e| {
        let hint = if ["NaN", "Infinity"].iter().any(|t| text.contains(t)) {
            " (NaN/Infinity are not valid JSON numbers, and actions must be finite)"
        } else {
            ""
        };
        Error::Sidecar {
            path: path.to_path_buf(),
            msg: format!("invalid JSON: {e}{hint}"),
        }
    })?;
    if let Some(f) = &raw.format
        && f != SIDECAR_FORMAT
    {
        return Err(Error::Sidecar {
            path: path.to_path_buf(),
            msg: format!("format {f:?} is not {SIDECAR_FORMAT:?}"),
        });
    }
    let actions = raw
        .actions
        .map(|r| rows_to_f32(path, "action", raw.action_names.as_deref(), r))
        .transpose()?;
    let states = raw
        .states
        .map(|r| rows_to_f32(path, "state", raw.state_names.as_deref(), r))
        .transpose()?;
    Ok(Sidecar {
        path: path.to_path_buf(),
        meta: raw.episode,
        action_names: raw.action_names,
        state_names: raw.state_names,
        actions,
        states,
    })
}

fn parse_csv(path: &Path, text: &str) -> Result<Sidecar> {
    let bad = |msg: String| Error::Sidecar {
        path: path.to_path_buf(),
        msg,
    };
    let mut meta = EpisodeMeta::default();
    let mut body = String::new();
    for (n, line) in text.lines().enumerate() {
        if let Some(c) = line.strip_prefix('#') {
            let (k, v) = c
                .split_once(':')
                .or_else(|| c.split_once('='))
                .ok_or_else(|| bad(format!("line {}: comment is not `# key: value`", n + 1)))?;
            meta.set(k, v).map_err(|m| bad(format!("line {}: {m}", n + 1)))?;
        } else {
            body.push_str(line);
            body.push('\n');
        }
    }
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(body.as_bytes());
    let headers = rdr.headers().map_err(|e| bad(format!("header: {e}")))?.clone();
    let mut action_cols = Vec::new();
    let mut state_cols = Vec::new();
    let mut index_col = None;
    for (i, h) in headers.iter().enumerate() {
        let h = h.trim();
        if let Some(n) = h.strip_prefix("action.") {
            action_cols.push((i, n.to_string()));
        } else if let Some(n) = h.strip_prefix("state.") {
            state_cols.push((i, n.to_string()));
        } else if h == "frame_index" {
            index_col = Some(i);
        } else {
            return Err(bad(format!(
                "column {h:?} is neither action.<name>, state.<name> nor frame_index"
            )));
        }
    }
    let mut actions = Vec::new();
    let mut states = Vec::new();
    for (r, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| bad(format!("row {r}: {e}")))?;
        if rec.len() != headers.len() {
            return Err(bad(format!(
                "row {r} has {} fields, header has {}",
                rec.len(),
                headers.len()
            )));
        }
        // Rows are matched to frames by position; a frame_index column must agree.
        if let Some(i) = index_col
            && rec.get(i).map(str::trim) != Some(r.to_string().as_str())
        {
            return Err(bad(format!(
                "row {r}: frame_index is {:?}, expected {r} (one row per frame, in order)",
                rec.get(i).unwrap_or("")
            )));
        }
        let get = |cols: &[(usize, String)]| -> Result<Vec<f64>> {
            cols.iter()
                .map(|(i, n)| {
                    let s = rec.get(*i).unwrap_or("").trim();
                    s.parse::<f64>()
                        .map_err(|_| bad(format!("row {r}, {n}: {s:?} is not a number")))
                })
                .collect()
        };
        actions.push(get(&action_cols)?);
        states.push(get(&state_cols)?);
    }
    let names = |c: &[(usize, String)]| c.iter().map(|(_, n)| n.clone()).collect::<Vec<_>>();
    let (an, sn) = (names(&action_cols), names(&state_cols));
    Ok(Sidecar {
        path: path.to_path_buf(),
        meta,
        actions: (!an.is_empty())
            .then(|| rows_to_f32(path, "action", Some(&an), actions))
            .transpose()?,
        states: (!sn.is_empty())
            .then(|| rows_to_f32(path, "state", Some(&sn), states))
            .transpose()?,
        action_names: (!an.is_empty()).then_some(an),
        state_names: (!sn.is_empty()).then_some(sn),
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("ep.json")
    }

    #[test]
    fn json_sidecar_parses() {
        let s = parse_json(
            p(),
            r#"{"format":"milv-sidecar/1","episode":{"domain":"robot","fps":10},
               "action_names":["dx","dy"],"actions":[[1,2],[3,4.5]]}"#,
        )
        .unwrap();
        assert_eq!(s.meta.domain.as_deref(), Some("robot"));
        assert_eq!(s.meta.fps, Some(10.0));
        assert_eq!(s.actions.unwrap(), vec![vec![1.0, 2.0], vec![3.0, 4.5]]);
    }

    #[test]
    fn bad_json_sidecars_are_named_errors() {
        for (text, needle) in [
            (r#"{"actions":[[1,2],[3]]}"#, "same width"),
            (r#"{"actions":[[1,NaN]]}"#, "NaN"),
            (r#"{"actions":[[1,1e300]]}"#, "finite"),
            (r#"{"format":"other"}"#, "format"),
            (r#"{"bogus":1}"#, "unknown field"),
        ] {
            let e = parse_json(p(), text).unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
            assert!(e.contains("ep.json"), "{e}");
        }
    }

    #[test]
    fn csv_sidecar_parses_with_metadata() {
        let s = parse_csv(
            Path::new("a.csv"),
            "# domain: human\n# task_id: draw/square\naction.dx,action.dy,state.x\n1,2,3\n4,5,6\n",
        )
        .unwrap();
        assert_eq!(s.meta.domain.as_deref(), Some("human"));
        assert_eq!(s.meta.task_id.as_deref(), Some("draw/square"));
        assert_eq!(s.action_names.unwrap(), vec!["dx", "dy"]);
        assert_eq!(s.states.unwrap(), vec![vec![3.0], vec![6.0]]);
    }

    #[test]
    fn csv_frame_index_must_count_rows() {
        let ok = parse_csv(Path::new("a.csv"), "frame_index,action.dx\n0,1\n1,2\n").unwrap();
        assert_eq!(ok.actions.unwrap().len(), 2);
        let e = parse_csv(Path::new("a.csv"), "frame_index,action.dx\n0,1\n2,2\n").unwrap_err();
        assert!(e.to_string().contains("frame_index is \"2\", expected 1"), "{e}");
    }

    #[test]
    fn csv_nan_is_rejected() {
        let e = parse_csv(Path::new("a.csv"), "action.dx\n1\nnan\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("row 1, dx") && e.contains("finite"), "{e}");
    }

    #[test]
    fn layering_prefers_the_specific_source() {
        let flags = EpisodeMeta {
            domain: Some("human".into()),
            split: Some("val".into()),
            ..Default::default()
        };
        let side = EpisodeMeta {
            domain: Some("robot".into()),
            ..Default::default()
        };
        let m = side.over(&flags);
        assert_eq!(m.domain.as_deref(), Some("robot"));
        assert_eq!(m.split.as_deref(), Some("val"));
    }

    #[test]
    fn a_written_sidecar_reads_back() {
        let s = Sidecar {
            path: PathBuf::from("x.json"),
            meta: EpisodeMeta {
                domain: Some("robot".into()),
                kind: Some("random".into()),
                pair_id: Some("p1".into()),
                ..EpisodeMeta::default()
            },
            action_names: Some(vec!["dx".into(), "dy".into()]),
            state_names: None,
            actions: Some(vec![vec![0.5, -0.1], vec![0.25, 3.0]]),
            states: None,
        };
        let text = s.to_json();
        assert!(text.contains("\"format\": \"milv-sidecar/1\""), "{text}");
        assert!(!text.contains("states") && !text.contains("task_id"), "{text}");
        assert_eq!(parse_json(&s.path, &text).unwrap(), s);
    }
}
