//! Per-frame features that mean the same thing in both domains.
//!
//! Pixels do not: the arms look different and the cameras see the table from opposite
//! sides. A [`FeatureKind`] turns one clip into a [`Features`] matrix, and may adjust the
//! robot clip's features to the human's before alignment ([`FeatureKind::fit_pair`]);
//! the aligner knows nothing else about them, so a new kind (e.g. one reading a learned
//! embedding) plugs in without touching it.

use milv_data::frame_codec::{self, FrameEncoding};

use crate::Error;
use crate::dtw::Features;

/// One clip as stored: encoded frames (from `frames`, or `imagined` for translated human
/// clips) and, when the episode has them, per-frame state vectors.
#[derive(Clone, Debug)]
pub struct Clip {
    pub episode_id: String,
    pub domain: String,
    pub encoding: FrameEncoding,
    pub width: u32,
    pub height: u32,
    pub images: Vec<Vec<u8>>,
    pub states: Option<Vec<Vec<f32>>>,
}

impl Clip {
    /// Decodes frame `t` to RGB24 (imagined frames are PNGs of any size).
    pub fn rgb(&self, t: usize) -> Result<(Vec<u8>, usize, usize), Error> {
        let bytes = &self.images[t];
        let bad = |e: String| {
            Error::Invalid(format!(
                "episode {}: frame {t}: undecodable image: {e}",
                self.episode_id
            ))
        };
        if self.width == 0 {
            let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
                .map_err(|e| bad(e.to_string()))?
                .into_rgb8();
            let (w, h) = (img.width() as usize, img.height() as usize);
            return Ok((img.into_raw(), w, h));
        }
        let rgb = frame_codec::decode(self.encoding, bytes, self.width, self.height)
            .map_err(|e| bad(e.to_string()))?;
        Ok((rgb, self.width as usize, self.height as usize))
    }
}

/// Which table each side's frames come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipSource {
    Frames,
    /// The human clip's translation into the robot domain (`imagined` table).
    Imagined,
}

/// A way to describe every frame of a clip.
pub trait FeatureKind: Sync {
    fn name(&self) -> &'static str;

    /// Where the human clip's frames come from (the robot clip always uses `frames`).
    fn human_source(&self) -> ClipSource {
        ClipSource::Frames
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error>;

    /// Adjusts the robot features to the human ones before alignment (e.g. resolving
    /// camera axis flips). Default: nothing.
    fn fit_pair(&self, _human: &Features, robot: Features) -> Features {
        robot
    }
}

/// End-effector / state columns, z-normalised per clip. Both episodes must carry states
/// of the same width.
pub struct State;

impl FeatureKind for State {
    fn name(&self) -> &'static str {
        "state"
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        let states = clip.states.as_ref().ok_or_else(|| {
            Error::Invalid(format!(
                "episode {} has no state vectors (use --features motion)",
                clip.episode_id
            ))
        })?;
        let d = states.first().map_or(0, Vec::len);
        if d == 0 || states.iter().any(|s| s.len() != d) {
            return Err(Error::Invalid(format!(
                "episode {}: state vectors missing or of mixed widths",
                clip.episode_id
            )));
        }
        let data = states.iter().flatten().map(|&v| f64::from(v)).collect();
        Ok(Features::new(states.len(), d, data)?.z_normalized())
    }
}

/// Luma of an RGB24 frame averaged over `f×f` blocks.
fn block_luma(rgb: &[u8], w: usize, h: usize, f: usize) -> (Vec<f64>, usize, usize) {
    let (sw, sh) = (w / f, h / f);
    let mut out = vec![0.0; sw * sh];
    for y in 0..sh * f {
        for x in 0..sw * f {
            let p = &rgb[(y * w + x) * 3..(y * w + x) * 3 + 3];
            out[(y / f) * sw + x / f] +=
                0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]);
        }
    }
    let norm = (f * f) as f64;
    out.iter_mut().for_each(|v| *v /= norm);
    (out, sw, sh)
}

/// Where the arm's tip is, from pixels alone, in a way that survives a change of
/// embodiment and viewpoint:
/// 1. frames are reduced to a coarse luma grid (about 21 cells on the short side, which
///    keeps the arm and drops texture);
/// 2. the background is the per-cell median over the clip (the arm moves, the table does
///    not), and the foreground is what differs from it by more than 30 % of the frame's
///    largest difference (at least 10 grey levels);
/// 3. the arm enters the picture from the side whose border row holds the most
///    foreground over the clip; its tip is the foreground row farthest from that side,
///    and the feature is that row and the mean column on it (image-normalised);
/// 4. a 3-frame moving average, then z-normalisation per clip.
///
/// The two cameras look from different sides, so [`FeatureKind::fit_pair`] picks the
/// signed axis permutation of the robot's (column, row) that best matches the human's,
/// both resampled to one length.
pub struct Motion;

const MOTION_D: usize = 2;
const GRID_CELLS: usize = 21;

