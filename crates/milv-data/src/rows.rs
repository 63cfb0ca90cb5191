//! Typed rows of the `episodes` and `frames` tables and their Arrow conversions.

use std::sync::Arc;

use deltalake::arrow::array::{
    Array, ArrayRef, BinaryBuilder, Float32Builder, Float64Array, Int32Array, Int32Builder, Int64Array,
    Int64Builder, ListArray, ListBuilder, RecordBatch, StringArray, StringBuilder, TimestampMicrosecondArray,
};
use deltalake::arrow::datatypes::{DataType, Field};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::schema::TableKind;

/// One row of the `episodes` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Episode {
    pub episode_id: String,
    pub domain: String,
    pub kind: String,
    pub task_id: Option<String>,
    pub task_family: Option<String>,
    pub pair_id: Option<String>,
    pub split: String,
    pub n_frames: i64,
    pub fps: f64,
    pub width: i32,
    pub height: i32,
    pub frame_encoding: String,
    pub action_dim: Option<i32>,
    pub state_dim: Option<i32>,
    pub action_names: Option<Vec<String>>,
    pub state_names: Option<Vec<String>>,
    pub source_uri: String,
    pub source_sha256: String,
    pub sidecar_uri: Option<String>,
    pub duration_ns: i64,
    /// Microseconds since the Unix epoch, UTC.
    pub ingested_at_us: i64,
}

fn names_array(values: impl Iterator<Item = Option<Vec<String>>>) -> ArrayRef {
    let mut b = ListBuilder::new(StringBuilder::new()).with_field(Arc::new(Field::new(
        "element",
        DataType::Utf8,
        false,
    )));
    for v in values {
        match v {
            Some(names) => {
                for n in names {
                    b.values().append_value(n);
                }
                b.append(true);
            }
            None => b.append(false),
        }
    }
    Arc::new(b.finish())
}

/// Builds the `episodes` batch of these rows.
pub fn episodes_to_batch(rows: &[Episode]) -> Result<RecordBatch> {
    let s =
        |f: fn(&Episode) -> &str| -> ArrayRef { Arc::new(StringArray::from_iter_values(rows.iter().map(f))) };
    let o = |f: fn(&Episode) -> Option<&str>| -> ArrayRef {
        Arc::new(rows.iter().map(f).collect::<StringArray>())
    };
    let columns: Vec<ArrayRef> = vec![
        s(|e| &e.episode_id),
        s(|e| &e.domain),
        s(|e| &e.kind),
        o(|e| e.task_id.as_deref()),
        o(|e| e.task_family.as_deref()),
        o(|e| e.pair_id.as_deref()),
        s(|e| &e.split),
        Arc::new(Int64Array::from_iter_values(rows.iter().map(|e| e.n_frames))),
        Arc::new(Float64Array::from_iter_values(rows.iter().map(|e| e.fps))),
        Arc::new(Int32Array::from_iter_values(rows.iter().map(|e| e.width))),
        Arc::new(Int32Array::from_iter_values(rows.iter().map(|e| e.height))),
        s(|e| &e.frame_encoding),
        Arc::new(rows.iter().map(|e| e.action_dim).collect::<Int32Array>()),
        Arc::new(rows.iter().map(|e| e.state_dim).collect::<Int32Array>()),
        names_array(rows.iter().map(|e| e.action_names.clone())),
        names_array(rows.iter().map(|e| e.state_names.clone())),
        s(|e| &e.source_uri),
        s(|e| &e.source_sha256),
        o(|e| e.sidecar_uri.as_deref()),
        Arc::new(Int64Array::from_iter_values(rows.iter().map(|e| e.duration_ns))),
        Arc::new(
            TimestampMicrosecondArray::from_iter_values(rows.iter().map(|e| e.ingested_at_us))
                .with_timezone("UTC"),
        ),
    ];
    Ok(RecordBatch::try_new(TableKind::Episodes.arrow_schema(), columns)?)
}

fn column<'a, T: 'static>(batch: &'a RecordBatch, name: &str) -> Result<&'a T> {
    batch
        .column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<T>())
        .ok_or_else(|| Error::Schema {
            table: "episodes".into(),
            msg: format!("column {name} missing or of the wrong type"),
        })
}

fn opt_str(a: &StringArray, i: usize) -> Option<String> {
    a.is_valid(i).then(|| a.value(i).to_string())
}

fn opt_names(a: &ListArray, i: usize) -> Option<Vec<String>> {
    if a.is_null(i) {
        return None;
    }
    let v = a.value(i);
    let s = v.as_any().downcast_ref::<StringArray>()?;
    Some((0..s.len()).map(|j| s.value(j).to_string()).collect())
}

