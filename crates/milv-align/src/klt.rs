//! Feature-point tracking (Shi–Tomasi corners followed by pyramidal Lucas–Kanade with a
//! forward–backward check): where the most travelled points of a clip's moving region go.
//!
//! Nothing here knows the scene: no table, no border the arm enters from. Corners are
//! picked in the first frame ([`Seeds::First`]), or also in every 8th frame after it and
//! followed both ways ([`Seeds::Through`]), wherever anything moves in the clip; the
//! points that travel farthest are on the part of the arm farthest from its fixed base,
//! i.e. the hand or gripper, whatever the camera. When a lost point had out-travelled
//! every survivor, the hand was lost (it turns and changes its texture) and the clip is
//! tracked again with a larger window (BENCHMARKS.md, "A lost hand is tracked again").

use crate::motion;

/// The tracker's window: LK half-width and pyramid levels above the full image.
#[derive(Clone, Copy)]
struct Window {
    half: isize,
    levels: usize,
}
/// 9×9 on 3 levels: holds a small textured hand in a cluttered scene.
const FINE: Window = Window { half: 4, levels: 2 };
/// 15×15 on 4 levels: the retry when the fine window lost the hand (the hand's own texture
/// changes as it turns; the larger window also holds on to its outline).
const COARSE: Window = Window { half: 7, levels: 3 };
const LK_ITERS: usize = 30;
const LK_EPS: f64 = 0.01;
/// A point whose forward-then-backward track misses its start by more (pixels) is lost.
const FB_MAX: f64 = 1.0;
const MAX_CORNERS: usize = 300;
const CORNER_QUALITY: f32 = 0.01;
const MIN_DISTANCE: f64 = 2.0;
/// Frame differences (RGB distance, 3×3 mean) above this count as motion for the mask.
const MASK_MOTION: f32 = 12.0;
/// Frames between the frames whose corners seed new points.
const SEED_EVERY: usize = 8;
/// How many of the most travelled points are kept.
pub const TOP_POINTS: usize = 3;
/// ... if they travel at least this share of the farthest one's path.
const MIN_TRAVEL_SHARE: f64 = 0.5;

/// A grey image (luma in [0, 1]) with bilinear sampling, clamped at the border.
#[derive(Clone)]
struct Gray {
    w: usize,
    h: usize,
    v: Vec<f32>,
}

impl Gray {
    fn from_rgb(rgb: &[u8], w: usize, h: usize) -> Gray {
        Gray {
            w,
            h,
            v: rgb
                .chunks_exact(3)
                .map(|p| f32::from(motion::luma(p)) / 255.0)
                .collect(),
        }
    }

    fn at(&self, x: isize, y: isize) -> f32 {
        let x = x.clamp(0, self.w as isize - 1) as usize;
        let y = y.clamp(0, self.h as isize - 1) as usize;
        self.v[y * self.w + x]
    }

    fn sample(&self, x: f64, y: f64) -> f64 {
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as isize, y0 as isize);
        let p = |dx, dy| f64::from(self.at(x0 + dx, y0 + dy));
        (1.0 - fy) * ((1.0 - fx) * p(0, 0) + fx * p(1, 0)) + fy * ((1.0 - fx) * p(0, 1) + fx * p(1, 1))
    }

    /// Half size, smoothed with the 5-tap binomial kernel first (as `cv::pyrDown`).
    fn down(&self) -> Gray {
        const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
        let (w, h) = (self.w.div_ceil(2), self.h.div_ceil(2));
        let mut v = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for (j, ky) in K.iter().enumerate() {
                    for (i, kx) in K.iter().enumerate() {
                        s += ky
                            * kx
                            * self.at(2 * x as isize + i as isize - 2, 2 * y as isize + j as isize - 2);
                    }
                }
                v.push(s);
            }
        }
        Gray { w, h, v }
    }

    /// Scharr derivatives (x, y), scaled to intensity per pixel.
    fn gradients(&self) -> (Gray, Gray) {
        let mut gx = Vec::with_capacity(self.v.len());
        let mut gy = Vec::with_capacity(self.v.len());
        for y in 0..self.h as isize {
            for x in 0..self.w as isize {
                let p = |dx, dy| self.at(x + dx, y + dy);
                gx.push(
                    (3.0 * (p(1, -1) - p(-1, -1)) + 10.0 * (p(1, 0) - p(-1, 0)) + 3.0 * (p(1, 1) - p(-1, 1)))
                        / 32.0,
                );
                gy.push(
                    (3.0 * (p(-1, 1) - p(-1, -1)) + 10.0 * (p(0, 1) - p(0, -1)) + 3.0 * (p(1, 1) - p(1, -1)))
                        / 32.0,
                );
            }
        }
        let g = |v| Gray {
            w: self.w,
            h: self.h,
            v,
        };
        (g(gx), g(gy))
    }
}

