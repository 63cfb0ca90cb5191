//! Table schemas, defined once here and mirrored in `schemas/v1/*.json`.
//!
//! Each table is a list of [`Column`]s; the Arrow schema and the JSON description are both
//! derived from it, and a test checks the JSON files in the repository agree.

use std::sync::Arc;

use deltalake::arrow::datatypes::{DataType, Field, Schema, SchemaRef, TimeUnit};
use serde_json::{Value, json};

/// Version of the table schemas (the `v1` in `schemas/v1/`).
pub const SCHEMA_VERSION: u32 = 1;

/// The tables of a dataset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TableKind {
    Episodes,
    Frames,
    Imagined,
    Scores,
    Curated,
    Alignments,
}

impl TableKind {
    pub const ALL: [TableKind; 6] = [
        TableKind::Episodes,
        TableKind::Frames,
        TableKind::Imagined,
        TableKind::Scores,
        TableKind::Curated,
        TableKind::Alignments,
    ];

    /// Folder name of the table under the dataset root.
    pub fn name(self) -> &'static str {
        match self {
            TableKind::Episodes => "episodes",
            TableKind::Frames => "frames",
            TableKind::Imagined => "imagined",
            TableKind::Scores => "scores",
            TableKind::Curated => "curated",
            TableKind::Alignments => "alignments",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The column naming the group a row belongs to: rows are written, deduplicated and
    /// deleted a group at a time (an episode; a pair for `alignments`).
    pub fn group_column(self) -> &'static str {
        match self {
            TableKind::Alignments => "pair_id",
            _ => "episode_id",
        }
    }

    /// The column naming what produced a row (a translation model, a scoring run, a
    /// curation, an alignment run); `None` for the tables ingest writes. Writing the same
    /// group of the same run twice is a no-op ([`crate::write`]).
    pub fn run_column(self) -> Option<&'static str> {
        match self {
            TableKind::Episodes | TableKind::Frames => None,
            TableKind::Imagined => Some("model_id"),
            TableKind::Scores | TableKind::Alignments => Some("run_id"),
            TableKind::Curated => Some("curation_id"),
        }
    }

    pub fn columns(self) -> &'static [Column] {
        match self {
            TableKind::Episodes => EPISODES,
            TableKind::Frames => FRAMES,
            TableKind::Imagined => IMAGINED,
            TableKind::Scores => SCORES,
            TableKind::Curated => CURATED,
            TableKind::Alignments => ALIGNMENTS,
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            TableKind::Episodes => "One row per episode (one clip of one embodiment).",
            TableKind::Frames => "One row per frame: encoded image plus the per-frame action/state vectors.",
            TableKind::Imagined => {
                "One row per translated human frame: the imagined robot frame G(x), its latent \
                 from F's encoder and the inverse-dynamics action, per translation model."
            }
            TableKind::Scores => {
                "One row per scored frame: Brenner x SSIM quality (beta_qua) of a scoring run; \
                 the run's Brenner normalisation is in each file's `milv.scores` metadata."
            }
            TableKind::Curated => {
                "The curated view the trainer reads: one row per frame it uses, with its loss weight."
            }
            TableKind::Alignments => {
                "One row per aligned (human frame, robot frame) pair of a loosely paired clip pair \
                 (banded DTW), for the A-CycleGAN auxiliary loss."
            }
        }
    }

    /// The Arrow schema rows of this table are written with.
    pub fn arrow_schema(self) -> SchemaRef {
        let fields: Vec<Field> = self.columns().iter().map(Column::arrow_field).collect();
        Arc::new(Schema::new(fields))
    }

    /// The machine-readable description stored in `schemas/v1/<table>.json`.
    pub fn json(self) -> Value {
        json!({
            "table": self.name(),
            "schema_version": SCHEMA_VERSION,
            "description": self.description(),
            "fields": self.columns().iter().map(|c| json!({
                "name": c.name,
                "type": c.ty.name(),
                "nullable": c.nullable,
                "description": c.doc,
            })).collect::<Vec<_>>(),
        })
    }
}

impl std::fmt::Display for TableKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Column types used by MILV tables (a small subset of Arrow that Delta Lake supports).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColType {
    Utf8,
    Int32,
    Int64,
    Float64,
    Binary,
    /// `list<float32>`; Delta has no fixed-size lists, so the width is an episode attribute.
    ListF32,
    ListUtf8,
    ListI32,
    TimestampUsUtc,
}

