//! `milv-export lerobot` (the real binary) and the LeRobot import (`milv_ingest::ingest_lerobot`)
//! round-trip a small dataset: inline images exactly, AV1 video within its codec error and
//! never off by a frame. Broken LeRobot datasets (a truncated video, an episode past the
//! end of its video, lengths that disagree, a template leaving the folder, a missing
//! feature) are refused with the file and episode named, and the good episodes land.
//! LeRobot's own reading and writing of these datasets is tested in tests/lerobot/.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;

use common::{meta, score_and_curate_imagined};
use milv_data::arrow::array::{ArrayRef, Int64Array, RecordBatch};
use milv_data::frame_codec;
use milv_data::{Dataset, Domain, Episode};
use milv_fixtures::{Frame, ImaginedFrame, commit_episodes, commit_imagined};
use milv_ingest::{IngestOptions, NoProgress};
use milv_lerobot::format::read_parquet;

const W: u32 = 64;
const H: u32 = 48;
const LENS: [usize; 3] = [12, 15, 9];
const TASKS: [&str; 3] = ["pick the red cube", "push the block left", "pick the red cube"];

/// Frame k of episode e: a bright square moving 3 px a frame over a gradient, so every
/// frame differs clearly from its neighbours.
fn frame(e: usize, k: usize) -> Vec<u8> {
    let mut rgb = vec![0u8; (W * H * 3) as usize];
    for y in 0..H as usize {
        for x in 0..W as usize {
            let p = (y * W as usize + x) * 3;
            rgb[p] = (x * 4) as u8;
            rgb[p + 1] = (y * 5) as u8;
            rgb[p + 2] = (40 * e) as u8;
        }
    }
    let (x0, y0) = (2 + 3 * k, 8 + 4 * e);
    for y in y0..y0 + 12 {
        for x in x0..(x0 + 12).min(W as usize) {
            let p = (y * W as usize + x) * 3;
            rgb[p..p + 3].copy_from_slice(&[250, 250, 250]);
        }
    }
    rgb
}

/// An imagined frame: the translator's own size (32×24), not the human clip's.
fn small(k: usize) -> Vec<u8> {
    let big = frame(2, k);
    (0..24)
        .flat_map(|y| big[y * W as usize * 3..(y * W as usize + 32) * 3].to_vec())
        .collect()
}

fn action(e: usize, k: usize) -> Vec<f32> {
    vec![k as f32 * 0.25, -(e as f32), (k * e) as f32 / 7.0]
}

fn state(e: usize, k: usize) -> Vec<f32> {
    vec![2.0 + 3.0 * k as f32, 8.0 + 4.0 * e as f32]
}

/// Three robot demos (tasks as text, actions and states with names) and one model's
/// imagined version of the first.
fn dataset(dir: &Path) -> PathBuf {
    let root = dir.join("ds");
    let ds = Dataset::open_or_create(&root, meta()).unwrap();
    let eps: Vec<(Episode, Vec<Frame>)> = LENS
        .iter()
        .enumerate()
        .map(|(e, &n)| {
            let ep = Episode {
                task_id: Some(TASKS[e].into()),
                action_dim: Some(3),
                state_dim: Some(2),
                action_names: Some(vec!["dx".into(), "dy".into(), "grip".into()]),
                state_names: Some(vec!["x".into(), "y".into()]),
                ..milv_fixtures::episode(&format!("ep{e}"), Domain::Robot, n, (W, H))
            };
            let frames = (0..n)
                .map(|k| Frame {
                    image: milv_fixtures::png(&frame(e, k), W, H),
                    action: Some(action(e, k)),
                    state: Some(state(e, k)),
                })
                .collect();
            (ep, frames)
        })
        .collect();
    commit_episodes(&ds, &eps, meta()).unwrap();
    let imagined: Vec<ImaginedFrame> = (0..LENS[0])
        .map(|k| ImaginedFrame {
            image: milv_fixtures::png(&small(k), 32, 24),
            latent: None,
            action: Some(vec![k as f32, 1.0]),
        })
        .collect();
    commit_imagined(&ds, "acg-0011", &[("ep0", imagined)], meta()).unwrap();
    root
}