/// One frame's pyramid: images and their gradients, finest first.
struct Pyramid {
    levels: Vec<(Gray, Gray, Gray)>,
}

impl Pyramid {
    fn new(img: Gray, n_levels: usize) -> Pyramid {
        let mut levels = Vec::with_capacity(n_levels + 1);
        let mut cur = img;
        for l in 0..=n_levels {
            let next = (l < n_levels).then(|| cur.down());
            let (gx, gy) = cur.gradients();
            levels.push((cur, gx, gy));
            match next {
                Some(n) => cur = n,
                None => break,
            }
        }
        Pyramid { levels }
    }
}

/// Where point `p` of frame `a` is in frame `b`, with `window`'s half-width on its levels
/// of the pyramids; `None` when the window leaves the image or has no texture to lock on to
/// in the full image.
fn lk(a: &Pyramid, b: &Pyramid, p: (f64, f64), window: Window) -> Option<(f64, f64)> {
    let half = window.half;
    let mut g = (0.0f64, 0.0f64);
    for l in (0..=window.levels.min(a.levels.len() - 1)).rev() {
        let (ia, gx, gy) = &a.levels[l];
        let (ib, _, _) = &b.levels[l];
        let s = f64::from(1u32 << l);
        let (px, py) = (p.0 / s, p.1 / s);
        let (mut gxx, mut gxy, mut gyy) = (0.0, 0.0, 0.0);
        let mut win = Vec::with_capacity(((2 * half + 1) * (2 * half + 1)) as usize);
        for oy in -half..=half {
            for ox in -half..=half {
                let (x, y) = (px + ox as f64, py + oy as f64);
                let (dx, dy) = (gx.sample(x, y), gy.sample(x, y));
                gxx += dx * dx;
                gxy += dx * dy;
                gyy += dy * dy;
                win.push((x, y, ia.sample(x, y), dx, dy));
            }
        }
        let count = win.len() as f64;
        let det = gxx * gyy - gxy * gxy;
        let min_eig = 0.5 * (gxx + gyy - ((gxx - gyy).powi(2) + 4.0 * gxy * gxy).sqrt());
        if min_eig / count < 1e-4 || det.abs() < 1e-12 {
            // As OpenCV's pyramidal LK: a coarse level too blurred to lock on to passes its
            // guess down; only the full image decides that a point is lost.
            if l == 0 {
                return None;
            }
            g = (2.0 * g.0, 2.0 * g.1);
            continue;
        }
        let mut v = (0.0f64, 0.0f64);
        for _ in 0..LK_ITERS {
            let (mut bx, mut by) = (0.0, 0.0);
            for &(x, y, i, dx, dy) in &win {
                let e = i - ib.sample(x + g.0 + v.0, y + g.1 + v.1);
                bx += e * dx;
                by += e * dy;
            }
            let eta = ((gyy * bx - gxy * by) / det, (gxx * by - gxy * bx) / det);
            v = (v.0 + eta.0, v.1 + eta.1);
            if eta.0.hypot(eta.1) < LK_EPS {
                break;
            }
        }
        let (qx, qy) = (px + g.0 + v.0, py + g.1 + v.1);
        if qx < 0.0 || qy < 0.0 || qx > (ib.w - 1) as f64 || qy > (ib.h - 1) as f64 {
            return None;
        }
        g = if l > 0 {
            (2.0 * (g.0 + v.0), 2.0 * (g.1 + v.1))
        } else {
            (g.0 + v.0, g.1 + v.1)
        };
    }
    Some((p.0 + g.0, p.1 + g.1))
}