impl ColType {
    pub fn name(self) -> &'static str {
        match self {
            ColType::Utf8 => "string",
            ColType::Int32 => "int32",
            ColType::Int64 => "int64",
            ColType::Float64 => "float64",
            ColType::Binary => "binary",
            ColType::ListF32 => "list<float32>",
            ColType::ListUtf8 => "list<string>",
            ColType::ListI32 => "list<int32>",
            ColType::TimestampUsUtc => "timestamp[us, UTC]",
        }
    }

    pub fn arrow(self) -> DataType {
        // List items are named "element" as the Parquet spec and Spark/Delta expect.
        match self {
            ColType::Utf8 => DataType::Utf8,
            ColType::Int32 => DataType::Int32,
            ColType::Int64 => DataType::Int64,
            ColType::Float64 => DataType::Float64,
            ColType::Binary => DataType::Binary,
            ColType::ListF32 => list_of(DataType::Float32),
            ColType::ListUtf8 => list_of(DataType::Utf8),
            ColType::ListI32 => list_of(DataType::Int32),
            ColType::TimestampUsUtc => DataType::Timestamp(TimeUnit::Microsecond, Some("UTC".into())),
        }
    }
}

/// The list type used for vector columns.
pub fn list_of(item: DataType) -> DataType {
    DataType::List(Arc::new(Field::new("element", item, false)))
}

/// One column of a table.
#[derive(Clone, Copy, Debug)]
pub struct Column {
    pub name: &'static str,
    pub ty: ColType,
    pub nullable: bool,
    pub doc: &'static str,
}

impl Column {
    pub fn arrow_field(&self) -> Field {
        Field::new(self.name, self.ty.arrow(), self.nullable)
    }
}

const fn col(name: &'static str, ty: ColType, nullable: bool, doc: &'static str) -> Column {
    Column {
        name,
        ty,
        nullable,
        doc,
    }
}

use ColType::*;

const EPISODES: &[Column] = &[
    col(
        "episode_id",
        Utf8,
        false,
        "Content hash (sha256, 32 hex chars) of source bytes, sidecar bytes and ingest options.",
    ),
    col("domain", Utf8, false, "Embodiment: human | robot."),
    col("kind", Utf8, false, "demo | random | paired."),
    col("task_id", Utf8, true, "Task identifier, e.g. draw/circle."),
    col("task_family", Utf8, true, "Task family, e.g. drawing or pushing."),
    col(
        "pair_id",
        Utf8,
        true,
        "Links a human and a robot episode of the same motion.",
    ),
    col("split", Utf8, false, "train | val | test."),
    col(
        "n_frames",
        Int64,
        false,
        "Number of rows of this episode in the frames table.",
    ),
    col("fps", Float64, false, "Frame rate of the stored frames."),
    col("width", Int32, false, "Stored frame width in pixels."),
    col("height", Int32, false, "Stored frame height in pixels."),
    col(
        "frame_encoding",
        Utf8,
        false,
        "png | jpeg | raw (RGB24, row-major).",
    ),
    col(
        "action_dim",
        Int32,
        true,
        "Width of the action vectors, if the episode has actions.",
    ),
    col(
        "state_dim",
        Int32,
        true,
        "Width of the state vectors, if the episode has states.",
    ),
    col(
        "action_names",
        ListUtf8,
        true,
        "Names of the action components, e.g. [dx, dy].",
    ),
    col("state_names", ListUtf8, true, "Names of the state components."),
    col(
        "source_uri",
        Utf8,
        false,
        "Path or URI of the source video or frame folder.",
    ),
    col(
        "source_sha256",
        Utf8,
        false,
        "sha256 of the source bytes (a folder: of its frame files in order).",
    ),
    col(
        "sidecar_uri",
        Utf8,
        true,
        "Path of the action/metadata sidecar, if any.",
    ),
    col(
        "duration_ns",
        Int64,
        false,
        "Timestamp of the last frame plus one frame period.",
    ),
    col(
        "ingested_at",
        TimestampUsUtc,
        false,
        "When the episode was ingested.",
    ),
];

const FRAMES: &[Column] = &[
    col("episode_id", Utf8, false, "Episode this frame belongs to."),
    col("frame_index", Int32, false, "0-based index within the episode."),
    col(
        "timestamp_ns",
        Int64,
        false,
        "Presentation timestamp relative to the first frame.",
    ),
    col(
        "image",
        Binary,
        false,
        "Encoded frame (see the episode's frame_encoding).",
    ),
    col(
        "action",
        ListF32,
        true,
        "Action taken at this frame (episode's action_dim wide).",
    ),
    col(
        "state",
        ListF32,
        true,
        "State at this frame (episode's state_dim wide).",
    ),
];

