//! Reading tables back for the stages downstream of their writers:
//! - [`episode_rows`]: whole episodes of `frames` or `imagined`, grouped by episode and in
//!   frame order (shards hold rows in any order of episodes);
//! - [`score_run`]: the rows of one scoring run (`scores`);
//! - [`alignment_run`]: the aligned frame pairs of one alignment run (`alignments`).

use std::collections::BTreeMap;

use deltalake::arrow::array::{
    Array, BinaryArray, Float32Array, Float64Array, Int32Array, Int64Array, ListArray, RecordBatch,
    StringArray,
};
use serde::Serialize;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::schema::TableKind;

/// One episode's rows, ordered by `frame_index`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EpisodeRows {
    pub frame_index: Vec<i32>,
    pub timestamp_ns: Vec<i64>,
    pub images: Vec<Vec<u8>>,
    /// The vector column asked for (`action` or `state`), per row; `None` where null.
    pub vectors: Vec<Option<Vec<f32>>>,
}

impl EpisodeRows {
    /// Every row's vector, or `None` if any row has none.
    pub fn all_vectors(&self) -> Option<Vec<Vec<f32>>> {
        self.vectors.iter().cloned().collect()
    }
}

fn column<'a, T: 'static>(b: &'a RecordBatch, name: &str, table: TableKind) -> Result<&'a T> {
    b.column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<T>())
        .ok_or_else(|| {
            Error::Invalid(format!(
                "{} table: column {name} missing or of an unexpected type",
                table.name()
            ))
        })
}

/// The rows of the episodes `keep` accepts, from `table` (`frames` or `imagined`) at
/// `version`, with one vector column (`action` | `state`) if asked; `model` restricts
/// `imagined` rows to one translation model.
pub fn episode_rows(
    ds: &Dataset,
    version: u64,
    table: TableKind,
    keep: &dyn Fn(&str) -> bool,
    vector: Option<&str>,
    model: Option<&str>,
) -> Result<BTreeMap<String, EpisodeRows>> {
    let mut cols = vec!["episode_id", "frame_index", "timestamp_ns", "image"];
    cols.extend(vector);
    if model.is_some() {
        cols.push("model_id");
    }
    type Row = (i32, i64, Vec<u8>, Option<Vec<f32>>);
    let mut rows: BTreeMap<String, Vec<Row>> = BTreeMap::new();
    for b in ds.scan(table, version, Some(&cols))? {
        let b = b?;
        let ids: &StringArray = column(&b, "episode_id", table)?;
        let idx: &Int32Array = column(&b, "frame_index", table)?;
        let ts: &Int64Array = column(&b, "timestamp_ns", table)?;
        let img: &BinaryArray = column(&b, "image", table)?;
        let vec_col: Option<&ListArray> = vector.map(|v| column(&b, v, table)).transpose()?;
        let models: Option<&StringArray> = model.map(|_| column(&b, "model_id", table)).transpose()?;
        for i in 0..b.num_rows() {
            let id = ids.value(i);
            if !keep(id) || models.is_some_and(|m| Some(m.value(i)) != model) {
                continue;
            }
            let v = vec_col.and_then(|l| {
                (!l.is_null(i))
                    .then(|| {
                        l.value(i)
                            .as_any()
                            .downcast_ref::<Float32Array>()
                            .map(|f| f.values().to_vec())
                    })
                    .flatten()
            });
            rows.entry(id.to_string()).or_default().push((
                idx.value(i),
                ts.value(i),
                img.value(i).to_vec(),
                v,
            ));
        }
    }
    Ok(rows
        .into_iter()
        .map(|(id, mut r)| {
            r.sort_by_key(|x| x.0);
            let mut e = EpisodeRows::default();
            for (i, t, img, v) in r {
                e.frame_index.push(i);
                e.timestamp_ns.push(t);
                e.images.push(img);
                e.vectors.push(v);
            }
            (id, e)
        })
        .collect())
}

/// One row of the scores table.
#[derive(Clone, Debug, Serialize)]
pub struct ScoreRow {
    pub episode_id: String,
    pub frame_index: i32,
    pub source_table: String,
    pub model_id: Option<String>,
    pub brenner_raw: f64,
    pub brenner: f64,
    pub ssim: f64,
    pub beta: f64,
}