impl FeatureKind for Motion {
    fn name(&self) -> &'static str {
        "motion"
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        let n = clip.images.len();
        let mut grids = Vec::with_capacity(n);
        let mut size = None;
        for t in 0..n {
            let (rgb, w, h) = clip.rgb(t)?;
            let f = (w.min(h) / GRID_CELLS).max(1);
            let g = block_luma(&rgb, w, h, f);
            if size.is_some_and(|s| s != (g.1, g.2)) {
                return Err(Error::Invalid(format!(
                    "episode {}: frame {t} changes size",
                    clip.episode_id
                )));
            }
            size = Some((g.1, g.2));
            grids.push(g.0);
        }
        let (sw, sh) = size.unwrap_or((0, 0));
        let cells = sw * sh;
        let mut bg = vec![0.0; cells];
        let mut col = vec![0.0; n];
        for (c, b) in bg.iter_mut().enumerate() {
            for (t, g) in grids.iter().enumerate() {
                col[t] = g[c];
            }
            col.sort_by(f64::total_cmp);
            *b = col[n / 2];
        }
        let masks: Vec<Vec<bool>> = grids
            .iter()
            .map(|g| {
                let d: Vec<f64> = g.iter().zip(&bg).map(|(a, b)| (a - b).abs()).collect();
                let thr = d.iter().copied().fold(0.0, f64::max).mul_add(0.3, 0.0).max(10.0);
                d.iter().map(|&v| v > thr).collect()
            })
            .collect();
        // Entry side: 0 bottom, 1 top, 2 left, 3 right.
        let mut border = [0usize; 4];
        for m in &masks {
            for x in 0..sw {
                border[0] += usize::from(m[(sh - 1) * sw + x]);
                border[1] += usize::from(m[x]);
            }
            for y in 0..sh {
                border[2] += usize::from(m[y * sw]);
                border[3] += usize::from(m[y * sw + sw - 1]);
            }
        }
        // Ties (e.g. an arm that never touches the border) resolve to the bottom.
        let side = (0..4).rev().max_by_key(|&s| border[s]).unwrap_or(0);
        // View every grid with the entry side at the bottom: (u across, v up from entry).
        let (uw, vh) = if side < 2 { (sw, sh) } else { (sh, sw) };
        let at = |m: &[bool], u: usize, v: usize| -> bool {
            let (x, y) = match side {
                0 => (u, sh - 1 - v),
                1 => (sw - 1 - u, v),
                2 => (v, u),
                _ => (sw - 1 - v, sh - 1 - u),
            };
            m[y * sw + x]
        };
        let mut data = Vec::with_capacity(n * MOTION_D);
        for m in &masks {
            let tip = (0..vh).rev().find(|&v| (0..uw).any(|u| at(m, u, v)));
            let row = match tip {
                Some(v) => {
                    let us: Vec<usize> = (0..uw)
                        .filter(|&u| at(m, u, v) || (v > 0 && at(m, u, v - 1)))
                        .collect();
                    let mean_u = us.iter().sum::<usize>() as f64 / us.len().max(1) as f64;
                    [mean_u / uw as f64, v as f64 / vh as f64]
                }
                None => [0.5, 0.0],
            };
            data.extend_from_slice(&row);
        }
        let smoothed: Vec<f64> = (0..n)
            .flat_map(|t| {
                let (a, b) = (t.saturating_sub(1), (t + 1).min(n - 1));
                let data = &data;
                (0..MOTION_D).map(move |k| {
                    (data[a * MOTION_D + k] + data[t * MOTION_D + k] + data[b * MOTION_D + k]) / 3.0
                })
            })
            .collect();
        Ok(Features::new(n, MOTION_D, smoothed)?.z_normalized())
    }

    fn fit_pair(&self, human: &Features, robot: Features) -> Features {
        // Candidate maps of (u, v): identity or swapped axes, each with the sign that
        // correlates best.
        let k = 64;
        let resample = |f: &Features, c: usize| -> Vec<f64> {
            (0..k)
                .map(|s| {
                    let i = ((s as f64 / (k - 1) as f64) * (f.n - 1) as f64).round() as usize;
                    f.data[i * f.d + c]
                })
                .collect()
        };
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (hx, hy) = (resample(human, 0), resample(human, 1));
        let (rx, ry) = (resample(&robot, 0), resample(&robot, 1));
        let sign = |c: f64| if c < 0.0 { -1.0 } else { 1.0 };
        let mut best = (f64::NEG_INFINITY, false, 1.0, 1.0);
        for swap in [false, true] {
            let (ax, ay) = if swap { (&ry, &rx) } else { (&rx, &ry) };
            let (cx, cy) = (dot(&hx, ax), dot(&hy, ay));
            if cx.abs() + cy.abs() > best.0 {
                best = (cx.abs() + cy.abs(), swap, sign(cx), sign(cy));
            }
        }
        let (_, swap, sx, sy) = best;
        let mut out = robot;
        for r in out.data.chunks_exact_mut(MOTION_D) {
            if swap {
                r.swap(0, 1);
            }
            r[0] *= sx;
            r[1] *= sy;
        }
        out
    }
}

