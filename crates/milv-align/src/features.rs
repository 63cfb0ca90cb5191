//! Per-frame features that mean the same thing in both domains.
//!
//! Pixels do not: the arms look different and the cameras see the table from opposite
//! sides. A [`FeatureKind`] turns one clip into a [`Features`] matrix, and may adjust the
//! robot clip's features to the human's before alignment ([`FeatureKind::fit_pair`]);
//! the aligner knows nothing else about them, so a new kind (e.g. one reading a learned
//! embedding) plugs in without touching it.

use milv_data::frame_codec::{self, FrameEncoding};

use crate::dtw::Features;
use crate::{Error, klt, motion};

/// One clip as stored: encoded frames (from `frames`, or `imagined` for translated human
/// clips) and, when the episode has them, per-frame state vectors.
#[derive(Clone, Debug)]
pub struct Clip {
    pub episode_id: String,
    pub domain: milv_data::Domain,
    pub encoding: FrameEncoding,
    pub width: u32,
    pub height: u32,
    pub images: Vec<Vec<u8>>,
    pub states: Option<Vec<Vec<f32>>>,
    /// The clip's frame-difference track once found ([`Clip::tips`]): `auto` reads it for
    /// motion's tip, again for its hand region and as [`crate::track::HandTrack`]'s
    /// yardstick, all on the same clip.
    pub(crate) motion_cache: std::sync::OnceLock<Option<MotionTrack>>,
    /// The human's tracked points with both seeds, once asked for points seeded through the
    /// clip ([`Clip::hand_tracks`]): `auto` tries both on the same clip.
    pub(crate) points_cache: std::sync::OnceLock<[Option<klt::Tracks>; 2]>,
}

/// A clip's [`motion::Track`] and the frame size it was found at.
#[derive(Clone, Debug)]
pub(crate) struct MotionTrack {
    pub track: motion::Track,
    pub w: usize,
    pub h: usize,
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

    /// Every frame decoded to RGB24, and their common size.
    pub fn all_rgb(&self) -> Result<(Vec<Vec<u8>>, usize, usize), Error> {
        let mut frames = Vec::with_capacity(self.images.len());
        let mut size = None;
        for t in 0..self.images.len() {
            let (rgb, w, h) = self.rgb(t)?;
            if *size.get_or_insert((w, h)) != (w, h) {
                return Err(Error::Invalid(format!(
                    "episode {}: frame {t} changes size",
                    self.episode_id
                )));
            }
            frames.push(rgb);
        }
        let (w, h) =
            size.ok_or_else(|| Error::Invalid(format!("episode {} has no frames", self.episode_id)))?;
        Ok((frames, w, h))
    }

    /// The tip found from frame differences in every frame ([`motion::TipTracker`]) of
    /// this clip, decoded as `frames`, unless already found; `None` when nothing moves
    /// beyond the entry border.
    pub fn tips(&self, frames: &[Vec<u8>], w: usize, h: usize) -> Option<&[(f64, f64)]> {
        self.motion_track(frames.iter().cloned(), w, h)
            .map(|m| &m.track.tips[..])
    }

    /// The clip's [`motion::Track`] from `frames`, unless already found.
    fn motion_track(
        &self,
        frames: impl ExactSizeIterator<Item = Vec<u8>>,
        w: usize,
        h: usize,
    ) -> Option<&MotionTrack> {
        self.motion_cache
            .get_or_init(|| {
                let mut tracker = motion::TipTracker::new(w, h, frames.len());
                for f in frames {
                    tracker.push(f);
                }
                tracker.finish().map(|track| MotionTrack { track, w, h })
            })
            .as_ref()
    }

    /// [`Clip::motion_track`], decoding the frames only when it is not already found.
    pub(crate) fn motion_decoded(&self) -> Result<Option<&MotionTrack>, Error> {
        if let Some(m) = self.motion_cache.get() {
            return Ok(m.as_ref());
        }
        // Decoded for this pass alone: the tracker takes the frames over.
        let (frames, w, h) = self.all_rgb()?;
        Ok(self.motion_track(frames.into_iter(), w, h))
    }

