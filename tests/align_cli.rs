//! `milv-align` on simulated pairs with a known time warp, and on broken pairs.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;

fn align_bin() -> &'static str {
    env!("CARGO_BIN_EXE_milv-align")
}

fn align_json(args: &[&str]) -> (i32, serde_json::Value, String) {
    run_json(align_bin(), args)
}

#[test]
fn simulated_pairs_align_within_the_goals() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let ds_s = path_str(&ds);
    let mut rows = 0;
    for (task, seed) in [("drawing", "7"), ("pushing", "11")] {
        let sim = dir.path().join(task);
        let r = run(
            env!("CARGO_BIN_EXE_milv-sim"),
            &[
                "gen",
                "--task",
                task,
                "--episodes",
                "8",
                "--seed",
                seed,
                "--out",
                path_str(&sim),
            ],
        );
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let manifest = sim.join("manifest.jsonl");
        let (code, _) = ingest(&[ds_s, "--manifest", path_str(&manifest)]);
        assert_eq!(code, 0);
        let truth = sim.join("warps.jsonl");
        let pairs: Vec<String> = (0..8).map(|k| format!("{task}-{seed}-{k:04}")).collect();
        let pairs = pairs.join(",");
        // `auto` is the default: run it without naming features. `--temperature 0` decodes
        // the best path instead of the posterior medians: a run of its own.
        for (features, temperature, goal) in [
            ("state", None, 1.0),
            ("motion", None, 2.0),
            ("motion", Some("0"), 2.0),
            ("auto", None, 2.0),
        ] {
            let mut args = vec![ds_s, "--pairs", &pairs, "--truth", path_str(&truth)];
            if features != "auto" {
                args.extend(["--features", features]);
            }
            if let Some(t) = temperature {
                args.extend(["--temperature", t]);
            }
            let (code, rep, err) = align_json(&args);
            assert_eq!(code, 0, "{err}");
            assert_eq!(rep["features"], features);
            assert_eq!(rep["already_aligned"], 0, "{task} {features} {temperature:?}");
            let pairs = rep["pairs"].as_array().unwrap();
            assert_eq!(pairs.len(), 8);
            let mean = rep["mean_frame_error"].as_f64().unwrap();
            assert!(
                mean <= goal,
                "{task} {features}: mean frame error {mean} > {goal}"
            );
            for p in pairs {
                let kind = p["features"].as_str().unwrap();
                let allowed: &[&str] = if features == "auto" {
                    &["motion", "motion-hand", "track"]
                } else {
                    &[features]
                };
                assert!(allowed.contains(&kind), "{task} {features}: {p}");
                // Paths run from (0, 0) to the last frames, one row per aligned cell.
                assert!(p["path_length"].as_u64().unwrap() >= p["human_frames"].as_u64().unwrap());
                assert!(p["trusted"].as_bool().unwrap(), "{task} {features}: {p}");
                // Off by default: no pair takes the proportional warp.
                assert_eq!(p["proportional"], false, "{task} {features}: {p}");
            }
            rows += rep["rows"].as_u64().unwrap();
        }
        // Where the posterior cannot tell the decoded warp from the proportional one, that
        // is taken, and its error is the proportional warp's (a run of its own).
        let args = [
            ds_s,
            "--pairs",
            &pairs,
            "--truth",
            path_str(&truth),
            "--features",
            "motion",
            "--proportional-within",
            "1.3",
        ];
        let (code, rep, err) = align_json(&args);
        assert_eq!(code, 0, "{err}");
        assert_eq!(rep["already_aligned"], 0, "{task}");
        let pairs = rep["pairs"].as_array().unwrap();
        for p in pairs {
            assert!(p["posterior_sd"].as_f64().unwrap() > 0.0, "{task}: {p}");
            if p["proportional"].as_bool().unwrap() {
                assert_eq!(p["mean_frame_error"], p["proportional_mean_error"], "{task}: {p}");
            }
        }
        let taken = pairs.iter().filter(|p| p["proportional"] == true).count();
        assert!(
            taken > 0 && taken < pairs.len(),
            "{task}: {taken} of {} took it",
            pairs.len()
        );
        rows += rep["rows"].as_u64().unwrap();
    }
    let info = ds_json(&["info", ds_s]);
    assert_eq!(info["tables"]["alignments"]["rows"].as_u64().unwrap(), rows);
    assert_eq!(
        ds_json(&["verify", ds_s])["problems"].as_array().unwrap().len(),
        0
    );

    let png = dir.path().join("cost.png");
    let out = run(
        align_bin(),
        &[
            "show",
            ds_s,
            "drawing-7-0000",
            "-o",
            path_str(&png),
            "--features",
            "state",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::open(&png).unwrap();
    assert!(img.width() > 200 && img.height() > 200);

    // No imagined table yet: translated features say what is missing.
    let (code, _, err) = align_json(&[ds_s, "--features", "translated"]);
    assert_eq!(code, 1);
    assert!(err.contains("milv-train translate"), "{err}");

    // A temperature below 0 is refused by name before anything is read.
    let (code, _, err) = align_json(&[ds_s, "--temperature=-1"]);
    assert_ne!(code, 0);
    assert!(err.contains("--temperature -1"), "{err}");
    let (code, _, err) = align_json(&[ds_s, "--proportional-within=-1"]);
    assert_ne!(code, 0);
    assert!(err.contains("--proportional-within -1"), "{err}");
}

#[test]
fn broken_pairs_fail_one_by_one_and_the_others_align() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir(&src).unwrap();
    let mut clips = Vec::new();
    let mut add = |name: &str, frames: u32, domain: &str, pair: &str, seed: u32| {
        let clip = src.join(name);
        make_clip(&clip, frames, 48, 40, seed);
        write_sidecar(
            &clip.with_extension("json"),
            frames as usize,
            domain,
            serde_json::json!({"pair_id": pair, "kind": "paired"}),
        );
        clips.push(clip);
    };
    add("good_h.mp4", 10, "human", "good", 1);
    add("good_r.mp4", 12, "robot", "good", 2);
    add("alone_h.mp4", 8, "human", "alone", 3);
    add("three_a.mp4", 8, "human", "three", 4);
    add("three_b.mp4", 8, "robot", "three", 5);
    add("three_c.mp4", 9, "robot", "three", 6);
    add("same_a.mp4", 8, "robot", "same", 7);
    add("same_b.mp4", 9, "robot", "same", 8);
    add("one_h.mp4", 1, "human", "one", 9);
    add("one_r.mp4", 8, "robot", "one", 10);
    let ds = dir.path().join("ds");
    let mut args = vec![path_str(&ds)];
    args.extend(clips.iter().map(|c| path_str(c)));
    let (code, _) = ingest(&args);
    assert_eq!(code, 0);
    let (code, rep, err) = align_json(&[path_str(&ds), "--features", "motion"]);
    assert_eq!(code, 3, "{err}");
    let pairs: Vec<&str> = rep["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["pair_id"].as_str().unwrap())
        .collect();
    assert_eq!(pairs, ["good"]);
    let failed: std::collections::BTreeMap<String, String> = rep["failed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["pair_id"].as_str().unwrap().to_string(),
                f["message"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    assert!(failed["alone"].contains("robot episode is missing"), "{failed:?}");
    assert!(
        failed["three"].contains("3 episodes share this pair id"),
        "{failed:?}"
    );
    assert!(failed["same"].contains("both episodes are robot"), "{failed:?}");
    assert!(failed["one"].contains("1 frame(s)"), "{failed:?}");
    assert!(err.contains("pair alone:"), "{err}");
    assert_eq!(
        ds_json(&["info", path_str(&ds)])["tables"]["alignments"]["rows"],
        rep["rows"]
    );
}
