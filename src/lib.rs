//! # milv — meta-imitation learning from human videos: the toolkit
//!
//! This package holds the command-line tools (`src/bin/milv-*.rs`, each a thin `clap`
//! front over one library call) and re-exports the libraries they stand on:
//!
//! | crate | role |
//! |---|---|
//! | [`align`] (`milv-align`) | banded DTW alignment of paired human/robot clips → the `alignments` table |
//! | [`data`] (`milv-data`) | versioned dataset store: schemas, Delta tables, Parquet shards, maintenance |
//! | [`video`] (`milv-video`) | FFmpeg decode/encode to RGB frames with timestamps, frame folders, resizing |
//! | [`ingest`] (`milv-ingest`) | videos + sidecars into the `episodes` and `frames` tables |
//! | [`lerobot`] (`milv-lerobot`) | LeRobot v3.0 datasets: read for ingest, export, LeRobot-style statistics |
//! | [`plot`] (`milv-plot`) | PNG charts (histogram, lines, heatmap) with plotters |
//! | [`quality`] (`milv-quality`) | Brenner, SSIM and β_qua kernels (exact, pure) |
//! | [`score`] (`milv-score`) | β_qua over a dataset: the `scores` table, curation, reports |
//! | [`sim`] (`milv-sim`) | the two-embodiment tabletop: tasks, experts, renderer, evaluation |
//!
//! [`cli`] (`milv-cli`) holds what the binaries share (progress bars, exit codes), also
//! used by `milv-train`, which links libtorch and so lives in its own package.

pub use milv_align as align;
pub use milv_data as data;
pub use milv_ingest as ingest;
pub use milv_lerobot as lerobot;
pub use milv_plot as plot;
pub use milv_quality as quality;
pub use milv_score as score;
pub use milv_sim as sim;
pub use milv_video as video;

pub use milv_cli as cli;
