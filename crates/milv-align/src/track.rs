//! `track` features: the human's hand tracked in the image, the robot's end effector read
//! from its states, related by an affine camera fitted per pair.
//!
//! Progress along the path as each camera sees it is not comparable across cameras: a
//! stretch that runs towards one camera is short in its image and long in the other's
//! (on the MuJoCo set, even a perfect image-space tracker aligns to no better than 0.63×
//! the proportional warp). The robot's states give its end-effector path in 3-D; the
//! human clip shows the same path through one unknown camera. So the robot path is
//! mapped into the human image by the affine map that best fits the current alignment,
//! the pair is re-aligned on image positions, and the two steps alternate until the
//! alignment stops changing (a resection inside DTW, in the spirit of canonical time
//! warping).
//!
//! * human clip: the [`klt::TOP_POINTS`] most travelled points of [`klt::hand_tracks`]
//!   (or, when no point survives, the tip from frame differences of
//!   [`motion::TipTracker`]), each cleaned (3-frame median, Gaussian σ = 0.75 frames),
//!   centred and scaled together; features `[progress, x₁, y₁, …, x_K, y_K]`, progress
//!   along the path of the points' per-frame median.
//! * robot clip: its state vectors (any width: 3-D end-effector positions, or milv-sim's
//!   2-D table positions), centred and scaled.
//! * [`FeatureKind::fit_pair`]: one affine map state → all K image points (each point is
//!   its own view of the hand), alternated with re-alignment up to [`ROUNDS`] times, from
//!   two starts (the alignment of progress alone, and the proportional warp); the start
//!   whose fit leaves the smaller residual wins. The robot's features become
//!   `[progress, points]` of its projected path.

use crate::dtw::Features;
use crate::features::{Aligner, Clip, FeatureKind};
use crate::{Error, klt, motion};

pub struct Track;

/// `track`'s trust bound (cost per dimension). MuJoCo design seeds 1+2: every pair above
/// this was off, none trusted below it was worse than proportional; held-out seeds overlap
/// (BENCHMARKS.md).
pub const TRACK_MAX_COST: f64 = 0.01;

/// Most alternations of fitting the camera and re-aligning (most pairs settle in < 10).
pub const ROUNDS: usize = 20;
/// Weight of progress against the position columns (which weigh as much as one point).
/// Heavier progress keeps the alternation from buying a lower residual with a camera that
/// bends a wrong warp onto the points: 2–5 tie on the MuJoCo design seeds, 3 is their
/// middle (1.0 before; BENCHMARKS.md, "Progress weight of `track`").
pub const PROGRESS_WEIGHT: f64 = 3.0;

impl FeatureKind for Track {
    fn name(&self) -> &'static str {
        "track"
    }

    fn untrusted_cost(&self) -> f64 {
        TRACK_MAX_COST
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        match clip.domain {
            milv_data::Domain::Human => human_features(clip, None),
            milv_data::Domain::Robot => robot_states(clip),
        }
    }

    fn fit_pair(&self, human: &Features, robot: Features, align: &Aligner) -> Features {
        if human.d < 3 || human.d.is_multiple_of(2) || robot.n < 2 {
            return robot;
        }
        // The image points as `features_of` had them, before their weighting.
        let scale = point_weight(human.d - 1);
        let owned: Vec<Vec<f64>> = (0..human.n)
            .map(|i| human.row(i)[1..].iter().map(|v| v / scale).collect())
            .collect();
        let points: Vec<&[f64]> = owned.iter().map(Vec::as_slice).collect();
        let Ok(hprog) = Features::new(human.n, 1, (0..human.n).map(|i| human.row(i)[0]).collect()) else {
            return robot;
        };
        let rows: Vec<Vec<f64>> = (0..robot.n).map(|j| robot.row(j).to_vec()).collect();
        let rprog = Features::new(
            robot.n,
            1,
            progress(&rows).iter().map(|p| PROGRESS_WEIGHT * p).collect(),
        );
        let starts = [
            rprog.ok().and_then(|r| align(&hprog, &r)),
            Some(crate::align::proportional_warp(human.n, robot.n)),
        ];
        let Some(fit) = starts
            .into_iter()
            .flatten()
            .filter_map(|w| alternate(human, &points, &robot, w, align))
            .min_by(|a, b| a.resid.total_cmp(&b.resid))
        else {
            return robot;
        };
        fit.features
    }
}

