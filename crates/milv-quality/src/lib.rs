//! # milv-quality — exact frame-quality kernels (`shared/spec/quality.md`)
//!
//! The paper weights every imagined robot frame by `β_qua = Bre(y_t) · SSIM(y_t, y_{t+1})`.
//! This crate computes its parts exactly as the spec fixes them, agreeing with
//! scikit-image 0.26 (`structural_similarity(gaussian_weights=True, sigma=1.5,
//! use_sample_covariance=False, data_range=255)`) to 1e-6:
//!
//! | function | what |
//! |---|---|
//! | [`luma`] | BT.601 luma in f64, never rounded |
//! | [`brenner`] | Brenner gradient (distance 2, h+v and h-only), raw and normalised to [0, 1] |
//! | [`ssim`] | SSIM, gray (on luma) or rgb (per channel, then mean); 11-tap Gaussian, valid region |
//! | [`Scorer`], [`ClipScorer`] | the same with reusable buffers; a clip streams frame by frame |
//! | [`beta_video`], [`beta_video_par`] | β per frame of a clip with the last-frame rule (serial, rayon) |
//! | [`set_weight`], [`set_weights`] | the set-normalised loss weight |
//!
//! Pure functions over `&[u8]` RGB24 plus dimensions: no I/O, no panics on bad sizes.
//! The SSIM kernel (`kernel.rs`) fuses the five Gaussian moment maps into one pass over
//! the rows with an 11-row ring buffer, vectorised for AVX-512/AVX2 when the CPU has them
//! and bit-identical on every path.

/// Errors for inputs the kernels cannot score.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    #[error("image is {width}x{height}, the minimum is {min}x{min}")]
    TooSmall { width: usize, height: usize, min: usize },
    #[error("buffer has {got} bytes, {width}x{height} RGB needs {want}")]
    BadLength {
        got: usize,
        want: usize,
        width: usize,
        height: usize,
    },
    #[error("images differ in size: {a_w}x{a_h} and {b_w}x{b_h}")]
    SizeMismatch {
        a_w: usize,
        a_h: usize,
        b_w: usize,
        b_h: usize,
    },
    #[error("a clip needs at least 2 frames to score, got {0}")]
    TooFewFrames(usize),
}

pub type Result<T> = std::result::Result<T, Error>;

mod kernel;

/// A borrowed RGB24 image.
#[derive(Clone, Copy, Debug)]
pub struct Rgb<'a> {
    pub data: &'a [u8],
    pub width: usize,
    pub height: usize,
}

impl<'a> Rgb<'a> {
    /// Checks the buffer length.
    pub fn new(data: &'a [u8], width: usize, height: usize) -> Result<Self> {
        let want = width * height * 3;
        if data.len() != want {
            return Err(Error::BadLength {
                got: data.len(),
                want,
                width,
                height,
            });
        }
        Ok(Rgb { data, width, height })
    }

    fn check_min(&self, min: usize) -> Result<()> {
        if self.width < min || self.height < min {
            return Err(Error::TooSmall {
                width: self.width,
                height: self.height,
                min,
            });
        }
        Ok(())
    }
}

/// BT.601 luma, `Y = 0.299 R + 0.587 G + 0.114 B`, in f64 (not rounded).
pub fn luma(img: Rgb<'_>) -> Vec<f64> {
    let mut y = Vec::new();
    luma_into(img, &mut y);
    y
}

fn luma_into(img: Rgb<'_>, out: &mut Vec<f64>) {
    out.resize(img.data.len() / 3, 0.0);
    kernel::luma(img.data, out);
}

fn channel_into(img: Rgb<'_>, c: usize, out: &mut Vec<f64>) {
    out.clear();
    out.extend(img.data.chunks_exact(3).map(|p| f64::from(p[c])));
}

/// Brenner gradient parts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Brenner {
    /// `S_h + S_v`.
    pub raw: f64,
    /// `(S_h + S_v) / ((n_h + n_v) · 255²)`, in [0, 1].
    pub normalized: f64,
    /// Horizontal-only variant `S_h / (n_h · 255²)`.
    pub horizontal: f64,
}

/// Brenner gradient on luma, neighbour at distance 2, no threshold. Minimum size 3×3.
pub fn brenner(img: Rgb<'_>) -> Result<Brenner> {
    img.check_min(3)?;
    Ok(brenner_luma(&luma(img), img.width, img.height))
}

fn brenner_luma(y: &[f64], w: usize, h: usize) -> Brenner {
    let (sh, sv) = kernel::brenner_sums(y, w, h);
    let nh = (h * (w - 2)) as f64;
    let nv = ((h - 2) * w) as f64;
    let full = 255.0 * 255.0;
    Brenner {
        raw: sh + sv,
        normalized: (sh + sv) / ((nh + nv) * full),
        horizontal: sh / (nh * full),
    }
}