/// Reads `episodes` rows back from batches.
pub fn episodes_from_batches(batches: &[RecordBatch]) -> Result<Vec<Episode>> {
    let mut out = Vec::new();
    for b in batches {
        let id = column::<StringArray>(b, "episode_id")?;
        let domain = column::<StringArray>(b, "domain")?;
        let kind = column::<StringArray>(b, "kind")?;
        let task_id = column::<StringArray>(b, "task_id")?;
        let task_family = column::<StringArray>(b, "task_family")?;
        let pair_id = column::<StringArray>(b, "pair_id")?;
        let split = column::<StringArray>(b, "split")?;
        let n_frames = column::<Int64Array>(b, "n_frames")?;
        let fps = column::<Float64Array>(b, "fps")?;
        let width = column::<Int32Array>(b, "width")?;
        let height = column::<Int32Array>(b, "height")?;
        let enc = column::<StringArray>(b, "frame_encoding")?;
        let adim = column::<Int32Array>(b, "action_dim")?;
        let sdim = column::<Int32Array>(b, "state_dim")?;
        let anames = column::<ListArray>(b, "action_names")?;
        let snames = column::<ListArray>(b, "state_names")?;
        let src = column::<StringArray>(b, "source_uri")?;
        let sha = column::<StringArray>(b, "source_sha256")?;
        let sidecar = column::<StringArray>(b, "sidecar_uri")?;
        let dur = column::<Int64Array>(b, "duration_ns")?;
        let at = column::<TimestampMicrosecondArray>(b, "ingested_at")?;
        for i in 0..b.num_rows() {
            out.push(Episode {
                episode_id: id.value(i).into(),
                domain: domain.value(i).into(),
                kind: kind.value(i).into(),
                task_id: opt_str(task_id, i),
                task_family: opt_str(task_family, i),
                pair_id: opt_str(pair_id, i),
                split: split.value(i).into(),
                n_frames: n_frames.value(i),
                fps: fps.value(i),
                width: width.value(i),
                height: height.value(i),
                frame_encoding: enc.value(i).into(),
                action_dim: adim.is_valid(i).then(|| adim.value(i)),
                state_dim: sdim.is_valid(i).then(|| sdim.value(i)),
                action_names: opt_names(anames, i),
                state_names: opt_names(snames, i),
                source_uri: src.value(i).into(),
                source_sha256: sha.value(i).into(),
                sidecar_uri: opt_str(sidecar, i),
                duration_ns: dur.value(i),
                ingested_at_us: at.value(i),
            });
        }
    }
    Ok(out)
}

/// Accumulates `frames` rows and emits them as batches.
pub struct FrameRows {
    episode_id: StringBuilder,
    frame_index: Int32Builder,
    timestamp_ns: Int64Builder,
    image: BinaryBuilder,
    action: ListBuilder<Float32Builder>,
    state: ListBuilder<Float32Builder>,
    rows: usize,
    bytes: usize,
}

impl Default for FrameRows {
    fn default() -> Self {
        Self::new()
    }
}

fn f32_list() -> ListBuilder<Float32Builder> {
    ListBuilder::new(Float32Builder::new()).with_field(Arc::new(Field::new(
        "element",
        DataType::Float32,
        false,
    )))
}

impl FrameRows {
    pub fn new() -> Self {
        FrameRows {
            episode_id: StringBuilder::new(),
            frame_index: Int32Builder::new(),
            timestamp_ns: Int64Builder::new(),
            image: BinaryBuilder::new(),
            action: f32_list(),
            state: f32_list(),
            rows: 0,
            bytes: 0,
        }
    }

    pub fn push(
        &mut self,
        episode_id: &str,
        frame_index: i32,
        timestamp_ns: i64,
        image: &[u8],
        action: Option<&[f32]>,
        state: Option<&[f32]>,
    ) {
        self.episode_id.append_value(episode_id);
        self.frame_index.append_value(frame_index);
        self.timestamp_ns.append_value(timestamp_ns);
        self.image.append_value(image);
        for (b, v) in [(&mut self.action, action), (&mut self.state, state)] {
            match v {
                Some(v) => {
                    b.values().append_slice(v);
                    b.append(true);
                }
                None => b.append(false),
            }
        }
        self.rows += 1;
        self.bytes += image.len() + 64;
    }

    pub fn len(&self) -> usize {
        self.rows
    }

    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// Approximate bytes buffered (to decide when to flush).
    pub fn buffered_bytes(&self) -> usize {
        self.bytes
    }

    /// Emits the buffered rows and starts over.
    pub fn finish(&mut self) -> Result<RecordBatch> {
        let columns: Vec<ArrayRef> = vec![
            Arc::new(self.episode_id.finish()),
            Arc::new(self.frame_index.finish()),
            Arc::new(self.timestamp_ns.finish()),
            Arc::new(self.image.finish()),
            Arc::new(self.action.finish()),
            Arc::new(self.state.finish()),
        ];
        self.rows = 0;
        self.bytes = 0;
        Ok(RecordBatch::try_new(TableKind::Frames.arrow_schema(), columns)?)
    }
}

