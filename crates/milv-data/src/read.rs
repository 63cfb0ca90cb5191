//! Reading tables back for the stages downstream of their writers:
//! - [`episode_rows`]: whole episodes of `frames` or `imagined`, grouped by episode and in
//!   frame order (shards hold rows in any order of episodes);
//! - [`imagined_models`] / [`resolve_model`]: the translation models in `imagined` and
//!   the episodes each translated;
//! - [`run_groups`] / [`duplicate_groups`]: which groups a run holds, and groups a run
//!   holds more than once (datasets written before writes were idempotent);
//! - [`score_run`]: the rows of one scoring run (`scores`);
//! - [`curated_weights`]: the weights of one curation (`curated`);
//! - [`alignment_run`]: the aligned frame pairs of one alignment run (`alignments`).

use std::collections::{BTreeMap, BTreeSet, HashMap};

use deltalake::arrow::array::{Array, BinaryArray, Int32Array, Int64Array, ListArray, StringArray};
use serde::Serialize;

use crate::columns::{column, opt_f32s};
use crate::dataset::{Dataset, TableFile};
use crate::error::{Error, Result};
use crate::rows::{AlignmentRow, CuratedRow, Row, ScoreRow};
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
            let v = vec_col.and_then(|l| opt_f32s(l, i));
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

/// Every row of `R`'s table at `version`, typed (for small tables and tests; large
/// tables are better streamed with [`Dataset::scan`] or read per episode).
pub fn rows<R: Row>(ds: &Dataset, version: u64) -> Result<Vec<R>> {
    let mut out = Vec::new();
    for b in ds.scan(R::TABLE, version, None)? {
        out.extend(R::from_batch(&b?)?);
    }
    Ok(out)
}

/// The key-value metadata in a data file's Parquet footer (what
/// [`ShardOptions::file_metadata`](crate::ShardOptions) wrote, e.g. `milv.scores`).
pub fn file_metadata(ds: &Dataset, file: &TableFile) -> Result<Vec<(String, String)>> {
    let footer = ds.file_footer(file)?;
    Ok(footer
        .file_metadata()
        .key_value_metadata()
        .map(|kv| {
            kv.iter()
                .map(|k| (k.key.clone(), k.value.clone().unwrap_or_default()))
                .collect()
        })
        .unwrap_or_default())
}

/// One stored image of `frames` or `imagined`.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredImage {
    pub episode_id: String,
    pub frame_index: i32,
    pub image: Vec<u8>,
}

/// The images of `table` (`frames` or `imagined`; of one `model` for `imagined`) at
/// `version` in storage order, only of the episodes `keep` accepts; reads only the id,
/// index and image columns, a batch at a time (for one streaming pass over a large table).
pub fn stream_images<'a>(
    ds: &Dataset,
    version: u64,
    table: TableKind,
    model: Option<&'a str>,
    keep: &'a (dyn Fn(&str) -> bool + Sync),
) -> Result<impl Iterator<Item = Result<StoredImage>> + 'a> {
    let mut cols = vec!["episode_id", "frame_index", "image"];
    if model.is_some() {
        cols.push("model_id");
    }
    let batches = ds.scan(table, version, Some(&cols))?;
    Ok(batches.flat_map(move |b| {
        let rows = (|| -> Result<Vec<StoredImage>> {
            let b = b?;
            let ids: &StringArray = column(&b, "episode_id", table)?;
            let idx: &Int32Array = column(&b, "frame_index", table)?;
            let img: &BinaryArray = column(&b, "image", table)?;
            let models: Option<&StringArray> = model.map(|_| column(&b, "model_id", table)).transpose()?;
            Ok((0..b.num_rows())
                .filter(|&i| keep(ids.value(i)) && models.is_none_or(|m| Some(m.value(i)) == model))
                .map(|i| StoredImage {
                    episode_id: ids.value(i).to_string(),
                    frame_index: idx.value(i),
                    image: img.value(i).to_vec(),
                })
                .collect())
        })();
        match rows {
            Ok(r) => r.into_iter().map(Ok).collect::<Vec<_>>(),
            Err(e) => vec![Err(e)],
        }
    }))
}

/// For every (run, group) of `table` at `version`: the files holding its rows, in the
/// order they were added.
fn group_files(
    ds: &Dataset,
    version: u64,
    table: TableKind,
) -> Result<BTreeMap<(String, String), Vec<String>>> {
    let Some(run_col) = table.run_column() else {
        return Ok(BTreeMap::new());
    };
    let group_col = table.group_column();
    let mut out: BTreeMap<(String, String), Vec<String>> = BTreeMap::new();
    for f in ds.files(table, version)? {
        let mut seen: BTreeSet<(String, String)> = BTreeSet::new();
        for b in ds.read_file(&f, Some(&[group_col, run_col]))? {
            let b = b?;
            let (g, r): (&StringArray, &StringArray) =
                (column(&b, group_col, table)?, column(&b, run_col, table)?);
            for i in 0..b.num_rows() {
                if r.is_valid(i) {
                    seen.insert((r.value(i).to_string(), g.value(i).to_string()));
                }
            }
        }
        for key in seen {
            out.entry(key).or_default().push(f.info.path.clone());
        }
    }
    Ok(out)
}

