//! A small simulated dataset, built in-process with milv-sim's renderer and written
//! through milv-data (PNG frames, no video codec), aligned with milv-align's `state`
//! features: what `milv-sim gen | milv-ingest | milv-align` would produce, in seconds.
#![allow(clippy::unwrap_used, dead_code)]

use std::path::{Path, PathBuf};

use milv_align::{AlignOptions, align_dataset, features};
use milv_data::{CommitMeta, Dataset, Domain, Episode, Kind, Split};
use milv_fixtures::{Frame, commit_episodes};
use milv_sim::env::{Rollout, Sim, SmoothRandom, Task, expert_action, paired_clips, rollout};
use milv_sim::render::Domain as SimDomain;
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

/// A rollout as a fixture episode with its frames (PNG, actions and states).
fn episode(
    name: &str,
    domain: Domain,
    kind: Kind,
    split: Split,
    r: &Rollout,
    pair: Option<&str>,
    extra_actions: usize,
) -> (Episode, Vec<Frame>) {
    let e = Episode {
        kind,
        split,
        task_id: Some("draw/x".into()),
        pair_id: pair.map(String::from),
        action_dim: Some(2 + extra_actions as i32),
        state_dim: Some(2),
        ..milv_fixtures::episode(name, domain, r.frames.len(), (SIZE, SIZE))
    };
    let frames = (0..r.frames.len())
        .map(|i| Frame {
            image: milv_fixtures::png(&r.frames[i], SIZE, SIZE),
            action: Some(
                r.actions[i]
                    .iter()
                    .copied()
                    .chain(std::iter::repeat_n(0.0, extra_actions))
                    .collect(),
            ),
            state: Some(r.states[i].to_vec()),
        })
        .collect();
    (e, frames)
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
    sim_dataset_with_actions(dir, tasks, with_random, &|_| 0)
}

/// [`sim_dataset`] with `extra_actions(name)` zero action values appended to the
/// episode called `name` (robots with wider actions than milv-sim's Δx, Δy).
pub fn sim_dataset_with_actions(
    dir: &Path,
    tasks: usize,
    with_random: bool,
    extra_actions: &dyn Fn(&str) -> usize,
) -> Fixture {
    let root = dir.join("ds");
    let ds = Dataset::open_or_create(&root, meta()).unwrap();
    let mut eps = Vec::new();
    let mut truth = String::new();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut human_frames = 0;
    let shapes = shapes::training_shapes();
    for i in 0..tasks {
        let task = Task::Drawing {
            shape: shapes[i % shapes.len()].clone(),
        };
        let sim = |d| Sim::reset(task.clone(), d, SIZE).unwrap();
        let h = rollout(sim(SimDomain::Human), expert_action);
        let r = rollout(sim(SimDomain::Robot), expert_action);
        human_frames += h.frames.len();
        let (hn, rn) = (format!("human_demo_{i}"), format!("robot_demo_{i}"));
        eps.push(episode(
            &hn,
            Domain::Human,
            Kind::Demo,
            Split::Train,
            &h,
            None,
            extra_actions(&hn),
        ));
        eps.push(episode(
            &rn,
            Domain::Robot,
            Kind::Demo,
            Split::Train,
            &r,
            None,
            extra_actions(&rn),
        ));
        truth += &format!("{{\"human\":\"{hn}.mp4\",\"robot\":\"{rn}.mp4\"}}\n");
        if with_random {
            for split in [Split::Train, Split::Test]
                .into_iter()
                .take(if i == 0 { 2 } else { 1 })
            {
                let mut policy = SmoothRandom::new(100 + i as u64);
                let rr = rollout(sim(SimDomain::Robot), |s| policy.act(s));
                let name = format!("robot_random_{i}_{split}");
                eps.push(episode(
                    &name,
                    Domain::Robot,
                    Kind::Random,
                    split,
                    &rr,
                    None,
                    extra_actions(&name),
                ));
            }
        }
        let pair = paired_clips(&task, SIZE, 20, 16, &mut rng).unwrap();
        let pid = format!("pair-{i}");
        let hp = format!("human_paired_{i}");
        human_frames += pair.human.frames.len();
        eps.push(episode(
            &hp,
            Domain::Human,
            Kind::Paired,
            Split::Train,
            &pair.human,
            Some(&pid),
            extra_actions(&hp),
        ));
        let rp = format!("robot_paired_{i}");
        eps.push(episode(
            &rp,
            Domain::Robot,
            Kind::Paired,
            Split::Train,
            &pair.robot,
            Some(&pid),
            extra_actions(&rp),
        ));
    }
    commit_episodes(&ds, &eps, meta()).unwrap();
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
