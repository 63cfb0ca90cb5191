//! Criterion benches of the quality kernels on real frames (the astronaut photograph of
//! the golden tests): one frame's β at 128×128 and 640×480, gray and rgb SSIM, and a
//! 64-frame clip scored with 1 and 2 rayon threads (frames/s scaling).
#![allow(clippy::unwrap_used)]

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use milv_quality::{Rgb, Scorer, SsimMode, beta_video_par};

fn golden(name: &str) -> (Vec<u8>, usize, usize) {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name);
    let img = image::open(p).unwrap().into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    (img.into_raw(), w, h)
}

/// A `w×h` frame tiled from the 128×128 photograph, shifted by `dx` pixels per frame so
/// consecutive frames differ like a slow pan.
fn tiled(src: &[u8], sw: usize, sh: usize, w: usize, h: usize, dx: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let (u, v) = ((x + dx) % sw, y % sh);
            out.extend_from_slice(&src[(v * sw + u) * 3..(v * sw + u) * 3 + 3]);
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let (a, w, h) = golden("astronaut_128_a.png");
    let (b, _, _) = golden("astronaut_128_b.png");
    let mut g = c.benchmark_group("beta_pair");
    let mut scorer = Scorer::default();
    let (ra, rb) = (Rgb::new(&a, w, h).unwrap(), Rgb::new(&b, w, h).unwrap());
    g.bench_function("128x128", |bn| bn.iter(|| scorer.beta_pair(ra, rb).unwrap()));
    let (la, lb) = (tiled(&a, w, h, 640, 480, 0), tiled(&a, w, h, 640, 480, 1));
    let (ra, rb) = (Rgb::new(&la, 640, 480).unwrap(), Rgb::new(&lb, 640, 480).unwrap());
    g.bench_function("640x480", |bn| bn.iter(|| scorer.beta_pair(ra, rb).unwrap()));
    g.finish();

    let mut g = c.benchmark_group("ssim_128x128");
    let (ra, rb) = (Rgb::new(&a, w, h).unwrap(), Rgb::new(&b, w, h).unwrap());
    for (name, mode) in [("gray", SsimMode::Gray), ("rgb", SsimMode::Rgb)] {
        g.bench_function(name, |bn| bn.iter(|| scorer.ssim(ra, rb, mode).unwrap()));
    }
    g.finish();

    let frames: Vec<Vec<u8>> = (0..64).map(|k| tiled(&a, w, h, 128, 128, k)).collect();
    let clip: Vec<Rgb<'_>> = frames.iter().map(|f| Rgb::new(f, 128, 128).unwrap()).collect();
    let mut g = c.benchmark_group("clip_64x128x128");
    g.throughput(Throughput::Elements(clip.len() as u64));
    for jobs in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build().unwrap();
        g.bench_with_input(BenchmarkId::new("jobs", jobs), &jobs, |bn, &j| {
            bn.iter(|| pool.install(|| beta_video_par(&clip, j).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
