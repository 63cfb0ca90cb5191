//! Reading whole episodes back: the rows of `frames` or `imagined` for some episodes,
//! grouped by episode and in frame order (shards hold rows in any order of episodes).

use std::collections::BTreeMap;

use deltalake::arrow::array::{
    Array, BinaryArray, Float32Array, Int32Array, Int64Array, ListArray, RecordBatch, StringArray,
};

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
