//! `MILV_FONT` pointing at a missing file must give a typed error naming the file and the
//! Debian package. The env var and the registered font are process-global, and setting env
//! vars is `unsafe` in edition 2024 (denied here), so the parent test re-runs this binary
//! as a child process with `MILV_FONT` set, and the child does the check.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::process::Command;

use milv_plot::{Error, FONT_ENV, FONT_PACKAGE, Series};

const CHILD: &str = "child_checks_missing_font";

#[test]
fn missing_font_is_a_typed_error() {
    let dir = tempfile::tempdir().unwrap();
    let font = dir.path().join("no-such-font.ttf");
    let out = Command::new(std::env::current_exe().unwrap())
        .args([CHILD, "--exact", "--nocapture", "--test-threads=1"])
        .env(FONT_ENV, &font)
        .env("MILV_PLOT_CHILD_OUT", dir.path())
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "child failed:\n{log}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Guard against the filter matching nothing, which would also "succeed".
    assert!(log.contains("1 passed"), "{log}");
}

/// Does nothing unless started by the test above (the env var tells).
#[test]
fn child_checks_missing_font() {
    let Some(dir) = std::env::var_os("MILV_PLOT_CHILD_OUT").map(PathBuf::from) else {
        return;
    };
    let font = PathBuf::from(std::env::var_os(FONT_ENV).unwrap());
    let out = dir.join("l.png");
    let series = [Series {
        name: "a".into(),
        points: vec![(0.0, 0.0), (1.0, 1.0)],
    }];
    let err = milv_plot::lines_png(&out, &series, "t", "x", "y").unwrap_err();
    match &err {
        Error::FontUnreadable { path, .. } => assert_eq!(path, &font),
        other => panic!("expected FontUnreadable, got {other:?}"),
    }
    let msg = err.to_string();
    assert!(
        msg.contains("no-such-font.ttf") && msg.contains(FONT_PACKAGE),
        "{msg}"
    );
    assert!(!out.exists());
}