/// `track` refused for a human clip whose tracked points do not move with the hand, for
/// `auto` ([`crate::features::Auto`]), judged against the tip found from frame
/// differences ([`motion::TipTracker`]): the farthest-travelled point must travel at
/// least [`min_travel`](Self::min_travel) times as far as that tip.
///
/// * [`HandTrack::ON_HAND`] (1×; a clip it cannot judge is refused; points seeded through
///   the clip, [`klt::Seeds::Through`]): where motion explains the pair, its alignment
///   replaces motion's unless its path runs along the band's edge. On milv-sim's low-contrast
///   hand, points seeded in later frames too are on the hand where the first frame's are
///   not (BENCHMARKS.md, "Points seeded through the clip"). [`HandTrack::ON_HAND_FIRST`]
///   is the same yardstick on the first frame's points; `auto` keeps whichever of the two
///   trusted alignments costs less (BENCHMARKS.md, "Both point sets, the cheaper fit").
///   A point on the hand goes as far as the tip (on milv-sim's drawing, 0.94–1.40× over 60
///   clips); points on a pushed object, which only moves in the push, or where the arm
///   leaves the picture, go less far (pushing: 0.03–0.99×). The tip is only a fair
///   yardstick this strict where motion explains the pair: on the MuJoCo set's textured
///   scenes it jitters, and hand points travel 0.16–2× as far. Motion's cost has vouched
///   for the pair, so track's own cost bound is not applied: true milv-sim drawing pairs
///   that pass this yardstick cost up to 0.058 and are still aligned better than by motion
///   (BENCHMARKS.md, "Where the tip vouches, track's cost does not veto").
/// * [`HandTrack::MOVING`] (0.1×; a clip it cannot judge is kept as [`Track`] keeps it):
///   where motion does not explain the pair and `auto` falls back to track. Points that
///   travel less than a tenth of the tip's path sit on what barely moves (a pushed object:
///   milv-sim pushing clips down to 0.03×), so track's alignment would follow the wrong
///   thing; no clip of the MuJoCo set's six seeds is below 0.16× (BENCHMARKS.md, "Track's
///   points must move").
pub struct HandTrack {
    /// Least travel of the farthest-travelled point, as a fraction of the tip's.
    pub min_travel: f64,
    /// Whether a clip the yardstick cannot judge is kept as [`Track`] keeps it: the tip
    /// stands in where no tracked point survives, and the points are kept where frame
    /// differences find no tip. Otherwise such a clip is refused.
    pub lenient: bool,
    /// Trust bound on the cost per dimension.
    pub max_cost: f64,
    /// Which frames seed the tracked points.
    pub seeds: klt::Seeds,
}

impl HandTrack {
    /// Points on the hand: as far as the tip; motion's cost has vouched for the pair.
    pub const ON_HAND: HandTrack = HandTrack {
        min_travel: 1.0,
        lenient: false,
        max_cost: f64::INFINITY,
        seeds: klt::Seeds::Through,
    };
    /// [`ON_HAND`](Self::ON_HAND) with the first frame's points only.
    pub const ON_HAND_FIRST: HandTrack = HandTrack {
        seeds: klt::Seeds::First,
        ..Self::ON_HAND
    };
    /// Points that move at all: a tenth of the tip's path; track's own bound.
    pub const MOVING: HandTrack = HandTrack {
        min_travel: 0.1,
        lenient: true,
        max_cost: TRACK_MAX_COST,
        seeds: klt::Seeds::First,
    };

    /// Why tracked `points` fail this yardstick against the frame-difference `tip`, if they
    /// do (both [`cleaned`]).
    fn check(
        &self,
        points: &[(Vec<f64>, Vec<f64>)],
        tip: &(Vec<f64>, Vec<f64>),
    ) -> std::result::Result<(), String> {
        let farthest = points.iter().map(travel).fold(0.0, f64::max);
        let tip_travel = travel(tip);
        if farthest < self.min_travel * tip_travel {
            return Err(format!(
                "the tracked points travel {farthest:.0} px, less than {}× the moving region's \
                 tip ({tip_travel:.0} px): they do not move with the hand",
                self.min_travel
            ));
        }
        Ok(())
    }
}