/// The groups (episodes; pairs for `alignments`) that run `run` holds in `table` at
/// `version`. An error for a table without runs (`episodes`, `frames`).
pub fn run_groups(ds: &Dataset, version: u64, table: TableKind, run: &str) -> Result<BTreeSet<String>> {
    let run_col = table
        .run_column()
        .ok_or_else(|| Error::Invalid(format!("table {table} has no runs")))?;
    let group_col = table.group_column();
    let mut out = BTreeSet::new();
    for b in ds.scan(table, version, Some(&[group_col, run_col]))? {
        let b = b?;
        let (g, r): (&StringArray, &StringArray) =
            (column(&b, group_col, table)?, column(&b, run_col, table)?);
        for i in 0..b.num_rows() {
            if r.is_valid(i) && r.value(i) == run {
                out.insert(g.value(i).to_string());
            }
        }
    }
    Ok(out)
}

/// A group written more than once by the same run (in several files).
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct DuplicateGroup {
    pub table: TableKind,
    pub run: String,
    pub group: String,
    /// The files holding it, oldest first; readers keep the first.
    pub files: Vec<String>,
}

impl std::fmt::Display for DuplicateGroup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} table: {} {} of run {} is written {} times (files {}); readers use the first",
            self.table,
            self.table.group_column(),
            self.group,
            self.run,
            self.files.len(),
            self.files.join(", ")
        )
    }
}

/// Every group that a run holds in more than one file, in every table with runs.
pub fn duplicate_groups(ds: &Dataset, version: u64) -> Result<Vec<DuplicateGroup>> {
    let mut out = Vec::new();
    for table in TableKind::ALL {
        for ((run, group), files) in group_files(ds, version, table)? {
            if files.len() > 1 {
                out.push(DuplicateGroup {
                    table,
                    run,
                    group,
                    files,
                });
            }
        }
    }
    Ok(out)
}

/// Typed rows of a run table at `version`, file by file, keeping each (run, group) from
/// the first file that holds it: a group a run wrote twice is read once.
fn run_rows<R: Row>(
    ds: &Dataset,
    version: u64,
    run_of: impl Fn(&R) -> &str,
    keep: impl Fn(&R) -> bool,
) -> Result<Vec<R>> {
    let mut first: HashMap<(String, String), String> = HashMap::new();
    let mut out = Vec::new();
    for f in ds.files(R::TABLE, version)? {
        for b in ds.read_file(&f, None)? {
            for r in R::from_batch(&b?)? {
                let key = (run_of(&r).to_string(), r.group().to_string());
                let owner = first.entry(key).or_insert_with(|| f.info.path.clone());
                if *owner == f.info.path && keep(&r) {
                    out.push(r);
                }
            }
        }
    }
    Ok(out)
}

/// Models in the `imagined` table at `version`, with the episodes each translated.
pub fn imagined_models(ds: &Dataset, version: u64) -> Result<BTreeMap<String, BTreeSet<String>>> {
    const T: TableKind = TableKind::Imagined;
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for b in ds.scan(T, version, Some(&["model_id", "episode_id"]))? {
        let b = b?;
        let (m, e): (&StringArray, &StringArray) = (column(&b, "model_id", T)?, column(&b, "episode_id", T)?);
        for i in 0..b.num_rows() {
            if !out.get(m.value(i)).is_some_and(|s| s.contains(e.value(i))) {
                out.entry(m.value(i).to_string())
                    .or_default()
                    .insert(e.value(i).to_string());
            }
        }
    }
    Ok(out)
}

/// The translation model to read at `version` and the episodes it translated: `wanted`,
/// checked, or else the only model of the `imagined` table. `None` when the table is
/// empty and no model was asked for (the caller says what to run first).
pub fn resolve_model(
    ds: &Dataset,
    version: u64,
    wanted: Option<&str>,
) -> Result<Option<(String, BTreeSet<String>)>> {
    let mut models = imagined_models(ds, version)?;
    let names = |m: &BTreeMap<String, BTreeSet<String>>| {
        if m.is_empty() {
            "none".to_string()
        } else {
            m.keys().cloned().collect::<Vec<_>>().join(", ")
        }
    };
    match wanted {
        Some(w) => match models.remove_entry(w) {
            Some(found) => Ok(Some(found)),
            None => Err(Error::Invalid(format!(
                "model {w} has no rows in the imagined table at version {version} (models there: {})",
                names(&models)
            ))),
        },
        None if models.len() <= 1 => Ok(models.pop_first()),
        None => Err(Error::Invalid(format!(
            "the imagined table at version {version} holds {} models ({}); choose one with --model-id",
            models.len(),
            names(&models)
        ))),
    }
}

