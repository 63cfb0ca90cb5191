//! The LeRobot v3.0 layout: `meta/info.json`, its path templates, feature descriptions,
//! `meta/tasks.parquet` and the typed columns of the Parquet files.
//! See docs/interop/lerobot-v3.md for the format as LeRobot 0.6.1 reads and writes it.

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use milv_data::arrow::array::{
    Array, ArrayRef, AsArray as _, FixedSizeListArray, Float32Array, Float64Array, Int32Array, Int64Array,
    LargeListArray, ListArray, RecordBatch, StringArray, UInt32Array, UInt64Array,
};
use milv_data::arrow::datatypes::{DataType, Field, Schema};
use serde_json::{Value, json};

use crate::error::{Error, Result};

/// The codebase version this crate reads and writes.
pub const CODEBASE_VERSION: &str = "v3.0";
/// LeRobot's default templates (written on export; any safe template is read).
pub const DATA_PATH: &str = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
pub const VIDEO_PATH: &str = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4";
pub const EPISODES_PATH: &str = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
pub const INFO_PATH: &str = "meta/info.json";
pub const STATS_PATH: &str = "meta/stats.json";
pub const TASKS_PATH: &str = "meta/tasks.parquet";
/// LeRobot's tolerance on a decoded frame's timestamp (`LeRobotDataset(tolerance_s=1e-4)`).
pub const TOLERANCE_S: f64 = 1e-4;
/// The features every LeRobot dataset has, in LeRobot's order.
pub const DEFAULT_FEATURES: [&str; 5] = ["timestamp", "frame_index", "episode_index", "index", "task_index"];

/// One entry of `info.json`'s `features`.
#[derive(Clone, Debug, PartialEq)]
pub struct Feature {
    pub key: String,
    pub dtype: String,
    pub shape: Vec<usize>,
    /// Component names, flattened (`["x", "y"]`; LeRobot also writes `{"motors": [...]}`).
    pub names: Option<Vec<String>>,
}

impl Feature {
    pub fn is_visual(&self) -> bool {
        self.dtype == "video" || self.dtype == "image"
    }
}

/// The parts of `meta/info.json` MILV uses.
#[derive(Clone, Debug)]
pub struct Info {
    pub path: PathBuf,
    pub codebase_version: String,
    pub fps: u32,
    pub total_episodes: u64,
    pub total_frames: u64,
    pub data_path: String,
    pub video_path: Option<String>,
    pub features: Vec<Feature>,
    /// `splits`: name → `"start:end"` episode ranges.
    pub splits: Vec<(String, u64, u64)>,
}

fn names_of(v: &Value) -> Option<Vec<String>> {
    match v {
        Value::Array(a) => Some(
            a.iter()
                .map(|x| x.as_str().map_or_else(|| x.to_string(), str::to_string))
                .collect(),
        ),
        // {"motors": [...]} (older datasets): the single list inside.
        Value::Object(m) if m.len() == 1 => m.values().next().and_then(names_of),
        _ => None,
    }
}