impl FeatureKind for HandTrack {
    fn name(&self) -> &'static str {
        Track.name()
    }

    fn untrusted_cost(&self) -> f64 {
        self.max_cost
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        match clip.domain {
            milv_data::Domain::Human => human_features(clip, Some(self)),
            milv_data::Domain::Robot => robot_states(clip),
        }
    }

    fn fit_pair(&self, human: &Features, robot: Features, align: &Aligner) -> Features {
        Track.fit_pair(human, robot, align)
    }
}

/// Where alternating fits settled.
struct Fit {
    features: Features,
    /// Mean squared distance of the human points from the projected robot path on it.
    resid: f64,
}

/// Fits the camera on alignment `w` and re-aligns, until `w` settles or [`ROUNDS`].
fn alternate(
    human: &Features,
    points: &[&[f64]],
    robot: &Features,
    mut w: Vec<usize>,
    align: &Aligner,
) -> Option<Fit> {
    let mut out = None;
    for _ in 0..ROUNDS {
        let cams = fit_camera(robot, &w, points)?;
        let projected = project(robot, &cams);
        let features = features_of(&projected).ok()?;
        let next = align(human, &features)?;
        let resid = next
            .iter()
            .zip(points)
            .map(|(&j, p)| {
                p.iter()
                    .zip(&projected[j])
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / points.len() as f64;
        out = Some(Fit { features, resid });
        if next == w {
            break;
        }
        w = next;
    }
    out
}

/// The human clip's tracked points as `[progress, x₁, y₁, …]`; with a [`HandTrack`]
/// yardstick, refused unless the points travel far enough against the frame-difference tip.
fn human_features(clip: &Clip, yardstick: Option<&HandTrack>) -> Result<Features, Error> {
    // Each of the clip's calls decodes its frames only for what it has not found before.
    let n = clip.images.len();
    let points = clip.hand_tracks(yardstick.map_or(klt::Seeds::First, |y| y.seeds))?;
    let tip = || {
        clip.tips_decoded()?
            .map(<[_]>::to_vec)
            .ok_or_else(|| clip.no_motion("track"))
    };
    // The points, and the yardstick and tip that must vouch for them.
    let (tracks, vouch) = match (points, yardstick) {
        (Some(p), None) => (p, None),
        // Untextured, flat-shaded arms (milv-sim's) may give the point tracker nothing to
        // hold: then the tip found from frame differences stands in, in image coordinates.
        (None, None) => (vec![tip()?], None),
        (None, Some(y)) if y.lenient => (vec![tip()?], None),
        (Some(p), Some(y)) => match tip() {
            Ok(t) => (p, Some((y, t))),
            Err(_) if y.lenient => (p, None),
            Err(e) => return Err(e),
        },
        (None, Some(_)) => {
            return Err(Error::Invalid(format!(
                "episode {}: no tracked point survives the clip",
                clip.episode_id
            )));
        }
    };
    let clean: Vec<(Vec<f64>, Vec<f64>)> = tracks.iter().map(|t| cleaned(t)).collect();
    if let Some((y, tip)) = vouch {
        y.check(&clean, &cleaned(&tip))
            .map_err(|m| Error::Invalid(format!("episode {}: {m}", clip.episode_id)))?;
    }
    let rows: Vec<Vec<f64>> = (0..n)
        .map(|t| clean.iter().flat_map(|(x, y)| [x[t], y[t]]).collect())
        .collect();
    features_of(&standardized(&rows))
}

/// One image track's x and y, cleaned lightly: the robot's states are not smoothed, so
/// smoothing just the human side erases wiggles of the path that the states keep (5-frame
/// median and σ = 1.5 before; BENCHMARKS.md, "Lighter cleaning of the human points").
fn cleaned(track: &[(f64, f64)]) -> (Vec<f64>, Vec<f64>) {
    let clean = |v: Vec<f64>| motion::gaussian_filter(&motion::median_filter(&v, 3), 0.75);
    (
        clean(track.iter().map(|p| p.0).collect()),
        clean(track.iter().map(|p| p.1).collect()),
    )
}

/// Length of a cleaned track's path.
fn travel((x, y): &(Vec<f64>, Vec<f64>)) -> f64 {
    (1..x.len())
        .map(|t| (x[t] - x[t - 1]).hypot(y[t] - y[t - 1]))
        .sum()
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

/// Weight of each of `q` point coordinates (K = q / 2 points weigh as much as one).
fn point_weight(q: usize) -> f64 {
    (2.0 / q.max(2) as f64).sqrt()
}

/// `[PROGRESS_WEIGHT · progress, points / √K]` of K image points per frame (rows of
/// `x₁, y₁, …`): progress along the path of their per-frame median; the points weigh
/// together as much as one.
fn features_of(rows: &[Vec<f64>]) -> Result<Features, Error> {
    let q = rows.first().map_or(0, Vec::len);
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let m = v.len() / 2;
        if v.len() % 2 == 1 {
            v[m]
        } else {
            0.5 * (v[m - 1] + v[m])
        }
    };
    let centre: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            vec![
                median(r.iter().step_by(2).copied().collect()),
                median(r.iter().skip(1).step_by(2).copied().collect()),
            ]
        })
        .collect();
    let p = progress(&centre);
    let scale = point_weight(q);
    let data = rows
        .iter()
        .zip(&p)
        .flat_map(|(r, &p)| std::iter::once(PROGRESS_WEIGHT * p).chain(r.iter().map(|v| scale * v)))
        .collect();
    Features::new(rows.len(), q + 1, data)
}