/// Shi–Tomasi corners of an image (given by its gradients, as its pyramid has them)
/// inside `mask`, strongest first, at least [`MIN_DISTANCE`] apart.
fn corners(gx: &Gray, gy: &Gray, mask: &[bool]) -> Vec<(f64, f64)> {
    let (w, h) = (gx.w, gx.h);
    let mut eig = vec![0.0f32; w * h];
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let (mut a, mut b, mut c) = (0.0f32, 0.0f32, 0.0f32);
            for yy in y - 1..=y + 1 {
                for xx in x - 1..=x + 1 {
                    let (dx, dy) = (gx.v[yy * w + xx], gy.v[yy * w + xx]);
                    a += dx * dx;
                    b += dx * dy;
                    c += dy * dy;
                }
            }
            eig[y * w + x] = 0.5 * (a + c - ((a - c).powi(2) + 4.0 * b * b).sqrt());
        }
    }
    // Quality is relative to the strongest corner inside the mask (as OpenCV's), so that a
    // textured background does not raise the bar for a low-contrast hand.
    let max = eig
        .iter()
        .zip(mask)
        .filter(|p| *p.1)
        .map(|p| *p.0)
        .fold(0.0f32, f32::max);
    if max <= 0.0 {
        return Vec::new();
    }
    let mut cand: Vec<(f32, usize, usize)> = Vec::new();
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let e = eig[y * w + x];
            let local_max = (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| eig[yy * w + xx] <= e));
            if mask[y * w + x] && e >= CORNER_QUALITY * max && local_max {
                cand.push((e, x, y));
            }
        }
    }
    cand.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.2, a.1).cmp(&(b.2, b.1))));
    let mut out: Vec<(f64, f64)> = Vec::new();
    for (_, x, y) in cand {
        let p = (x as f64, y as f64);
        if out.iter().all(|q| (q.0 - p.0).hypot(q.1 - p.1) >= MIN_DISTANCE) {
            out.push(p);
            if out.len() == MAX_CORNERS {
                break;
            }
        }
    }
    out
}

/// Pixels that change between frames t−1 and t+1 anywhere in the clip, grown by 2 pixels.
fn motion_mask(frames: &[Vec<u8>], w: usize, h: usize) -> Vec<bool> {
    let n = frames.len();
    let mut any = vec![false; w * h];
    for t in 0..n {
        let d = motion::motion_map(&frames[t.saturating_sub(1)], &frames[(t + 1).min(n - 1)], w, h);
        for (m, v) in any.iter_mut().zip(d) {
            *m |= v > MASK_MOTION;
        }
    }
    let mut grown = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            if any[y * w + x] {
                for yy in y.saturating_sub(2)..(y + 3).min(h) {
                    for xx in x.saturating_sub(2)..(x + 3).min(w) {
                        grown[yy * w + xx] = true;
                    }
                }
            }
        }
    }
    grown
}

/// Tracked points: per point, its pixel position (x right, y down) in every frame.
pub type Tracks = Vec<Vec<(f64, f64)>>;

/// Which frames' corners seed points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Seeds {
    /// The first frame's, followed forwards.
    First,
    /// The first frame's and every 8th frame's after it (`SEED_EVERY`), each followed
    /// forwards and backwards to both ends of the clip: a hand that enters the picture, or
    /// shows its corners only later, gets points where it shows.
    Through,
}

