//! `track` features: the human's hand tracked in the image, the robot's end effector read
//! from its states, related by an affine camera fitted per pair.
//!
//! Progress along the path as each camera sees it is not comparable across cameras: a
//! stretch that runs towards one camera is short in its image and long in the other's
//! (on the MuJoCo set, even a perfect image-space tracker aligns to no better than 0.63×
//! the proportional warp). The robot's states give its end-effector path in 3-D; the
//! human clip shows the same path through one unknown camera. So the robot path is
//! mapped into the human image by the affine map that best fits the current alignment,
//! the pair is re-aligned on image positions, and the two steps alternate
//! (a resection inside DTW, in the spirit of canonical time warping).
//!
//! * human clip: [`crate::klt::hand_track`] (or, when no point survives, the tip from
//!   frame differences of [`crate::motion::TipTracker`]), cleaned (5-frame median, Gaussian σ = 1.5
//!   frames), centred and scaled; features `[progress, x, y]`.
//! * robot clip: its state vectors (any width: 3-D end-effector positions, or milv-sim's
//!   2-D table positions), centred and scaled.
//! * [`FeatureKind::fit_pair`]: start from the alignment of progress alone, then
//!   [`ROUNDS`] × (fit the affine map state → image on the alignment, project, re-align);
//!   the robot's features become `[progress, x, y]` of its projected path.

use crate::dtw::Features;
use crate::features::{Aligner, Clip, FeatureKind};
use crate::{Error, klt, motion};

pub struct Track;

/// Alternations of fitting the camera and re-aligning.
pub const ROUNDS: usize = 8;
/// Weight of progress against the two position columns.
pub const PROGRESS_WEIGHT: f64 = 1.0;
const D: usize = 3;

impl FeatureKind for Track {
    fn name(&self) -> &'static str {
        "track"
    }

    fn untrusted_cost(&self) -> f64 {
        // MuJoCo design seeds 1+2: every pair above this was off, none trusted below it was
        // worse than proportional; held-out seeds overlap (BENCHMARKS.md).
        0.01
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        match clip.domain {
            milv_data::Domain::Human => human_features(clip),
            milv_data::Domain::Robot => robot_states(clip),
        }
    }

    fn fit_pair(&self, human: &Features, robot: Features, align: &Aligner) -> Features {
        if human.d != D || robot.n < 2 {
            return robot;
        }
        let hxy: Vec<[f64; 2]> = (0..human.n).map(|i| [human.row(i)[1], human.row(i)[2]]).collect();
        let hprog = Features::new(
            human.n,
            1,
            (0..human.n).map(|i| human.row(i)[0] / PROGRESS_WEIGHT).collect(),
        );
        let rprog = Features::new(
            robot.n,
            1,
            progress(&(0..robot.n).map(|j| robot.row(j).to_vec()).collect::<Vec<_>>()),
        );
        let (Ok(hprog), Ok(rprog)) = (hprog, rprog) else {
            return robot;
        };
        let Some(mut w) = align(&hprog, &rprog) else {
            return robot;
        };
        let mut out = None;
        for _ in 0..ROUNDS {
            let Some(map) = fit_affine(&robot, &w, &hxy) else {
                break;
            };
            let projected = project(&robot, &map);
            let Ok(f) = features_of(&projected) else {
                break;
            };
            let Some(next) = align(human, &f) else {
                break;
            };
            out = Some(f);
            if next == w {
                break;
            }
            w = next;
        }
        out.unwrap_or(robot)
    }
}

