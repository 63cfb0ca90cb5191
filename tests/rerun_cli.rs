//! Re-running a pipeline script after a failure must change nothing: every stage that
//! commits (ingest, align, score, curate) is run twice on the same inputs through the
//! real binaries, and the second run commits no version and adds no row.
//! (`milv-train translate` twice: `crates/milv-train/tests/train_cli.rs`.)
#![allow(clippy::unwrap_used)]

mod common;

use common::*;

fn tables(ds: &str) -> serde_json::Value {
    ds_json(&["info", ds])["tables"].clone()
}

fn ok(bin: &str, args: &[&str]) -> serde_json::Value {
    let (code, rep, err) = run_json(bin, args);
    assert_eq!(code, 0, "{bin} {args:?}: {err}");
    rep
}

#[test]
fn every_stage_run_twice_is_a_no_op() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    let r = run(
        env!("CARGO_BIN_EXE_milv-sim"),
        &[
            "gen",
            "--episodes",
            "3",
            "--seed",
            "5",
            "--size",
            "48",
            "--out",
            path_str(&sim),
        ],
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let ds = dir.path().join("ds");
    let ds_s = path_str(&ds);
    let manifest = sim.join("manifest.jsonl");
    let (align, score) = (env!("CARGO_BIN_EXE_milv-align"), env!("CARGO_BIN_EXE_milv-score"));
    let stages: Vec<(&str, Vec<&str>)> = vec![
        (ingest_bin(), vec![ds_s, "--manifest", path_str(&manifest)]),
        (align, vec![ds_s, "--features", "state"]),
        (align, vec![ds_s, "--features", "motion"]),
        (score, vec!["run", ds_s]),
        (score, vec!["curate", ds_s, "--top-fraction", "0.8"]),
    ];
    for (bin, args) in &stages {
        let first = ok(bin, args);
        let (before, tables_before) = (ds_json(&["info", ds_s])["version"].clone(), tables(ds_s));
        let again = ok(bin, args);
        assert_eq!(again["version"], first["version"], "{args:?}: {again}");
        assert_eq!(
            ds_json(&["info", ds_s])["version"],
            before,
            "{args:?} committed again"
        );
        assert_eq!(tables(ds_s), tables_before, "{args:?} added rows");
    }
    // What each second run reported.
    let again = ok(align, &[ds_s, "--features", "state"]);
    assert_eq!(
        (again["already_aligned"].as_u64(), again["rows"].as_u64()),
        (Some(3), Some(0))
    );
    let again = ok(score, &["curate", ds_s, "--top-fraction", "0.8"]);
    assert_eq!(again["unchanged"], true);
    let verify = ds_json(&["verify", ds_s]);
    assert_eq!(verify["problems"].as_array().unwrap().len(), 0, "{verify}");
    assert_eq!(verify["duplicates"].as_array().unwrap().len(), 0, "{verify}");
}
