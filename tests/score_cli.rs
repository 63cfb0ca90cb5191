//! `milv-score frames` on a folder of frames reproduces the golden references.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;

fn score_bin() -> &'static str {
    env!("CARGO_BIN_EXE_milv-score")
}

#[test]
fn frames_scores_match_the_golden_values_and_bad_clips_fail_clearly() {
    let golden_dir = repo().join("crates/milv-quality/tests/golden");
    let golden: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(golden_dir.join("golden.json")).unwrap()).unwrap();
    let case = golden["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "astronaut_64")
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("clip");
    std::fs::create_dir(&clip).unwrap();
    std::fs::copy(golden_dir.join("astronaut_64_a.png"), clip.join("frame_0.png")).unwrap();
    std::fs::copy(golden_dir.join("astronaut_64_b.png"), clip.join("frame_1.png")).unwrap();
    let out = run(score_bin(), &["frames", path_str(&clip), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 2);
    let want_ssim = case["ssim_gray"].as_f64().unwrap();
    for r in &rows {
        assert!((r["ssim"].as_f64().unwrap() - want_ssim).abs() < 1e-6, "{r}");
        assert!((r["ssim_rgb"].as_f64().unwrap() - case["ssim_rgb"].as_f64().unwrap()).abs() < 1e-6);
    }
    let b0 = rows[0]["brenner"].as_f64().unwrap();
    assert!((b0 - case["brenner_a"]["normalized"].as_f64().unwrap()).abs() < 1e-6);
    let beta = rows[0]["beta"].as_f64().unwrap();
    assert!((beta - b0 * (want_ssim + 1.0) / 2.0).abs() < 1e-12);

    // A one-frame clip cannot be scored; the message names it, and the exit code says so.
    let one = dir.path().join("one");
    std::fs::create_dir(&one).unwrap();
    std::fs::copy(golden_dir.join("constant_a.png"), one.join("0.png")).unwrap();
    let out = run(
        score_bin(),
        &["frames", path_str(&one), path_str(&clip), "--json"],
    );
    assert_eq!(out.status.code(), Some(3));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("at least 2") && err.contains("one"), "{err}");
}

fn score_json(args: &[&str]) -> (i32, serde_json::Value, String) {
    run_json(score_bin(), args)
}

#[test]
fn run_curate_report_on_an_ingested_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir(&src).unwrap();
    let clips = [
        clip_with_sidecar(&src, "h1.mp4", 8, "human", 1),
        clip_with_sidecar(&src, "r1.mp4", 9, "robot", 2),
        clip_with_sidecar(&src, "one.mp4", 1, "robot", 3),
    ];
    let ds = dir.path().join("ds");
    let mut args = vec![path_str(&ds)];
    args.extend(clips.iter().map(|c| path_str(c)));
    let (code, _) = ingest(&args);
    assert_eq!(code, 0);
    let ds_s = path_str(&ds);

    // The one-frame episode fails the run: clear message, no new version.
    let (code, _, err) = score_json(&["run", ds_s]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("1 frame(s): a clip needs at least 2"), "{err}");
    assert_eq!(ds_json(&["info", ds_s])["latest_version"], 1);

    // --skip-bad commits the rest and exits 3.
    let (code, rep, err) = score_json(&["run", ds_s, "--skip-bad", "--jobs", "2"]);
    assert_eq!(code, 3, "{err}");
    assert_eq!(rep["frames_scored"], 17);
    assert_eq!(rep["failed"].as_array().unwrap().len(), 1);
    let run_id = rep["run_id"].as_str().unwrap().to_string();

    // Only the human domain is a different run.
    let (code, rep, _) = score_json(&["run", ds_s, "--domain", "human"]);
    assert_eq!(code, 0);
    assert_eq!(rep["frames_scored"], 8);

    let (code, cur, err) = score_json(&[
        "curate",
        ds_s,
        "--top-fraction",
        "0.5",
        "--min-episode-fraction",
        "0",
        "--run",
        &run_id,
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(cur["frames_kept"], 9);
    let (code, _, err) = score_json(&["curate", &format!("{ds_s}@2"), "--min-weight", "0.1"]);
    assert_eq!(code, 1);
    assert!(err.contains("drop the @N"), "{err}");

    let plots = dir.path().join("plots");
    let (code, rep, err) = score_json(&[
        "report",
        ds_s,
        "--run",
        &run_id,
        "--worst",
        "2",
        "--out",
        path_str(&plots),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(rep["frames"], 17);
    assert_eq!(rep["episodes_total"], 2);
    assert_eq!(rep["worst_frames"].as_array().unwrap().len(), 2);
    for p in rep["plots"].as_array().unwrap() {
        let img = image::open(p.as_str().unwrap()).unwrap();
        assert!(img.width() > 100 && img.height() > 100);
    }
    assert_eq!(rep["plots"].as_array().unwrap().len(), 2);

    // Tables that pyarrow/polars would read: the scores and curated tables are listed.
    let info = ds_json(&["info", ds_s]);
    assert_eq!(info["tables"]["scores"]["rows"], 25);
    assert_eq!(info["tables"]["curated"]["rows"], 9);
    assert_eq!(
        ds_json(&["verify", ds_s])["problems"].as_array().unwrap().len(),
        0
    );
}