/// The human clip's tracked hand as `[progress, x, y]`.
fn human_features(clip: &Clip) -> Result<Features, Error> {
    let (frames, w, h) = clip.all_rgb()?;
    let n = frames.len();
    // Untextured, flat-shaded arms (milv-sim's) give the point tracker nothing to hold:
    // then the tip found from frame differences stands in, in image coordinates.
    let track = match klt::hand_track(&frames, w, h) {
        Some(t) => t,
        None => {
            let mut tips = motion::TipTracker::new(w, h, n);
            for f in frames {
                tips.push(f);
            }
            tips.finish()
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "episode {}: nothing moves in the clip (track features need a moving arm)",
                        clip.episode_id
                    ))
                })?
                .tips
        }
    };
    let clean = |c: fn(&(f64, f64)) -> f64| {
        let v: Vec<f64> = track.iter().map(c).collect();
        motion::gaussian_filter(&motion::median_filter(&v, 5), 1.5)
    };
    let (xs, ys) = (clean(|p| p.0), clean(|p| p.1));
    let rows: Vec<Vec<f64>> = xs.iter().zip(&ys).map(|(&x, &y)| vec![x, y]).collect();
    features_of(&standardized(&rows))
}

/// The robot clip's states, centred and scaled (one scale for all columns, so the path's
/// shape is kept).
fn robot_states(clip: &Clip) -> Result<Features, Error> {
    let rows = clip.state_rows(
        "track features map the robot's end-effector states into the human's image; \
         use --features motion for clips without states",
    )?;
    let d = rows[0].len();
    let rows = standardized(&rows);
    Features::new(rows.len(), d, rows.concat())
}

/// Rows minus their mean, over the mean of the columns' standard deviations.
fn standardized(rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (n, d) = (rows.len() as f64, rows.first().map_or(0, Vec::len));
    let mean: Vec<f64> = (0..d)
        .map(|k| rows.iter().map(|r| r[k]).sum::<f64>() / n)
        .collect();
    let sd = (0..d)
        .map(|k| (rows.iter().map(|r| (r[k] - mean[k]).powi(2)).sum::<f64>() / n).sqrt())
        .sum::<f64>()
        / d.max(1) as f64;
    let sd = if sd > 1e-12 { sd } else { 1.0 };
    rows.iter()
        .map(|r| r.iter().zip(&mean).map(|(v, m)| (v - m) / sd).collect())
        .collect()
}

/// Arc length travelled so far over the whole path's (0 → 1); time when nothing moves.
fn progress(rows: &[Vec<f64>]) -> Vec<f64> {
    let n = rows.len();
    let mut done = vec![0.0; n];
    for t in 1..n {
        let step: f64 = rows[t]
            .iter()
            .zip(&rows[t - 1])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        done[t] = done[t - 1] + step;
    }
    let total = done[n.saturating_sub(1)];
    if total > 1e-12 {
        done.iter().map(|d| d / total).collect()
    } else {
        (0..n).map(|t| t as f64 / (n - 1).max(1) as f64).collect()
    }
}

/// `[PROGRESS_WEIGHT · progress, x, y]` of an image path.
fn features_of(xy: &[Vec<f64>]) -> Result<Features, Error> {
    let p = progress(xy);
    let data = xy
        .iter()
        .zip(&p)
        .flat_map(|(r, &p)| [PROGRESS_WEIGHT * p, r[0], r[1]])
        .collect();
    Features::new(xy.len(), D, data)
}

/// Least-squares affine map (a `(d + 1) × 2` matrix, last row the offset) taking robot
/// state `w[i]` to human image point `i`; `None` when the states are degenerate.
fn fit_affine(robot: &Features, w: &[usize], hxy: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
    let k = robot.d + 1;
    // Normal equations, with a whisker of ridge so a flat state column does not stop it.
    let mut a = vec![vec![0.0; k + 2]; k];
    for (i, &j) in w.iter().enumerate() {
        let x: Vec<f64> = robot.row(j).iter().copied().chain([1.0]).collect();
        for r in 0..k {
            for c in 0..k {
                a[r][c] += x[r] * x[c];
            }
            a[r][k] += x[r] * hxy[i][0];
            a[r][k + 1] += x[r] * hxy[i][1];
        }
    }
    for (r, row) in a.iter_mut().enumerate() {
        row[r] += 1e-6;
    }
    // Gauss–Jordan with partial pivoting on the two right-hand sides at once.
    for c in 0..k {
        let p = (c..k).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        if a[p][c].abs() < 1e-12 {
            return None;
        }
        a.swap(c, p);
        let pivot = a[c].clone();
        for (r, row) in a.iter_mut().enumerate() {
            if r != c {
                let f = row[c] / pivot[c];
                for (x, p) in row.iter_mut().zip(&pivot).skip(c) {
                    *x -= f * p;
                }
            }
        }
    }
    Some(
        (0..k)
            .map(|r| [a[r][k] / a[r][r], a[r][k + 1] / a[r][r]])
            .collect(),
    )
}