/// The tracks (pixel positions, one per frame) of the [`TOP_POINTS`] points that travel
/// farthest among those tracked through the whole clip (RGB24 frames of `w`×`h`),
/// farthest first; `None` when nothing moves or no point survives.
///
/// When a point the tracker lost had travelled farther before it was lost than every
/// point that survived, the hand itself was lost and the survivors are on the slower
/// shoulder or torso: the clip is tracked again with the coarse window (15×15 on 4 levels).
pub fn hand_tracks(frames: &[Vec<u8>], w: usize, h: usize, seeds: Seeds) -> Option<Tracks> {
    Tracker::new(frames, w, h)?.tracks(seeds)
}

/// [`hand_tracks`] with both seeds, `(First, Through)`: the first frame's corners, which
/// both follow, are followed once.
pub fn hand_tracks_both(frames: &[Vec<u8>], w: usize, h: usize) -> [Option<Tracks>; 2] {
    match Tracker::new(frames, w, h) {
        Some(mut t) => [t.tracks(Seeds::First), t.tracks(Seeds::Through)],
        None => [None, None],
    }
}

/// A clip's pyramids and motion mask, and the points followed from each seed frame with
/// each window so far.
struct Tracker {
    mask: Vec<bool>,
    pyr: Vec<Pyramid>,
    /// (seed frame, coarse window?) → its points followed.
    followed: std::collections::HashMap<(usize, bool), Followed>,
}

impl Tracker {
    /// `None` for fewer than 2 frames.
    fn new(frames: &[Vec<u8>], w: usize, h: usize) -> Option<Tracker> {
        if frames.len() < 2 {
            return None;
        }
        Some(Tracker {
            mask: motion_mask(frames, w, h),
            // One pyramid per frame serves both windows (the fine one uses its lower levels).
            pyr: frames
                .iter()
                .map(|f| Pyramid::new(Gray::from_rgb(f, w, h), COARSE.levels))
                .collect(),
            followed: std::collections::HashMap::new(),
        })
    }

    /// The most travelled points seeded as `seeds` says (see [`hand_tracks`]).
    fn tracks(&mut self, seeds: Seeds) -> Option<Tracks> {
        let every = match seeds {
            Seeds::First => self.pyr.len(),
            Seeds::Through => SEED_EVERY,
        };
        let fine = self.all_from(every, false);
        let followed = if fine.hand_lost() {
            self.all_from(every, true)
        } else {
            fine
        };
        followed.top()
    }

    /// The points of every `every`th frame's corners, followed with the fine or coarse window.
    fn all_from(&mut self, every: usize, coarse: bool) -> Followed {
        let mut all = Followed {
            tracks: Vec::new(),
            alive: Vec::new(),
        };
        for k in (0..self.pyr.len()).step_by(every) {
            let (pyr, mask) = (&self.pyr, &self.mask);
            let more = self.followed.entry((k, coarse)).or_insert_with(|| {
                let (_, gx, gy) = &pyr[k].levels[0];
                follow(pyr, k, &corners(gx, gy, mask), if coarse { COARSE } else { FINE })
            });
            all.tracks.extend(more.tracks.iter().cloned());
            all.alive.extend(more.alive.iter().copied());
        }
        all
    }
}

/// Points followed through a clip.
struct Followed {
    /// Per point, its position in every frame (held where it was lost).
    tracks: Vec<Vec<(f64, f64)>>,
    alive: Vec<bool>,
}

