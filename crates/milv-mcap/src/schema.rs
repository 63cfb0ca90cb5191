//! The channels of a MILV recording and their schemas (documented in `schemas/mcap/`).
//!
//! Images are `foxglove.CompressedImage` in protobuf, so Foxglove and Rerun's MCAP importer
//! both show them unchanged; actions and quality are JSON-schema messages with named
//! fields, so Foxglove plots them; latents are the compact protobuf [`Tensor`] (raw
//! little-endian bytes, never JSON arrays of floats).

use foxglove::Encode;
use prost::Message;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};
use serde_json::{Value, json};

pub const HUMAN_IMAGE: &str = "/human/image";
pub const IMAGINED_IMAGE: &str = "/imagined/image";
pub const ROBOT_IMAGE: &str = "/robot/image";
pub const IMAGINED_ACTION: &str = "/imagined/action";
pub const ROBOT_ACTION: &str = "/robot/action";
pub const QUALITY: &str = "/quality";
pub const IMAGINED_LATENT: &str = "/imagined/latent";

/// Name of the latent message type (protobuf full name).
pub const TENSOR_SCHEMA: &str = "milv.Tensor";
pub const ACTION_SCHEMA: &str = "milv.Action";
pub const QUALITY_SCHEMA: &str = "milv.Quality";

/// One latent tensor of a translated frame: `shape` values of `dtype`, row-major,
/// little-endian, in `data`.
#[derive(Clone, PartialEq, Message)]
pub struct Tensor {
    /// The frame's timestamp within its episode (ns).
    #[prost(int64, tag = "1")]
    pub timestamp_ns: i64,
    #[prost(string, tag = "2")]
    pub episode_id: String,
    #[prost(int32, tag = "3")]
    pub frame_index: i32,
    /// Translation model (checkpoint digest).
    #[prost(string, tag = "4")]
    pub model_id: String,
    /// `f16` or `f32`.
    #[prost(string, tag = "5")]
    pub dtype: String,
    #[prost(uint32, repeated, tag = "6")]
    pub shape: Vec<u32>,
    #[prost(bytes = "vec", tag = "7")]
    pub data: Vec<u8>,
}

/// Fields of [`Tensor`] as (name, number, type, repeated): the descriptor and the
/// `.proto` text are both made from this, so they cannot disagree.
const TENSOR_FIELDS: [(&str, i32, Type, bool); 7] = [
    ("timestamp_ns", 1, Type::Int64, false),
    ("episode_id", 2, Type::String, false),
    ("frame_index", 3, Type::Int32, false),
    ("model_id", 4, Type::String, false),
    ("dtype", 5, Type::String, false),
    ("shape", 6, Type::Uint32, true),
    ("data", 7, Type::Bytes, false),
];

/// The serialized `FileDescriptorSet` of [`Tensor`], as MCAP's protobuf schema encoding wants.
pub fn tensor_descriptor() -> Vec<u8> {
    let field = TENSOR_FIELDS
        .iter()
        .map(|(name, number, ty, repeated)| FieldDescriptorProto {
            name: Some((*name).into()),
            number: Some(*number),
            label: Some(if *repeated {
                Label::Repeated
            } else {
                Label::Optional
            } as i32),
            r#type: Some(*ty as i32),
            json_name: Some(lower_camel(name)),
            ..Default::default()
        })
        .collect();
    let file = FileDescriptorProto {
        name: Some("milv/tensor.proto".into()),
        package: Some("milv".into()),
        message_type: vec![DescriptorProto {
            name: Some("Tensor".into()),
            field,
            ..Default::default()
        }],
        syntax: Some("proto3".into()),
        ..Default::default()
    };
    FileDescriptorSet { file: vec![file] }.encode_to_vec()
}

fn lower_camel(s: &str) -> String {
    let mut out = String::new();
    let mut up = false;
    for c in s.chars() {
        if c == '_' {
            up = true;
        } else if up {
            out.extend(c.to_uppercase());
            up = false;
        } else {
            out.push(c);
        }
    }
    out
}

/// `schemas/mcap/milv/tensor.proto`, rendered from the same field list as the descriptor.
pub fn tensor_proto_text() -> String {
    let mut s = String::from(
        "// Generated from milv-mcap's schema (schema::tensor_proto_text); a test keeps it in sync.\n\
         syntax = \"proto3\";\n\npackage milv;\n\n\
         // One latent tensor of a translated frame: `shape` values of `dtype` (f16 | f32),\n\
         // row-major, little-endian, in `data`.\nmessage Tensor {\n",
    );
    for (name, number, ty, repeated) in TENSOR_FIELDS {
        let t = match ty {
            Type::Int64 => "int64",
            Type::Int32 => "int32",
            Type::Uint32 => "uint32",
            Type::Bytes => "bytes",
            _ => "string",
        };
        let rep = if repeated { "repeated " } else { "" };
        s.push_str(&format!("  {rep}{t} {name} = {number};\n"));
    }
    s.push_str("}\n");
    s
}

