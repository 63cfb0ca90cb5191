//! Crash safety and concurrency of `milv-ingest`: SIGKILL mid-batch leaves the dataset at
//! its last good version, a re-run completes the batch without duplicates, and two
//! processes ingesting into one dataset at once both land everything.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;

fn manifest(dir: &Path, name: &str, clips: &[std::path::PathBuf]) -> std::path::PathBuf {
    let m = dir.join(name);
    let lines: Vec<String> = clips
        .iter()
        .map(|c| serde_json::json!({"path": c.to_str().unwrap()}).to_string())
        .collect();
    std::fs::write(&m, lines.join("\n")).unwrap();
    m
}

fn clips(dir: &Path, prefix: &str, n: u32, frames: u32) -> Vec<std::path::PathBuf> {
    (0..n)
        .map(|i| {
            let c = dir.join(format!("{prefix}{i:03}.mp4"));
            make_clip(&c, frames, 64, 48, i + 100 * prefix.len() as u32);
            write_sidecar(
                &c.with_extension("json"),
                frames as usize,
                "robot",
                serde_json::json!({"kind": "random"}),
            );
            c
        })
        .collect()
}

fn parquet_count(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "parquet"))
            })
            .count()
        })
        .unwrap_or(0)
}

#[test]
fn sigkill_mid_batch_keeps_the_last_good_version_and_rerun_completes() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let ds_s = path_str(&ds);
    let first = clips(dir.path(), "a", 2, 10);
    let (code, r) = ingest(&[ds_s, path_str(&first[0]), path_str(&first[1])]);
    assert_eq!((code, r["version"].as_u64()), (0, Some(1)), "{r}");

    // A batch large enough to be killed in the middle: many clips, small shards so files
    // appear on disk while it runs.
    let batch = clips(dir.path(), "b", 24, 40);
    let m = manifest(dir.path(), "batch.jsonl", &batch);
    let args = [
        ds_s,
        "--manifest",
        path_str(&m),
        "--jobs",
        "1",
        "--shard-mb",
        "0",
        "--frame-encoding",
        "png",
    ];
    let frames_dir = ds.join("frames");
    let committed = parquet_count(&frames_dir);
    let mut child = Command::new(ingest_bin())
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    // Three new shards exist, so the first (episode 0) is closed and journaled: mid-batch.
    while parquet_count(&frames_dir) < committed + 3 && t0.elapsed() < Duration::from_secs(60) {
        assert!(
            child.try_wait().unwrap().is_none(),
            "ingest finished before it could be killed"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();

    let info = ds_json(&["info", ds_s]);
    assert_eq!(info["version"], 1, "{info}");
    assert_eq!(info["episodes"], 2);
    let v = ds_json(&["verify", ds_s]);
    assert!(v["problems"].as_array().unwrap().is_empty(), "{v}");
    assert!(parquet_count(&frames_dir) > 1, "the killed run left orphan files");

    let (code, r) = ingest(&args);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["version"], 2);
    assert_eq!(r["ingested"].as_array().unwrap().len(), 24);
    // Shards the killed run had finished were journaled and are reused, not decoded again.
    assert!(r["resumed"].as_u64().unwrap() >= 1, "{r}");
    assert!(
        std::fs::read_dir(ds.join("_milv/staging"))
            .unwrap()
            .next()
            .is_none(),
        "journal removed"
    );
    let info = ds_json(&["info", ds_s]);
    assert_eq!(info["episodes"], 26);
    assert_eq!(info["frames"], 2 * 10 + 24 * 40);
    let v = ds_json(&["verify", ds_s]);
    assert!(v["problems"].as_array().unwrap().is_empty(), "{v}");

    // The killed run's files are garbage only vacuum sees; it removes them.
    let vac = ds_json(&["vacuum", ds_s, "--retain-hours", "0"]);
    assert!(!vac["deleted"].as_array().unwrap().is_empty(), "{vac}");
    let v = ds_json(&["verify", ds_s]);
    assert!(v["problems"].as_array().unwrap().is_empty(), "{v}");
    assert_eq!(v["frames_decoded"], 2 * 10 + 24 * 40);
}

#[test]
fn two_processes_ingesting_at_once_both_land() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let ds_s = path_str(&ds);
    let x = clips(dir.path(), "x", 8, 10);
    let y = clips(dir.path(), "yy", 8, 10);
    let mx = manifest(dir.path(), "x.jsonl", &x);
    let my = manifest(dir.path(), "y.jsonl", &y);
    let spawn = |m: &Path| {
        Command::new(ingest_bin())
            .args([ds_s, "--manifest", path_str(m), "--jobs", "1", "--json"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let a = spawn(&mx);
    let b = spawn(&my);
    for child in [a, b] {
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert_eq!(stdout_json(&out)["ingested"].as_array().unwrap().len(), 8);
    }
    let info = ds_json(&["info", ds_s]);
    assert_eq!(info["episodes"], 16);
    assert_eq!(info["frames"], 160);
    assert_eq!(info["latest_version"], 2);
    let v = ds_json(&["verify", ds_s]);
    assert!(v["problems"].as_array().unwrap().is_empty(), "{v}");
}
