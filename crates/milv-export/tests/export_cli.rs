//! The real `milv-export` binary on a small dataset built in-process: milv-sim's paired
//! clips, `state` alignments, imagined rows (PNG frames, f16 latents, actions), a scoring
//! run and a curation. The MCAP files are read back with our reader and compared bit for
//! bit with the tables; bad selections fail clearly and leave no file.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{meta, score_and_curate_imagined};
use milv_align::{AlignOptions, align_dataset, features};
use milv_data::arrow::array::{Array, BinaryArray, Float32Array, Int32Array, ListArray, StringArray};
use milv_data::{Dataset, Domain, Episode, Kind, TableKind};
use milv_fixtures::{Frame, ImaginedFrame, commit_episodes, commit_imagined};
use milv_mcap::{Recording, schema};
use milv_sim::env::{Task, paired_clips};
use milv_sim::shapes;
use rand::SeedableRng;

const SIZE: u32 = 32;
const MODEL: &str = "acg-00112233aabbccdd";

fn episode(id: &str, domain: Domain, pair: &str, n: usize) -> Episode {
    Episode {
        kind: Kind::Paired,
        task_id: Some("draw/x".into()),
        pair_id: Some(pair.into()),
        action_dim: Some(2),
        state_dim: Some(2),
        action_names: Some(vec!["dx".into(), "dy".into()]),
        ..milv_fixtures::episode(id, domain, n, (SIZE, SIZE))
    }
}

fn png(rgb: &[u8]) -> Vec<u8> {
    milv_fixtures::png(rgb, SIZE, SIZE)
}

/// Two pairs of clips, aligned, translated by a made-up model, scored and curated.
fn dataset(dir: &Path) -> PathBuf {
    let root = dir.join("ds");
    let ds = Dataset::open_or_create(&root, meta()).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    let shapes = shapes::training_shapes();
    let (mut eps, mut clips) = (Vec::new(), Vec::new());
    for (i, shape) in shapes.iter().take(2).enumerate() {
        let task = Task::Drawing { shape: shape.clone() };
        let pair = paired_clips(&task, SIZE, 12, 9, &mut rng).unwrap();
        for (domain, r) in [(Domain::Human, &pair.human), (Domain::Robot, &pair.robot)] {
            let id = format!("{domain}_{i}");
            let frames = (0..r.frames.len())
                .map(|k| Frame {
                    image: png(&r.frames[k]),
                    action: Some(r.actions[k].to_vec()),
                    state: Some(r.states[k].to_vec()),
                })
                .collect();
            eps.push((episode(&id, domain, &format!("pair-{i}"), r.frames.len()), frames));
        }
        clips.push(pair);
    }
    commit_episodes(&ds, &eps, meta()).unwrap();
    align_dataset(
        &ds,
        None,
        features::by_name("state").unwrap(),
        &AlignOptions::default(),
        meta(),
        &|| {},
    )
    .unwrap();

    // The "translation": the robot clip's frame, a latent and an action that differ per frame.
    let mut m = meta();
    m.summary = serde_json::json!({"model_id": MODEL, "model_config": {"image_size": SIZE}});
    let translated: Vec<(String, Vec<ImaginedFrame>)> = clips
        .iter()
        .enumerate()
        .map(|(i, pair)| {
            let frames = (0..pair.human.frames.len())
                .map(|k| ImaginedFrame {
                    image: png(&pair.robot.frames[pair.human_to_robot[k]]),
                    latent: Some((
                        (0..4 * 4 * 4)
                            .flat_map(|j| half_bits((j as f32 * 0.37 + k as f32 * 1.1 + i as f32).sin()))
                            .collect(),
                        "f16".into(),
                        vec![4, 4, 4],
                    )),
                    action: Some(vec![0.1 * k as f32 + 0.3, -0.7 * k as f32 / 3.0]),
                })
                .collect();
            (format!("human_{i}"), frames)
        })
        .collect();
    let refs: Vec<(&str, Vec<ImaginedFrame>)> = translated
        .iter()
        .map(|(id, f)| (id.as_str(), f.clone()))
        .collect();
    commit_imagined(&ds, MODEL, &refs, m).unwrap();
    score_and_curate_imagined(&ds, 0.8);
    root
}

/// f32 → IEEE half (round to nearest even), little-endian; independent of milv-data's reader.
fn half_bits(x: f32) -> [u8; 2] {
    let b = x.to_bits();
    let sign = ((b >> 16) & 0x8000) as u16;
    let exp = ((b >> 23) & 0xff) as i32 - 127 + 15;
    let man = b & 0x7f_ffff;
    let h = if exp <= 0 {
        sign // |x| < 2^-14: flush to zero is fine for these test values
    } else {
        let mut h = (exp as u32) << 10 | (man >> 13);
        let rest = man & 0x1fff;
        if rest > 0x1000 || (rest == 0x1000 && h & 1 == 1) {
            h += 1;
        }
        sign | h as u16
    };
    h.to_le_bytes()
}

