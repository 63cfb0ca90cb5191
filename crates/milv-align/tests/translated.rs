//! `translated` features read the human clip from the `imagined` table: when the
//! "translation" of each human frame is the robot frame it corresponds to, the aligner
//! recovers that correspondence exactly.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use milv_align::{AlignOptions, StepPattern, align_dataset, features};
use milv_data::arrow::array::{
    ArrayRef, BinaryArray, Int32Array, Int64Array, RecordBatch, StringArray, new_null_array,
};
use milv_data::arrow::datatypes::DataType;
use milv_data::frame_codec::{FrameEncoding, encode};
use milv_data::schema::list_of;
use milv_data::{CommitMeta, Dataset, Episode, FrameRows, ShardOptions, TableKind};

const W: u32 = 32;

fn meta() -> CommitMeta {
    CommitMeta::for_this_process("align-test", "test")
}

/// A bright square drifting along a curve: frame `k` of a 30-frame motion.
fn frame(k: usize) -> Vec<u8> {
    let (cx, cy) = (4 + (k * 2) % 24, 4 + ((k * k) / 12) % 24);
    let mut rgb = vec![40u8; (W * W * 3) as usize];
    for y in cy..cy + 5 {
        for x in cx..cx + 5 {
            let i = (y * W as usize + x) * 3;
            rgb[i..i + 3].copy_from_slice(&[250, 220, 90]);
        }
    }
    rgb
}

fn png(rgb: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    encode(FrameEncoding::Png, rgb, W, W, &mut out).unwrap();
    out
}

fn episode(id: &str, domain: &str, n: usize) -> Episode {
    Episode {
        episode_id: id.into(),
        domain: domain.into(),
        kind: "paired".into(),
        task_id: None,
        task_family: None,
        pair_id: Some("p".into()),
        split: "train".into(),
        n_frames: n as i64,
        fps: 10.0,
        width: W as i32,
        height: W as i32,
        frame_encoding: "png".into(),
        action_dim: None,
        state_dim: None,
        action_names: None,
        state_names: None,
        source_uri: format!("{id}.mp4"),
        source_sha256: "ab".into(),
        sidecar_uri: None,
        duration_ns: 0,
        ingested_at_us: 0,
    }
}

#[test]
fn translated_frames_align_to_the_robot_frames_they_show() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta()).unwrap();
    // Robot: the motion at full speed (30 frames); human: 20 frames, a warp of it.
    let truth: Vec<usize> = (0..20)
        .map(|i| ((i as f64 / 19.0).powf(1.3) * 29.0).round() as usize)
        .collect();
    let mut txn = ds.begin(meta()).unwrap();
    let mut w = txn
        .shard_writer(TableKind::Frames, ShardOptions::default())
        .unwrap();
    for (id, frames) in [
        (
            "human",
            (0..20)
                .map(|_| vec![128u8; (W * W * 3) as usize])
                .collect::<Vec<_>>(),
        ),
        ("robot", (0..30).map(frame).collect()),
    ] {
        w.begin_episode().unwrap();
        let mut rows = FrameRows::new();
        for (i, f) in frames.iter().enumerate() {
            rows.push(id, i as i32, 0, &png(f), None, None);
        }
        w.push(rows.finish().unwrap()).unwrap();
        w.end_episode().unwrap();
    }
    let files = w.finish().unwrap();
    txn.add_files(TableKind::Frames, files, vec!["human".into(), "robot".into()]);
    let mut ew = txn
        .shard_writer(TableKind::Episodes, ShardOptions::default())
        .unwrap();
    ew.begin_episode().unwrap();
    ew.push(
        milv_data::episodes_to_batch(&[episode("human", "human", 20), episode("robot", "robot", 30)])
            .unwrap(),
    )
    .unwrap();
    ew.end_episode().unwrap();
    txn.add_files(
        TableKind::Episodes,
        ew.finish().unwrap(),
        vec!["human".into(), "robot".into()],
    );
    txn.commit().unwrap();

    let opts = AlignOptions {
        step: StepPattern::Asymmetric,
        band: 0.5,
        truth: [("p".to_string(), truth.clone())].into(),
        ..AlignOptions::default()
    };
    let kind = features::by_name("translated").unwrap();
    let err = align_dataset(&ds, None, kind, &opts, meta(), &|| {}).unwrap_err();
    assert!(err.to_string().contains("milv-train translate"), "{err}");

    // The imagined table: human frame i "translated" to the robot frame it shows.
    let images: Vec<Vec<u8>> = truth.iter().map(|&j| png(&frame(j))).collect();
    let n = images.len();
    let cols: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(vec!["human"; n])),
        Arc::new(Int32Array::from_iter_values(0..n as i32)),
        Arc::new(Int64Array::from_iter_values(0..n as i64)),
        Arc::new(StringArray::from(vec!["model-x"; n])),
        Arc::new(BinaryArray::from_iter_values(images.iter().map(Vec::as_slice))),
        new_null_array(&DataType::Binary, n),
        new_null_array(&DataType::Utf8, n),
        new_null_array(&list_of(DataType::Int32), n),
        new_null_array(&list_of(DataType::Float32), n),
    ];
    let mut txn = ds.begin(meta()).unwrap();
    let mut w = txn
        .shard_writer(TableKind::Imagined, ShardOptions::default())
        .unwrap();
    w.begin_episode().unwrap();
    w.push(RecordBatch::try_new(TableKind::Imagined.arrow_schema(), cols).unwrap())
        .unwrap();
    w.end_episode().unwrap();
    txn.add_files(TableKind::Imagined, w.finish().unwrap(), vec!["human".into()]);
    txn.commit().unwrap();

    let rep = align_dataset(&ds, None, kind, &opts, meta(), &|| {}).unwrap();
    assert_eq!(rep.pairs.len(), 1, "{:?}", rep.failed);
    assert_eq!(rep.pairs[0].mean_frame_error, Some(0.0), "{:?}", rep.pairs[0]);
    assert!(rep.pairs[0].trusted);
}