const IMAGINED: &[Column] = &[
    col(
        "episode_id",
        Utf8,
        false,
        "The human episode that was translated.",
    ),
    col("frame_index", Int32, false, "0-based index within the episode."),
    col(
        "timestamp_ns",
        Int64,
        false,
        "Timestamp of the source frame relative to the first frame.",
    ),
    col(
        "model_id",
        Utf8,
        false,
        "Translation model (digest of the A-CycleGAN checkpoint).",
    ),
    col("image", Binary, false, "The imagined robot frame G(x), PNG."),
    col(
        "latent",
        Binary,
        true,
        "Latent of the imagined frame, raw little-endian values (see latent_dtype/shape).",
    ),
    col("latent_dtype", Utf8, true, "f16 | f32."),
    col(
        "latent_shape",
        ListI32,
        true,
        "Shape of the latent, e.g. [64, 32, 32].",
    ),
    col(
        "action",
        ListF32,
        true,
        "Action predicted by the inverse-dynamics model for this frame.",
    ),
];

const SCORES: &[Column] = &[
    col("episode_id", Utf8, false, "Episode of the scored frame."),
    col("frame_index", Int32, false, "0-based index within the episode."),
    col(
        "source_table",
        Utf8,
        false,
        "Table the frame was read from: frames | imagined.",
    ),
    col(
        "model_id",
        Utf8,
        true,
        "Translation model of an imagined frame (null for recorded frames).",
    ),
    col(
        "run_id",
        Utf8,
        false,
        "Scoring run: digest of dataset version, table, model and selection.",
    ),
    col(
        "brenner_raw",
        Float64,
        false,
        "Brenner gradient S_h + S_v on BT.601 luma (spec/quality.md).",
    ),
    col(
        "brenner",
        Float64,
        false,
        "Brenner normalised per image to [0, 1].",
    ),
    col(
        "ssim",
        Float64,
        false,
        "Gray SSIM in [-1, 1] with the next frame (the last frame reuses the last pair).",
    ),
    col(
        "beta",
        Float64,
        false,
        "brenner * (ssim + 1) / 2, the per-image beta_qua.",
    ),
    col(
        "weight",
        Float64,
        true,
        "Set-normalised loss weight (brenner - min)/(max - min) * (ssim + 1)/2 over the run; \
         null when the run was split into partitions (curate computes it then).",
    ),
];

const CURATED: &[Column] = &[
    col("episode_id", Utf8, false, "Episode the trainer uses."),
    col(
        "frame_index",
        Int32,
        false,
        "Frame of that episode the trainer uses.",
    ),
    col("weight", Float64, false, "Loss weight of the frame (eq. 11)."),
    col("source_table", Utf8, false, "frames | imagined."),
    col("model_id", Utf8, true, "Translation model of imagined frames."),
    col("run_id", Utf8, false, "Scoring run the weights come from."),
    col(
        "curation_id",
        Utf8,
        false,
        "Digest of the curation (run and thresholds).",
    ),
];

const ALIGNMENTS: &[Column] = &[
    col("pair_id", Utf8, false, "The pair (episodes sharing a pair_id)."),
    col("human_episode_id", Utf8, false, "The human episode of the pair."),
    col("human_frame", Int32, false, "Frame of the human episode."),
    col("robot_episode_id", Utf8, false, "The robot episode of the pair."),
    col(
        "robot_frame",
        Int32,
        false,
        "Frame of the robot episode aligned with it.",
    ),
    col(
        "cost",
        Float64,
        false,
        "Local cost of this cell: squared distance of the two frames' features.",
    ),
    col(
        "features",
        Utf8,
        false,
        "Feature kind aligned on: motion | state | translated.",
    ),
    col(
        "run_id",
        Utf8,
        false,
        "Alignment run: digest of what it read and its options.",
    ),
];

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn schema_file(table: TableKind) -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../schemas/v1")
            .join(format!("{}.json", table.name()))
    }

    /// The JSON schemas in `schemas/v1/` must match the code. Run with MILV_BLESS=1 to rewrite them.
    #[test]
    fn json_schemas_agree_with_code() {
        for table in TableKind::ALL {
            let path = schema_file(table);
            let expected = table.json();
            if std::env::var_os("MILV_BLESS").is_some() {
                let text = serde_json::to_string_pretty(&expected).unwrap() + "\n";
                std::fs::write(&path, text).unwrap();
            }
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("{}: {e} (run with MILV_BLESS=1)", path.display()));
            let on_disk: Value = serde_json::from_str(&text).unwrap();
            assert_eq!(on_disk, expected, "{} disagrees with the code", path.display());
        }
    }

    #[test]
    fn arrow_schema_has_every_column_once() {
        for table in TableKind::ALL {
            let schema = table.arrow_schema();
            assert_eq!(schema.fields().len(), table.columns().len());
            for c in table.columns() {
                let f = schema.field_with_name(c.name).unwrap();
                assert_eq!(f.is_nullable(), c.nullable);
            }
        }
    }
}
