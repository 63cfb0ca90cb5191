//! `milv-ingest` and `milv-ds` end to end, on clips made with FFmpeg's test sources.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;

#[test]
fn ingest_is_idempotent_and_versions_time_travel() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let ds = path_str(&ds);
    let a = clip_with_sidecar(dir.path(), "a.mp4", 12, "human", 1);
    let b = clip_with_sidecar(dir.path(), "b.webm", 9, "robot", 2);

    let (code, r) = ingest(&[ds, path_str(&a)]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["version"], 1);
    assert_eq!(r["ingested"][0]["n_frames"], 12);

    let (code, r) = ingest(&[ds, path_str(&a), path_str(&b)]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["version"], 2);
    assert_eq!(r["ingested"].as_array().unwrap().len(), 1);
    assert_eq!(r["skipped"].as_array().unwrap().len(), 1);

    // The same command again: nothing new, no new version.
    let (code, r) = ingest(&[ds, path_str(&a), path_str(&b)]);
    assert_eq!(code, 0);
    assert_eq!(r["version"], 2);
    assert!(r["ingested"].as_array().unwrap().is_empty());

    let latest = ds_json(&["info", ds]);
    assert_eq!(latest["episodes"], 2);
    assert_eq!(latest["frames"], 21);
    assert_eq!(latest["by_domain_kind"]["human/demo"], 1);
    let old = ds_json(&["info", &format!("{ds}@1")]);
    assert_eq!(old["episodes"], 1);
    assert_eq!(old["frames"], 12);
    let out = run(ds_bin(), &["info", &format!("{ds}@9")]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("version 9 does not exist"));

    let log = ds_json(&["log", ds]);
    let log = log.as_array().unwrap();
    assert_eq!(log.len(), 3);
    assert!(log[2]["command"].as_str().unwrap().contains("b.webm"));
    assert_eq!(log[2]["tables"]["frames"], 2);

    let v = ds_json(&["verify", ds]);
    assert_eq!(v["problems"].as_array().unwrap().len(), 0, "{v}");
    assert_eq!(v["frames_decoded"], 21);
}

#[test]
fn frame_folders_resize_and_resampling() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let ds = path_str(&ds);
    // A folder of numbered PNGs (frame_1 .. frame_12: numeric, not lexicographic order).
    let frames = dir.path().join("shots");
    std::fs::create_dir(&frames).unwrap();
    for i in 1..=12u8 {
        let img = image::RgbImage::from_fn(20, 10, |x, y| image::Rgb([i * 10, x as u8 * 5, y as u8 * 9]));
        img.save(frames.join(format!("frame_{i}.png"))).unwrap();
    }
    let (code, r) = ingest(&[
        ds,
        path_str(&frames),
        "--fps",
        "10",
        "--domain",
        "robot",
        "--kind",
        "random",
    ]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["ingested"][0]["n_frames"], 12);

    // A 10 fps clip resampled to 5 fps and cropped to 16x16.
    let clip = clip_with_sidecar(dir.path(), "c.mp4", 20, "human", 3);
    let (code, r) = ingest(&[
        ds,
        path_str(&clip),
        "--fps",
        "5",
        "--resize",
        "16x16",
        "--aspect",
        "crop",
    ]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["ingested"][0]["n_frames"], 10);
    let info = ds_json(&["info", ds]);
    assert_eq!(info["frames"], 22);
    let v = ds_json(&["verify", ds]);
    assert_eq!(v["problems"].as_array().unwrap().len(), 0, "{v}");
}

#[test]
fn missing_domain_and_bad_arguments_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let clip = dir.path().join("x.mp4");
    make_clip(&clip, 5, 16, 16, 0);
    let (code, r) = ingest(&[path_str(&ds), path_str(&clip)]);
    assert_eq!(code, 3);
    assert!(
        r["failed"][0]["error"].as_str().unwrap().contains("no domain"),
        "{r}"
    );
    assert_eq!(r["version"], 0);
    let out = run(ingest_bin(), &[path_str(&ds)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no inputs"));
    let out = run(
        ingest_bin(),
        &[path_str(&ds), path_str(&clip), "--resize", "12by5"],
    );
    assert_eq!(out.status.code(), Some(2), "clap usage error");
}

#[test]
fn maintenance_commands_each_make_one_version() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let ds = path_str(&ds);
    let a = clip_with_sidecar(dir.path(), "a.mp4", 6, "human", 4);
    let b = clip_with_sidecar(dir.path(), "b.mp4", 7, "robot", 5);
    let c = clip_with_sidecar(dir.path(), "c.avi", 8, "robot", 6);
    for clip in [&a, &b, &c] {
        let (code, r) = ingest(&[ds, path_str(clip)]);
        assert_eq!(code, 0, "{r}");
    }
    let victim = ingest(&[ds, path_str(&b)]).1["skipped"][0]["episode_id"]
        .as_str()
        .unwrap()
        .to_string();
    let r = ds_json(&["delete-episodes", ds, &victim]);
    assert_eq!(r["version"], 4);
    let info = ds_json(&["info", ds]);
    assert_eq!(
        (info["episodes"].as_u64(), info["frames"].as_u64()),
        (Some(2), Some(14))
    );
    assert_eq!(ds_json(&["info", &format!("{ds}@3")])["frames"], 21);

    let r = ds_json(&["compact", ds]);
    assert_eq!(r["version"], 5);
    let info = ds_json(&["info", ds]);
    assert_eq!(info["tables"]["frames"]["files"], 1);
    assert_eq!(info["frames"], 14);

    let out = run(ds_bin(), &["compact", &format!("{ds}@2")]);
    assert!(!out.status.success(), "writes to an old version are refused");
    let v = ds_json(&["verify", ds]);
    assert!(v["problems"].as_array().unwrap().is_empty(), "{v}");
    let log = ds_json(&["log", ds]);
    let ops: Vec<&str> = log
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["operation"].as_str().unwrap())
        .collect();
    assert_eq!(
        ops,
        [
            "create",
            "ingest",
            "ingest",
            "ingest",
            "delete-episodes",
            "compact"
        ]
    );
}