/// One translated frame for [`ImaginedRows::push`].
pub struct ImaginedRow<'a> {
    pub episode_id: &'a str,
    pub frame_index: i32,
    pub timestamp_ns: i64,
    pub model_id: &'a str,
    /// PNG of the imagined robot frame.
    pub image: &'a [u8],
    /// Raw little-endian latent values, their dtype (`f16` | `f32`) and shape.
    pub latent: Option<(&'a [u8], &'a str, &'a [i32])>,
    pub action: Option<&'a [f32]>,
}

/// Accumulates `imagined` rows and emits them as batches.
pub struct ImaginedRows {
    episode_id: StringBuilder,
    frame_index: Int32Builder,
    timestamp_ns: Int64Builder,
    model_id: StringBuilder,
    image: BinaryBuilder,
    latent: BinaryBuilder,
    latent_dtype: StringBuilder,
    latent_shape: ListBuilder<Int32Builder>,
    action: ListBuilder<Float32Builder>,
    rows: usize,
}

impl Default for ImaginedRows {
    fn default() -> Self {
        Self::new()
    }
}

impl ImaginedRows {
    pub fn new() -> Self {
        ImaginedRows {
            episode_id: StringBuilder::new(),
            frame_index: Int32Builder::new(),
            timestamp_ns: Int64Builder::new(),
            model_id: StringBuilder::new(),
            image: BinaryBuilder::new(),
            latent: BinaryBuilder::new(),
            latent_dtype: StringBuilder::new(),
            latent_shape: ListBuilder::new(Int32Builder::new()).with_field(Arc::new(Field::new(
                "element",
                DataType::Int32,
                false,
            ))),
            action: f32_list(),
            rows: 0,
        }
    }

    pub fn push(&mut self, r: &ImaginedRow<'_>) {
        self.episode_id.append_value(r.episode_id);
        self.frame_index.append_value(r.frame_index);
        self.timestamp_ns.append_value(r.timestamp_ns);
        self.model_id.append_value(r.model_id);
        self.image.append_value(r.image);
        match r.latent {
            Some((bytes, dtype, shape)) => {
                self.latent.append_value(bytes);
                self.latent_dtype.append_value(dtype);
                self.latent_shape.values().append_slice(shape);
                self.latent_shape.append(true);
            }
            None => {
                self.latent.append_null();
                self.latent_dtype.append_null();
                self.latent_shape.append(false);
            }
        }
        match r.action {
            Some(a) => {
                self.action.values().append_slice(a);
                self.action.append(true);
            }
            None => self.action.append(false),
        }
        self.rows += 1;
    }

    pub fn len(&self) -> usize {
        self.rows
    }

    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// Emits the buffered rows and starts over.
    pub fn finish(&mut self) -> Result<RecordBatch> {
        let columns: Vec<ArrayRef> = vec![
            Arc::new(self.episode_id.finish()),
            Arc::new(self.frame_index.finish()),
            Arc::new(self.timestamp_ns.finish()),
            Arc::new(self.model_id.finish()),
            Arc::new(self.image.finish()),
            Arc::new(self.latent.finish()),
            Arc::new(self.latent_dtype.finish()),
            Arc::new(self.latent_shape.finish()),
            Arc::new(self.action.finish()),
        ];
        self.rows = 0;
        Ok(RecordBatch::try_new(TableKind::Imagined.arrow_schema(), columns)?)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    pub(crate) fn sample_episode(id: &str) -> Episode {
        Episode {
            episode_id: id.into(),
            domain: "robot".into(),
            kind: "random".into(),
            task_id: Some("draw/circle".into()),
            task_family: None,
            pair_id: None,
            split: "train".into(),
            n_frames: 3,
            fps: 10.0,
            width: 4,
            height: 2,
            frame_encoding: "raw".into(),
            action_dim: Some(2),
            state_dim: None,
            action_names: Some(vec!["dx".into(), "dy".into()]),
            state_names: None,
            source_uri: "a.mp4".into(),
            source_sha256: "00".into(),
            sidecar_uri: None,
            duration_ns: 300_000_000,
            ingested_at_us: 1_700_000_000_000_000,
        }
    }

    #[test]
    fn episodes_round_trip() {
        let rows = vec![sample_episode("a"), sample_episode("b")];
        let batch = episodes_to_batch(&rows).unwrap();
        assert_eq!(batch.schema(), TableKind::Episodes.arrow_schema());
        assert_eq!(episodes_from_batches(&[batch]).unwrap(), rows);
    }

    #[test]
    fn frame_rows_match_schema() {
        let mut f = FrameRows::new();
        f.push("a", 0, 0, b"xyz", Some(&[1.0, 2.0]), None);
        f.push("a", 1, 100, b"uvw", Some(&[3.0, 4.0]), None);
        let b = f.finish().unwrap();
        assert_eq!(b.num_rows(), 2);
        assert_eq!(b.schema(), TableKind::Frames.arrow_schema());
        assert!(f.is_empty());
    }
}
