//! Fixture steps shared by the export tests.
#![allow(dead_code, clippy::unwrap_used)]

use milv_data::{CommitMeta, Dataset};
use milv_score::{CurateOptions, Rule, RunOptions, Source, curate, score_dataset};

pub fn meta() -> CommitMeta {
    CommitMeta::for_this_process("milv-export-test", "fixture")
}

/// Scores every imagined frame, then curates the best `top_fraction` of them.
pub fn score_and_curate_imagined(ds: &Dataset, top_fraction: f64) {
    let opts = RunOptions {
        source: Source::Imagined,
        model_id: None,
        episodes: None,
        domain: None,
        jobs: 1,
        partition: None,
        skip_bad: false,
    };
    score_dataset(ds, None, &opts, meta(), &|_| {}).unwrap();
    let c = CurateOptions {
        run_id: None,
        rule: Rule::TopFraction(top_fraction),
        min_episode_fraction: 0.0,
    };
    curate(ds, &c, meta()).unwrap();
}