fn export(ds: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let o = Command::new(env!("CARGO_BIN_EXE_milv-export"))
        .args([
            "lerobot",
            ds.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--json",
        ])
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn import(
    dir: &Path,
    lerobot: &Path,
    camera: Option<&str>,
) -> milv_ingest::Result<milv_ingest::IngestReport> {
    let ds = Dataset::open_or_create(dir, meta()).unwrap();
    let mut opts = IngestOptions::default();
    opts.defaults.domain = Some("robot".into());
    opts.jobs = 2;
    milv_ingest::ingest_lerobot(&ds, lerobot, camera, &opts, meta(), &NoProgress)
}

/// The imported episodes, in LeRobot episode order, with their decoded frames and actions.
/// An imported episode: its row, RGB frames, actions and states.
type Imported = (Episode, Vec<Vec<u8>>, Vec<Vec<f32>>, Vec<Vec<f32>>);

fn imported(dir: &Path) -> Vec<Imported> {
    let ds = Dataset::open(dir).unwrap();
    let v = ds.latest_version().unwrap();
    let mut eps = milv_data::read::rows::<Episode>(&ds, v).unwrap();
    let index = |e: &Episode| -> i64 {
        let s = e.source_uri.split("#episode=").nth(1).unwrap();
        s.split('&').next().unwrap().parse().unwrap()
    };
    eps.sort_by_key(index);
    let ids: Vec<String> = eps.iter().map(|e| e.episode_id.clone()).collect();
    let keep = |id: &str| ids.iter().any(|x| x == id);
    let acts =
        milv_data::read::episode_rows(&ds, v, milv_data::TableKind::Frames, &keep, Some("action"), None)
            .unwrap();
    let sts = milv_data::read::episode_rows(&ds, v, milv_data::TableKind::Frames, &keep, Some("state"), None)
        .unwrap();
    eps.into_iter()
        .map(|e| {
            let r = &acts[&e.episode_id];
            let rgb = r
                .images
                .iter()
                .map(|b| frame_codec::decode(e.frame_encoding, b, e.width as u32, e.height as u32).unwrap())
                .collect();
            let a = r.all_vectors().unwrap();
            let s = sts[&e.episode_id].all_vectors().unwrap_or_default();
            (e, rgb, a, s)
        })
        .collect()
}

fn mad(a: &[u8], b: &[u8]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).abs())
        .sum::<f64>()
        / a.len() as f64
}

#[test]
fn inline_images_round_trip_exactly_and_reimport_is_a_no_op() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let out = tmp.path().join("lr_images");
    let r = export(&ds, &out, &["--images"]);
    assert_eq!(
        (r["episodes"].as_u64(), r["frames"].as_u64(), r["fps"].as_u64()),
        (Some(3), Some(36), Some(10))
    );
    assert!(out.join("meta/info.json").is_file() && out.join("meta/tasks.parquet").is_file());
    assert!(!out.join("videos").exists());
    // No temporary folder is left beside the export.
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        left.iter().all(|n| !n.to_string_lossy().ends_with(".tmp")),
        "{left:?}"
    );

    // The statistics are those of the version, and milv-ds stats computes the same.
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta/stats.json")).unwrap()).unwrap();
    for k in [
        "min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99",
    ] {
        assert!(
            stats["action"][k].is_array() && stats["observation.image"][k].is_array(),
            "{k}"
        );
    }
    assert_eq!(
        stats["action"]["max"],
        serde_json::json!([3.5, 0.0, f64::from(16.0f32 / 7.0)])
    );
    assert_eq!(stats["observation.image"]["mean"].as_array().unwrap().len(), 3);
    let ds_handle = Dataset::open(&ds).unwrap();
    let opts = milv_lerobot::ExportOptions {
        source: milv_lerobot::Source::Frames,
        video: false,
        gop: milv_lerobot::write::DEFAULT_GOP,
        model_id: None,
    };
    assert_eq!(milv_lerobot::write::stats(&ds_handle, 2, &opts).unwrap(), stats);

    let back = tmp.path().join("back");
    let rep = import(&back, &out, None).unwrap();
    assert!(rep.all_ok(), "{:?}", rep.failed);
    assert_eq!((rep.ingested.len(), rep.frames), (3, 36));
    for (e, (ep, rgb, acts, sts)) in imported(&back).into_iter().enumerate() {
        assert_eq!(ep.n_frames as usize, LENS[e]);
        assert_eq!(ep.task_id.as_deref(), Some(TASKS[e]));
        assert_eq!((ep.fps, ep.width, ep.height), (10.0, W as i32, H as i32));
        assert_eq!(
            ep.action_names,
            Some(vec!["dx".into(), "dy".into(), "grip".into()])
        );
        assert_eq!(ep.state_names, Some(vec!["x".into(), "y".into()]));
        assert_eq!(ep.domain, Domain::Robot);
        assert_eq!(ep.task_family.as_deref(), None);
        for k in 0..LENS[e] {
            assert!(rgb[k] == frame(e, k), "episode {e} frame {k} differs");
            assert_eq!(acts[k], action(e, k));
            assert_eq!(sts[k], state(e, k));
        }
    }
    // Every file read is recorded as an input of the version.
    let entry = Dataset::open(&back).unwrap().entry(1).unwrap();
    let uris: Vec<&str> = entry.meta.inputs.iter().map(|d| d.uri.as_str()).collect();
    assert!(
        uris.iter().any(|u| u.ends_with("meta/info.json"))
            && uris.iter().any(|u| u.ends_with("file-000.parquet")),
        "{uris:?}"
    );
    // Importing again changes nothing.
    let again = import(&back, &out, None).unwrap();
    assert_eq!(
        (again.version, again.ingested.len(), again.skipped.len()),
        (1, 0, 3)
    );
}

