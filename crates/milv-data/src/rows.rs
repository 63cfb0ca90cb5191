//! Typed rows of every table and their Arrow conversions: the only place that builds or
//! takes apart the tables' columns. Stages hand these rows to a
//! [`GroupWriter`](crate::write::GroupWriter) and get them back from [`crate::read`].
//!
//! | table | row type | batch builder / conversion |
//! |---|---|---|
//! | `episodes` | [`Episode`] (typed [`Domain`], [`Kind`], [`Split`], [`FrameEncoding`]) | [`episodes_to_batch`], [`episodes_from_batches`] |
//! | `frames` | — | [`FrameRows`] |
//! | `imagined` | [`ImaginedRow`] | [`ImaginedRows`] |
//! | `scores` | [`ScoreRow`] | [`Row`] |
//! | `curated` | [`CuratedRow`] | [`Row`] |
//! | `alignments` | [`AlignmentRow`] | [`Row`] |

use std::sync::Arc;

use deltalake::arrow::array::{
    Array, ArrayRef, BinaryArray, BinaryBuilder, Float32Builder, Float64Array, Int32Array, Int32Builder,
    Int64Array, Int64Builder, ListArray, ListBuilder, RecordBatch, StringArray, StringBuilder,
    TimestampMicrosecondArray,
};
use deltalake::arrow::datatypes::{DataType, Field};
use serde::{Deserialize, Serialize};

use crate::columns::{column, opt_f32s, opt_i32s, opt_str, opt_strs};
use crate::error::{Error, Result};
pub use crate::frame_codec::FrameEncoding;
use crate::schema::TableKind;