/// The JSON schema of action messages with these component names (e.g. `dx`, `dy`).
pub fn action_schema(names: &[String]) -> Value {
    let mut props = serde_json::Map::new();
    props.insert("episode_id".into(), json!({"type": "string"}));
    props.insert("frame_index".into(), json!({"type": "integer"}));
    for n in names {
        props.insert(n.clone(), json!({"type": "number"}));
    }
    let mut required = vec!["episode_id".to_string(), "frame_index".to_string()];
    required.extend(names.iter().cloned());
    json!({
        "title": ACTION_SCHEMA,
        "description": "One action: the inverse dynamics' prediction (/imagined/action) or the recorded action of the aligned robot frame (/robot/action).",
        "type": "object",
        "properties": props,
        "required": required,
    })
}

/// The JSON schema of quality messages.
pub fn quality_schema() -> Value {
    json!({
        "title": QUALITY_SCHEMA,
        "description": "Quality of a translated frame (spec/quality.md): Brenner normalised to [0, 1], SSIM with the next frame, beta = Brenner x SSIM, and the curated loss weight (null without a curation).",
        "type": "object",
        "properties": {
            "episode_id": {"type": "string"},
            "frame_index": {"type": "integer"},
            "brenner": {"type": "number"},
            "ssim": {"type": "number"},
            "beta": {"type": "number"},
            "weight": {"type": ["number", "null"]},
        },
        "required": ["episode_id", "frame_index", "brenner", "ssim", "beta", "weight"],
    })
}

/// `foxglove.CompressedImage`'s schema (name, encoding, descriptor bytes).
pub fn image_schema() -> (String, String, Vec<u8>) {
    let s = foxglove::messages::CompressedImage::get_schema()
        .unwrap_or_else(|| foxglove::Schema::new("foxglove.CompressedImage", "protobuf", Vec::new()));
    (s.name, s.encoding, s.data.into_owned())
}

/// The documented schema files (`schemas/mcap/`): relative path and contents.
pub fn schema_files() -> Vec<(&'static str, String)> {
    let pretty = |v: &Value| serde_json::to_string_pretty(v).unwrap_or_default() + "\n";
    vec![
        ("milv/tensor.proto", tensor_proto_text()),
        (
            "milv.Action.schema.json",
            pretty(&action_schema(&["dx".into(), "dy".into()])),
        ),
        ("milv.Quality.schema.json", pretty(&quality_schema())),
    ]
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn committed(rel: &str) -> String {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../schemas/mcap")
            .join(rel);
        std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    #[test]
    fn committed_schemas_match_the_code() {
        // `milv-export schemas schemas/mcap` rewrites them.
        for (rel, text) in schema_files() {
            assert_eq!(committed(rel), text, "schemas/mcap/{rel} is stale");
        }
    }

    #[test]
    fn tensor_descriptor_describes_the_message() {
        let set = FileDescriptorSet::decode(tensor_descriptor().as_slice()).unwrap();
        let msg = &set.file[0].message_type[0];
        assert_eq!(msg.name(), "Tensor");
        // Every field of the prost message round-trips through its declared number.
        let t = Tensor {
            timestamp_ns: -5,
            episode_id: "e".into(),
            frame_index: 3,
            model_id: "m".into(),
            dtype: "f16".into(),
            shape: vec![4, 2, 2],
            data: vec![1, 2, 3],
        };
        assert_eq!(Tensor::decode(t.encode_to_vec().as_slice()).unwrap(), t);
        let numbers: Vec<i32> = msg.field.iter().map(|f| f.number()).collect();
        assert_eq!(numbers, (1..=7).collect::<Vec<_>>());
        assert_eq!(msg.field[5].label(), Label::Repeated);
        assert_eq!(lower_camel("timestamp_ns"), "timestampNs");
    }

    #[test]
    fn image_schema_is_foxgloves_protobuf() {
        let (name, enc, data) = image_schema();
        assert_eq!(
            (name.as_str(), enc.as_str()),
            ("foxglove.CompressedImage", "protobuf")
        );
        let set = FileDescriptorSet::decode(data.as_slice()).unwrap();
        assert!(
            set.file
                .iter()
                .any(|f| f.message_type.iter().any(|m| m.name() == "CompressedImage"))
        );
    }
}
