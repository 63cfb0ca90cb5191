//! Helpers shared by the integration tests: run the real binaries, make clips with the
//! `ffmpeg` CLI, write sidecars.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn ingest_bin() -> &'static str {
    env!("CARGO_BIN_EXE_milv-ingest")
}

pub fn ds_bin() -> &'static str {
    env!("CARGO_BIN_EXE_milv-ds")
}

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs a command, returning its output (never panics on a non-zero exit).
pub fn run(bin: &str, args: &[&str]) -> Output {
    Command::new(bin).args(args).output().unwrap()
}

pub fn stdout_json(out: &Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}): {text}\nstderr: {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// `milv-ingest ... --json`, returning (exit code, report).
pub fn ingest(args: &[&str]) -> (i32, serde_json::Value) {
    let mut a = args.to_vec();
    a.push("--json");
    let out = run(ingest_bin(), &a);
    (out.status.code().unwrap_or(-1), stdout_json(&out))
}

pub fn ds_json(args: &[&str]) -> serde_json::Value {
    let mut a = args.to_vec();
    a.push("--json");
    let out = run(ds_bin(), &a);
    assert!(
        out.status.success(),
        "milv-ds {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout_json(&out)
}

/// A test clip from FFmpeg's testsrc2: `frames` frames of `w`x`h` at 10 fps.
pub fn make_clip(path: &Path, frames: u32, w: u32, h: u32, seed: u32) {
    let (codec, extra): (&str, &[&str]) = match path.extension().and_then(|e| e.to_str()) {
        Some("webm") => ("libvpx-vp9", &["-deadline", "realtime", "-cpu-used", "8"]),
        Some("avi") => ("mjpeg", &["-q:v", "3"]),
        _ => ("libx264", &["-preset", "ultrafast"]),
    };
    let pix = if codec == "mjpeg" { "yuvj420p" } else { "yuv420p" };
    let src = format!(
        "testsrc2=size={w}x{h}:rate=10:duration=100,hue=h={}",
        seed * 37 % 360
    );
    let out = Command::new("ffmpeg")
        .args(["-nostdin", "-v", "error", "-y", "-f", "lavfi", "-i", &src])
        .args(["-frames:v", &frames.to_string(), "-c:v", codec, "-pix_fmt", pix])
        .args(extra)
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ffmpeg: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A JSON sidecar with `n` action rows [i, -i] and metadata (`extra`: more metadata keys).
pub fn write_sidecar(path: &Path, n: usize, domain: &str, extra: serde_json::Value) {
    let mut meta = milv::ingest::EpisodeMeta {
        domain: Some(domain.into()),
        task_id: Some("draw/circle".into()),
        task_family: Some("drawing".into()),
        ..Default::default()
    };
    if let serde_json::Value::Object(m) = extra {
        for (k, v) in m {
            meta.set(&k, v.as_str().unwrap()).unwrap();
        }
    }
    let sidecar = milv::ingest::Sidecar {
        path: path.to_path_buf(),
        meta,
        action_names: Some(vec!["dx".into(), "dy".into()]),
        actions: Some((0..n).map(|i| vec![i as f32 * 0.5, -(i as f32)]).collect()),
        ..Default::default()
    };
    sidecar.write(path).unwrap();
}

/// A clip plus its sidecar beside it; returns the clip path.
pub fn clip_with_sidecar(dir: &Path, name: &str, frames: u32, domain: &str, seed: u32) -> PathBuf {
    let clip = dir.join(name);
    make_clip(&clip, frames, 32, 24, seed);
    write_sidecar(
        &clip.with_extension("json"),
        frames as usize,
        domain,
        serde_json::json!({}),
    );
    clip
}

pub fn path_str(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `bin args… --json`: exit code, the JSON on stdout (null if none), stderr.
pub fn run_json(bin: &str, args: &[&str]) -> (i32, serde_json::Value, String) {
    let mut a = args.to_vec();
    a.push("--json");
    let out = run(bin, &a);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let v = if out.stdout.is_empty() {
        serde_json::Value::Null
    } else {
        stdout_json(&out)
    };
    (out.status.code().unwrap_or(-1), v, err)
}