impl Info {
    /// Reads and checks `DIR/meta/info.json`. v2.x is refused with the conversion command.
    pub fn read(dir: &Path) -> Result<Info> {
        let path = dir.join(INFO_PATH);
        let text = std::fs::read_to_string(&path).map_err(Error::io("cannot read", &path))?;
        let v: Value = serde_json::from_str(&text).map_err(|source| Error::Json {
            path: path.clone(),
            source,
        })?;
        let bad = |msg: String| Error::format(&path, msg);
        let version = v["codebase_version"]
            .as_str()
            .ok_or_else(|| bad("no codebase_version".into()))?
            .to_string();
        if version != CODEBASE_VERSION {
            let hint = if version.starts_with("v2") {
                " (convert it first: python -m lerobot.scripts.convert_dataset_v21_to_v30 --repo-id=X --root=DIR --push-to-hub=false)"
            } else {
                ""
            };
            return Err(bad(format!(
                "codebase_version {version:?} is not supported: MILV reads LeRobot {CODEBASE_VERSION}{hint}"
            )));
        }
        let fps = v["fps"].as_f64().ok_or_else(|| bad("no numeric fps".into()))?;
        if !(fps >= 1.0 && fps.fract() == 0.0 && fps <= 10_000.0) {
            return Err(bad(format!("fps {fps} is not a positive integer")));
        }
        let int = |k: &str| v[k].as_u64().ok_or_else(|| bad(format!("no integer {k}")));
        let data_path = v["data_path"]
            .as_str()
            .ok_or_else(|| bad("no data_path".into()))?
            .to_string();
        let video_path = v["video_path"].as_str().map(str::to_string);
        let Some(feats) = v["features"].as_object() else {
            return Err(bad("no features object".into()));
        };
        let mut features = Vec::new();
        for (key, f) in feats {
            let dtype = f["dtype"]
                .as_str()
                .ok_or_else(|| bad(format!("feature {key:?} has no dtype")))?
                .to_string();
            let shape = f["shape"]
                .as_array()
                .ok_or_else(|| bad(format!("feature {key:?} has no shape")))?
                .iter()
                .map(|d| d.as_u64().map(|d| d as usize))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| bad(format!("feature {key:?} has a non-integer shape")))?;
            features.push(Feature {
                key: key.clone(),
                dtype,
                shape,
                names: names_of(&f["names"]),
            });
        }
        for d in DEFAULT_FEATURES {
            if !features.iter().any(|f| f.key == d) {
                return Err(bad(format!("missing the default feature {d:?}")));
            }
        }
        let mut splits = Vec::new();
        if let Some(m) = v["splits"].as_object() {
            for (name, r) in m {
                let parsed = r.as_str().and_then(|r| {
                    let (a, b) = r.split_once(':')?;
                    Some((a.trim().parse().ok()?, b.trim().parse().ok()?))
                });
                let (a, b) =
                    parsed.ok_or_else(|| bad(format!("split {name:?}: {r} is not \"start:end\"")))?;
                splits.push((name.clone(), a, b));
            }
        }
        Ok(Info {
            codebase_version: version,
            fps: fps as u32,
            total_episodes: int("total_episodes")?,
            total_frames: int("total_frames")?,
            data_path,
            video_path,
            features,
            splits,
            path,
        })
    }

    pub fn feature(&self, key: &str) -> Option<&Feature> {
        self.features.iter().find(|f| f.key == key)
    }

    /// Keys of the camera features (video or image), in info.json order.
    pub fn cameras(&self) -> Vec<&Feature> {
        self.features.iter().filter(|f| f.is_visual()).collect()
    }

    /// The split an episode index falls in (`train` when `splits` does not cover it).
    pub fn split_of(&self, episode: u64) -> &str {
        self.splits
            .iter()
            .find(|(_, a, b)| (*a..*b).contains(&episode))
            .map_or("train", |(n, _, _)| n.as_str())
    }
}

/// A value substituted into a path template.
pub enum Arg<'a> {
    Int(i64),
    Str(&'a str),
}

