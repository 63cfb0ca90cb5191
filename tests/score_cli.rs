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