/// The human clip translated into the robot domain (`imagined` table of one model) and
/// the robot clip, compared in pixel space: 16×16 luma thumbnails, z-normalised per
/// clip. Needs `milv-train translate` to have run.
pub struct Translated;

const THUMB: usize = 16;

impl FeatureKind for Translated {
    fn name(&self) -> &'static str {
        "translated"
    }

    fn human_source(&self) -> ClipSource {
        ClipSource::Imagined
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        let n = clip.images.len();
        let mut data = Vec::with_capacity(n * THUMB * THUMB);
        for t in 0..n {
            let (rgb, w, h) = clip.rgb(t)?;
            if w < THUMB || h < THUMB {
                return Err(Error::Invalid(format!(
                    "episode {}: frame {t} is smaller than {THUMB}x{THUMB}",
                    clip.episode_id
                )));
            }
            for ty in 0..THUMB {
                for tx in 0..THUMB {
                    let (y0, y1) = (ty * h / THUMB, (ty + 1) * h / THUMB);
                    let (x0, x1) = (tx * w / THUMB, (tx + 1) * w / THUMB);
                    let mut s = 0.0;
                    for y in y0..y1 {
                        for x in x0..x1 {
                            let p = &rgb[(y * w + x) * 3..(y * w + x) * 3 + 3];
                            s += 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]);
                        }
                    }
                    data.push(s / ((y1 - y0) * (x1 - x0)) as f64);
                }
            }
        }
        Ok(Features::new(n, THUMB * THUMB, data)?.z_normalized())
    }
}

/// The feature kind named on the command line.
pub fn by_name(name: &str) -> Result<&'static dyn FeatureKind, Error> {
    match name {
        "motion" => Ok(&Motion),
        "state" => Ok(&State),
        "translated" => Ok(&Translated),
        _ => Err(Error::Invalid(format!(
            "unknown features {name:?} (motion | state | translated)"
        ))),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A dark "arm" entering from `side` (0 bottom, 1 top) whose tip reaches `reach[t]`
    /// of the way across a 64×48 grey frame, at column `col[t]`.
    fn clip(side: u8, reach: &[f64], col: &[f64]) -> Clip {
        let (w, h) = (64usize, 48usize);
        let images = reach
            .iter()
            .zip(col)
            .map(|(&r, &c)| {
                let mut rgb = vec![200u8; w * h * 3];
                let len = (r * h as f64) as usize;
                let x0 = (c * (w - 8) as f64) as usize;
                for k in 0..len {
                    let y = if side == 0 { h - 1 - k } else { k };
                    for x in x0..x0 + 8 {
                        rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[30, 30, 30]);
                    }
                }
                let mut png = Vec::new();
                frame_codec::encode(FrameEncoding::Png, &rgb, w as u32, h as u32, &mut png).unwrap();
                png
            })
            .collect();
        Clip {
            episode_id: "e".into(),
            domain: "human".into(),
            encoding: FrameEncoding::Png,
            width: w as u32,
            height: h as u32,
            images,
            states: None,
        }
    }

    #[test]
    fn motion_follows_the_tip_whichever_side_the_arm_enters_from() {
        let reach: Vec<f64> = (0..20).map(|t| 0.2 + 0.6 * (t as f64 / 19.0)).collect();
        let col: Vec<f64> = (0..20).map(|t| (t as f64 / 19.0 * 3.0).sin().abs()).collect();
        let from_bottom = Motion.extract(&clip(0, &reach, &col)).unwrap();
        let from_top = Motion.extract(&clip(1, &reach, &col)).unwrap();
        // The "how far in" coordinate rises with reach in both clips.
        for f in [&from_bottom, &from_top] {
            let v: Vec<f64> = (0..f.n).map(|i| f.row(i)[1]).collect();
            assert!(v.windows(2).filter(|w| w[1] < w[0] - 1e-9).count() <= 2, "{v:?}");
            assert!(v[19] > v[0]);
        }
        // Fitting the pair undoes the mirrored column axis of the top view.
        let fitted = Motion.fit_pair(&from_bottom, from_top);
        let corr: f64 = (0..20)
            .map(|i| fitted.row(i)[0] * from_bottom.row(i)[0])
            .sum::<f64>()
            / 20.0;
        assert!(corr > 0.8, "{corr}");
    }

    #[test]
    fn state_features_need_states() {
        let c = clip(0, &[0.5, 0.6], &[0.1, 0.2]);
        assert!(
            State
                .extract(&c)
                .unwrap_err()
                .to_string()
                .contains("no state vectors")
        );
        let mut c = c;
        c.states = Some(vec![vec![1.0, 2.0], vec![3.0, 5.0]]);
        let f = State.extract(&c).unwrap();
        assert_eq!((f.n, f.d), (2, 2));
        assert_eq!(f.row(0), [-1.0, -1.0]);
        assert!(by_name("pixels").is_err());
    }
}
