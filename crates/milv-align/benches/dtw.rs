//! Criterion bench of banded DTW: two clips of 1,000 frames with 64-d features, bands of
//! 5/10/20 %, cost only and with the warping path (tools/bench/align.py compares the same
//! alignment with dtaidistance's C implementation).
#![allow(clippy::unwrap_used)]

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use milv_align::{Band, Features, StepPattern, dtw};

fn clip(n: usize, d: usize, seed: u64, warp: f64) -> Features {
    let mut s = seed;
    let mut next = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let data = (0..n)
        .flat_map(|i| {
            let t = i as f64 / n as f64;
            let t = t + warp * (6.0 * std::f64::consts::PI * t).sin();
            (0..d)
                .map(move |k| (t * (k + 1) as f64).sin())
                .collect::<Vec<_>>()
        })
        .map(|v| v + 0.05 * next())
        .collect();
    Features::new(n, d, data).unwrap()
}

fn bench(c: &mut Criterion) {
    let (a, b) = (clip(1000, 64, 1, 0.0), clip(1000, 64, 2, 0.05));
    let mut g = c.benchmark_group("dtw_1000x1000x64");
    g.sample_size(20);
    for frac in [5usize, 10, 20] {
        let band = Band::absolute(1000, 1000, frac * 10);
        for (name, path) in [("cost", false), ("path", true)] {
            g.bench_with_input(BenchmarkId::new(name, format!("{frac}%")), &band, |bn, band| {
                bn.iter(|| dtw(&a, &b, band, StepPattern::Symmetric1, path).unwrap())
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