    /// [`klt::hand_tracks`] of this clip, decoding its frames only when not already kept.
    /// Points seeded through the clip are tracked with the first frame's (which they
    /// include) and both kept; the first frame's alone are tracked alone unless kept.
    pub(crate) fn hand_tracks(&self, seeds: klt::Seeds) -> Result<Option<klt::Tracks>, Error> {
        if let Some(both) = self.points_cache.get() {
            return Ok(both[usize::from(seeds == klt::Seeds::Through)].clone());
        }
        let (frames, w, h) = self.all_rgb()?;
        Ok(match seeds {
            klt::Seeds::First => klt::hand_tracks(&frames, w, h, seeds),
            klt::Seeds::Through => self
                .points_cache
                .get_or_init(|| klt::hand_tracks_both(&frames, w, h))[1]
                .clone(),
        })
    }

    /// Why `kind`'s features cannot describe this clip when its frame-difference pass
    /// found no tip ([`Clip::motion_decoded`] is `None`).
    pub(crate) fn no_motion(&self, kind: &str) -> Error {
        Error::Invalid(format!(
            "episode {}: nothing moves in the clip beyond the border the arm enters from \
             ({kind} features need a moving arm)",
            self.episode_id
        ))
    }

    /// [`Clip::tips`], decoding the frames only when the tips are not already found.
    pub(crate) fn tips_decoded(&self) -> Result<Option<&[(f64, f64)]>, Error> {
        Ok(self.motion_decoded()?.map(|m| &m.track.tips[..]))
    }

    /// The state vectors as rows of one width; `hint` says what to use instead.
    pub fn state_rows(&self, hint: &str) -> Result<Vec<Vec<f64>>, Error> {
        let states = self.states.as_ref().ok_or_else(|| {
            Error::Invalid(format!(
                "episode {} has no state vectors ({hint})",
                self.episode_id
            ))
        })?;
        let d = states.first().map_or(0, Vec::len);
        if d == 0 || states.iter().any(|s| s.len() != d) {
            return Err(Error::Invalid(format!(
                "episode {}: state vectors missing or of mixed widths",
                self.episode_id
            )));
        }
        Ok(states
            .iter()
            .map(|s| s.iter().map(|&v| f64::from(v)).collect())
            .collect())
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

    /// Normalised DTW cost per feature dimension above which a pair is not trusted: just
    /// above the worst true pair of milv-sim's paired clips for each kind.
    fn untrusted_cost(&self) -> f64 {
        0.5
    }

    /// Adjusts the robot features to the human ones before alignment (e.g. resolving
    /// camera axis flips, or mapping robot states into the human's image), and may use
    /// `align` (the pair's own DTW: band and step pattern) to do it. The result must have
    /// the human features' width. Default: nothing.
    fn fit_pair(&self, _human: &Features, robot: Features, _align: &Aligner) -> Features {
        robot
    }

    /// For a kind that picks other kinds per pair: its [`Stage`]s in order. Empty for a
    /// kind that describes frames itself.
    fn cascade(&self) -> &'static [Stage] {
        &[]
    }
}

/// One step of a kind that picks other kinds per pair ([`FeatureKind::cascade`]).
pub struct Stage {
    pub kind: &'static dyn FeatureKind,
    /// Cost per dimension up to which `kind`'s alignment is kept when also within the
    /// kind's own [`untrusted_cost`](FeatureKind::untrusted_cost) (else the next stage is
    /// tried).
    pub keep_below: f64,
    /// Kinds whose alignment replaces the kept one where it is trusted (cost and band
    /// edge, [`PairFit::trusted`](crate::align::PairFit::trusted)): of those trusted, the
    /// one with the lowest cost per dimension; a kind that cannot align the pair is passed
    /// over.
    pub unless_trusted: &'static [&'static dyn FeatureKind],
    /// Where none of those replaces a kept alignment, the kind that aligns the pair again
    /// (the kept one stands if it cannot): `kind`'s cost decides, this kind aligns.
    pub aligned_by: Option<&'static dyn FeatureKind>,
}