/// Fills a Python format template (`{chunk_index:03d}`, `{video_key}`) and checks that the
/// result stays inside the dataset: a relative path of plain components (no `..`, no
/// absolute path). Anything else is refused, never read or written.
pub fn fill_template(template: &str, args: &[(&str, Arg<'_>)], info_path: &Path) -> Result<PathBuf> {
    let bad = |msg: String| Error::format(info_path, format!("template {template:?}: {msg}"));
    let mut out = String::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let close = rest[open..].find('}').ok_or_else(|| bad("unclosed '{'".into()))? + open;
        let field = &rest[open + 1..close];
        let (name, spec) = field.split_once(':').unwrap_or((field, ""));
        let (_, value) = args
            .iter()
            .find(|(n, _)| *n == name)
            .ok_or_else(|| bad(format!("unknown placeholder {{{name}}}")))?;
        match (value, spec) {
            (Arg::Str(s), "") => out.push_str(s),
            (Arg::Int(i), "") | (Arg::Int(i), "d") => out.push_str(&i.to_string()),
            (Arg::Int(i), spec) if spec.starts_with('0') && spec.ends_with('d') => {
                let width: usize = spec[1..spec.len() - 1]
                    .parse()
                    .map_err(|_| bad(format!("format spec {spec:?}")))?;
                out.push_str(&format!("{i:0width$}"));
            }
            _ => return Err(bad(format!("format spec {spec:?} for {{{name}}}"))),
        }
        rest = &rest[close + 1..];
    }
    out.push_str(rest);
    let p = PathBuf::from(&out);
    if out.is_empty() || !p.components().all(|c| matches!(c, Component::Normal(_))) {
        return Err(bad(format!(
            "gives {out:?}, which is not a relative path inside the dataset (no '..', no absolute path)"
        )));
    }
    Ok(p)
}

/// `root/rel` if the existing file there (symlinks resolved) is inside `root`.
pub fn inside(root: &Path, rel: &Path) -> Result<PathBuf> {
    let p = root.join(rel);
    let canon_root = root.canonicalize().map_err(Error::io("cannot resolve", root))?;
    let canon = p.canonicalize().map_err(Error::io("cannot open", &p))?;
    if !canon.starts_with(&canon_root) {
        return Err(Error::format(&p, "resolves outside the dataset folder (refused)"));
    }
    Ok(p)
}

/// `meta/tasks.parquet`: task_index → task text. Takes the task from the `task` column
/// (pandas writes its index as one) or, failing that, the pandas index metadata.
pub fn read_tasks(dir: &Path) -> Result<Vec<String>> {
    let path = dir.join(TASKS_PATH);
    let batches = read_parquet(&path, None)?;
    let mut tasks: Vec<(i64, String)> = Vec::new();
    for b in &batches {
        let idx = int_values(&path, b, "task_index")?;
        let col = b
            .column_by_name("task")
            .or_else(|| b.column_by_name("__index_level_0__"))
            .ok_or_else(|| Error::format(&path, "no task column"))?;
        let text = col
            .as_any()
            .downcast_ref::<StringArray>()
            .ok_or_else(|| Error::format(&path, "the task column is not a string column"))?;
        for (i, t) in idx.into_iter().zip(text.iter()) {
            tasks.push((i, t.unwrap_or_default().to_string()));
        }
    }
    tasks.sort_by_key(|t| t.0);
    for (want, (got, _)) in tasks.iter().enumerate() {
        if *got != want as i64 {
            return Err(Error::format(
                &path,
                format!("task_index {got} where {want} was expected"),
            ));
        }
    }
    Ok(tasks.into_iter().map(|t| t.1).collect())
}

/// The pandas metadata LeRobot's loader needs to see `task` as the frame's index (without
/// it, `item["task"]` silently becomes the row number).
pub fn tasks_batch(tasks: &[String]) -> Result<RecordBatch, milv_data::arrow::error::ArrowError> {
    let pandas = json!({
        "index_columns": ["task"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode", "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": null}
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": "26.0.1"},
        "pandas_version": "2.3.3"
    });
    let schema = Schema::new(vec![
        Field::new("task_index", DataType::Int64, true),
        Field::new("task", DataType::Utf8, true),
    ])
    .with_metadata([("pandas".to_string(), pandas.to_string())].into());
    RecordBatch::try_new(
        Arc::new(schema),
        vec![
            Arc::new(Int64Array::from_iter_values(0..tasks.len() as i64)),
            Arc::new(StringArray::from_iter_values(tasks)),
        ],
    )
}

/// Every batch of a Parquet file, optionally only some columns (by name; missing ones are
/// ignored, the caller checks).
pub fn read_parquet(path: &Path, columns: Option<&[&str]>) -> Result<Vec<RecordBatch>> {
    use milv_data::parquet::arrow::ProjectionMask;
    use milv_data::parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let f = std::fs::File::open(path).map_err(Error::io("cannot open", path))?;
    let mut b = ParquetRecordBatchReaderBuilder::try_new(f).map_err(Error::parquet(path))?;
    if let Some(cols) = columns {
        let roots: Vec<usize> = b
            .schema()
            .fields()
            .iter()
            .enumerate()
            .filter(|(_, f)| cols.contains(&f.name().as_str()))
            .map(|(i, _)| i)
            .collect();
        let mask = ProjectionMask::roots(b.parquet_schema(), roots);
        b = b.with_projection(mask);
    }
    let reader = b.with_batch_size(4096).build().map_err(Error::parquet(path))?;
    reader.map(|r| r.map_err(Error::arrow(path))).collect()
}

fn column<'a>(path: &Path, b: &'a RecordBatch, name: &str) -> Result<&'a ArrayRef> {
    b.column_by_name(name)
        .ok_or_else(|| Error::format(path, format!("no column {name:?}")))
}

/// An integer column as i64 (LeRobot writes int64; int32/uint are accepted).
pub fn int_values(path: &Path, b: &RecordBatch, name: &str) -> Result<Vec<i64>> {
    let c = column(path, b, name)?;
    let any = c.as_any();
    let v: Option<Vec<i64>> = if let Some(a) = any.downcast_ref::<Int64Array>() {
        a.iter().collect()
    } else if let Some(a) = any.downcast_ref::<Int32Array>() {
        a.iter().map(|x| x.map(i64::from)).collect()
    } else if let Some(a) = any.downcast_ref::<UInt64Array>() {
        a.iter().map(|x| x.map(|x| x as i64)).collect()
    } else if let Some(a) = any.downcast_ref::<UInt32Array>() {
        a.iter().map(|x| x.map(i64::from)).collect()
    } else {
        return Err(Error::format(
            path,
            format!("column {name:?} is {}, not an integer", c.data_type()),
        ));
    };
    v.ok_or_else(|| Error::format(path, format!("column {name:?} has nulls")))
}