fn project(robot: &Features, map: &[[f64; 2]]) -> Vec<Vec<f64>> {
    let d = robot.d;
    (0..robot.n)
        .map(|j| {
            let s = robot.row(j);
            (0..2)
                .map(|o| s.iter().zip(map).map(|(v, m)| v * m[o]).sum::<f64>() + map[d][o])
                .collect()
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::dtw::{Band, StepPattern, dtw, row_to_col};

    fn aligner(h: &Features, r: &Features) -> Option<Vec<usize>> {
        let w = (0.2 * h.n.max(r.n) as f64).ceil() as usize;
        let al = dtw(
            h,
            r,
            &Band::around_diagonal(h.n, r.n, w),
            StepPattern::Symmetric2,
            true,
        )
        .ok()?;
        Some(row_to_col(&al.path, h.n))
    }

    /// A 3-D curve with depth, and its point at arc-length-free parameter `s`.
    fn curve(s: f64) -> [f64; 3] {
        [s, (3.0 * s).sin() * 0.4, 0.5 * s * s]
    }

    #[test]
    fn an_affine_view_of_the_robot_path_is_recovered_with_its_time_warp() {
        // Robot: uniform in s over 60 frames. Human: the same curve at a warped pace,
        // 45 frames, seen through an affine camera that loses the depth axis.
        let robot: Vec<Vec<f64>> = (0..60).map(|j| curve(j as f64 / 59.0).to_vec()).collect();
        let warp = |i: usize| (i as f64 / 44.0).powf(1.6);
        let human: Vec<Vec<f64>> = (0..45)
            .map(|i| {
                let p = curve(warp(i));
                vec![
                    0.8 * p[0] - 0.3 * p[1] + 0.2 * p[2] + 2.0,
                    0.1 * p[0] + 0.9 * p[1] - 0.6 * p[2] - 1.0,
                ]
            })
            .collect();
        let truth: Vec<f64> = (0..45).map(|i| warp(i) * 59.0).collect();
        let hf = features_of(&standardized(&human)).unwrap();
        let rs = standardized(&robot);
        let rf = Features::new(60, 3, rs.concat()).unwrap();
        let fitted = Track.fit_pair(&hf, rf, &aligner);
        assert_eq!(fitted.d, D);
        let got = aligner(&hf, &fitted).unwrap();
        let err: f64 = got
            .iter()
            .zip(&truth)
            .map(|(&g, t)| (g as f64 - t).abs())
            .sum::<f64>()
            / 45.0;
        let prop: f64 = crate::align::proportional_warp(45, 60)
            .iter()
            .zip(&truth)
            .map(|(&g, t)| (g as f64 - t).abs())
            .sum::<f64>()
            / 45.0;
        assert!(
            err < 1.5 && err < 0.25 * prop,
            "error {err} vs proportional {prop}"
        );
    }

    #[test]
    fn a_robot_clip_without_states_is_refused_with_its_name() {
        let clip = Clip {
            episode_id: "r7".into(),
            domain: milv_data::Domain::Robot,
            encoding: milv_data::frame_codec::FrameEncoding::Png,
            width: 4,
            height: 4,
            images: vec![],
            states: None,
        };
        let e = Track.extract(&clip).unwrap_err().to_string();
        assert!(e.contains("r7") && e.contains("no state vectors"), "{e}");
    }
}
