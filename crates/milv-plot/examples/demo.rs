//! Writes one chart of each kind into a folder, for eyeballing layout and text:
//! `cargo run -p milv-plot --example demo -- /tmp/milv-plot-demo`

use std::path::PathBuf;

use milv_plot::{Series, heatmap_png, histogram_png, lines_png};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "milv-plot-demo".into()));
    std::fs::create_dir_all(&dir)?;

    let values: Vec<f64> = (0..2000)
        .map(|i| {
            let u = (i as f64 * 0.618_034).fract();
            let v = (i as f64 * 0.414_214).fract();
            (-2.0 * u.max(1e-9).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        })
        .collect();
    histogram_png(
        &dir.join("histogram.png"),
        &values,
        30,
        "Normal-ish samples",
        "value",
    )?;

    let series: Vec<Series> = (0..14)
        .map(|k| Series {
            name: format!("episode {k}"),
            points: (0..100)
                .map(|i| {
                    (
                        i as f64 / 10.0,
                        (i as f64 / 10.0 + k as f64 * 0.4).sin() * (1.0 + k as f64 * 0.1),
                    )
                })
                .collect(),
        })
        .collect();
    lines_png(
        &dir.join("lines.png"),
        &series,
        "Joint angle per episode",
        "time [s]",
        "angle [rad]",
    )?;

    let (n, m) = (60, 80);
    let a: Vec<f64> = (0..n).map(|i| (i as f64 / 9.0).sin()).collect();
    let b: Vec<f64> = (0..m).map(|j| (j as f64 / 12.0).sin()).collect();
    let cost: Vec<f64> = (0..n * m).map(|k| (a[k / m] - b[k % m]).abs()).collect();
    let path: Vec<(usize, usize)> = (0..m).map(|j| (j * (n - 1) / (m - 1), j)).collect();
    heatmap_png(
        &dir.join("heatmap.png"),
        &cost,
        n,
        m,
        "DTW cost",
        "demo frame j",
        "human frame i",
        Some(&path),
    )?;
    println!("wrote {}", dir.display());
    Ok(())
}
