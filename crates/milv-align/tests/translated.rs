//! `translated` features read the human clip from the `imagined` table: when the
//! "translation" of each human frame is the robot frame it corresponds to, the aligner
//! recovers that correspondence exactly.
#![allow(clippy::unwrap_used)]

use milv_align::{AlignOptions, StepPattern, align_dataset, features};
use milv_data::{CommitMeta, Dataset, Domain, Episode, Kind};
use milv_fixtures::{Frame, ImaginedFrame, commit_episodes, commit_imagined};

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
    milv_fixtures::png(rgb, W, W)
}

fn episode(id: &str, domain: Domain, frames: &[Vec<u8>]) -> (Episode, Vec<Frame>) {
    let e = Episode {
        kind: Kind::Paired,
        task_id: None,
        task_family: None,
        pair_id: Some("p".into()),
        ..milv_fixtures::episode(id, domain, frames.len(), (W, W))
    };
    (e, frames.iter().map(|f| Frame::image(png(f))).collect())
}

#[test]
fn translated_frames_align_to_the_robot_frames_they_show() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta()).unwrap();
    // Robot: the motion at full speed (30 frames); human: 20 frames, a warp of it.
    let truth: Vec<usize> = (0..20)
        .map(|i| ((i as f64 / 19.0).powf(1.3) * 29.0).round() as usize)
        .collect();
    let human: Vec<Vec<u8>> = (0..20).map(|_| vec![128u8; (W * W * 3) as usize]).collect();
    let robot: Vec<Vec<u8>> = (0..30).map(frame).collect();
    commit_episodes(
        &ds,
        &[
            episode("human", Domain::Human, &human),
            episode("robot", Domain::Robot, &robot),
        ],
        meta(),
    )
    .unwrap();

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
    let translated: Vec<ImaginedFrame> = truth
        .iter()
        .map(|&j| ImaginedFrame {
            image: png(&frame(j)),
            ..ImaginedFrame::default()
        })
        .collect();
    commit_imagined(&ds, "model-x", &[("human", translated)], meta()).unwrap();

    let rep = align_dataset(&ds, None, kind, &opts, meta(), &|| {}).unwrap();
    assert_eq!(rep.pairs.len(), 1, "{:?}", rep.failed);
    assert_eq!(rep.pairs[0].mean_frame_error, Some(0.0), "{:?}", rep.pairs[0]);
    assert!(rep.pairs[0].trusted);
}