/// SSIM over luma or per RGB channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SsimMode {
    Gray,
    Rgb,
}

fn same_size(a: Rgb<'_>, b: Rgb<'_>) -> Result<()> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(Error::SizeMismatch {
            a_w: a.width,
            a_h: a.height,
            b_w: b.width,
            b_h: b.height,
        });
    }
    Ok(())
}

/// SSIM in [-1, 1] of two same-size images. Minimum size 11×11. Allocates scratch per
/// call; use a [`Scorer`] to score many frames.
pub fn ssim(a: Rgb<'_>, b: Rgb<'_>, mode: SsimMode) -> Result<f64> {
    Scorer::default().ssim(a, b, mode)
}

/// SSIM mapped to [0, 1] as `(s + 1) / 2`, never clipped.
pub fn ssim01(s: f64) -> f64 {
    (s + 1.0) / 2.0
}

/// Reusable buffers for scoring many frames without allocating per frame.
#[derive(Debug, Default, Clone)]
pub struct Scorer {
    a: Vec<f64>,
    b: Vec<f64>,
    scratch: kernel::Scratch,
}

impl Scorer {
    /// β of frame `a` paired with its successor `b`: Brenner of `a`, gray SSIM of the
    /// pair. What one frame of a clip costs when nothing is shared with its neighbours.
    pub fn beta_pair(&mut self, a: Rgb<'_>, b: Rgb<'_>) -> Result<FrameScore> {
        same_size(a, b)?;
        a.check_min(kernel::TAPS)?;
        luma_into(a, &mut self.a);
        luma_into(b, &mut self.b);
        let br = brenner_luma(&self.a, a.width, a.height);
        let s = kernel::ssim_planes(&self.a, &self.b, a.width, a.height, &mut self.scratch)?;
        Ok(FrameScore {
            brenner: br,
            ssim: s,
            beta: br.normalized * ssim01(s),
        })
    }

    /// SSIM in [-1, 1] of two same-size images (see [`ssim`]).
    pub fn ssim(&mut self, a: Rgb<'_>, b: Rgb<'_>, mode: SsimMode) -> Result<f64> {
        same_size(a, b)?;
        a.check_min(kernel::TAPS)?;
        let (w, h) = (a.width, a.height);
        match mode {
            SsimMode::Gray => {
                luma_into(a, &mut self.a);
                luma_into(b, &mut self.b);
                kernel::ssim_planes(&self.a, &self.b, w, h, &mut self.scratch)
            }
            SsimMode::Rgb => {
                let mut sum = 0.0;
                for c in 0..3 {
                    channel_into(a, c, &mut self.a);
                    channel_into(b, c, &mut self.b);
                    sum += kernel::ssim_planes(&self.a, &self.b, w, h, &mut self.scratch)?;
                }
                Ok(sum / 3.0)
            }
        }
    }
}

/// Scores of one frame of a clip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameScore {
    pub brenner: Brenner,
    /// SSIM (gray, in [-1, 1]) with the next frame; the last frame reuses the last pair.
    pub ssim: f64,
    /// `brenner.normalized · ssim01(ssim)`.
    pub beta: f64,
}

/// Streams a clip frame by frame: each frame's luma and Brenner are computed once and the
/// luma is kept for the next pair, so a clip of T frames costs T lumas, T Brenners and
/// T−1 SSIMs, with no allocation after the first frame.
#[derive(Debug, Default, Clone)]
pub struct ClipScorer {
    prev: Vec<f64>,
    cur: Vec<f64>,
    scratch: kernel::Scratch,
    size: Option<(usize, usize)>,
    prev_brenner: Option<Brenner>,
    last_ssim: Option<f64>,
    frames: usize,
}