/// Per image point (a pair of columns of `points`), the affine camera `[a (d), a₀, b (d),
/// b₀]` fitted by least squares on alignment `w`: `x = a·s + a₀`, `y = b·s + b₀` for robot
/// state `s`. `None` when the states are degenerate. (A projective camera, linearised as
/// in the DLT, measured worse on the MuJoCo set and no better on milv-sim: BENCHMARKS.md.)
fn fit_camera(robot: &Features, w: &[usize], points: &[&[f64]]) -> Option<Vec<Vec<f64>>> {
    let d = robot.d;
    let m = 2 * d + 2;
    (0..points.first()?.len() / 2)
        .map(|k| {
            // Normal equations [AᵀA | Aᵀb], with a whisker of ridge so a flat state column
            // does not stop it.
            let mut a = vec![vec![0.0; m + 1]; m];
            for (&j, p) in w.iter().zip(points) {
                let s = robot.row(j);
                for (axis, target) in [p[2 * k], p[2 * k + 1]].into_iter().enumerate() {
                    let mut row = vec![0.0; m];
                    let off = axis * (d + 1);
                    row[off..off + d].copy_from_slice(s);
                    row[off + d] = 1.0;
                    for r in 0..m {
                        for c in 0..m {
                            a[r][c] += row[r] * row[c];
                        }
                        a[r][m] += row[r] * target;
                    }
                }
            }
            for (r, row) in a.iter_mut().enumerate() {
                row[r] += 1e-6;
            }
            solve(a)
        })
        .collect()
}