/// The DTW a pair is aligned with (its band and step pattern), as the robot frame of
/// every human frame; `None` when the two feature matrices cannot be aligned.
pub type Aligner<'a> = dyn Fn(&Features, &Features) -> Option<Vec<usize>> + 'a;

/// End-effector / state columns, each scaled to [0, 1] by its range over the clip (see
/// [`Features::range_normalized`]). Both episodes must carry states of the same width.
pub struct State;

impl FeatureKind for State {
    fn name(&self) -> &'static str {
        "state"
    }

    fn untrusted_cost(&self) -> f64 {
        // True milv-sim pairs: ≤ 0.00054; pairs of different motions: mostly ≥ 0.006.
        0.002
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        let rows = clip.state_rows("use --features motion")?;
        let d = rows[0].len();
        Ok(Features::new(rows.len(), d, rows.concat())?.range_normalized())
    }
}

/// How far along its path the arm's tip is, and where it is heading, on the table plane:
/// what stays the same when the arm, the camera and the speed change.
///
/// 1. The tip is tracked from frame differences (see [`crate::motion`]): the moving
///    pixels farthest from the border the arm enters from.
/// 2. Its pixel position is mapped onto the table plane through the homography of the
///    table's quad in the clip's median frame (image coordinates if there is none), which
///    undoes the camera's perspective.
/// 3. The track is cleaned (5-frame median, then Gaussian σ = 2.5 frames).
/// 4. Features per frame: the path length travelled so far over the whole path's
///    (0 → 1), and the unit heading of the motion (central difference over 4 frames)
///    weighted by [`HEADING_WEIGHT`].
///
/// Progress is the main signal: unlike positions it carries no offset between embodiments
/// (a hand's fingertips lead its palm by more than a gripper leads its wrist) and unlike
/// z-normalised values it does not depend on where the clip dwells. The heading tells
/// apart stretches of equal progress that go different ways. The two tables are the same
/// square seen from different sides, so [`FeatureKind::fit_pair`] turns the robot's
/// headings by the symmetry of the square that best matches the human's.
///
/// Two points of the moving region are followed: its tip (the farthest part, `motion`) and
/// the hand region (deeper, [`Motion::HAND`]). The tip leads the end effector by the
/// hand's fingers, more for a hand than for a gripper and more where the arm turns, so
/// its progress runs ahead of the end effector's; the hand region's centre is nearer the
/// end effector and aligns milv-sim's pairs better (BENCHMARKS.md, "Motion's progress
/// from the hand region").
pub struct Motion {
    hand: bool,
}

impl Motion {
    /// The tip's progress and heading (`--features motion`).
    pub const TIP: Motion = Motion { hand: false };
    /// The hand region's (`motion-hand`): what `auto` aligns a pair with where motion's
    /// tip explains it (whose cost its bound was measured on).
    pub const HAND: Motion = Motion { hand: true };
}

/// Weight of the two heading columns against progress (measured on milv-sim pairs: more
/// than ~0.2 lets heading noise pull the path off).
pub const HEADING_WEIGHT: f64 = 0.1;
const MOTION_D: usize = 3;

