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
//! | [`beta_video`] | β per frame of a clip with the last-frame rule |
//! | [`set_weights`] | the set-normalised loss weight |
//!
//! Pure functions over `&[u8]` RGB24 plus dimensions: no I/O, no panics on bad sizes.

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
    img.data
        .chunks_exact(3)
        .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
        .collect()
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
    let y = luma(img);
    Ok(brenner_luma(&y, img.width, img.height))
}

fn brenner_luma(y: &[f64], w: usize, h: usize) -> Brenner {
    let mut sh = 0.0;
    let mut sv = 0.0;
    for r in 0..h {
        let row = &y[r * w..(r + 1) * w];
        for x in 0..w - 2 {
            let d = row[x + 2] - row[x];
            sh += d * d;
        }
        if r + 2 < h {
            let below = &y[(r + 2) * w..(r + 3) * w];
            for x in 0..w {
                let d = below[x] - row[x];
                sv += d * d;
            }
        }
    }
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

const RADIUS: usize = 5;
const TAPS: usize = 2 * RADIUS + 1;

fn gaussian() -> [f64; TAPS] {
    let mut w = [0.0; TAPS];
    for (i, v) in w.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        *v = (-d * d / (2.0 * 1.5 * 1.5)).exp();
    }
    let s: f64 = w.iter().sum();
    w.map(|v| v / s)
}

/// Valid separable convolution of a plane with the Gaussian: (h-10)×(w-10).
fn blur_valid(src: &[f64], w: usize, h: usize, g: &[f64; TAPS]) -> Vec<f64> {
    let ow = w - 2 * RADIUS;
    let oh = h - 2 * RADIUS;
    let mut tmp = vec![0.0; ow * h];
    for r in 0..h {
        let row = &src[r * w..(r + 1) * w];
        let out = &mut tmp[r * ow..(r + 1) * ow];
        for (x, o) in out.iter_mut().enumerate() {
            *o = g.iter().zip(&row[x..x + TAPS]).map(|(a, b)| a * b).sum();
        }
    }
    let mut dst = vec![0.0; ow * oh];
    for r in 0..oh {
        for (k, gk) in g.iter().enumerate() {
            let src_row = &tmp[(r + k) * ow..(r + k + 1) * ow];
            let out = &mut dst[r * ow..(r + 1) * ow];
            for (o, v) in out.iter_mut().zip(src_row) {
                *o += gk * v;
            }
        }
    }
    dst
}

/// Mean SSIM of two planes (population moments, valid region), scikit-image's recipe.
fn ssim_planes(x: &[f64], y: &[f64], w: usize, h: usize) -> f64 {
    let g = gaussian();
    let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
    let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
    let xy: Vec<f64> = x.iter().zip(y).map(|(a, b)| a * b).collect();
    let (ux, uy) = (blur_valid(x, w, h, &g), blur_valid(y, w, h, &g));
    let (uxx, uyy, uxy) = (
        blur_valid(&xx, w, h, &g),
        blur_valid(&yy, w, h, &g),
        blur_valid(&xy, w, h, &g),
    );
    let c1 = (0.01f64 * 255.0).powi(2);
    let c2 = (0.03f64 * 255.0).powi(2);
    let n = ux.len() as f64;
    let mut sum = 0.0;
    for i in 0..ux.len() {
        let (mx, my) = (ux[i], uy[i]);
        let vx = uxx[i] - mx * mx;
        let vy = uyy[i] - my * my;
        let vxy = uxy[i] - mx * my;
        sum += ((2.0 * mx * my + c1) * (2.0 * vxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
    }
    sum / n
}

fn channel(img: Rgb<'_>, c: usize) -> Vec<f64> {
    img.data.chunks_exact(3).map(|p| f64::from(p[c])).collect()
}

/// SSIM in [-1, 1] of two same-size images. Minimum size 11×11.
pub fn ssim(a: Rgb<'_>, b: Rgb<'_>, mode: SsimMode) -> Result<f64> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(Error::SizeMismatch {
            a_w: a.width,
            a_h: a.height,
            b_w: b.width,
            b_h: b.height,
        });
    }
    a.check_min(TAPS)?;
    let (w, h) = (a.width, a.height);
    Ok(match mode {
        SsimMode::Gray => ssim_planes(&luma(a), &luma(b), w, h),
        SsimMode::Rgb => {
            (0..3)
                .map(|c| ssim_planes(&channel(a, c), &channel(b, c), w, h))
                .sum::<f64>()
                / 3.0
        }
    })
}

/// SSIM mapped to [0, 1] as `(s + 1) / 2`, never clipped.
pub fn ssim01(s: f64) -> f64 {
    (s + 1.0) / 2.0
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

/// β for every frame of a clip (h+v Brenner, gray SSIM, last-frame rule). T ≥ 2.
pub fn beta_video(frames: &[Rgb<'_>]) -> Result<Vec<FrameScore>> {
    if frames.len() < 2 {
        return Err(Error::TooFewFrames(frames.len()));
    }
    let pairs: Vec<f64> = frames
        .windows(2)
        .map(|p| ssim(p[0], p[1], SsimMode::Gray))
        .collect::<Result<_>>()?;
    frames
        .iter()
        .enumerate()
        .map(|(t, f)| {
            let b = brenner(*f)?;
            let s = pairs[t.min(pairs.len() - 1)];
            Ok(FrameScore {
                brenner: b,
                ssim: s,
                beta: b.normalized * ssim01(s),
            })
        })
        .collect()
}

/// The set normalisation: `(b_min, b_max)` over normalised Brenner values, and each
/// frame's `weight = (b − b_min)/(b_max − b_min) · ssim01`. With `b_max = b_min` every
/// frame is equally sharp and the Brenner factor is 1.
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
        .map(|s| {
            let bw = if bmax > bmin {
                (s.brenner.normalized - bmin) / (bmax - bmin)
            } else {
                1.0
            };
            bw * ssim01(s.ssim)
        })
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
}