/// Solves the square system of augmented matrix `a` (Gauss–Jordan, partial pivoting).
fn solve(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    for c in 0..m {
        let p = (c..m).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
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
    Some((0..m).map(|r| a[r][m] / a[r][r]).collect())
}

/// The robot's path through the fitted cameras.
fn project(robot: &Features, cams: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let d = robot.d;
    let dot = |a: &[f64], s: &[f64]| a.iter().zip(s).map(|(x, y)| x * y).sum::<f64>();
    (0..robot.n)
        .map(|j| {
            let s = robot.row(j);
            cams.iter()
                .flat_map(|c| {
                    [
                        dot(&c[..d], s) + c[d],
                        dot(&c[d + 1..2 * d + 1], s) + c[2 * d + 1],
                    ]
                })
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
        let mean_error = |got: &[usize]| -> f64 {
            got.iter()
                .zip(&truth)
                .map(|(&g, t)| (g as f64 - t).abs())
                .sum::<f64>()
                / 45.0
        };
        let hf = features_of(&standardized(&human)).unwrap();
        let rf = Features::new(60, 3, standardized(&robot).concat()).unwrap();
        // The floor: the camera fitted on the true correspondences.
        let true_w: Vec<usize> = truth.iter().map(|t| t.round() as usize).collect();
        let owned: Vec<Vec<f64>> = (0..45).map(|i| hf.row(i)[1..].to_vec()).collect();
        let points: Vec<&[f64]> = owned.iter().map(Vec::as_slice).collect();
        let cams = fit_camera(&rf, &true_w, &points).unwrap();
        let best = features_of(&project(&rf, &cams)).unwrap();
        let floor = mean_error(&aligner(&hf, &best).unwrap());
        // Alternating fits from scratch settle near, not at, that camera.
        let fitted = Track.fit_pair(&hf, rf, &aligner);
        assert_eq!(fitted.d, 3);
        let err = mean_error(&aligner(&hf, &fitted).unwrap());
        let prop = mean_error(&crate::align::proportional_warp(45, 60));
        assert!(floor < 0.6, "floor {floor}");
        assert!(
            err < 2.0 && err < 0.3 * prop,
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
            motion_cache: Default::default(),
            points_cache: Default::default(),
        };
        let e = Track.extract(&clip).unwrap_err().to_string();
        assert!(e.contains("r7") && e.contains("no state vectors"), "{e}");
    }

    #[test]
    fn hand_track_refuses_a_clip_without_tracked_points_where_track_falls_back() {
        let still: Vec<Vec<u8>> = (0..6)
            .map(|_| {
                let mut png = Vec::new();
                milv_data::frame_codec::encode(
                    milv_data::frame_codec::FrameEncoding::Png,
                    &vec![120u8; 16 * 16 * 3],
                    16,
                    16,
                    &mut png,
                )
                .unwrap();
                png
            })
            .collect();
        let clip = Clip {
            episode_id: "h3".into(),
            domain: milv_data::Domain::Human,
            encoding: milv_data::frame_codec::FrameEncoding::Png,
            width: 16,
            height: 16,
            images: still,
            states: None,
            motion_cache: Default::default(),
            points_cache: Default::default(),
        };
        let e = HandTrack::ON_HAND.extract(&clip).unwrap_err().to_string();
        assert!(e.contains("h3") && e.contains("no tracked point"), "{e}");
        // Plain track, and auto's fallback to it, fall back to the frame-difference tip, which finds nothing moving.
        for e in [Track.extract(&clip), HandTrack::MOVING.extract(&clip)] {
            let e = e.unwrap_err().to_string();
            assert!(e.contains("nothing moves"), "{e}");
        }
    }

    #[test]
    fn the_yardsticks_refuse_points_that_travel_less_than_their_share_of_the_tip() {
        // The tip sweeps 60 px; points that sweep `px` along with it.
        let sweep =
            |px: f64| -> Vec<(f64, f64)> { (0..30).map(|t| (10.0 + px * t as f64 / 29.0, 20.0)).collect() };
        let tip = cleaned(&sweep(60.0));
        let points = |px: &[f64]| -> Vec<_> { px.iter().map(|&p| cleaned(&sweep(p))).collect() };
        let (object, wrist, hand) = (points(&[3.0, 1.0]), points(&[30.0]), points(&[66.0, 3.0]));
        // A pushed object's points (5 % of the tip's path) fail both.
        let e = HandTrack::MOVING.check(&object, &tip).unwrap_err();
        assert!(
            e.contains("travel 3 px") && e.contains("0.1×") && e.contains("tip (59 px)"),
            "{e}"
        );
        assert!(HandTrack::ON_HAND.check(&object, &tip).is_err());
        // Half the tip's path moves, but does not vouch for being on the hand.
        assert!(HandTrack::MOVING.check(&wrist, &tip).is_ok());
        assert!(HandTrack::ON_HAND.check(&wrist, &tip).is_err());
        // The farthest point counts: one on the hand is enough.
        assert!(HandTrack::ON_HAND.check(&hand, &tip).is_ok());
    }
}