impl ClipScorer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the next frame; returns the score of the previous frame, now that its pair is
    /// known. On error the clip state is unchanged.
    pub fn push(&mut self, img: Rgb<'_>) -> Result<Option<FrameScore>> {
        match self.size {
            Some((w, h)) if (w, h) != (img.width, img.height) => {
                return Err(Error::SizeMismatch {
                    a_w: w,
                    a_h: h,
                    b_w: img.width,
                    b_h: img.height,
                });
            }
            _ => img.check_min(kernel::TAPS)?,
        }
        let (w, h) = (img.width, img.height);
        luma_into(img, &mut self.cur);
        let b = brenner_luma(&self.cur, w, h);
        let out = match self.prev_brenner {
            Some(pb) => {
                let s = kernel::ssim_planes(&self.prev, &self.cur, w, h, &mut self.scratch)?;
                self.last_ssim = Some(s);
                Some(FrameScore {
                    brenner: pb,
                    ssim: s,
                    beta: pb.normalized * ssim01(s),
                })
            }
            None => None,
        };
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.prev_brenner = Some(b);
        self.size = Some((w, h));
        self.frames += 1;
        Ok(out)
    }

    /// Ends the clip: the last frame's score (it reuses the last pair's SSIM), and the
    /// scorer is ready for the next clip. A clip of fewer than 2 frames is an error.
    pub fn finish(&mut self) -> Result<FrameScore> {
        let frames = std::mem::take(&mut self.frames);
        let (b, s) = (self.prev_brenner.take(), self.last_ssim.take());
        self.size = None;
        match (b, s) {
            (Some(b), Some(s)) => Ok(FrameScore {
                brenner: b,
                ssim: s,
                beta: b.normalized * ssim01(s),
            }),
            _ => Err(Error::TooFewFrames(frames)),
        }
    }
}