#[test]
fn video_round_trips_within_codec_error_and_never_off_by_a_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let out = tmp.path().join("lr_video");
    let r = export(&ds, &out, &[]);
    assert_eq!(r["video"], true);
    // 48 rows are too few for SVT-AV1: the libaom fallback.
    assert_eq!(r["video_encoder"], "libaom-av1");
    assert!(r["max_timestamp_error_s"].as_f64().unwrap() < 1e-4, "{r}");
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(info["features"]["observation.image"]["dtype"], "video");
    assert_eq!(info["total_frames"], 36);

    let back = tmp.path().join("back");
    let rep = import(&back, &out, Some("observation.image")).unwrap();
    assert!(rep.all_ok(), "{:?}", rep.failed);
    for (e, (ep, rgb, acts, _)) in imported(&back).into_iter().enumerate() {
        assert_eq!(ep.n_frames as usize, LENS[e]);
        for k in 0..LENS[e] {
            let own = mad(&rgb[k], &frame(e, k));
            assert!(own < 6.0, "episode {e} frame {k}: mean abs error {own:.2}");
            for j in [k.wrapping_sub(1), k + 1] {
                if j < LENS[e] {
                    let other = mad(&rgb[k], &frame(e, j));
                    assert!(
                        own < other,
                        "episode {e} frame {k} is closer to frame {j} ({other:.2} <= {own:.2})"
                    );
                }
            }
            assert_eq!(acts[k], action(e, k));
        }
    }
}

#[test]
fn imagined_export_carries_the_model_and_its_actions() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let out = tmp.path().join("lr_imagined");
    let r = export(&ds, &out, &["--table", "imagined", "--images"]);
    assert_eq!(
        (r["episodes"].as_u64(), r["model_id"].as_str()),
        (Some(1), Some("acg-0011"))
    );
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(info["features"]["milv.model_id"]["dtype"], "string");
    assert_eq!(info["features"]["action"]["shape"], serde_json::json!([2]));
    let back = tmp.path().join("back");
    import(&back, &out, None).unwrap();
    assert_eq!((r["width"].as_u64(), r["height"].as_u64()), (Some(32), Some(24)));
    let (ep, rgb, acts, _) = imported(&back).remove(0);
    assert_eq!((ep.width, ep.height), (32, 24));
    assert!(rgb[3] == small(3));
    assert_eq!(acts[3], vec![3.0, 1.0]);
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let t = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &t);
        } else {
            std::fs::copy(e.path(), &t).unwrap();
        }
    }
}