fn export(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_milv-export"))
        .args(args)
        .output()
        .unwrap()
}

fn ok_json(args: &[&str]) -> serde_json::Value {
    let o = export(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

type Key = (String, i32);
/// Latent bytes, dtype, shape and action of one imagined row.
type Row = (Vec<u8>, String, Vec<i32>, Vec<f32>);

/// (latent bytes, dtype, shape, action) per frame, straight from the imagined table.
fn imagined_table(root: &Path) -> BTreeMap<Key, Row> {
    let ds = Dataset::open(root).unwrap();
    let v = ds.latest_version().unwrap();
    let mut out = BTreeMap::new();
    for b in ds.scan(TableKind::Imagined, v, None).unwrap() {
        let b = b.unwrap();
        let col = |n: &str| b.column_by_name(n).unwrap().clone();
        let (ids, idx) = (col("episode_id"), col("frame_index"));
        let ids = ids.as_any().downcast_ref::<StringArray>().unwrap();
        let idx = idx.as_any().downcast_ref::<Int32Array>().unwrap();
        let (lat, dt, sh, act) = (
            col("latent"),
            col("latent_dtype"),
            col("latent_shape"),
            col("action"),
        );
        let lat = lat.as_any().downcast_ref::<BinaryArray>().unwrap();
        let dt = dt.as_any().downcast_ref::<StringArray>().unwrap();
        let sh = sh.as_any().downcast_ref::<ListArray>().unwrap();
        let act = act.as_any().downcast_ref::<ListArray>().unwrap();
        for i in 0..b.num_rows() {
            let shape = sh
                .value(i)
                .as_any()
                .downcast_ref::<Int32Array>()
                .unwrap()
                .values()
                .to_vec();
            let a = act
                .value(i)
                .as_any()
                .downcast_ref::<Float32Array>()
                .unwrap()
                .values()
                .to_vec();
            out.insert(
                (ids.value(i).to_string(), idx.value(i)),
                (lat.value(i).to_vec(), dt.value(i).to_string(), shape, a),
            );
        }
    }
    out
}

#[test]
fn mcap_round_trips_every_latent_and_action_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let root = dataset(dir.path());
    let out = dir.path().join("all.mcap");
    let rep = ok_json(&[
        "mcap",
        root.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(rep["model_id"], MODEL);
    let rec = Recording::read(&out).unwrap();
    let table = imagined_table(&root);
    let latents: Vec<_> = rec.topic(schema::IMAGINED_LATENT).collect();
    assert_eq!(latents.len(), table.len());
    for m in &latents {
        let t = m.tensor().unwrap();
        let (data, dtype, shape, _) = &table[&(t.episode_id.clone(), t.frame_index)];
        assert_eq!(&t.data, data);
        assert_eq!(&t.dtype, dtype);
        assert_eq!(t.shape, shape.iter().map(|d| *d as u32).collect::<Vec<_>>());
        assert_eq!(t.model_id, MODEL);
    }
    let actions: Vec<_> = rec.topic(schema::IMAGINED_ACTION).collect();
    assert_eq!(actions.len(), table.len());
    for m in actions {
        let j = m.json().unwrap();
        let key = (
            j["episode_id"].as_str().unwrap().to_string(),
            j["frame_index"].as_i64().unwrap() as i32,
        );
        let want = &table[&key].3;
        let got = [j["dx"].as_f64().unwrap() as f32, j["dy"].as_f64().unwrap() as f32];
        assert_eq!(
            got.map(f32::to_bits),
            [want[0].to_bits(), want[1].to_bits()],
            "{key:?}"
        );
    }
    // Every human frame has its aligned robot frame and true action, and quality.
    let n = table.len() as u64;
    for t in [
        schema::HUMAN_IMAGE,
        schema::IMAGINED_IMAGE,
        schema::ROBOT_IMAGE,
        schema::ROBOT_ACTION,
        schema::QUALITY,
    ] {
        assert_eq!(rec.stats[t], n, "{t}");
        assert_eq!(rec.topic(t).count() as u64, n, "{t}");
    }
    let img = rec.topic(schema::ROBOT_IMAGE).next().unwrap().image().unwrap();
    assert_eq!((img.format.as_str(), &img.data[..4]), ("png", &b"\x89PNG"[..]));
    // Episodes end to end: log times never go back.
    let times: Vec<u64> = rec.topic(schema::HUMAN_IMAGE).map(|m| m.log_time).collect();
    assert!(times.windows(2).all(|w| w[0] < w[1]));
    let q = rec.topic(schema::QUALITY).next().unwrap().json().unwrap();
    assert!(q["beta"].is_number() && q["weight"].is_number());
    let milv = rec.metadata("milv").unwrap();
    assert_eq!(milv["model_id"], MODEL);
    assert_eq!(milv["dataset_version"], rep["version"].to_string());
    assert_eq!(rec.metadata.iter().filter(|(n, _)| n == "episode").count(), 2);
    assert_eq!(rec.attachments[0].0, "model_config.json");

    // One file per episode, each with its own timestamps.
    let per = dir.path().join("per");
    let rep = ok_json(&[
        "mcap",
        root.to_str().unwrap(),
        "--per-episode",
        "-o",
        per.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(rep["files"].as_array().unwrap().len(), 2);
    let one = Recording::read(&per.join("human_1.mcap")).unwrap();
    assert_eq!(one.topic(schema::HUMAN_IMAGE).next().unwrap().log_time, 0);

    // Worst β first in the rerun export; a robot episode on its own gets its own frames.
    let rrd = dir.path().join("all.rrd");
    let rep = ok_json(&[
        "rerun",
        root.to_str().unwrap(),
        "--sort",
        "beta",
        "-o",
        rrd.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(rep["logged"]["frames"].as_u64().unwrap(), n);
    assert!(std::fs::metadata(&rrd).unwrap().len() > 0);
    let robot = dir.path().join("robot.mcap");
    ok_json(&[
        "mcap",
        root.to_str().unwrap(),
        "--episodes",
        "robot_0",
        "-o",
        robot.to_str().unwrap(),
        "--json",
    ]);
    let r = Recording::read(&robot).unwrap();
    assert_eq!(r.stats[schema::ROBOT_ACTION], r.stats[schema::ROBOT_IMAGE]);
    assert_eq!(r.stats[schema::HUMAN_IMAGE], 0);
}

#[test]
fn bad_selections_fail_clearly_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let root = dataset(dir.path());
    let r = root.to_str().unwrap();
    let out = dir.path().join("x.mcap");
    let o = out.to_str().unwrap();
    let missing_dir = dir.path().join("no/such/dir/x.mcap");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["mcap", r, "--model-id", "acg-nope", "-o", o],
            "model acg-nope has no rows",
        ),
        (vec!["mcap", r, "--episodes", "nope", "-o", o], "no episode nope"),
        (
            vec!["mcap", r, "--episodes", "robot_0,human_9", "-o", o],
            "no episode human_9",
        ),
        (
            vec!["mcap", r, "-o", missing_dir.to_str().unwrap()],
            "no/such/dir",
        ),
        (vec!["rerun", r, "--model-id", "acg-nope", "-o", o], "acg-nope"),
    ];
    for (args, needle) in cases {
        let p = export(&args);
        let err = String::from_utf8_lossy(&p.stderr);
        assert_eq!(p.status.code(), Some(1), "{args:?}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        !out.exists() && left.iter().all(|n| !n.to_string_lossy().ends_with(".tmp")),
        "{left:?}"
    );
}

#[test]
fn a_human_episode_without_imagined_rows_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let root = dataset(dir.path());
    // A third human episode the model never translated.
    let ds = Dataset::open(&root).unwrap();
    let mut txn = ds.begin(meta()).unwrap();
    txn.add_episode_rows(&[episode("human_new", Domain::Human, "pair-9", 3)])
        .unwrap();
    txn.commit().unwrap();
    let out = dir.path().join("x.mcap");
    let p = export(&[
        "mcap",
        root.to_str().unwrap(),
        "--episodes",
        "human_new",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&p.stderr).contains("episode human_new has no imagined rows"));
    assert!(!out.exists());
}

#[test]
fn a_latent_that_does_not_match_its_shape_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let root = dataset(dir.path());
    let ds = Dataset::open(&root).unwrap();
    let img = png(&vec![0; (SIZE * SIZE * 3) as usize]);
    let bad = ImaginedFrame {
        image: img,
        // 63 values where the shape says 64.
        latent: Some((vec![0u8; 126], "f16".into(), vec![4, 4, 4])),
        action: Some(vec![0.0, 0.0]),
    };
    commit_imagined(&ds, "acg-bad", &[("human_0", vec![bad.clone(), bad])], meta()).unwrap();
    for cmd in ["mcap", "rerun"] {
        let out = dir.path().join(format!("x.{cmd}"));
        let p = export(&[
            cmd,
            root.to_str().unwrap(),
            "--model-id",
            "acg-bad",
            "-o",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&p.stderr);
        assert_eq!(p.status.code(), Some(1), "{cmd}: {err}");
        assert!(
            err.contains(
                "episode human_0 frame 0: latent of shape [4, 4, 4] (f16) has 126 bytes, expected 128"
            ),
            "{err}"
        );
        assert!(!out.exists());
    }
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        left.iter().all(|n| !n.to_string_lossy().ends_with(".tmp")),
        "{left:?}"
    );
}