/// β for every frame of a clip (h+v Brenner, gray SSIM, last-frame rule). T ≥ 2.
pub fn beta_video(frames: &[Rgb<'_>]) -> Result<Vec<FrameScore>> {
    if frames.len() < 2 {
        return Err(Error::TooFewFrames(frames.len()));
    }
    let mut c = ClipScorer::new();
    let mut out = Vec::with_capacity(frames.len());
    for f in frames {
        out.extend(c.push(*f)?);
    }
    out.push(c.finish()?);
    Ok(out)
}

/// [`beta_video`] split into `jobs` contiguous runs of frames scored in parallel on the
/// current rayon pool; each run re-reads one boundary frame. Same values as
/// [`beta_video`], bit for bit.
pub fn beta_video_par(frames: &[Rgb<'_>], jobs: usize) -> Result<Vec<FrameScore>> {
    use rayon::prelude::*;
    let n = frames.len();
    if n < 2 {
        return Err(Error::TooFewFrames(n));
    }
    let jobs = jobs.clamp(1, n - 1);
    // Run j scores frames [start_j, end_j) using frames up to end_j (inclusive) for pairs.
    let bounds: Vec<(usize, usize)> = (0..jobs)
        .map(|j| (j * (n - 1) / jobs, (j + 1) * (n - 1) / jobs))
        .collect();
    let parts: Vec<Vec<FrameScore>> = bounds
        .par_iter()
        .map(|&(s, e)| {
            let mut c = ClipScorer::new();
            let mut out = Vec::with_capacity(e - s + 1);
            for f in &frames[s..=e] {
                out.extend(c.push(*f)?);
            }
            let last = c.finish()?;
            if e == n - 1 {
                out.push(last);
            }
            Ok(out)
        })
        .collect::<Result<_>>()?;
    Ok(parts.into_iter().flatten().collect())
}

/// One frame's set-normalised weight, `(b − b_min)/(b_max − b_min) · ssim01(ssim)`, for
/// normalised Brenner `b`; with `b_max = b_min` every frame is equally sharp and the
/// Brenner factor is 1.
pub fn set_weight(b: f64, ssim: f64, bmin: f64, bmax: f64) -> f64 {
    let bw = if bmax > bmin {
        (b - bmin) / (bmax - bmin)
    } else {
        1.0
    };
    bw * ssim01(ssim)
}

/// The set normalisation over `scores`: `(b_min, b_max)` of the normalised Brenner values
/// and each frame's [`set_weight`].
pub fn set_weights(scores: &[FrameScore]) -> (f64, f64, Vec<f64>) {
    let bmin = scores
        .iter()
        .map(|s| s.brenner.normalized)
        .fold(f64::INFINITY, f64::min);
    let bmax = scores
        .iter()
        .map(|s| s.brenner.normalized)
        .fold(f64::NEG_INFINITY, f64::max);
    let weights = scores
        .iter()
        .map(|s| set_weight(s.brenner.normalized, s.ssim, bmin, bmax))
        .collect();
    (bmin, bmax, weights)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn img(w: usize, h: usize, f: impl Fn(usize, usize) -> [u8; 3]) -> Vec<u8> {
        let mut v = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                v.extend_from_slice(&f(x, y));
            }
        }
        v
    }

    #[test]
    fn identical_images_have_ssim_one_and_constant_brenner_zero() {
        let a = img(13, 17, |x, y| {
            [(x * 17) as u8, (y * 13) as u8, ((x + y) * 7) as u8]
        });
        let r = Rgb::new(&a, 13, 17).unwrap();
        assert!((ssim(r, r, SsimMode::Gray).unwrap() - 1.0).abs() < 1e-12);
        assert!((ssim(r, r, SsimMode::Rgb).unwrap() - 1.0).abs() < 1e-12);
        let c = vec![77u8; 12 * 12 * 3];
        let rc = Rgb::new(&c, 12, 12).unwrap();
        assert_eq!(brenner(rc).unwrap().raw, 0.0);
    }

    #[test]
    fn brenner_of_a_max_contrast_pattern_is_one() {
        // A checker of period 4: every distance-2 neighbour differs by 255, both directions.
        let a = img(8, 8, |x, y| {
            if ((x / 2) + (y / 2)) % 2 == 0 {
                [255; 3]
            } else {
                [0; 3]
            }
        });
        let b = brenner(Rgb::new(&a, 8, 8).unwrap()).unwrap();
        assert!((b.normalized - 1.0).abs() < 1e-12, "{b:?}");
        assert!((b.horizontal - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = vec![0u8; 10 * 10 * 3];
        let r = Rgb::new(&a, 10, 10).unwrap();
        assert!(matches!(ssim(r, r, SsimMode::Gray), Err(Error::TooSmall { .. })));
        assert!(matches!(Rgb::new(&a, 11, 10), Err(Error::BadLength { .. })));
        let b = vec![0u8; 12 * 11 * 3];
        let big = vec![0u8; 11 * 12 * 3];
        let (rb, rbig) = (Rgb::new(&b, 12, 11).unwrap(), Rgb::new(&big, 11, 12).unwrap());
        assert!(matches!(
            ssim(rb, rbig, SsimMode::Gray),
            Err(Error::SizeMismatch { .. })
        ));
        assert!(matches!(beta_video(&[rb]), Err(Error::TooFewFrames(1))));
        let tiny = vec![0u8; 2 * 2 * 3];
        assert!(brenner(Rgb::new(&tiny, 2, 2).unwrap()).is_err());
    }

    #[test]
    fn the_last_frame_reuses_the_last_pair() {
        let f: Vec<Vec<u8>> = (0..3)
            .map(|k| img(12, 12, |x, y| [((x * y + k * 40) % 256) as u8; 3]))
            .collect();
        let frames: Vec<Rgb<'_>> = f.iter().map(|v| Rgb::new(v, 12, 12).unwrap()).collect();
        let s = beta_video(&frames).unwrap();
        assert_eq!(s.len(), 3);
        assert_eq!(s[2].ssim, s[1].ssim);
        assert!((s[0].beta - s[0].brenner.normalized * ssim01(s[0].ssim)).abs() < 1e-15);
        let (lo, hi, w) = set_weights(&s);
        assert!(lo <= hi && w.iter().all(|v| (0.0..=1.0).contains(v)));
    }

    #[test]
    fn parallel_clip_scores_equal_serial_bit_for_bit() {
        let f: Vec<Vec<u8>> = (0..9)
            .map(|k| {
                img(23, 14, |x, y| {
                    [((x * 7 + y * k * 3) % 256) as u8, (x * y % 256) as u8, k as u8]
                })
            })
            .collect();
        let frames: Vec<Rgb<'_>> = f.iter().map(|v| Rgb::new(v, 23, 14).unwrap()).collect();
        let serial = beta_video(&frames).unwrap();
        for jobs in [1, 2, 3, 8, 20] {
            assert_eq!(beta_video_par(&frames, jobs).unwrap(), serial, "jobs {jobs}");
        }
        // Each pair's SSIM equals the free function's.
        assert_eq!(
            serial[3].ssim,
            ssim(frames[3], frames[4], SsimMode::Gray).unwrap()
        );
    }

    #[test]
    fn a_clip_rejects_a_frame_of_another_size_and_keeps_going() {
        let a = img(12, 12, |x, y| [(x * 20) as u8, (y * 20) as u8, 0]);
        let b = img(13, 12, |x, _| [(x * 20) as u8; 3]);
        let mut c = ClipScorer::new();
        assert!(c.push(Rgb::new(&a, 12, 12).unwrap()).unwrap().is_none());
        assert!(matches!(
            c.push(Rgb::new(&b, 13, 12).unwrap()),
            Err(Error::SizeMismatch { .. })
        ));
        assert!(c.push(Rgb::new(&a, 12, 12).unwrap()).unwrap().is_some());
        let last = c.finish().unwrap();
        assert!((last.ssim - 1.0).abs() < 1e-12);
        assert!(matches!(c.finish(), Err(Error::TooFewFrames(0))));
    }
}
