//! `milv-score`: frame-quality scores (Brenner × SSIM = β_qua, `shared/spec/quality.md`).

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::{Parser, Subcommand};
use milv::cli;
use milv::quality::{Rgb, SsimMode, beta_video, ssim};
use milv::video::DecodeOptions;

/// Score video frames by sharpness (Brenner) and temporal consistency (SSIM with the next
/// frame), the paper's β_qua.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Times one frame's β (Brenner of A + gray SSIM of A and B) on one thread, in process;
    /// used by tools/bench/score.py.
    Bench {
        a: PathBuf,
        b: PathBuf,
        #[arg(long, default_value_t = 200)]
        iters: usize,
        #[arg(long)]
        json: bool,
    },
    /// Scores one clip without any dataset: a folder of numbered PNG/JPEG frames or a video
    /// file. Prints one line per frame: frame, brenner_raw, brenner, brenner_h, ssim (gray,
    /// with the next frame; the last frame reuses the last pair), ssim_rgb, beta; with
    /// --json as JSON lines with full f64 precision.
    Frames {
        /// Frame folders or video files.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        #[arg(long)]
        json: bool,
    },
}

fn score_clip(path: &std::path::Path, json: bool) -> anyhow::Result<()> {
    // Folders need a rate to be read as a clip; it does not affect the scores.
    let source = milv::video::open_frames(path, Some(10.0), &DecodeOptions::default())
        .with_context(|| format!("opening {}", path.display()))?;
    let frames: Vec<milv::video::Frame> = source.collect::<Result<_, _>>()?;
    if frames.len() < 2 {
        bail!(
            "{} frame(s): a clip needs at least 2 to score: {}",
            frames.len(),
            path.display()
        );
    }
    let imgs: Vec<Rgb<'_>> = frames
        .iter()
        .map(|f| Rgb::new(&f.data, f.width as usize, f.height as usize))
        .collect::<Result<_, _>>()
        .with_context(|| format!("frame sizes differ in {}", path.display()))?;
    let scores = beta_video(&imgs).with_context(|| format!("scoring {}", path.display()))?;
    let mut out = std::io::stdout().lock();
    for (t, s) in scores.iter().enumerate() {
        let (a, b) = if t + 1 < imgs.len() {
            (imgs[t], imgs[t + 1])
        } else {
            (imgs[t - 1], imgs[t])
        };
        let ssim_rgb = ssim(a, b, SsimMode::Rgb)?;
        if json {
            writeln!(
                out,
                "{}",
                serde_json::json!({
                    "source": path.display().to_string(), "frame": t,
                    "brenner_raw": s.brenner.raw, "brenner": s.brenner.normalized,
                    "brenner_h": s.brenner.horizontal, "ssim": s.ssim, "ssim_rgb": ssim_rgb, "beta": s.beta,
                })
            )?;
        } else {
            writeln!(
                out,
                "{}\t{t}\t{:.6e}\t{:.9}\t{:.9}\t{:.9}\t{:.9}\t{:.9}",
                path.display(),
                s.brenner.raw,
                s.brenner.normalized,
                s.brenner.horizontal,
                s.ssim,
                ssim_rgb,
                s.beta
            )?;
        }
    }
    Ok(())
}

fn load(p: &std::path::Path) -> anyhow::Result<image::RgbImage> {
    Ok(image::open(p)
        .with_context(|| format!("reading {}", p.display()))?
        .into_rgb8())
}

fn run(args: Args) -> anyhow::Result<u8> {
    match args.cmd {
        Cmd::Bench { a, b, iters, json } => {
            let (ia, ib) = (load(&a)?, load(&b)?);
            let (w, h) = (ia.width() as usize, ia.height() as usize);
            let ra = Rgb::new(ia.as_raw(), w, h)?;
            let rb = Rgb::new(ib.as_raw(), ib.width() as usize, ib.height() as usize)?;
            let mut scorer = milv::quality::Scorer::default();
            let first = scorer.beta_pair(ra, rb)?;
            let t0 = std::time::Instant::now();
            for _ in 0..iters.max(1) {
                std::hint::black_box(scorer.beta_pair(std::hint::black_box(ra), rb)?);
            }
            let per_frame = t0.elapsed().as_secs_f64() / iters.max(1) as f64;
            let v = serde_json::json!({"width": w, "height": h, "iters": iters, "seconds_per_frame": per_frame,
                "brenner": first.brenner.normalized, "ssim": first.ssim, "beta": first.beta});
            if json {
                println!("{v}")
            } else {
                println!(
                    "{w}x{h}: {:.1} µs per frame, beta {}",
                    per_frame * 1e6,
                    first.beta
                )
            }
        }
        Cmd::Frames { paths, json } => {
            if !json {
                writeln!(
                    std::io::stdout().lock(),
                    "source\tframe\tbrenner_raw\tbrenner\tbrenner_h\tssim\tssim_rgb\tbeta"
                )?;
            }
            let mut failed = 0;
            for p in &paths {
                match score_clip(p, json) {
                    Ok(()) => {}
                    Err(e) if e.downcast_ref::<std::io::Error>().is_some() => return Err(e),
                    Err(e) => {
                        eprintln!("milv-score: error: {e:#}");
                        failed += 1;
                    }
                }
            }
            if failed > 0 {
                return Ok(if failed == paths.len() {
                    cli::EXIT_FATAL
                } else {
                    cli::EXIT_PARTIAL
                });
            }
        }
    }
    Ok(cli::EXIT_OK)
}

fn main() -> ExitCode {
    cli::finish("milv-score", run(Args::parse()))
}
