//! Bad inputs: each gets an error naming the file and the problem, the good inputs of the
//! same batch still land, the exit code says some failed, and a batch with nothing good
//! leaves the dataset at its last version. Fixtures come from tools/make_bad_inputs.py.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::*;

fn fixtures() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bad");
    let st = Command::new("python3")
        .arg(repo().join("tools/make_bad_inputs.py"))
        .arg(&out)
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", String::from_utf8_lossy(&st.stderr));
    (dir, out)
}

fn failures(r: &serde_json::Value) -> Vec<(String, String)> {
    r["failed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["source"].as_str().unwrap().to_string(),
                f["error"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

fn error_for<'a>(fails: &'a [(String, String)], name: &str) -> &'a str {
    fails
        .iter()
        .find(|(s, _)| Path::new(s).file_name().is_some_and(|f| f == name))
        .map(|(_, e)| e.as_str())
        .unwrap_or_else(|| panic!("{name} did not fail: {fails:?}"))
}

#[test]
fn every_bad_input_is_named_and_the_good_ones_land() {
    let (_tmp, bad) = fixtures();
    let ds = bad.join("ds");
    let ds = path_str(&ds);
    let manifest = bad.join("bad_manifest.jsonl");
    let (code, r) = ingest(&[ds, "--manifest", path_str(&manifest), "--domain", "human"]);
    assert_eq!(code, 3, "{r}");
    assert_eq!(r["version"], 1);
    let landed: Vec<&str> = r["ingested"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["source"].as_str().unwrap())
        .collect();
    assert_eq!(landed.len(), 3, "{landed:?}");
    for good in ["good_1.mp4", "good_2.mp4", "no_sidecar.mp4"] {
        assert!(
            landed.iter().any(|s| s.ends_with(good)),
            "{good} missing from {landed:?}"
        );
    }
    let fails = failures(&r);
    let cases: &[(&str, &[&str])] = &[
        ("empty.mp4", &["empty file"]),
        ("truncated.mp4", &["truncated.mp4"]),
        ("notavideo.mp4", &["notavideo.mp4"]),
        ("noframes.mkv", &["no video stream"]),
        ("noframes_video.avi", &["no decodable frames", "no frames"]),
        (
            "short_actions.mp4",
            &["7 action rows for at least 8 video frames"],
        ),
        ("long_actions.mp4", &["13 action rows for 10 video frames"]),
        ("nan_actions.mp4", &["not a finite number"]),
        ("nan_actions_json.mp4", &["NaN"]),
        ("ragged_actions.mp4", &["same width"]),
        ("mixed_sizes", &["size"]),
        ("bad_domain.mp4", &["unknown domain \"alien\""]),
        ("unreadable.mp4", &["cannot read input"]),
    ];
    assert_eq!(fails.len(), cases.len(), "{fails:#?}");
    for (name, needles) in cases {
        let e = error_for(&fails, name);
        let stem = name.split('.').next().unwrap();
        assert!(e.contains(stem), "{name}: error does not name the file: {e}");
        assert!(needles.iter().any(|n| e.contains(n)), "{name}: {e}");
    }
    let v = ds_json(&["verify", ds]);
    assert!(v["problems"].as_array().unwrap().is_empty(), "{v}");
    assert_eq!(ds_json(&["info", ds])["episodes"], 3);
}

#[test]
fn require_actions_duplicates_and_all_bad_batches() {
    let (_tmp, bad) = fixtures();
    let ds = bad.join("ds2");
    let ds = path_str(&ds);
    let good = bad.join("good_1.mp4");
    let (code, r) = ingest(&[ds, path_str(&good)]);
    assert_eq!((code, r["version"].as_u64()), (0, Some(1)), "{r}");

    let (code, r) = ingest(&[
        ds,
        path_str(&bad.join("no_sidecar.mp4")),
        "--domain",
        "robot",
        "--require-actions",
    ]);
    assert_eq!(code, 3);
    assert!(
        error_for(&failures(&r), "no_sidecar.mp4").contains("--require-actions"),
        "{r}"
    );
    assert_eq!(r["version"], 1, "nothing landed, no new version");

    let dup = bad.join("duplicate/manifest.jsonl");
    let (code, r) = ingest(&[ds, "--manifest", path_str(&dup)]);
    assert_eq!(code, 3, "{r}");
    assert_eq!(r["ingested"].as_array().unwrap().len(), 1);
    assert!(failures(&r)[0].1.contains("duplicate episode"), "{r}");

    let (code, r) = ingest(&[
        ds,
        path_str(&bad.join("empty.mp4")),
        path_str(&bad.join("notavideo.mp4")),
    ]);
    assert_eq!(code, 3);
    assert_eq!(r["version"], 2, "an all-bad batch commits nothing");
    assert_eq!(ds_json(&["info", ds])["latest_version"], 2);
}

#[test]
fn a_faststart_mp4_cut_short_is_reported_as_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.mp4");
    let out = Command::new("ffmpeg")
        .args([
            "-nostdin",
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc2=size=64x48:rate=10",
        ])
        .args([
            "-frames:v",
            "40",
            "-c:v",
            "libx264",
            "-preset",
            "ultrafast",
            "-pix_fmt",
            "yuv420p",
        ])
        .args(["-movflags", "+faststart"])
        .arg(&full)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let bytes = std::fs::read(&full).unwrap();
    let cut = dir.path().join("cut.mp4");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let ds = dir.path().join("ds");
    let (code, r) = ingest(&[
        path_str(&ds),
        path_str(&cut),
        path_str(&full),
        "--domain",
        "human",
    ]);
    assert_eq!(code, 3, "{r}");
    let fails = failures(&r);
    let e = error_for(&fails, "cut.mp4");
    assert!(e.contains("truncated"), "{e}");
    assert_eq!(r["ingested"][0]["n_frames"], 40);
}