/// What `pick` takes from the first row it accepts, searching the files of `R`'s table
/// at `version` newest first (the newest run, curation, … of something).
fn newest<R: Row>(ds: &Dataset, version: u64, pick: impl Fn(&R) -> Option<String>) -> Result<Option<String>> {
    let mut files: Vec<TableFile> = ds.files(R::TABLE, version)?;
    files.sort_by_key(|f| std::cmp::Reverse(f.added_in));
    for f in files {
        for b in ds.read_file(&f, None)? {
            if let Some(v) = R::from_batch(&b?)?.iter().find_map(&pick) {
                return Ok(Some(v));
            }
        }
    }
    Ok(None)
}

/// The rows of one scoring run at `version`: the given run, or the most recently added,
/// sorted by (episode, frame).
pub fn score_run(ds: &Dataset, version: u64, run_id: Option<&str>) -> Result<(String, Vec<ScoreRow>)> {
    let run_id = match run_id {
        Some(r) => r.to_string(),
        None => newest::<ScoreRow>(ds, version, |r| Some(r.run_id.clone()))?.ok_or_else(|| {
            Error::Invalid(format!(
                "{}@{version} has no scores; run `milv-score run` first",
                ds.root().display()
            ))
        })?,
    };
    let mut rows = run_rows(ds, version, |r: &ScoreRow| &r.run_id, |r| r.run_id == run_id)?;
    if rows.is_empty() {
        return Err(Error::Invalid(format!(
            "scoring run {run_id} has no rows at {}@{version}",
            ds.root().display()
        )));
    }
    rows.sort_by(|a, b| (&a.episode_id, a.frame_index).cmp(&(&b.episode_id, b.frame_index)));
    Ok((run_id, rows))
}

/// The newest scoring run over `model`'s imagined frames at `version`, if any.
pub fn newest_score_run(ds: &Dataset, version: u64, model: &str) -> Result<Option<String>> {
    newest::<ScoreRow>(ds, version, |r| {
        (r.source_table == "imagined" && r.model_id.as_deref() == Some(model)).then(|| r.run_id.clone())
    })
}

/// The curation ids of the `curated` view at `version` (one, unless the view is empty).
pub fn curations(ds: &Dataset, version: u64) -> Result<BTreeSet<String>> {
    let mut out = BTreeSet::new();
    for b in ds.scan(TableKind::Curated, version, Some(&["curation_id"]))? {
        let b = b?;
        let c: &StringArray = column(&b, "curation_id", TableKind::Curated)?;
        out.extend((0..b.num_rows()).map(|i| c.value(i).to_string()));
    }
    Ok(out)
}

/// Loss weight per (episode, frame).
pub type FrameWeights = HashMap<(String, i32), f64>;

/// The newest curation of scoring run `run` over `model`'s imagined frames, and its
/// weight per (episode, frame).
pub fn curated_weights(
    ds: &Dataset,
    version: u64,
    run: &str,
    model: &str,
) -> Result<Option<(String, FrameWeights)>> {
    let of_model = |r: &CuratedRow| r.source_table == "imagined" && r.model_id.as_deref() == Some(model);
    let Some(curation) = newest::<CuratedRow>(ds, version, |r| {
        (r.run_id == run && of_model(r)).then(|| r.curation_id.clone())
    })?
    else {
        return Ok(None);
    };
    let rows = run_rows(
        ds,
        version,
        |r: &CuratedRow| &r.curation_id,
        |r| r.curation_id == curation,
    )?;
    let weights = rows
        .into_iter()
        .map(|r| ((r.episode_id, r.frame_index), r.weight))
        .collect();
    Ok(Some((curation, weights)))
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

/// The newest alignment run at `version`, if any.
pub fn newest_alignment_run(ds: &Dataset, version: u64) -> Result<Option<String>> {
    newest::<AlignmentRow>(ds, version, |r| Some(r.run_id.clone()))
}

/// The rows of one alignment run at `version`: `want` names a run id or a feature kind;
/// without it the table must hold exactly one run. `hint` ends the error when there are
/// no alignments at all (what the caller's user can do about it). A pair the run wrote
/// twice is read once.
pub fn alignment_run(
    ds: &Dataset,
    version: u64,
    want: Option<&str>,
    hint: &str,
) -> Result<(AlignmentRun, Vec<AlignedPair>)> {
    let rows = run_rows(ds, version, |r: &AlignmentRow| &r.run_id, |_| true)?;
    let mut runs: BTreeMap<(String, String), Vec<AlignedPair>> = BTreeMap::new();
    for r in rows {
        runs.entry((r.run_id, r.features)).or_default().push(AlignedPair {
            human: (r.human_episode_id, r.human_frame as usize),
            robot: (r.robot_episode_id, r.robot_frame as usize),
        });
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
