//! `cargo bench -p milv-mcap --bench export -- DATASET OUT.mcap [REPEATS]`: the Rust side
//! of tools/bench/export_mcap.sh. Exports the latest version of DATASET (as
//! `milv-export mcap DATASET -o OUT` does) REPEATS times and prints one JSON line per run.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::time::Instant;

use milv_data::Dataset;
use milv_data::view::{ViewOptions, ViewPlan};
use milv_mcap::{McapOptions, RecordingInfo, write_recording};

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let [ds, out, rest @ ..] = args.as_slice() else {
        eprintln!("usage: export DATASET OUT.mcap [REPEATS]");
        return;
    };
    let repeats: usize = rest.first().and_then(|r| r.parse().ok()).unwrap_or(3);
    let ds = Dataset::open(std::path::Path::new(ds)).unwrap();
    let v = ds.latest_version().unwrap();
    let info = RecordingInfo {
        dataset_uri: ds.root().display().to_string(),
        tool_version: milv_data::TOOL_VERSION.into(),
        command: std::env::args().collect(),
    };
    // Where the time goes: reading the tables alone (on stderr, so the JSON lines on
    // stdout stay one per export).
    let t0 = Instant::now();
    let mut plan = ViewPlan::new(&ds, v, &ViewOptions::default()).unwrap();
    let n: usize = plan.views(&ds).map(|e| e.unwrap().frames.len()).sum();
    eprintln!(
        "{}",
        serde_json::json!({"read_only_seconds": t0.elapsed().as_secs_f64(), "frames": n})
    );
    for _ in 0..repeats {
        let t0 = Instant::now();
        let mut plan = ViewPlan::new(&ds, v, &ViewOptions::default()).unwrap();
        let w = write_recording(
            &mut plan,
            &ds,
            &info,
            &PathBuf::from(out),
            &McapOptions::default(),
            &mut |_| {},
        )
        .unwrap();
        let s = t0.elapsed().as_secs_f64();
        println!(
            "{}",
            serde_json::json!({"messages": w.messages, "bytes": w.bytes, "seconds": s})
        );
    }
}