/// A closed set of names stored as strings: `as_str`, `FromStr` with an error listing the
/// choices, `Display`, and serde as the same strings.
macro_rules! string_enum {
    ($(#[$doc:meta])* $name:ident, $what:literal, { $($(#[$vdoc:meta])* $variant:ident = $s:literal),+ $(,)? }) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        pub enum $name {
            $($(#[$vdoc])* #[serde(rename = $s)] $variant),+
        }

        impl $name {
            /// Every value, in the order of the schema's documentation.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
            /// Every stored name.
            pub const NAMES: &'static [&'static str] = &[$($s),+];

            /// The name stored in the table.
            pub fn as_str(self) -> &'static str {
                match self {
                    $($name::$variant => $s),+
                }
            }
        }

        impl std::str::FromStr for $name {
            type Err = String;
            fn from_str(s: &str) -> std::result::Result<Self, String> {
                match s {
                    $($s => Ok($name::$variant),)+
                    _ => Err(format!(
                        concat!("unknown ", $what, " {:?} (expected one of {})"),
                        s,
                        Self::NAMES.join(", ")
                    )),
                }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

string_enum!(
    /// Which embodiment an episode shows.
    Domain, "domain", { Human = "human", Robot = "robot" }
);

impl Domain {
    /// The other embodiment.
    pub fn other(self) -> Domain {
        match self {
            Domain::Human => Domain::Robot,
            Domain::Robot => Domain::Human,
        }
    }
}

string_enum!(
    /// What an episode is for.
    Kind, "kind", {
        /// A demonstration of a task.
        Demo = "demo",
        /// Random motion (robot: the inverse-dynamics data).
        Random = "random",
        /// One half of a loosely paired human/robot clip pair.
        Paired = "paired",
    }
);

string_enum!(
    /// Which split an episode belongs to.
    Split, "split", { Train = "train", Val = "val", Test = "test" }
);

impl Serialize for FrameEncoding {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for FrameEncoding {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        FrameEncoding::from_name(&name).ok_or_else(|| {
            serde::de::Error::custom(format!("unknown frame encoding {name:?} (png | jpeg | raw)"))
        })
    }
}

/// One row of the `episodes` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Episode {
    pub episode_id: String,
    pub domain: Domain,
    pub kind: Kind,
    pub task_id: Option<String>,
    pub task_family: Option<String>,
    pub pair_id: Option<String>,
    pub split: Split,
    pub n_frames: i64,
    pub fps: f64,
    pub width: i32,
    pub height: i32,
    pub frame_encoding: FrameEncoding,
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
        s(|e| e.domain.as_str()),
        s(|e| e.kind.as_str()),
        o(|e| e.task_id.as_deref()),
        o(|e| e.task_family.as_deref()),
        o(|e| e.pair_id.as_deref()),
        s(|e| e.split.as_str()),
        Arc::new(Int64Array::from_iter_values(rows.iter().map(|e| e.n_frames))),
        Arc::new(Float64Array::from_iter_values(rows.iter().map(|e| e.fps))),
        Arc::new(Int32Array::from_iter_values(rows.iter().map(|e| e.width))),
        Arc::new(Int32Array::from_iter_values(rows.iter().map(|e| e.height))),
        s(|e| e.frame_encoding.name()),
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

/// A stored name of a closed set, or a schema error naming the episode.
fn parse_stored<T: std::str::FromStr<Err = String>>(episode: &str, value: &str) -> Result<T> {
    value.parse().map_err(|msg| Error::Schema {
        table: TableKind::Episodes.name().into(),
        msg: format!("episode {episode}: {msg}"),
    })
}

/// Reads `episodes` rows back from batches.
pub fn episodes_from_batches(batches: &[RecordBatch]) -> Result<Vec<Episode>> {
    const T: TableKind = TableKind::Episodes;
    let mut out = Vec::new();
    for b in batches {
        let strs = |name: &str| column::<StringArray>(b, name, T);
        let (id, domain, kind, split) = (
            strs("episode_id")?,
            strs("domain")?,
            strs("kind")?,
            strs("split")?,
        );
        let (task_id, task_family, pair_id) = (strs("task_id")?, strs("task_family")?, strs("pair_id")?);
        let n_frames = column::<Int64Array>(b, "n_frames", T)?;
        let fps = column::<Float64Array>(b, "fps", T)?;
        let width = column::<Int32Array>(b, "width", T)?;
        let height = column::<Int32Array>(b, "height", T)?;
        let enc = strs("frame_encoding")?;
        let adim = column::<Int32Array>(b, "action_dim", T)?;
        let sdim = column::<Int32Array>(b, "state_dim", T)?;
        let anames = column::<ListArray>(b, "action_names", T)?;
        let snames = column::<ListArray>(b, "state_names", T)?;
        let (src, sha, sidecar) = (strs("source_uri")?, strs("source_sha256")?, strs("sidecar_uri")?);
        let dur = column::<Int64Array>(b, "duration_ns", T)?;
        let at = column::<TimestampMicrosecondArray>(b, "ingested_at", T)?;
        for i in 0..b.num_rows() {
            let episode_id = id.value(i);
            let frame_encoding = FrameEncoding::from_name(enc.value(i)).ok_or_else(|| Error::Schema {
                table: T.name().into(),
                msg: format!("episode {episode_id}: unknown frame encoding {:?}", enc.value(i)),
            })?;
            out.push(Episode {
                episode_id: episode_id.into(),
                domain: parse_stored(episode_id, domain.value(i))?,
                kind: parse_stored(episode_id, kind.value(i))?,
                task_id: opt_str(task_id, i),
                task_family: opt_str(task_family, i),
                pair_id: opt_str(pair_id, i),
                split: parse_stored(episode_id, split.value(i))?,
                n_frames: n_frames.value(i),
                fps: fps.value(i),
                width: width.value(i),
                height: height.value(i),
                frame_encoding,
                action_dim: adim.is_valid(i).then(|| adim.value(i)),
                state_dim: sdim.is_valid(i).then(|| sdim.value(i)),
                action_names: opt_strs(anames, i),
                state_names: opt_strs(snames, i),
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

impl Row for Episode {
    const TABLE: TableKind = TableKind::Episodes;

    fn group(&self) -> &str {
        &self.episode_id
    }

    fn to_batch(rows: &[Self]) -> Result<RecordBatch> {
        episodes_to_batch(rows)
    }

    fn from_batch(batch: &RecordBatch) -> Result<Vec<Self>> {
        episodes_from_batches(std::slice::from_ref(batch))
    }
}

/// Rows of a table that are buffered, then emitted as batches ([`FrameRows`],
/// [`ImaginedRows`]): for rows streamed in chunks (a long episode's frames).
pub trait RowBuffer {
    const TABLE: TableKind;
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Emits the buffered rows and starts over.
    fn finish(&mut self) -> Result<RecordBatch>;
}

/// Typed rows of a table written group by group (an episode's, a pair's).
pub trait Row: Sized {
    const TABLE: TableKind;
    /// The key of the group the row belongs to (the table's [`TableKind::group_column`]).
    fn group(&self) -> &str;
    /// The rows as one batch of the table's schema.
    fn to_batch(rows: &[Self]) -> Result<RecordBatch>;
    /// Rows back from a batch of the table.
    fn from_batch(batch: &RecordBatch) -> Result<Vec<Self>>;
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

    /// Approximate bytes buffered (to decide when to flush).
    pub fn buffered_bytes(&self) -> usize {
        self.bytes
    }
}

impl RowBuffer for FrameRows {
    const TABLE: TableKind = TableKind::Frames;
    fn len(&self) -> usize {
        self.rows
    }
    /// Emits the buffered rows and starts over.
    fn finish(&mut self) -> Result<RecordBatch> {
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
}

impl RowBuffer for ImaginedRows {
    const TABLE: TableKind = TableKind::Imagined;
    fn len(&self) -> usize {
        self.rows
    }
    /// Emits the buffered rows and starts over.
    fn finish(&mut self) -> Result<RecordBatch> {
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
/// A latent tensor as stored: little-endian values of `dtype` in row-major `shape`.
#[derive(Clone, Debug, PartialEq)]
pub struct Latent {
    pub dtype: String,
    pub shape: Vec<i32>,
    pub data: Vec<u8>,
}

impl Latent {
    fn item_size(dtype: &str) -> Option<usize> {
        match dtype {
            "f16" => Some(2),
            "f32" => Some(4),
            _ => None,
        }
    }

    /// Checks that the bytes hold exactly `shape` values of `dtype`.
    pub fn check(&self) -> std::result::Result<(), String> {
        let size =
            Latent::item_size(&self.dtype).ok_or_else(|| format!("unknown latent dtype {:?}", self.dtype))?;
        if self.shape.iter().any(|d| *d <= 0) {
            return Err(format!(
                "latent shape {:?} has a non-positive dimension",
                self.shape
            ));
        }
        let want = self.shape.iter().map(|d| *d as usize).product::<usize>() * size;
        if self.data.len() != want {
            return Err(format!(
                "latent of shape {:?} ({}) has {} bytes, expected {want}",
                self.shape,
                self.dtype,
                self.data.len()
            ));
        }
        Ok(())
    }

    /// The values as f32.
    pub fn to_f32(&self) -> std::result::Result<Vec<f32>, String> {
        self.check()?;
        Ok(match self.dtype.as_str() {
            "f16" => self
                .data
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            _ => self
                .data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
        })
    }
}

/// One row of the `imagined` table, read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ImaginedRecord {
    pub episode_id: String,
    pub frame_index: i32,
    pub timestamp_ns: i64,
    pub model_id: String,
    /// PNG of the imagined robot frame.
    pub image: Vec<u8>,
    pub latent: Option<Latent>,
    pub action: Option<Vec<f32>>,
}

impl Row for ImaginedRecord {
    const TABLE: TableKind = TableKind::Imagined;

    fn group(&self) -> &str {
        &self.episode_id
    }

    fn to_batch(rows: &[Self]) -> Result<RecordBatch> {
        let mut b = ImaginedRows::new();
        for r in rows {
            b.push(&ImaginedRow {
                episode_id: &r.episode_id,
                frame_index: r.frame_index,
                timestamp_ns: r.timestamp_ns,
                model_id: &r.model_id,
                image: &r.image,
                latent: r
                    .latent
                    .as_ref()
                    .map(|l| (l.data.as_slice(), l.dtype.as_str(), l.shape.as_slice())),
                action: r.action.as_deref(),
            });
        }
        b.finish()
    }

    fn from_batch(b: &RecordBatch) -> Result<Vec<Self>> {
        const T: TableKind = TableKind::Imagined;
        let s = |n: &str| column::<StringArray>(b, n, T);
        let (ids, model, dtype) = (s("episode_id")?, s("model_id")?, s("latent_dtype")?);
        let idx = column::<Int32Array>(b, "frame_index", T)?;
        let ts = column::<Int64Array>(b, "timestamp_ns", T)?;
        let (img, lat) = (
            column::<BinaryArray>(b, "image", T)?,
            column::<BinaryArray>(b, "latent", T)?,
        );
        let (shape, act) = (
            column::<ListArray>(b, "latent_shape", T)?,
            column::<ListArray>(b, "action", T)?,
        );
        Ok((0..b.num_rows())
            .map(|i| ImaginedRecord {
                episode_id: ids.value(i).to_string(),
                frame_index: idx.value(i),
                timestamp_ns: ts.value(i),
                model_id: model.value(i).to_string(),
                image: img.value(i).to_vec(),
                latent: lat.is_valid(i).then(|| Latent {
                    dtype: opt_str(dtype, i).unwrap_or_default(),
                    shape: opt_i32s(shape, i).unwrap_or_default(),
                    data: lat.value(i).to_vec(),
                }),
                action: opt_f32s(act, i),
            })
            .collect())
    }
}

/// One row of the `scores` table: the quality of one frame in one scoring run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ScoreRow {
    pub episode_id: String,
    pub frame_index: i32,
    /// `frames` or `imagined`.
    pub source_table: String,
    pub model_id: Option<String>,
    pub run_id: String,
    pub brenner_raw: f64,
    pub brenner: f64,
    pub ssim: f64,
    pub beta: f64,
    /// Set-normalised weight over the run (null for a partitioned run).
    pub weight: Option<f64>,
}

fn strings<'a, R>(rows: &'a [R], f: impl Fn(&'a R) -> &'a str) -> ArrayRef {
    Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
}

fn opt_strings<'a, R>(rows: &'a [R], f: impl Fn(&'a R) -> Option<&'a str>) -> ArrayRef {
    Arc::new(rows.iter().map(f).collect::<StringArray>())
}

fn f64s<R>(rows: &[R], f: impl Fn(&R) -> f64) -> ArrayRef {
    Arc::new(Float64Array::from_iter_values(rows.iter().map(f)))
}

fn i32s<R>(rows: &[R], f: impl Fn(&R) -> i32) -> ArrayRef {
    Arc::new(Int32Array::from_iter_values(rows.iter().map(f)))
}

impl Row for ScoreRow {
    const TABLE: TableKind = TableKind::Scores;

    fn group(&self) -> &str {
        &self.episode_id
    }

    fn to_batch(rows: &[Self]) -> Result<RecordBatch> {
        let cols: Vec<ArrayRef> = vec![
            strings(rows, |r| &r.episode_id),
            i32s(rows, |r| r.frame_index),
            strings(rows, |r| &r.source_table),
            opt_strings(rows, |r| r.model_id.as_deref()),
            strings(rows, |r| &r.run_id),
            f64s(rows, |r| r.brenner_raw),
            f64s(rows, |r| r.brenner),
            f64s(rows, |r| r.ssim),
            f64s(rows, |r| r.beta),
            Arc::new(rows.iter().map(|r| r.weight).collect::<Float64Array>()),
        ];
        Ok(RecordBatch::try_new(Self::TABLE.arrow_schema(), cols)?)
    }

    fn from_batch(b: &RecordBatch) -> Result<Vec<Self>> {
        const T: TableKind = TableKind::Scores;
        let s = |n: &str| column::<StringArray>(b, n, T);
        let f = |n: &str| column::<Float64Array>(b, n, T);
        let (ids, src, model, run) = (s("episode_id")?, s("source_table")?, s("model_id")?, s("run_id")?);
        let idx = column::<Int32Array>(b, "frame_index", T)?;
        let (raw, br, ss, be, w) = (
            f("brenner_raw")?,
            f("brenner")?,
            f("ssim")?,
            f("beta")?,
            f("weight")?,
        );
        Ok((0..b.num_rows())
            .map(|i| ScoreRow {
                episode_id: ids.value(i).to_string(),
                frame_index: idx.value(i),
                source_table: src.value(i).to_string(),
                model_id: opt_str(model, i),
                run_id: run.value(i).to_string(),
                brenner_raw: raw.value(i),
                brenner: br.value(i),
                ssim: ss.value(i),
                beta: be.value(i),
                weight: w.is_valid(i).then(|| w.value(i)),
            })
            .collect())
    }
}

/// One row of the `curated` view: a frame the trainer uses, with its loss weight.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CuratedRow {
    pub episode_id: String,
    pub frame_index: i32,
    pub weight: f64,
    pub source_table: String,
    pub model_id: Option<String>,
    pub run_id: String,
    pub curation_id: String,
}

impl Row for CuratedRow {
    const TABLE: TableKind = TableKind::Curated;

    fn group(&self) -> &str {
        &self.episode_id
    }

    fn to_batch(rows: &[Self]) -> Result<RecordBatch> {
        let cols: Vec<ArrayRef> = vec![
            strings(rows, |r| &r.episode_id),
            i32s(rows, |r| r.frame_index),
            f64s(rows, |r| r.weight),
            strings(rows, |r| &r.source_table),
            opt_strings(rows, |r| r.model_id.as_deref()),
            strings(rows, |r| &r.run_id),
            strings(rows, |r| &r.curation_id),
        ];
        Ok(RecordBatch::try_new(Self::TABLE.arrow_schema(), cols)?)
    }

    fn from_batch(b: &RecordBatch) -> Result<Vec<Self>> {
        const T: TableKind = TableKind::Curated;
        let s = |n: &str| column::<StringArray>(b, n, T);
        let (ids, src, model, run, cid) = (
            s("episode_id")?,
            s("source_table")?,
            s("model_id")?,
            s("run_id")?,
            s("curation_id")?,
        );
        let idx = column::<Int32Array>(b, "frame_index", T)?;
        let w = column::<Float64Array>(b, "weight", T)?;
        Ok((0..b.num_rows())
            .map(|i| CuratedRow {
                episode_id: ids.value(i).to_string(),
                frame_index: idx.value(i),
                weight: w.value(i),
                source_table: src.value(i).to_string(),
                model_id: opt_str(model, i),
                run_id: run.value(i).to_string(),
                curation_id: cid.value(i).to_string(),
            })
            .collect())
    }
}

/// One row of the `alignments` table: an aligned (human frame, robot frame) cell.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AlignmentRow {
    pub pair_id: String,
    pub human_episode_id: String,
    pub human_frame: i32,
    pub robot_episode_id: String,
    pub robot_frame: i32,
    pub cost: f64,
    /// The feature kind aligned on (`motion`, `state`, `translated`).
    pub features: String,
    pub run_id: String,
}

impl Row for AlignmentRow {
    const TABLE: TableKind = TableKind::Alignments;

    fn group(&self) -> &str {
        &self.pair_id
    }

    fn to_batch(rows: &[Self]) -> Result<RecordBatch> {
        let cols: Vec<ArrayRef> = vec![
            strings(rows, |r| &r.pair_id),
            strings(rows, |r| &r.human_episode_id),
            i32s(rows, |r| r.human_frame),
            strings(rows, |r| &r.robot_episode_id),
            i32s(rows, |r| r.robot_frame),
            f64s(rows, |r| r.cost),
            strings(rows, |r| &r.features),
            strings(rows, |r| &r.run_id),
        ];
        Ok(RecordBatch::try_new(Self::TABLE.arrow_schema(), cols)?)
    }

    fn from_batch(b: &RecordBatch) -> Result<Vec<Self>> {
        const T: TableKind = TableKind::Alignments;
        let s = |n: &str| column::<StringArray>(b, n, T);
        let (pair, he, re, feat, run) = (
            s("pair_id")?,
            s("human_episode_id")?,
            s("robot_episode_id")?,
            s("features")?,
            s("run_id")?,
        );
        let (hf, rf) = (
            column::<Int32Array>(b, "human_frame", T)?,
            column::<Int32Array>(b, "robot_frame", T)?,
        );
        let cost = column::<Float64Array>(b, "cost", T)?;
        Ok((0..b.num_rows())
            .map(|i| AlignmentRow {
                pair_id: pair.value(i).to_string(),
                human_episode_id: he.value(i).to_string(),
                human_frame: hf.value(i),
                robot_episode_id: re.value(i).to_string(),
                robot_frame: rf.value(i),
                cost: cost.value(i),
                features: feat.value(i).to_string(),
                run_id: run.value(i).to_string(),
            })
            .collect())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    pub(crate) fn sample_episode(id: &str) -> Episode {
        Episode {
            episode_id: id.into(),
            domain: Domain::Robot,
            kind: Kind::Random,
            task_id: Some("draw/circle".into()),
            task_family: None,
            pair_id: None,
            split: Split::Train,
            n_frames: 3,
            fps: 10.0,
            width: 4,
            height: 2,
            frame_encoding: FrameEncoding::Raw,
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

    #[test]
    fn closed_sets_are_stored_as_their_names() {
        assert_eq!(Domain::NAMES, ["human", "robot"]);
        assert_eq!(Kind::NAMES, ["demo", "random", "paired"]);
        assert_eq!(Split::NAMES, ["train", "val", "test"]);
        for d in Domain::ALL {
            assert_eq!(d.as_str().parse::<Domain>().unwrap(), *d);
            assert_eq!(serde_json::to_string(d).unwrap(), format!("\"{d}\""));
        }
        assert_eq!(Domain::Human.other(), Domain::Robot);
        let e = "alien".parse::<Domain>().unwrap_err();
        assert_eq!(e, "unknown domain \"alien\" (expected one of human, robot)");
        let b = episodes_to_batch(&[sample_episode("a")]).unwrap();
        let col = b
            .column_by_name("domain")
            .unwrap()
            .as_any()
            .downcast_ref::<StringArray>()
            .unwrap();
        assert_eq!(col.value(0), "robot");
        // An unknown stored value is a schema error naming the episode.
        let mut cols = b.columns().to_vec();
        cols[1] = Arc::new(StringArray::from(vec!["alien"]));
        let bad = RecordBatch::try_new(b.schema(), cols).unwrap();
        let err = episodes_from_batches(&[bad]).unwrap_err().to_string();
        assert!(err.contains("episode a: unknown domain \"alien\""), "{err}");
    }

    #[test]
    fn run_rows_round_trip() {
        let scores = vec![
            ScoreRow {
                episode_id: "e".into(),
                frame_index: 0,
                source_table: "imagined".into(),
                model_id: Some("m".into()),
                run_id: "r".into(),
                brenner_raw: 3.0,
                brenner: 0.5,
                ssim: 0.25,
                beta: 0.3125,
                weight: Some(0.1),
            },
            ScoreRow {
                frame_index: 1,
                model_id: None,
                weight: None,
                ..ScoreRow::default()
            },
        ];
        let b = ScoreRow::to_batch(&scores).unwrap();
        assert_eq!(b.schema(), TableKind::Scores.arrow_schema());
        assert_eq!(ScoreRow::from_batch(&b).unwrap(), scores);
        let curated = vec![CuratedRow {
            episode_id: "e".into(),
            frame_index: 4,
            weight: 0.7,
            source_table: "frames".into(),
            model_id: None,
            run_id: "r".into(),
            curation_id: "c".into(),
        }];
        let b = CuratedRow::to_batch(&curated).unwrap();
        assert_eq!(b.schema(), TableKind::Curated.arrow_schema());
        assert_eq!(CuratedRow::from_batch(&b).unwrap(), curated);
        let cells = vec![AlignmentRow {
            pair_id: "p".into(),
            human_episode_id: "h".into(),
            human_frame: 2,
            robot_episode_id: "r".into(),
            robot_frame: 3,
            cost: 0.5,
            features: "motion".into(),
            run_id: "x".into(),
        }];
        let b = AlignmentRow::to_batch(&cells).unwrap();
        assert_eq!(b.schema(), TableKind::Alignments.arrow_schema());
        assert_eq!(AlignmentRow::from_batch(&b).unwrap(), cells);
        assert_eq!(cells[0].group(), "p");
    }
}
