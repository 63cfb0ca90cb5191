//! A small simulated dataset, built in-process with milv-sim's renderer and written
//! through milv-data (PNG frames, no video codec), aligned with milv-align's `state`
//! features: what `milv-sim gen | milv-ingest | milv-align` would produce, in seconds.
#![allow(clippy::unwrap_used, dead_code)]

use std::path::{Path, PathBuf};

use milv_align::{AlignOptions, align_dataset, features};
use milv_data::frame_codec::{FrameEncoding, encode};
use milv_data::{CommitMeta, Dataset, Episode, FrameRows, ShardOptions, TableKind};
use milv_sim::env::{Rollout, Sim, SmoothRandom, Task, expert_action, paired_clips, rollout};
use milv_sim::render::Domain;
use milv_sim::shapes;
use rand::SeedableRng;

pub const SIZE: u32 = 32;

/// Runs the `milv-train` binary: exit code, stdout, stderr.
pub fn run(args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_milv-train"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `milv-train`, expects success and JSON on stdout.
pub fn json(args: &[&str]) -> serde_json::Value {
    let (code, out, err) = run(args);
    assert_eq!(code, 0, "{args:?}: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

pub fn meta() -> CommitMeta {
    CommitMeta::for_this_process("milv-train-test", "fixture")
}

fn episode(name: &str, domain: Domain, kind: &str, split: &str, r: &Rollout, pair: Option<&str>) -> Episode {
    Episode {
        episode_id: name.into(),
        domain: domain.name().into(),
        kind: kind.into(),
        task_id: Some("draw/x".into()),
        task_family: Some("drawing".into()),
        pair_id: pair.map(String::from),
        split: split.into(),
        n_frames: r.frames.len() as i64,
        fps: 10.0,
        width: SIZE as i32,
        height: SIZE as i32,
        frame_encoding: "png".into(),
        action_dim: Some(2),
        state_dim: Some(2),
        action_names: None,
        state_names: None,
        source_uri: format!("{name}.mp4"),
        source_sha256: "00".into(),
        sidecar_uri: None,
        duration_ns: r.frames.len() as i64 * 100_000_000,
        ingested_at_us: 0,
    }
}

/// What [`sim_dataset`] wrote.
pub struct Fixture {
    pub root: PathBuf,
    pub truth: PathBuf,
    pub human_frames: usize,
}

/// `tasks` drawing tasks, each with a human demo, the robot demo of the same states
/// (ground truth), a robot random video (split train, and one more in split test) and a
/// loosely paired clip; then the `alignments` of the pairs. `with_random: false` leaves
/// out the robot random videos.
pub fn sim_dataset(dir: &Path, tasks: usize, with_random: bool) -> Fixture {
    let root = dir.join("ds");
    let ds = Dataset::open_or_create(&root, meta()).unwrap();
    let mut txn = ds.begin(meta()).unwrap();
    let mut w = txn
        .shard_writer(TableKind::Frames, ShardOptions::default())
        .unwrap();
    let mut eps = Vec::new();
    let mut truth = String::new();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut human_frames = 0;
    let shapes = shapes::training_shapes();
    let mut add = |eps: &mut Vec<Episode>, e: Episode, r: &Rollout| {
        w.begin_episode().unwrap();
        let mut rows = FrameRows::new();
        for (i, f) in r.frames.iter().enumerate() {
            let mut png = Vec::new();
            encode(FrameEncoding::Png, f, SIZE, SIZE, &mut png).unwrap();
            rows.push(
                &e.episode_id,
                i as i32,
                i as i64 * 100_000_000,
                &png,
                Some(&r.actions[i]),
                Some(&r.states[i]),
            );
        }
        w.push(rows.finish().unwrap()).unwrap();
        w.end_episode().unwrap();
        eps.push(e);
    };
    for i in 0..tasks {
        let task = Task::Drawing {
            shape: shapes[i % shapes.len()].clone(),
        };
        let sim = |d| Sim::reset(task.clone(), d, SIZE).unwrap();
        let h = rollout(sim(Domain::Human), expert_action);
        let r = rollout(sim(Domain::Robot), expert_action);
        human_frames += h.frames.len();
        let (hn, rn) = (format!("human_demo_{i}"), format!("robot_demo_{i}"));
        add(
            &mut eps,
            episode(&hn, Domain::Human, "demo", "train", &h, None),
            &h,
        );
        add(
            &mut eps,
            episode(&rn, Domain::Robot, "demo", "train", &r, None),
            &r,
        );
        truth += &format!("{{\"human\":\"{hn}.mp4\",\"robot\":\"{rn}.mp4\"}}\n");
        if with_random {
            for split in ["train", "test"].iter().take(if i == 0 { 2 } else { 1 }) {
                let mut policy = SmoothRandom::new(100 + i as u64);
                let rr = rollout(sim(Domain::Robot), |s| policy.act(s));
                let name = format!("robot_random_{i}_{split}");
                add(
                    &mut eps,
                    episode(&name, Domain::Robot, "random", split, &rr, None),
                    &rr,
                );
            }
        }
        let pair = paired_clips(&task, SIZE, 20, 16, &mut rng).unwrap();
        let pid = format!("pair-{i}");
        let hp = format!("human_paired_{i}");
        human_frames += pair.human.frames.len();
        add(
            &mut eps,
            episode(&hp, Domain::Human, "paired", "train", &pair.human, Some(&pid)),
            &pair.human,
        );
        let rp = format!("robot_paired_{i}");
        add(
            &mut eps,
            episode(&rp, Domain::Robot, "paired", "train", &pair.robot, Some(&pid)),
            &pair.robot,
        );
    }
    let ids: Vec<String> = eps.iter().map(|e| e.episode_id.clone()).collect();
    txn.add_files(TableKind::Frames, w.finish().unwrap(), ids.clone());
    let mut ew = txn
        .shard_writer(TableKind::Episodes, ShardOptions::default())
        .unwrap();
    ew.begin_episode().unwrap();
    ew.push(milv_data::episodes_to_batch(&eps).unwrap()).unwrap();
    ew.end_episode().unwrap();
    txn.add_files(TableKind::Episodes, ew.finish().unwrap(), ids);
    txn.commit().unwrap();
    let kind = features::by_name("state").unwrap();
    align_dataset(&ds, None, kind, &AlignOptions::default(), meta(), &|| {}).unwrap();
    let truth_path = dir.join("ground_truth.jsonl");
    std::fs::write(&truth_path, truth).unwrap();
    Fixture {
        root,
        truth: truth_path,
        human_frames,
    }
}
