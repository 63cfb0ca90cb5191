//! `milv-train` end to end on a small simulated dataset: train, resume, translate,
//! evaluate, and the errors users meet.
#![allow(clippy::unwrap_used)]

mod common;

use common::{json, run, s};

use std::path::Path;

use milv_data::{Dataset, ImaginedRecord, TableKind};

/// `cyclegan DATASET --out RUN` with tiny networks and the default step count.
fn fresh_run<'a>(ds: &'a Path, run: &'a Path) -> Vec<&'a str> {
    vec!["cyclegan", s(ds), "--out", s(run), "--tiny", "--size", "32"]
}

const TINY: [&str; 6] = ["--tiny", "--size", "32", "--threads", "1", "--json"];

#[test]
fn trains_resumes_translates_and_evaluates() {
    let dir = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset(dir.path(), 3, true);
    let runs = dir.path().join("run");
    let mut args = vec![
        "cyclegan",
        s(&fx.root),
        "--out",
        s(&runs),
        "--steps",
        "6",
        "--grid-every",
        "3",
    ];
    args.extend([
        "--checkpoint-every",
        "3",
        "--eval-every",
        "3",
        "--truth",
        s(&fx.truth),
        "--idm-slope",
        "0.2",
    ]);
    args.extend(TINY);
    let rep = json(&args);
    assert_eq!(rep["step"], 6);
    // π_I's activation is part of the model: stored with every checkpoint.
    let meta: serde_json::Value = serde_json::from_slice(
        &std::fs::read(runs.join("checkpoints/step-00000006/checkpoint.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(meta["model"]["idm_slope"], 0.2);
    let lines = std::fs::read_to_string(runs.join("losses.jsonl")).unwrap();
    assert_eq!(lines.lines().count(), 6);
    let first: serde_json::Value = serde_json::from_str(lines.lines().next().unwrap()).unwrap();
    for k in ["gan_g", "cycle", "aux", "idm", "d_x", "step_ms", "wait_ms"] {
        assert!(first[k].as_f64().unwrap().is_finite(), "{k}: {first}");
    }
    // The auxiliary loss saw aligned pairs.
    assert!(first["aux"].as_f64().unwrap() > 0.0);
    let grid = image::open(runs.join("grids/step-00000006.png")).unwrap();
    assert_eq!((grid.width(), grid.height()), (3 * 32, 3 * 32));
    let eval = &rep["eval"];
    assert!(eval["ssim"].as_f64().unwrap().abs() <= 1.0, "{eval}");
    assert_eq!(eval["ssim_episodes"], 3);
    assert!(eval["action_mae"].as_f64().unwrap() >= 0.0);
    assert_eq!(
        std::fs::read_to_string(runs.join("eval.jsonl"))
            .unwrap()
            .lines()
            .count(),
        2
    );

    // Resume: continues at step 6 and appends.
    let mut more = vec![
        "cyclegan",
        s(&fx.root),
        "--out",
        s(&runs),
        "--steps",
        "8",
        "--resume",
    ];
    more.extend(TINY);
    assert_eq!(json(&more)["steps_run"], 2);
    assert_eq!(
        std::fs::read_to_string(runs.join("losses.jsonl"))
            .unwrap()
            .lines()
            .count(),
        8
    );
    // Without --resume an existing run is not overwritten.
    let (code, _, err) = run(&fresh_run(&fx.root, &runs));
    assert_eq!(code, 1);
    assert!(err.contains("--resume"), "{err}");

    let ckpt = runs.join("checkpoints/step-00000008");
    let tr = json(&[
        "translate",
        s(&fx.root),
        "--checkpoint",
        s(&ckpt),
        "--chunk",
        "5",
        "--json",
    ]);
    assert_eq!(tr["frames"].as_u64().unwrap() as usize, fx.human_frames);
    let model = tr["model_id"].as_str().unwrap().to_string();
    // A second run is a no-op.
    let again = json(&["translate", s(&fx.root), "--checkpoint", s(&ckpt), "--json"]);
    assert_eq!(
        (again["episodes"].as_u64(), again["version"].clone()),
        (Some(0), tr["version"].clone())
    );

    // Every latent decodes to the recorded dtype and shape; every frame has an action.
    let ds = Dataset::open(&fx.root).unwrap();
    let v = ds.latest_version().unwrap();
    let rows = milv_data::read::rows::<ImaginedRecord>(&ds, v).unwrap();
    for r in &rows {
        assert_eq!(r.model_id, model);
        let lat = r.latent.as_ref().unwrap();
        assert_eq!(lat.dtype, "f16");
        assert_eq!(lat.shape, vec![8, 8, 8]);
        assert_eq!(lat.data.len(), 8 * 8 * 8 * 2);
        assert_eq!(r.action.as_ref().unwrap().len(), 2);
    }
    let rows = rows.len();
    assert_eq!(rows, fx.human_frames);

    let ev = json(&[
        "eval-translation",
        s(&fx.root),
        "--checkpoint",
        s(&ckpt),
        "--truth",
        s(&fx.truth),
        "--json",
    ]);
    assert_eq!(ev["step"], 8);
    assert!(ev["ssim_frames"].as_u64().unwrap() > 0);
    assert!(ev["action_mae_zero"].as_f64().unwrap() > 0.0);
    // π_I on the ground-truth robot demos and on the translated human demos, both against
    // the true robot actions of every transition of the compared pairs.
    let pairs = ev["ssim_episodes"].as_u64().unwrap();
    for key in ["robot_demo_fit", "translated_fit"] {
        let fit = &ev[key];
        assert_eq!(
            fit["frames"].as_u64().unwrap(),
            ev["ssim_frames"].as_u64().unwrap() - pairs,
            "{key}: {fit}"
        );
        assert_eq!(fit["corr"].as_array().unwrap().len(), 2, "{key}: {fit}");
        assert!(fit["std_true"][0].as_f64().unwrap() > 0.0, "{key}: {fit}");
        assert!(fit["mae_zero"].as_f64().unwrap() > 0.0, "{key}: {fit}");
    }
}

#[test]
fn corrupt_checkpoints_and_missing_random_videos_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let no_random = common::sim_dataset(dir.path(), 2, false);
    let runs = dir.path().join("run");
    let (code, _, err) = run(&fresh_run(&no_random.root, &runs));
    assert_eq!(code, 1);
    assert!(err.contains("no robot random videos"), "{err}");

    let other = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset(other.path(), 2, true);
    let mut bad = fresh_run(&fx.root, &runs);
    bad.extend(["--idm-slope", "1.5"]);
    let (code, _, err) = run(&bad);
    assert_ne!(code, 0);
    assert!(err.contains("slope 1.5"), "{err}");
    let mut args = vec!["cyclegan", s(&fx.root), "--out", s(&runs), "--steps", "2"];
    args.extend(TINY);
    json(&args);
    let ckpt = runs.join("checkpoints/step-00000002");
    let g = ckpt.join("G.safetensors");
    let bytes = std::fs::read(&g).unwrap();
    std::fs::write(&g, &bytes[..bytes.len() / 2]).unwrap();
    let (code, _, err) = run(&["translate", s(&fx.root), "--checkpoint", s(&ckpt)]);
    assert_eq!(code, 1);
    assert!(err.contains("corrupt") && err.contains("step-00000002"), "{err}");
    // Nothing was committed.
    let ds = Dataset::open(&fx.root).unwrap();
    assert!(
        ds.files(TableKind::Imagined, ds.latest_version().unwrap())
            .unwrap()
            .is_empty()
    );
    let (code, _, err) = run(&[
        "translate",
        s(&fx.root),
        "--checkpoint",
        s(&dir.path().join("nope")),
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("checkpoint.json"), "{err}");
}

/// π_I predicts as many values as the robot's actions have (3 here, where milv-sim has
/// Δx, Δy); robot videos that disagree are refused by name.
#[test]
fn the_action_width_comes_from_the_robot_videos() {
    let dir = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset_with_actions(dir.path(), 2, true, &|_| 1);
    let runs = dir.path().join("run");
    let mut args = vec!["cyclegan", s(&fx.root), "--out", s(&runs), "--steps", "2"];
    args.extend(TINY);
    assert_eq!(json(&args)["step"], 2);
    let meta: serde_json::Value = serde_json::from_slice(
        &std::fs::read(runs.join("checkpoints/step-00000002/checkpoint.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(meta["model"]["action_dim"], 3);

    let dir = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset_with_actions(dir.path(), 2, true, &|name| {
        usize::from(name == "robot_random_1_train")
    });
    let runs = dir.path().join("run");
    let mut args = vec!["cyclegan", s(&fx.root), "--out", s(&runs), "--steps", "2"];
    args.extend(TINY);
    let (code, _, err) = run(&args);
    assert_ne!(code, 0);
    assert!(err.contains("action values where the others have"), "{err}");
}
