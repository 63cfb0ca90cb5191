//! `milv-sim gen` output ingests cleanly; generation is deterministic by seed.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;

fn sim_bin() -> &'static str {
    env!("CARGO_BIN_EXE_milv-sim")
}

#[test]
fn generated_episodes_ingest_cleanly_and_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gen");
    let args = [
        "gen",
        "--episodes",
        "2",
        "--seed",
        "3",
        "--size",
        "64",
        "--out",
        path_str(&out),
        "--json",
    ];
    let r = run(sim_bin(), &args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let report = stdout_json(&r);
    let eps = report["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 10);
    // Human demos come from the expert: they succeed.
    assert!(
        eps.iter()
            .filter(|e| e["path"].as_str().unwrap().contains("_human_"))
            .all(|e| e["success"] == true)
    );

    let ds = dir.path().join("ds");
    let (code, ing) = ingest(&[
        path_str(&ds),
        "--manifest",
        path_str(&out.join("manifest.jsonl")),
        "--require-actions",
    ]);
    assert_eq!(code, 0, "{ing}");
    let paired_robot_frames: u64 = std::fs::read_to_string(out.join("warps.jsonl"))
        .unwrap()
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["robot_frames"]
                .as_u64()
                .unwrap()
        })
        .sum();
    assert_eq!(ing["frames"].as_u64().unwrap(), 8 * 51 + paired_robot_frames);
    // instances.jsonl: one row per instance, the task itself (what `eval --instances` runs),
    // naming its robot demo.
    let inst: Vec<serde_json::Value> = std::fs::read_to_string(out.join("instances.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(inst.len(), 2);
    for (i, row) in inst.iter().enumerate() {
        assert_eq!(row["index"], i);
        assert_eq!(row["task"]["family"], "drawing");
        assert!(
            row["task"]["shape"]["path"].as_array().unwrap().len() > 2,
            "{row}"
        );
        let robot = row["robot"].as_str().unwrap();
        assert!(out.join(robot).exists(), "{robot}");
    }
    let info = ds_json(&["info", path_str(&ds)]);
    assert_eq!(info["by_domain_kind"]["human/demo"], 2);
    assert_eq!(info["by_domain_kind"]["robot/random"], 2);
    assert_eq!(info["by_domain_kind"]["robot/demo"], 2);
    assert_eq!(info["by_domain_kind"]["human/paired"], 2);
    assert_eq!(info["by_domain_kind"]["robot/paired"], 2);
    assert!(
        ds_json(&["verify", path_str(&ds)])["problems"]
            .as_array()
            .unwrap()
            .is_empty()
    );

    let again = dir.path().join("gen2");
    let args2 = [
        "gen",
        "--episodes",
        "2",
        "--seed",
        "3",
        "--size",
        "64",
        "--out",
        path_str(&again),
    ];
    assert!(run(sim_bin(), &args2).status.success());
    for name in [
        "drawing_human_demo_0000.json",
        "drawing_robot_random_0001.json",
        "manifest.jsonl",
    ] {
        assert_eq!(
            std::fs::read(out.join(name)).unwrap(),
            std::fs::read(again.join(name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn eval_expert_bounds() {
    let r = run(
        sim_bin(),
        &["eval-expert", "--split", "train", "--trials", "2", "--json"],
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let rows = stdout_json(&r);
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 11);
    let expert = rows.iter().filter(|r| r["expert_success"] == true).count();
    let random: u64 = rows.iter().map(|r| r["random_success"].as_u64().unwrap()).sum();
    assert!(expert >= 11 * 95 / 100, "{expert}");
    assert!(random <= 2, "{random}");
}

/// Pushing adds the blind baseline (both objects' experts averaged): it never lands the
/// target, which is why behaviour cloning without the demo cannot be judged by success.
#[test]
fn eval_expert_pushing_reports_the_blind_baseline() {
    let r = run(
        sim_bin(),
        &[
            "eval-expert",
            "--task",
            "pushing",
            "--split",
            "train",
            "--trials",
            "1",
            "--json",
        ],
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let rows = stdout_json(&r);
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 16);
    let expert = rows.iter().filter(|r| r["expert_success"] == true).count();
    let blind = rows.iter().filter(|r| r["blind_success"] == true).count();
    assert!(rows.iter().all(|r| r["blind_moved_distractor"].is_boolean()));
    assert!(expert >= 15, "{expert}");
    assert!(blind <= 2, "{blind}");
}

#[test]
fn pushing_episodes_generate_and_ingest() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("push");
    let args = [
        "gen",
        "--task",
        "pushing",
        "--split",
        "test",
        "--episodes",
        "2",
        "--size",
        "48",
        "--out",
        path_str(&out),
        "--json",
    ];
    let r = run(sim_bin(), &args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let report = stdout_json(&r);
    let eps = report["episodes"].as_array().unwrap();
    assert!(
        eps.iter()
            .filter(|e| e["path"].as_str().unwrap().contains("_human_"))
            .all(|e| e["success"] == true)
    );
    let ds = dir.path().join("ds");
    let (code, ing) = ingest(&[path_str(&ds), "--manifest", path_str(&out.join("manifest.jsonl"))]);
    assert_eq!(code, 0, "{ing}");
    let info = ds_json(&["info", path_str(&ds)]);
    assert_eq!(info["episodes"], 10);
    assert!(
        info["by_task"]
            .as_object()
            .unwrap()
            .keys()
            .all(|k| k.starts_with("push/"))
    );
}