impl FeatureKind for Motion {
    fn name(&self) -> &'static str {
        if self.hand { "motion-hand" } else { "motion" }
    }

    fn untrusted_cost(&self) -> f64 {
        // True milv-sim pairs: ≤ 0.0018. Any two motions progress from 0 to 1, so only
        // the heading tells a wrong pair apart: about half of them cost more than this.
        0.002
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        let MotionTrack { track, w, h } = clip.motion_decoded()?.ok_or_else(|| clip.no_motion("motion"))?;
        let (n, w, h) = (track.tips.len(), *w, *h);
        let plane = motion::table_quad(&track.background, w, h)
            .and_then(|q| motion::to_unit_square(&q))
            .unwrap_or_else(|| milv_geom::Homography::scale(1.0 / w as f64, 1.0 / h as f64));
        let followed = if self.hand { &track.hands } else { &track.tips };
        let on_table: Vec<(f64, f64)> = followed.iter().map(|&p| plane.apply(p)).collect();
        let clean = |c: fn(&(f64, f64)) -> f64| {
            let v: Vec<f64> = on_table.iter().map(c).collect();
            motion::gaussian_filter(&motion::median_filter(&v, 5), 2.5)
        };
        let (xs, ys) = (clean(|p| p.0), clean(|p| p.1));
        let travelled: Vec<f64> = std::iter::once(0.0)
            .chain((1..n).scan(0.0, |acc, t| {
                *acc += (xs[t] - xs[t - 1]).hypot(ys[t] - ys[t - 1]);
                Some(*acc)
            }))
            .collect();
        let total = travelled[n - 1];
        let mut data = Vec::with_capacity(n * MOTION_D);
        for (t, done) in travelled.iter().enumerate() {
            let (a, b) = (t.saturating_sub(2), (t + 2).min(n - 1));
            let (dx, dy) = (xs[b] - xs[a], ys[b] - ys[a]);
            let len = dx.hypot(dy).max(1e-9);
            let progress = if total > 1e-9 {
                done / total
            } else {
                t as f64 / (n - 1).max(1) as f64
            };
            data.extend_from_slice(&[progress, HEADING_WEIGHT * dx / len, HEADING_WEIGHT * dy / len]);
        }
        Features::new(n, MOTION_D, data)
    }

    fn fit_pair(&self, human: &Features, robot: Features, _align: &Aligner) -> Features {
        // The 8 symmetries of the square, as maps of the heading (x, y).
        const D4: [[f64; 4]; 8] = [
            [1.0, 0.0, 0.0, 1.0],
            [-1.0, 0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0, -1.0],
            [-1.0, 0.0, 0.0, -1.0],
            [0.0, 1.0, 1.0, 0.0],
            [0.0, -1.0, 1.0, 0.0],
            [0.0, 1.0, -1.0, 0.0],
            [0.0, -1.0, -1.0, 0.0],
        ];
        let turn = |m: &[f64; 4], r: &[f64]| [m[0] * r[1] + m[1] * r[2], m[2] * r[1] + m[3] * r[2]];
        // Compare the headings with the robot clip resampled to the human's length.
        let stretched = crate::align::proportional_warp(human.n, robot.n);
        let mismatch = |m: &[f64; 4]| -> f64 {
            stretched
                .iter()
                .enumerate()
                .map(|(i, &j)| {
                    let (hr, rr) = (human.row(i), turn(m, robot.row(j)));
                    (hr[1] - rr[0]).powi(2) + (hr[2] - rr[1]).powi(2)
                })
                .sum()
        };
        let best = D4
            .iter()
            .min_by(|a, b| mismatch(a).total_cmp(&mismatch(b)))
            .unwrap_or(&D4[0]);
        let mut out = robot;
        for r in out.data.chunks_exact_mut(MOTION_D) {
            let [x, y] = turn(best, r);
            r[1] = x;
            r[2] = y;
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

/// `auto`: [`Motion`] where its model of the scene explains the pair, [`Track`]
/// elsewhere (where its points move at all); and where motion explains it, track where its
/// points are on the hand and its path stays off the band's edge.
///
/// Motion's table-plane features cost at most 0.0018 per dimension on true milv-sim pairs
/// (median 0.0002) and at least 0.0015 on the MuJoCo set's (median 0.0035), where the
/// arms move in 3-D and motion aligns worse than the proportional warp; track needs robot
/// states and is worse than motion on milv-sim's pushing. So a pair whose motion cost is
/// above [`AUTO_MOTION_COST`] is re-aligned on track; it keeps motion's alignment when
/// motion's cost is within motion's trust bound and track's is not (a true milv-sim pair is
/// not newly flagged), and when track cannot align it: without robot states, or when the
/// human clip's tracked points barely move ([`HandTrack::MOVING`]: they are on a pushed
/// object, and track would follow it; BENCHMARKS.md, "Track's points must move"). A
/// pair that keeps motion's alignment so is aligned on [`Motion::HAND`] like any other
/// (below).
///
/// Where motion explains the pair, its tip (from frame differences) is where the scene
/// model says the hand is, and its progress carries each embodiment's own lead (a hand's
/// fingertips, a gripper's fingers) as a phase-dependent bias. `track` maps the robot's
/// own states instead and is better there, but only when its points are on the hand:
/// [`HandTrack::ON_HAND`] refuses clips whose points travel less than motion's tip (points on a
/// pushed object or where the arm leaves the picture), and its alignment replaces motion's
/// where its path stays off the band's edge, whatever track's own cost (motion's has
/// vouched for the pair; BENCHMARKS.md, "Track where motion's tip vouches for its points"
/// and "Where the tip vouches, track's cost does not veto"). Points seeded through the
/// clip and the first frame's are tried both ([`HandTrack::ON_HAND_FIRST`]); of the
/// alignments that qualify, the cheaper is kept. Where neither qualifies, the pair is
/// aligned on [`Motion::HAND`]: the tip's cost decides (the bounds were measured on it),
/// the hand region, nearer the end effector, aligns.
///
/// [`Track`]: crate::track::Track
/// [`HandTrack::MOVING`]: crate::track::HandTrack::MOVING
/// [`HandTrack::ON_HAND`]: crate::track::HandTrack::ON_HAND
/// [`HandTrack::ON_HAND_FIRST`]: crate::track::HandTrack::ON_HAND_FIRST
pub struct Auto;

/// Motion's cost per dimension above which `auto` turns to track: between the design
/// seeds' milv-sim pairs (3 of 40 above) and MuJoCo pairs (none of 20 below); BENCHMARKS.md.
pub const AUTO_MOTION_COST: f64 = 0.0012;

impl FeatureKind for Auto {
    fn name(&self) -> &'static str {
        "auto"
    }

    fn extract(&self, clip: &Clip) -> Result<Features, Error> {
        Err(Error::Invalid(format!(
            "episode {}: auto features are chosen per pair (motion or track), not per clip",
            clip.episode_id
        )))
    }

    fn cascade(&self) -> &'static [Stage] {
        &[
            Stage {
                kind: &Motion::TIP,
                keep_below: AUTO_MOTION_COST,
                aligned_by: Some(&Motion::HAND),
                unless_trusted: &[
                    &crate::track::HandTrack::ON_HAND,
                    &crate::track::HandTrack::ON_HAND_FIRST,
                ],
            },
            Stage {
                kind: &crate::track::HandTrack::MOVING,
                keep_below: f64::INFINITY,
                aligned_by: None,
                unless_trusted: &[],
            },
        ]
    }
}