/// Rewrites one int64/float64 column of the episodes file with `f(episode, value)`.
fn edit_episodes(root: &Path, col: &str, f: impl Fn(usize, f64) -> f64) {
    use milv_data::arrow::array::{Array, Float64Array};
    let path = root.join("meta/episodes/chunk-000/file-000.parquet");
    let b = read_parquet(&path, None).unwrap().remove(0);
    let i = b.schema().index_of(col).unwrap();
    let c = b.column(i);
    let new: ArrayRef = if let Some(a) = c.as_any().downcast_ref::<Int64Array>() {
        Arc::new(Int64Array::from_iter_values(
            (0..a.len()).map(|r| f(r, a.value(r) as f64) as i64),
        ))
    } else {
        let a = c.as_any().downcast_ref::<Float64Array>().unwrap();
        Arc::new(Float64Array::from_iter_values(
            (0..a.len()).map(|r| f(r, a.value(r))),
        ))
    };
    let mut cols = b.columns().to_vec();
    cols[i] = new;
    let b = RecordBatch::try_new(b.schema(), cols).unwrap();
    let mut w = milv_data::parquet::arrow::ArrowWriter::try_new(
        std::fs::File::create(&path).unwrap(),
        b.schema(),
        None,
    )
    .unwrap();
    w.write(&b).unwrap();
    w.close().unwrap();
}

fn edit_info(root: &Path, f: impl Fn(&mut serde_json::Value)) {
    let p = root.join("meta/info.json");
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(&p, serde_json::to_string(&v).unwrap()).unwrap();
}

fn failed(r: &milv_ingest::IngestReport) -> Vec<String> {
    r.failed.iter().map(|f| f.error.clone()).collect()
}