/// A float column as f64 (timestamps: float32 in data files, double in episode files).
pub fn float_values(path: &Path, b: &RecordBatch, name: &str) -> Result<Vec<f64>> {
    let c = column(path, b, name)?;
    let any = c.as_any();
    let v: Option<Vec<f64>> = if let Some(a) = any.downcast_ref::<Float64Array>() {
        a.iter().collect()
    } else if let Some(a) = any.downcast_ref::<Float32Array>() {
        a.iter().map(|x| x.map(f64::from)).collect()
    } else {
        return Err(Error::format(
            path,
            format!("column {name:?} is {}, not a float", c.data_type()),
        ));
    };
    v.ok_or_else(|| Error::format(path, format!("column {name:?} has nulls")))
}

fn floats_of(values: &ArrayRef) -> Option<Vec<f32>> {
    if let Some(a) = values.as_any().downcast_ref::<Float32Array>() {
        return Some(a.values().to_vec());
    }
    if let Some(a) = values.as_any().downcast_ref::<Float64Array>() {
        return Some(a.values().iter().map(|&x| x as f32).collect());
    }
    None
}

/// A vector feature, one `Vec<f32>` per row: fixed-size or variable lists of float32/64,
/// or a scalar float column (a feature of shape `[1]`).
pub fn vector_values(path: &Path, b: &RecordBatch, name: &str) -> Result<Vec<Vec<f32>>> {
    let c = column(path, b, name)?;
    let bad = || {
        Error::format(
            path,
            format!("column {name:?} ({}) is not a float vector", c.data_type()),
        )
    };
    if c.null_count() > 0 {
        return Err(Error::format(path, format!("column {name:?} has nulls")));
    }
    let rows =
        |n: usize, offsets: &dyn Fn(usize) -> (usize, usize), values: &ArrayRef| -> Result<Vec<Vec<f32>>> {
            let flat = floats_of(values).ok_or_else(bad)?;
            (0..n)
                .map(|i| {
                    let (a, b) = offsets(i);
                    flat.get(a..b).map(<[f32]>::to_vec).ok_or_else(bad)
                })
                .collect()
        };
    match c.data_type() {
        DataType::FixedSizeList(_, w) => {
            let l: &FixedSizeListArray = c.as_fixed_size_list();
            let w = *w as usize;
            let off = l.offset() * w;
            rows(l.len(), &|i| (off + i * w, off + (i + 1) * w), l.values())
        }
        DataType::List(_) => {
            let l: &ListArray = c.as_list();
            let o = l.value_offsets();
            rows(l.len(), &|i| (o[i] as usize, o[i + 1] as usize), l.values())
        }
        DataType::LargeList(_) => {
            let l: &LargeListArray = c.as_list();
            let o = l.value_offsets();
            rows(l.len(), &|i| (o[i] as usize, o[i + 1] as usize), l.values())
        }
        _ => Ok(floats_of(c)
            .ok_or_else(bad)?
            .into_iter()
            .map(|x| vec![x])
            .collect()),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn templates_fill_like_python_and_stay_inside() {
        let info = Path::new("meta/info.json");
        let p = fill_template(
            VIDEO_PATH,
            &[
                ("video_key", Arg::Str("observation.image")),
                ("chunk_index", Arg::Int(0)),
                ("file_index", Arg::Int(12)),
            ],
            info,
        )
        .unwrap();
        assert_eq!(p, Path::new("videos/observation.image/chunk-000/file-012.mp4"));
        for bad in [
            "../x/{file_index:03d}.parquet",
            "/etc/{file_index}",
            "data/../../{file_index}",
        ] {
            let e = fill_template(bad, &[("file_index", Arg::Int(1))], info)
                .unwrap_err()
                .to_string();
            assert!(e.contains("not a relative path inside the dataset"), "{e}");
        }
        let e = fill_template("data/{episode_chunk:03d}.parquet", &[], info)
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown placeholder {episode_chunk}"), "{e}");
    }
}