/// The feature kind named on the command line.
pub fn by_name(name: &str) -> Result<&'static dyn FeatureKind, Error> {
    match name {
        "auto" => Ok(&Auto),
        "motion" => Ok(&Motion::TIP),
        "motion-hand" => Ok(&Motion::HAND),
        "state" => Ok(&State),
        "translated" => Ok(&Translated),
        "track" => Ok(&crate::track::Track),
        _ => Err(Error::Invalid(format!(
            "unknown features {name:?} (auto | motion | motion-hand | track | state | translated)"
        ))),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A dark "arm" entering from `side` (0 bottom, 1 top: the view turned by 180°) whose
    /// tip reaches `reach[t]` of the way across a 64×48 grey frame, at column `col[t]`.
    fn clip(side: u8, reach: &[f64], col: &[f64]) -> Clip {
        let (w, h) = (64usize, 48usize);
        let images = reach
            .iter()
            .zip(col)
            .map(|(&r, &c)| {
                let mut rgb = vec![200u8; w * h * 3];
                let len = (r * h as f64) as usize;
                let x0 = (c * (w - 8) as f64) as usize;
                // Seen from the top, the picture is turned by 180°.
                let x0 = if side == 0 { x0 } else { w - 8 - x0 };
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
            domain: milv_data::Domain::Human,
            encoding: FrameEncoding::Png,
            width: w as u32,
            height: h as u32,
            images,
            states: None,
            motion_cache: Default::default(),
            points_cache: Default::default(),
        }
    }

    #[test]
    fn motion_progress_and_heading_agree_across_mirrored_views() {
        // The bar reaches in, then sweeps sideways: two legs, at an uneven pace.
        let pace: Vec<f64> = (0..30).map(|t| (t as f64 / 29.0).powf(1.3)).collect();
        let reach: Vec<f64> = pace.iter().map(|&p| 0.2 + 0.6 * (2.0 * p).min(1.0)).collect();
        let col: Vec<f64> = pace
            .iter()
            .map(|&p| 0.1 + 0.8 * (2.0 * p - 1.0).max(0.0))
            .collect();
        let from_bottom = Motion::TIP.extract(&clip(0, &reach, &col)).unwrap();
        let from_top = Motion::TIP.extract(&clip(1, &reach, &col)).unwrap();
        for f in [&from_bottom, &from_top] {
            let p: Vec<f64> = (0..f.n).map(|i| f.row(i)[0]).collect();
            assert!(p.windows(2).all(|w| w[1] >= w[0] - 1e-12), "{p:?}");
            assert!(p[0].abs() < 1e-12 && (p[29] - 1.0).abs() < 1e-12);
        }
        // The same motion: equal progress frame by frame, whichever side it is seen from.
        for i in 0..30 {
            let (a, b) = (from_bottom.row(i)[0], from_top.row(i)[0]);
            assert!((a - b).abs() < 0.05, "frame {i}: {a} vs {b}");
        }
        // The top view turns the motion by 180°; fitting the pair turns it back.
        let heading_dot = |f: &Features| -> f64 {
            (0..30)
                .map(|i| {
                    let (h, r) = (from_bottom.row(i), f.row(i));
                    (h[1] * r[1] + h[2] * r[2]) / (HEADING_WEIGHT * HEADING_WEIGHT)
                })
                .sum::<f64>()
                / 30.0
        };
        assert!(heading_dot(&from_top) < -0.8, "{}", heading_dot(&from_top));
        let fitted = Motion::TIP.fit_pair(&from_bottom, from_top, &|_, _| None);
        assert!(heading_dot(&fitted) > 0.8, "{}", heading_dot(&fitted));
        // A clip where nothing moves has no motion features.
        let still = clip(0, &[0.5; 4], &[0.3; 4]);
        assert!(
            Motion::TIP
                .extract(&still)
                .unwrap_err()
                .to_string()
                .contains("nothing moves")
        );
    }

    #[test]
    fn motion_leaves_the_clips_tips_for_the_next_kind() {
        let pace: Vec<f64> = (0..12).map(|t| t as f64 / 11.0).collect();
        let reach: Vec<f64> = pace.iter().map(|&p| 0.2 + 0.6 * p).collect();
        let c = clip(0, &reach, &[0.4; 12]);
        let (frames, w, h) = c.all_rgb().unwrap();
        let fresh = clip(0, &reach, &[0.4; 12]).tips(&frames, w, h).unwrap().to_vec();
        assert!(c.motion_cache.get().is_none());
        Motion::TIP.extract(&c).unwrap();
        let kept = c.motion_cache.get().unwrap().as_ref().unwrap();
        assert_eq!(kept.track.tips, fresh);
        // The hand region, for motion-hand, comes from the same pass.
        let hand = Motion::HAND.extract(&c).unwrap();
        assert!(std::ptr::eq(
            kept,
            c.motion_cache.get().unwrap().as_ref().unwrap()
        ));
        assert_eq!(hand.n, 12);
        // Found once: other frames passed later do not change it.
        assert_eq!(c.tips(&frames[..2], w, h), Some(&fresh[..]));
        // The tip follows the bar's end upwards (y falls as it reaches in).
        assert!(fresh[11].1 < fresh[0].1 - 10.0, "{fresh:?}");
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
        assert_eq!(f.row(0), [0.0, 0.0]);
        assert_eq!(f.row(1), [1.0, 1.0]);
        assert!(by_name("pixels").is_err());
    }

    #[test]
    fn every_kind_is_named_on_the_command_line_by_its_report_name() {
        for name in ["auto", "motion", "motion-hand", "track", "state", "translated"] {
            assert_eq!(by_name(name).unwrap().name(), name);
        }
        let e = by_name("hand").err().unwrap().to_string();
        assert!(e.contains("\"hand\"") && e.contains("motion-hand"), "{e}");
    }
}