/// The rows of one scoring run at `version`: the given run, or the most recently added,
/// sorted by (episode, frame).
pub fn score_run(ds: &Dataset, version: u64, run_id: Option<&str>) -> Result<(String, Vec<ScoreRow>)> {
    const T: TableKind = TableKind::Scores;
    let files = ds.files(T, version)?;
    let run_id = match run_id {
        Some(r) => r.to_string(),
        None => {
            let newest = files.iter().max_by_key(|f| f.added_in).ok_or_else(|| {
                Error::Invalid(format!(
                    "{}@{version} has no scores; run `milv-score run` first",
                    ds.root().display()
                ))
            })?;
            let mut it = crate::dataset::read_file(&newest.abs_path, Some(&["run_id"]))?;
            let b = it
                .next()
                .transpose()?
                .ok_or_else(|| Error::Invalid(format!("empty scores file {}", newest.abs_path.display())))?;
            let r: &StringArray = column(&b, "run_id", T)?;
            r.value(0).to_string()
        }
    };
    let mut rows = Vec::new();
    for b in ds.scan(T, version, None)? {
        let b = b?;
        let run: &StringArray = column(&b, "run_id", T)?;
        let ids: &StringArray = column(&b, "episode_id", T)?;
        let idx: &Int32Array = column(&b, "frame_index", T)?;
        let src: &StringArray = column(&b, "source_table", T)?;
        let model: &StringArray = column(&b, "model_id", T)?;
        let f = |n: &str| column::<Float64Array>(&b, n, T);
        let (raw, br, ss, be) = (f("brenner_raw")?, f("brenner")?, f("ssim")?, f("beta")?);
        for i in 0..b.num_rows() {
            if run.value(i) != run_id {
                continue;
            }
            rows.push(ScoreRow {
                episode_id: ids.value(i).to_string(),
                frame_index: idx.value(i),
                source_table: src.value(i).to_string(),
                model_id: model.is_valid(i).then(|| model.value(i).to_string()),
                brenner_raw: raw.value(i),
                brenner: br.value(i),
                ssim: ss.value(i),
                beta: be.value(i),
            });
        }
    }
    if rows.is_empty() {
        return Err(Error::Invalid(format!(
            "scoring run {run_id} has no rows at {}@{version}",
            ds.root().display()
        )));
    }
    rows.sort_by(|a, b| (&a.episode_id, a.frame_index).cmp(&(&b.episode_id, b.frame_index)));
    Ok((run_id, rows))
}

/// One aligned cell: (human episode, frame) ↔ (robot episode, frame).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AlignedPair {
    pub human: (String, usize),
    pub robot: (String, usize),
}

/// Which alignment run was read.
#[derive(Clone, Debug, Serialize)]
pub struct AlignmentRun {
    pub run_id: String,
    pub features: String,
    pub rows: usize,
}

/// The rows of one alignment run at `version`: `want` names a run id or a feature kind;
/// without it the table must hold exactly one run. `hint` ends the error when there are
/// no alignments at all (what the caller's user can do about it).
pub fn alignment_run(
    ds: &Dataset,
    version: u64,
    want: Option<&str>,
    hint: &str,
) -> Result<(AlignmentRun, Vec<AlignedPair>)> {
    const T: TableKind = TableKind::Alignments;
    let mut runs: BTreeMap<(String, String), Vec<AlignedPair>> = BTreeMap::new();
    let cols = [
        "human_episode_id",
        "human_frame",
        "robot_episode_id",
        "robot_frame",
        "features",
        "run_id",
    ];
    for b in ds.scan(T, version, Some(&cols))? {
        let b = b?;
        let (he, re): (&StringArray, &StringArray) = (
            column(&b, "human_episode_id", T)?,
            column(&b, "robot_episode_id", T)?,
        );
        let (hf, rf): (&Int32Array, &Int32Array) =
            (column(&b, "human_frame", T)?, column(&b, "robot_frame", T)?);
        let (feat, run): (&StringArray, &StringArray) =
            (column(&b, "features", T)?, column(&b, "run_id", T)?);
        for i in 0..b.num_rows() {
            runs.entry((run.value(i).to_string(), feat.value(i).to_string()))
                .or_default()
                .push(AlignedPair {
                    human: (he.value(i).to_string(), hf.value(i) as usize),
                    robot: (re.value(i).to_string(), rf.value(i) as usize),
                });
        }
    }
    if runs.is_empty() {
        return Err(Error::Invalid(format!(
            "version {version} has no alignments ({hint})"
        )));
    }
    let matching: Vec<&(String, String)> = runs
        .keys()
        .filter(|(run, feat)| want.is_none_or(|w| w == run || w == feat))
        .collect();
    let key = match matching.as_slice() {
        [one] => (*one).clone(),
        _ => {
            let listed: Vec<String> = runs.keys().map(|(r, f)| format!("{r} ({f})")).collect();
            return Err(Error::Invalid(format!(
                "{} alignment runs match{}: {}; choose one with --alignment RUN_ID",
                matching.len(),
                want.map(|w| format!(" {w:?}")).unwrap_or_default(),
                listed.join(", ")
            )));
        }
    };
    let rows = runs.remove(&key).unwrap_or_default();
    Ok((
        AlignmentRun {
            run_id: key.0,
            features: key.1,
            rows: rows.len(),
        },
        rows,
    ))
}