/// Follows `start` (points of frame `k`) forwards to the last frame and backwards to the
/// first through the frames' pyramids with `window`; a point is lost when LK fails or its
/// forward–backward check misses by [`FB_MAX`].
fn follow(pyr: &[Pyramid], k: usize, start: &[(f64, f64)], window: Window) -> Followed {
    let n = pyr.len();
    let mut tracks: Vec<Vec<(f64, f64)>> = start.iter().map(|&p| vec![p; n]).collect();
    let mut alive = vec![true; start.len()];
    let step = |from: usize, to: usize, p: (f64, f64)| {
        lk(&pyr[from], &pyr[to], p, window).filter(|&q| {
            lk(&pyr[to], &pyr[from], q, window)
                .is_some_and(|back| (back.0 - p.0).hypot(back.1 - p.1) < FB_MAX)
        })
    };
    for (track, alive) in tracks.iter_mut().zip(alive.iter_mut()) {
        for (from, to) in (k..n - 1)
            .map(|t| (t, t + 1))
            .chain((1..=k).rev().map(|t| (t, t - 1)))
        {
            let p = track[from];
            match (*alive).then(|| step(from, to, p)).flatten() {
                Some(q) => track[to] = q,
                None => {
                    *alive = false;
                    track[to] = p;
                }
            }
        }
    }
    Followed { tracks, alive }
}

impl Followed {
    fn travel(track: &[(f64, f64)]) -> f64 {
        track
            .windows(2)
            .map(|s| (s[1].0 - s[0].0).hypot(s[1].1 - s[0].1))
            .sum()
    }

    /// Whether a lost point had travelled farther than every surviving one.
    fn hand_lost(&self) -> bool {
        let farthest = |alive: bool| {
            self.tracks
                .iter()
                .zip(&self.alive)
                .filter(|&(_, &a)| a == alive)
                .map(|(t, _)| Self::travel(t))
                .fold(0.0, f64::max)
        };
        farthest(false) > farthest(true)
    }

