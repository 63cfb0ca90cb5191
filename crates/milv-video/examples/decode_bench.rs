//! Decode throughput check: `cargo run --release -p milv-video --example decode_bench -- VIDEO [WxH[:policy]]`.
//!
//! Compare with `ffmpeg -benchmark -i VIDEO -pix_fmt rgb24 -f null -`.

use std::path::PathBuf;
use std::time::Instant;

use milv_video::{DecodeOptions, VideoReader};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().ok_or("usage: decode_bench VIDEO [WxH[:policy]]")?);
    let opts = DecodeOptions {
        resize: args.next().map(|s| s.parse()).transpose()?,
        ..Default::default()
    };
    let start = Instant::now();
    let reader = VideoReader::open(&path, &opts)?;
    let mut frames = 0u64;
    let mut bytes = 0usize;
    for frame in reader {
        bytes += frame?.data.len();
        frames += 1;
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{frames} frames, {:.1} MB RGB in {secs:.3} s: {:.1} fps",
        bytes as f64 / 1e6,
        frames as f64 / secs
    );
    Ok(())
}