#[test]
fn bad_lerobot_datasets_are_refused_naming_the_file_and_episode() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let good = tmp.path().join("good");
    export(&ds, &good, &[]);
    let case = |name: &str| -> PathBuf {
        let d = tmp.path().join(name);
        copy_dir(&good, &d);
        d
    };

    // The last episode's timestamps run past the end of the video: it fails, the others land.
    let past = case("past");
    edit_episodes(&past, "videos/observation.image/from_timestamp", |e, v| {
        if e == 2 { v + 5.0 } else { v }
    });
    let target = tmp.path().join("t_past");
    let r = import(&target, &past, None).unwrap();
    assert_eq!(r.ingested.len(), 2, "{:?}", failed(&r));
    let err = &failed(&r)[0];
    assert!(
        err.contains("episode 2") && err.contains("file-000.mp4") && err.contains("ends before the episode"),
        "{err}"
    );

    // Lengths that disagree with the data rows.
    let len = case("length");
    edit_episodes(&len, "length", |e, v| if e == 1 { v + 1.0 } else { v });
    let r = import(&tmp.path().join("t_len"), &len, None).unwrap();
    assert_eq!(r.ingested.len(), 2);
    let err = &failed(&r)[0];
    assert!(
        err.contains("episode 1") && err.contains("length 16") && err.contains("15 rows"),
        "{err}"
    );

    // A truncated video: every episode in it fails with the file named; the dataset stays
    // at its last good version.
    let trunc = case("truncated");
    let mp4 = trunc.join("videos/observation.image/chunk-000/file-000.mp4");
    let bytes = std::fs::read(&mp4).unwrap();
    std::fs::write(&mp4, &bytes[..bytes.len() / 2]).unwrap();
    let t = tmp.path().join("t_trunc");
    let r = import(&t, &trunc, None).unwrap();
    assert_eq!((r.ingested.len(), r.version), (0, 0), "{:?}", failed(&r));
    assert!(
        failed(&r).iter().all(|e| e.contains("file-000.mp4")),
        "{:?}",
        failed(&r)
    );

    // Templates that leave the dataset folder are refused before anything is read.
    for bad in [
        "../outside/{chunk_index}/{file_index}.parquet",
        "/etc/{file_index}.parquet",
    ] {
        let d = case("escape");
        edit_info(&d, |v| v["data_path"] = serde_json::json!(bad));
        let err = import(&tmp.path().join("t_escape"), &d, None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("not a relative path inside the dataset") && err.contains("info.json"),
            "{err}"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }
    let d = case("escape_video");
    edit_info(&d, |v| {
        v["video_path"] = serde_json::json!("../../{video_key}/{file_index}.mp4")
    });
    let err = import(&tmp.path().join("t_escape_video"), &d, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("not a relative path inside the dataset") && err.contains("info.json"),
        "{err}"
    );
    assert!(
        !tmp.path().join("t_escape_video/_milv").exists()
            || Dataset::open(tmp.path().join("t_escape_video"))
                .unwrap()
                .latest_version()
                .unwrap()
                == 0
    );

    // A missing default feature, a camera that is not there, an unsupported version.
    let d = case("missing");
    edit_info(&d, |v| {
        v["features"].as_object_mut().unwrap().remove("frame_index");
    });
    let err = import(&tmp.path().join("t_missing"), &d, None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("info.json") && err.contains("frame_index"), "{err}");
    let err = import(&tmp.path().join("t_cam"), &good, Some("observation.images.wrist"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("no camera \"observation.images.wrist\"") && err.contains("observation.image"),
        "{err}"
    );
    let d = case("v21");
    edit_info(&d, |v| v["codebase_version"] = serde_json::json!("v2.1"));
    let err = import(&tmp.path().join("t_v21"), &d, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("\"v2.1\" is not supported") && err.contains("convert_dataset_v21_to_v30"),
        "{err}"
    );
}

#[test]
fn exports_refuse_what_lerobot_cannot_hold_and_leave_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let ds_path = dataset(tmp.path());
    // A non-empty target is refused.
    let out = tmp.path().join("busy");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("x"), b"x").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_milv-export"))
        .args(["lerobot", ds_path.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not empty"));
    // Mixed frame rates are refused with the fix named, and no folder appears.
    let ds = Dataset::open(&ds_path).unwrap();
    let ep = Episode {
        fps: 15.0,
        ..milv_fixtures::episode("odd", Domain::Robot, 2, (W, H))
    };
    commit_episodes(
        &ds,
        &[(ep, vec![Frame::image(milv_fixtures::png(&frame(0, 0), W, H)); 2])],
        meta(),
    )
    .unwrap();
    let out = tmp.path().join("mixed");
    let o = Command::new(env!("CARGO_BIN_EXE_milv-export"))
        .args(["lerobot", ds_path.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("differ in fps") && err.contains("--fps"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn curated_export_carries_each_frames_weight() {
    let tmp = tempfile::tempdir().unwrap();
    let root = dataset(tmp.path());
    let ds = Dataset::open(&root).unwrap();
    score_and_curate_imagined(&ds, 0.5);
    let v = ds.latest_version().unwrap();
    let curated = milv_data::read::rows::<milv_data::CuratedRow>(&ds, v).unwrap();

    let out = tmp.path().join("lr_curated");
    let r = export(&root, &out, &["--table", "curated", "--images"]);
    assert_eq!(
        (r["episodes"].as_u64(), r["frames"].as_u64()),
        (Some(1), Some(LENS[0] as u64))
    );
    assert_eq!(r["curation_id"].as_str(), Some(curated[0].curation_id.as_str()));
    let data = read_parquet(&out.join("data/chunk-000/file-000.parquet"), None)
        .unwrap()
        .remove(0);
    let w = data
        .column_by_name("milv.weight")
        .unwrap()
        .as_any()
        .downcast_ref::<milv_data::arrow::array::Float32Array>()
        .unwrap()
        .values()
        .to_vec();
    // Kept frames carry their curated weight, dropped ones 0.
    for (k, got) in w.iter().enumerate() {
        let want = curated
            .iter()
            .find(|c| c.frame_index == k as i32)
            .map_or(0.0, |c| c.weight as f32);
        assert_eq!(*got, want, "frame {k}");
    }
    assert!(w.iter().filter(|x| **x == 0.0).count() >= LENS[0] / 3, "{w:?}");
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta/stats.json")).unwrap()).unwrap();
    assert!(stats["milv.weight"]["mean"].is_array());
}