    /// The [`TOP_POINTS`] most travelled surviving tracks, farthest first.
    fn top(mut self) -> Option<Tracks> {
        let mut travelled: Vec<(f64, usize)> = self
            .tracks
            .iter()
            .enumerate()
            .filter(|&(k, _)| self.alive[k])
            .map(|(k, t)| (Self::travel(t), k))
            .collect();
        travelled.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let top: Vec<usize> = travelled
            .iter()
            .take(TOP_POINTS)
            // Points that hardly move (background corners at the mask's edge) are no hand.
            .filter(|t| t.0 > 0.0 && t.0 >= MIN_TRAVEL_SHARE * travelled[0].0)
            .map(|t| t.1)
            .collect();
        if top.is_empty() {
            return None;
        }
        Some(
            top.into_iter()
                .map(|k| std::mem::take(&mut self.tracks[k]))
                .collect(),
        )
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A textured square (checkerboard of 2-pixel cells) on a flat grey background.
    fn frame(w: usize, h: usize, cx: f64, cy: f64) -> Vec<u8> {
        let mut rgb = vec![90u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f64 - cx, y as f64 - cy);
                if dx.abs() < 8.0 && dy.abs() < 8.0 {
                    let on = ((dx + 8.0) as usize / 2 + (dy + 8.0) as usize / 2).is_multiple_of(2);
                    let v = if on { 230 } else { 20 };
                    rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].fill(v);
                }
            }
        }
        rgb
    }

    /// The patch's centre over `n` frames: 2 px right and 1 px down per frame from (12, 12).
    fn diagonal(n: usize) -> Vec<(f64, f64)> {
        (0..n).map(|t| (12.0 + 2.0 * t as f64, 12.0 + t as f64)).collect()
    }

    /// The pyramids of the patch's frames along `path`, for `window`.
    fn pyramids(path: &[(f64, f64)], w: usize, h: usize, window: Window) -> Vec<Pyramid> {
        path.iter()
            .map(|&(x, y)| Pyramid::new(Gray::from_rgb(&frame(w, h, x, y), w, h), window.levels))
            .collect()
    }

    #[test]
    fn a_moving_textured_patch_is_followed_to_within_a_pixel() {
        let (w, h) = (64, 48);
        let path = diagonal(20);
        let frames: Vec<Vec<u8>> = path.iter().map(|&(x, y)| frame(w, h, x, y)).collect();
        let tracks = hand_tracks(&frames, w, h, Seeds::First).unwrap();
        assert_eq!(tracks.len(), TOP_POINTS);
        // The points sit on the patch: each one's offset from its centre stays within a
        // pixel for most of the clip (a point at an edge may slide along it a little).
        for track in tracks {
            let off = (track[0].0 - path[0].0, track[0].1 - path[0].1);
            let held = track
                .iter()
                .zip(&path)
                .filter(|(got, want)| (got.0 - want.0 - off.0).hypot(got.1 - want.1 - off.1) < 1.0)
                .count();
            assert!(held >= 18, "{held} of 20 frames: {track:?}");
        }
    }

    #[test]
    fn a_lost_point_that_outran_every_survivor_means_the_hand_was_lost() {
        let line = |len: usize, speed: f64| (0..len).map(|t| (speed * t as f64, 0.0)).collect::<Vec<_>>();
        // The fast point is lost at frame 6 after 10 px; the survivor moves 8 px in all.
        let mut lost = line(6, 2.0);
        lost.resize(9, lost[5]);
        let f = Followed {
            tracks: vec![lost.clone(), line(9, 1.0)],
            alive: vec![false, true],
        };
        assert!(f.hand_lost());
        // A survivor that travels farther than anything lost keeps the fine tracks.
        let f = Followed {
            tracks: vec![lost, line(9, 1.5)],
            alive: vec![false, true],
        };
        assert!(!f.hand_lost());
        assert_eq!(f.top().unwrap().len(), 1);
    }

    #[test]
    fn the_coarse_window_follows_the_patch_too() {
        // At the frame size of the sets it is meant for (its coarsest level is 1/8 of it).
        let path: Vec<(f64, f64)> = (0..12)
            .map(|t| (30.0 + 4.0 * t as f64, 40.0 + 2.0 * t as f64))
            .collect();
        let pyr = pyramids(&path, 128, 128, COARSE);
        let f = follow(&pyr, 0, &[(path[0].0 - 1.0, path[0].1 - 1.0)], COARSE);
        assert!(f.alive[0]);
        let end = f.tracks[0][11];
        assert!(
            (end.0 - path[11].0 + 1.0).hypot(end.1 - path[11].1 + 1.0) < 1.0,
            "{end:?}"
        );
    }

    #[test]
    fn a_still_clip_has_no_track() {
        let frames = vec![frame(32, 32, 16.0, 16.0); 5];
        assert!(hand_tracks(&frames, 32, 32, Seeds::First).is_none());
    }

    #[test]
    fn a_point_seeded_mid_clip_is_followed_to_both_ends() {
        let (w, h) = (64, 48);
        let path = diagonal(16);
        let pyr = pyramids(&path, w, h, FINE);
        // A corner of the checkerboard, 2 px up and left of the patch's centre, at frame 9.
        let f = follow(&pyr, 9, &[(path[9].0 - 2.0, path[9].1 - 2.0)], FINE);
        assert!(f.alive[0]);
        for t in [0, 9, 15] {
            let got = f.tracks[0][t];
            assert!(
                (got.0 - path[t].0 + 2.0).hypot(got.1 - path[t].1 + 2.0) < 1.0,
                "frame {t}: {got:?}"
            );
        }
        // Seeding through the clip finds the patch as seeding at the start does.
        let frames: Vec<Vec<u8>> = path.iter().map(|&(x, y)| frame(w, h, x, y)).collect();
        let through = hand_tracks(&frames, w, h, Seeds::Through).unwrap();
        assert_eq!(through.len(), TOP_POINTS);
        // Both seeds in one pass (the first frame's points followed once): the same tracks.
        let both = hand_tracks_both(&frames, w, h);
        assert_eq!(both[0], hand_tracks(&frames, w, h, Seeds::First));
        assert_eq!(both[1].as_ref(), Some(&through));
        for track in through {
            let off = (track[0].0 - path[0].0, track[0].1 - path[0].1);
            assert!(off.0.hypot(off.1) < 12.0, "{track:?}");
            let end = (track[15].0 - path[15].0 - off.0, track[15].1 - path[15].1 - off.1);
            assert!(end.0.hypot(end.1) < 1.5, "{track:?}");
        }
    }
}
