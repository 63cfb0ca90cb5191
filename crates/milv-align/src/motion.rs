//! The pieces of the `motion` feature: where the arm's tip is in each frame, from frame
//! differences, and where that is on the table plane.
//!
//! Both arms enter the picture from one side and their tip is the part of the moving
//! region farthest from it. Differencing frames `t−1` and `t+1` finds what moves without a
//! background model, so objects that were pushed leave no "ghost" behind and a sleeve
//! that covers the same cells for most of the clip is not mistaken for the table. The
//! tip's pixel position is then mapped onto the table plane through the homography of
//! the table's image quad (detected in the clip's median frame), which undoes each
//! camera's perspective: both clips then move in one square, up to its 8 symmetries.
//! The hand region, reaching deeper into the moving pixels than the tip, is followed
//! alongside: its centre is nearer the end effector. It is measured from where the arm
//! enters the picture rather than from the border as a whole, so an arm that enters at one
//! end of the border and lies along it (a robot's link across the table) still ends in
//! its hand, not in the middle of the link.

use milv_geom::Homography;

/// RGB distance (0–441) below which a pixel counts as still; raised for noisy clips.
const MIN_MOTION: f32 = 12.0;
/// The tip region: moving pixels within this many pixels (at 128 px) of the farthest one.
const TIP_BAND_128: f64 = 8.0;
/// The hand region, deeper: its centre is nearer the end effector than the tip's (on the
/// milv-sim sets 12 px aligned best of 8–24 measured as depth from the border, and tied
/// with 14 of 8–16 measured from the arm's entry; BENCHMARKS.md).
const HAND_BAND_128: f64 = 12.0;
/// At most this many frames go into the median frame the table is found in.
const BACKGROUND_SAMPLES: usize = 32;

/// Which image border the arm enters from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Bottom,
    Top,
    Left,
    Right,
}

const SIDES: [Side; 4] = [Side::Bottom, Side::Top, Side::Left, Side::Right];

impl Side {
    /// Distance of pixel (x, y) from this border.
    fn depth(self, x: usize, y: usize, w: usize, h: usize) -> usize {
        match self {
            Side::Bottom => h - 1 - y,
            Side::Top => y,
            Side::Left => x,
            Side::Right => w - 1 - x,
        }
    }
}

/// What one frame's moving pixels say: for each possible entry side, the tip (pixel
/// centre, x right, y down), and how many moving pixels lie on that border.
#[derive(Clone, Debug, Default)]
struct FrameMotion {
    tips: [Option<(f64, f64)>; 4],
    hands: [Option<(f64, f64)>; 4],
    border: [usize; 4],
}

/// The centre (mean position) of the pixels added to it: of a tip or hand region, and,
/// summed over the frames so far, of the moving pixels on one border, where the arm enters.
#[derive(Clone, Copy, Debug, Default)]
struct Centre {
    sx: f64,
    sy: f64,
    k: usize,
}

impl Centre {
    /// Adds pixel (x, y), at its centre.
    fn add(&mut self, (x, y): (usize, usize)) {
        self.sx += x as f64 + 0.5;
        self.sy += y as f64 + 0.5;
        self.k += 1;
    }

    /// Adds every pixel another centre holds.
    fn merge(&mut self, other: Centre) {
        self.sx += other.sx;
        self.sy += other.sy;
        self.k += other.k;
    }

    fn of<'a>(pixels: impl IntoIterator<Item = &'a (usize, usize)>) -> Centre {
        let mut c = Centre::default();
        pixels.into_iter().for_each(|&p| c.add(p));
        c
    }

    fn centre(&self) -> Option<(f64, f64)> {
        (self.k > 0).then(|| (self.sx / self.k as f64, self.sy / self.k as f64))
    }
}

/// `|frame_b − frame_a|` per pixel (RGB distance), box-blurred over 3×3 so a single
/// noisy pixel does not count as motion.
pub(crate) fn motion_map(a: &[u8], b: &[u8], w: usize, h: usize) -> Vec<f32> {
    let d: Vec<f32> = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| {
            let s: f32 = (0..3).map(|c| (f32::from(p[c]) - f32::from(q[c])).powi(2)).sum();
            s.sqrt()
        })
        .collect();
    box3(&d, w, h)
}

/// 3×3 mean filter, edges clamped.
fn box3(v: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut rows = vec![0.0f32; v.len()];
    for y in 0..h {
        for x in 0..w {
            let (l, r) = (x.saturating_sub(1), (x + 1).min(w - 1));
            rows[y * w + x] = (v[y * w + l] + v[y * w + x] + v[y * w + r]) / 3.0;
        }
    }
    let mut out = vec![0.0f32; v.len()];
    for y in 0..h {
        let (u, d) = (y.saturating_sub(1), (y + 1).min(h - 1));
        for x in 0..w {
            out[y * w + x] = (rows[u * w + x] + rows[y * w + x] + rows[d * w + x]) / 3.0;
        }
    }
    out
}

/// The moving pixels of one motion map and their tip and hand region for every entry side;
/// `entries` gathers each border's moving pixels over the clip, for frames with too few
/// of their own to say where the arm enters.
fn frame_motion(d: &[f32], w: usize, h: usize, entries: &mut [Centre; 4]) -> FrameMotion {
    // Noise floor: a robust scale of the map (most pixels are still), never below
    // MIN_MOTION, so clean synthetic clips and noisy camera clips both work.
    let mut sorted = d.to_vec();
    let mid = sorted.len() / 2;
    let median = *sorted.select_nth_unstable_by(mid, f32::total_cmp).1;
    let thr = MIN_MOTION.max(5.0 * 1.4826 * median);
    let moving: Vec<(usize, usize)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| d[y * w + x] > thr)
        .collect();
    let mut fm = FrameMotion::default();
    // Where the arm enters through each border in this frame (its own moving pixels there,
    // if at least 3), else over the clip so far.
    let mut enters: [Option<(f64, f64)>; 4] = [None; 4];
    for (s, side) in SIDES.iter().enumerate() {
        let own = Centre::of(moving.iter().filter(|&&(x, y)| side.depth(x, y, w, h) == 0));
        entries[s].merge(own);
        fm.border[s] = own.k;
        enters[s] = if own.k >= 3 {
            own.centre()
        } else {
            entries[s].centre()
        };
    }
    if moving.len() < 3 {
        return fm;
    }
    let px = |band: f64| (band * w.min(h) as f64 / 128.0).round().max(2.0) as usize;
    for (s, side) in SIDES.iter().enumerate() {
        let far = moving
            .iter()
            .map(|&(x, y)| side.depth(x, y, w, h))
            .max()
            .unwrap_or(0);
        // Every moving pixel fewer than the tip band's pixels from this border (depth 0 is
        // the border row): the arm moved where it enters the picture and the hand did not
        // register (a hand starting from rest, its thin fingers under the threshold), so
        // the frame says nothing of where the hand is and holds a neighbour's tip. (An arm
        // whose tip itself is still entering the picture loses those frames too; on the
        // twelve evaluation sets this fired on one frame: BENCHMARKS.md, "A tip on the
        // entry border".)
        if far < px(TIP_BAND_128) {
            continue;
        }
        // At least the farthest pixel lies in either band.
        let centre = |band: usize| {
            Centre::of(
                moving
                    .iter()
                    .filter(|&&(x, y)| side.depth(x, y, w, h) + band >= far),
            )
            .centre()
        };
        fm.tips[s] = centre(px(TIP_BAND_128));
        fm.hands[s] = match enters[s] {
            Some(entry) => hand_region(&moving, *side, entry, w, h, px(TIP_BAND_128), px(HAND_BAND_128)),
            None => centre(px(HAND_BAND_128)),
        };
    }
    fm
}

/// The centre of the moving pixels within `band` pixels of the farthest from `entry`,
/// among those at least `skip` pixels deep: the border's own rows are where the arm
/// enters, and a sleeve as wide as the hand would otherwise pull the region onto the
/// border while the hand is still coming in. Depth from the border would instead take
/// the whole top edge of an arm lying across the picture (on milv-sim's pushing, the
/// robot's link, whose middle then stood for the hand; BENCHMARKS.md, "The hand region
/// measured from where the arm enters"). None when no pixel lies that deep.
fn hand_region(
    moving: &[(usize, usize)],
    side: Side,
    entry: (f64, f64),
    w: usize,
    h: usize,
    skip: usize,
    band: usize,
) -> Option<(f64, f64)> {
    let dist = |x: usize, y: usize| (x as f64 + 0.5 - entry.0).hypot(y as f64 + 0.5 - entry.1);
    let deep = || moving.iter().filter(|&&(x, y)| side.depth(x, y, w, h) >= skip);
    let far = deep().map(|&(x, y)| dist(x, y)).fold(0.0, f64::max);
    Centre::of(deep().filter(|&&(x, y)| dist(x, y) + band as f64 >= far)).centre()
}

/// What [`TipTracker::finish`] found in a clip.
#[derive(Clone, Debug)]
pub struct Track {
    /// The border the arm enters from.
    pub side: Side,
    /// One tip (pixels) per frame; frames without motion beyond the entry border's tip band
    /// hold the nearest earlier tip (the first frames the first found).
    pub tips: Vec<(f64, f64)>,
    /// The hand region's centre per frame, held like `tips`.
    pub hands: Vec<(f64, f64)>,
    /// Median luma frame (of at most 32 frames spread over the clip).
    pub background: Vec<u8>,
}

/// Tip positions (pixels) of a clip, one per frame, from frames decoded in order.
pub struct TipTracker {
    w: usize,
    h: usize,
    n: usize,
    frames: Vec<FrameMotion>,
    entries: [Centre; 4],
    /// Frames t−1 and t of the sliding window (the map of t needs t+1).
    window: Vec<Vec<u8>>,
    background: Vec<Vec<u8>>,
    sample_every: usize,
    seen: usize,
}

impl TipTracker {
    /// A tracker for a clip of `n ≥ 2` frames of `w`×`h`.
    pub fn new(w: usize, h: usize, n: usize) -> Self {
        TipTracker {
            w,
            h,
            n,
            frames: Vec::with_capacity(n),
            entries: [Centre::default(); 4],
            window: Vec::new(),
            background: Vec::new(),
            sample_every: n.div_ceil(BACKGROUND_SAMPLES).max(1),
            seen: 0,
        }
    }

    /// Feeds the next frame (RGB24, `w`×`h`).
    pub fn push(&mut self, rgb: Vec<u8>) {
        if self.seen.is_multiple_of(self.sample_every) {
            self.background.push(rgb.chunks_exact(3).map(luma).collect());
        }
        self.seen += 1;
        // The map of frame t compares t−1 and t+1 (clamped at the ends).
        if self.window.len() == 2 {
            let d = motion_map(&self.window[0], &rgb, self.w, self.h);
            self.frames
                .push(frame_motion(&d, self.w, self.h, &mut self.entries));
            self.window.remove(0);
        } else if self.window.len() == 1 {
            let d = motion_map(&self.window[0], &rgb, self.w, self.h);
            self.frames
                .push(frame_motion(&d, self.w, self.h, &mut self.entries));
        }
        self.window.push(rgb);
        if self.seen == self.n && self.window.len() == 2 {
            let d = motion_map(&self.window[0], &self.window[1], self.w, self.h);
            self.frames
                .push(frame_motion(&d, self.w, self.h, &mut self.entries));
        }
    }

    /// The clip's track; `None` when nothing moves in it beyond the tip band of the border
    /// it enters from.
    pub fn finish(self) -> Option<Track> {
        let totals: [usize; 4] = std::array::from_fn(|s| self.frames.iter().map(|f| f.border[s]).sum());
        // Ties (e.g. an arm that never touches the border) resolve to the bottom.
        let s = (0..4).rev().max_by_key(|&s| totals[s]).unwrap_or(0);
        Some(Track {
            side: SIDES[s],
            tips: held(self.frames.iter().map(|f| f.tips[s]))?,
            hands: held(self.frames.iter().map(|f| f.hands[s]))?,
            background: median_frame(&self.background),
        })
    }
}

/// One point per frame, frames without one holding the nearest earlier (the first frames
/// the first found); `None` when no frame has one.
fn held(points: impl Iterator<Item = Option<(f64, f64)>> + Clone) -> Option<Vec<(f64, f64)>> {
    let mut last = points.clone().flatten().next()?;
    Some(
        points
            .map(|p| {
                if let Some(p) = p {
                    last = p;
                }
                last
            })
            .collect(),
    )
}

pub(crate) fn luma(p: &[u8]) -> u8 {
    (0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2])).round() as u8
}

/// Per-pixel median of equally sized luma frames.
fn median_frame(frames: &[Vec<u8>]) -> Vec<u8> {
    let len = frames.first().map_or(0, Vec::len);
    let mut col = Vec::with_capacity(frames.len());
    (0..len)
        .map(|i| {
            col.clear();
            col.extend(frames.iter().map(|f| f[i]));
            col.sort_unstable();
            col[col.len() / 2]
        })
        .collect()
}

/// Otsu's threshold of a luma image: the level that best separates two classes, if
/// their means differ by at least 20 grey levels (a picture with no bright table has none).
fn otsu(img: &[u8]) -> Option<u8> {
    let mut hist = [0u64; 256];
    img.iter().for_each(|&v| hist[v as usize] += 1);
    let total = img.len() as f64;
    let sum_all: f64 = hist.iter().enumerate().map(|(v, &c)| v as f64 * c as f64).sum();
    let (mut w0, mut sum0, mut best, mut level) = (0.0, 0.0, -1.0, None);
    for (v, &c) in hist.iter().enumerate() {
        w0 += c as f64;
        sum0 += v as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (sum_all - sum0) / w1);
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            level = ((m1 - m0) >= 20.0).then_some(v as u8);
        }
    }
    level
}

/// The largest 4-connected region of `mask` (indices into it).
fn largest_region(mask: &[bool], w: usize, h: usize) -> Vec<usize> {
    let mut seen = vec![false; mask.len()];
    let mut best = Vec::new();
    let mut stack = Vec::new();
    for start in 0..mask.len() {
        if !mask[start] || seen[start] {
            continue;
        }
        let mut region = Vec::new();
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            region.push(i);
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if mask[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        if region.len() > best.len() {
            best = region;
        }
    }
    best
}

/// The table's corners in a (median) luma frame: the largest bright region's extreme
/// points along the two diagonals, in image order top-left, top-right, bottom-right,
/// bottom-left. `None` when no plausible table quad is found (too small, or the region
/// is not quad-shaped), and the caller falls back to image coordinates.
pub fn table_quad(luma: &[u8], w: usize, h: usize) -> Option<[(f64, f64); 4]> {
    let thr = otsu(luma)?;
    let mask: Vec<bool> = luma.iter().map(|&v| v > thr).collect();
    let region = largest_region(&mask, w, h);
    if region.len() * 10 < w * h {
        return None;
    }
    let pt = |i: usize| ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
    let extreme = |f: &dyn Fn((f64, f64)) -> f64| {
        region
            .iter()
            .map(|&i| pt(i))
            .max_by(|a, b| f(*a).total_cmp(&f(*b)))
            .unwrap_or((0.0, 0.0))
    };
    let quad = [
        extreme(&|(x, y)| -x - y),
        extreme(&|(x, y)| x - y),
        extreme(&|(x, y)| x + y),
        extreme(&|(x, y)| y - x),
    ];
    // Shoelace area: a table seen in perspective fills most of its corners' quad.
    let area = (0..4)
        .map(|k| {
            let (a, b) = (quad[k], quad[(k + 1) % 4]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum::<f64>()
        / 2.0;
    (area > 0.0 && (region.len() as f64) > 0.7 * area && (region.len() as f64) < 1.2 * area).then_some(quad)
}

/// The map taking `quad` (image order) to the unit square's (0,0), (1,0), (1,1), (0,1).
pub fn to_unit_square(quad: &[(f64, f64); 4]) -> Option<Homography> {
    Homography::from_points(quad, &[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
}

/// Median over a `k`-frame window (edges repeat the end values), per coordinate.
pub fn median_filter(v: &[f64], k: usize) -> Vec<f64> {
    let r = k / 2;
    let n = v.len();
    let mut win = Vec::with_capacity(k);
    (0..n)
        .map(|i| {
            win.clear();
            win.extend((0..k).map(|o| v[(i + o).saturating_sub(r).min(n - 1)]));
            win.sort_by(f64::total_cmp);
            win[r]
        })
        .collect()
}

/// Gaussian smoothing with standard deviation `sigma` frames (kernel cut at 4σ, edges
/// repeat the end values).
pub fn gaussian_filter(v: &[f64], sigma: f64) -> Vec<f64> {
    let r = (4.0 * sigma).round() as isize;
    let kernel: Vec<f64> = (-r..=r)
        .map(|o| (-(o * o) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f64 = kernel.iter().sum();
    let n = v.len() as isize;
    (0..n)
        .map(|i| {
            (-r..=r)
                .zip(&kernel)
                .map(|(o, k)| k * v[(i + o).clamp(0, n - 1) as usize])
                .sum::<f64>()
                / norm
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_tilted_bright_quad_is_found_and_mapped_to_the_unit_square() {
        let (w, h) = (96usize, 80usize);
        let corners = [(20.0, 10.0), (80.0, 16.0), (90.0, 70.0), (6.0, 64.0)];
        // Inside test by the sign of the cross product along each (clockwise in image) edge.
        let inside = |x: f64, y: f64| {
            (0..4).all(|k| {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0) >= 0.0
            })
        };
        let luma: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                if inside(x, y) { 180 } else { 40 }
            })
            .collect();
        let quad = table_quad(&luma, w, h).unwrap();
        for (got, want) in quad.iter().zip(&corners) {
            assert!(
                (got.0 - want.0).abs() < 2.0 && (got.1 - want.1).abs() < 2.0,
                "{quad:?}"
            );
        }
        let hmg = to_unit_square(&corners).unwrap();
        for (c, want) in corners
            .iter()
            .zip([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
        {
            let (u, v) = hmg.apply(*c);
            assert!((u - want.0).abs() < 1e-9 && (v - want.1).abs() < 1e-9);
        }
        // A dark frame with no table: no quad.
        assert!(table_quad(&vec![30u8; w * h], w, h).is_none());
    }

    #[test]
    fn filters_keep_constants_and_remove_spikes() {
        let mut v = vec![2.0; 11];
        assert_eq!(gaussian_filter(&v, 2.5), v);
        v[5] = 50.0;
        assert_eq!(median_filter(&v, 5), vec![2.0; 11]);
        let ramp: Vec<f64> = (0..20).map(f64::from).collect();
        let g = gaussian_filter(&ramp, 1.0);
        assert!((g[10] - 10.0).abs() < 1e-9);
    }

    #[test]
    fn motion_only_on_the_entry_border_holds_the_next_frames_tip() {
        // Frame 0's map sees only the sleeve shifting on the bottom border (rows 125..128);
        // from frame 1 on the hand moves at rows 60..70.
        let (w, h, n) = (64usize, 128usize, 5usize);
        let frame = |t: usize| -> Vec<u8> {
            let mut rgb = vec![120u8; w * h * 3];
            let mut paint = |x0: usize, y0: usize, x1: usize, y1: usize| {
                for y in y0..y1 {
                    for x in x0..x1 {
                        rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[230, 180, 150]);
                    }
                }
            };
            // The sleeve: frames 0 and 1 differ by it only.
            paint(20 + 4 * t.min(1), 125, 30 + 4 * t.min(1), 128);
            // The hand: still over frames 0 and 1, then moving up 4 rows a frame.
            let top = 60 - 4 * t.saturating_sub(1);
            paint(28, top, 36, top + 10);
            rgb
        };
        let mut tr = TipTracker::new(w, h, n);
        (0..n).for_each(|t| tr.push(frame(t)));
        let track = tr.finish().unwrap();
        assert_eq!(track.side, Side::Bottom);
        // Frame 0 (map of frames 0 and 1) has no tip of its own: it holds frame 1's, on the
        // hand, not a point on the border.
        assert!(track.tips[0].1 < 70.0, "{:?}", track.tips);
        assert_eq!(track.tips[0], track.tips[1]);
        assert_eq!(track.hands[0], track.hands[1]);
    }

    #[test]
    fn still_clips_have_no_tip() {
        let mut t = TipTracker::new(16, 16, 3);
        for _ in 0..3 {
            t.push(vec![100u8; 16 * 16 * 3]);
        }
        assert!(t.finish().is_none());
        // Nor do clips whose only motion is a sleeve shifting on the border.
        let (w, h) = (64usize, 64usize);
        let mut t = TipTracker::new(w, h, 4);
        for k in 0..4 {
            let mut rgb = vec![120u8; w * h * 3];
            for y in 62..64 {
                for x in 10 + 3 * k..20 + 3 * k {
                    rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[40, 60, 160]);
                }
            }
            t.push(rgb);
        }
        assert!(t.finish().is_none());
    }

    /// A motion map with the given rectangles (x0, y0, x1, y1, half-open) moving.
    fn moving_map(w: usize, h: usize, rects: &[(usize, usize, usize, usize)]) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let on = rects
                    .iter()
                    .any(|&(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y));
                if on { 100.0 } else { 0.0 }
            })
            .collect()
    }

    #[test]
    fn an_arm_lying_across_the_picture_ends_in_its_hand() {
        // A robot's upper link up from the bottom border at the left, its forearm lying
        // level across the picture (rows 56..60) to a gripper at x 100..106 (rows 55..61).
        let (w, h) = (128usize, 128usize);
        let d = moving_map(w, h, &[(10, 58, 14, 128), (14, 56, 100, 60), (100, 55, 106, 61)]);
        let fm = frame_motion(&d, w, h, &mut [Centre::default(); 4]);
        let (tip, hand) = (fm.tips[0].unwrap(), fm.hands[0].unwrap());
        // Depth from the border takes the forearm's whole top edge: the tip is mid-link.
        assert!(tip.0 < 70.0, "{tip:?}");
        // Distance from where the arm enters (x ≈ 12 on the bottom row) ends at the gripper.
        assert!(hand.0 > 90.0 && (55.0..61.0).contains(&hand.1), "{hand:?}");
    }

    #[test]
    fn a_hand_coming_in_over_a_wide_sleeve_stays_off_the_border() {
        // Only a 24 px wide blob on the bottom rows moves: the hand entering the picture.
        let (w, h) = (128usize, 128usize);
        let d = moving_map(w, h, &[(48, 116, 72, 128)]);
        let mut entries = [Centre::default(); 4];
        let fm = frame_motion(&d, w, h, &mut entries);
        let hand = fm.hands[0].unwrap();
        // The border's rows (within the tip band, 8 px) are where the arm enters; the
        // region lies above them.
        assert!(hand.1 < 120.0 && (hand.0 - 60.0).abs() < 1e-9, "{hand:?}");
        // The frame's border pixels were gathered for later frames with too few of their own.
        assert_eq!(entries[0].centre(), Some((60.0, 127.5)));
    }

    #[test]
    fn the_hand_region_lies_deeper_than_the_tip() {
        // An arm from the bottom border up to row 40: a 4 px forearm under a 10 px hand.
        let (w, h) = (128usize, 128usize);
        let d = moving_map(w, h, &[(59, 40, 69, 50), (62, 50, 66, 128)]);
        let fm = frame_motion(&d, w, h, &mut [Centre::default(); 4]);
        let (tip, hand) = (fm.tips[0].unwrap(), fm.hands[0].unwrap());
        // Rows 40..=48 against the pixels within 12 px of the farthest from the entry
        // (x 64 on the bottom row): the hand down to row 51 (the forearm's narrow rows
        // weigh less).
        assert!((tip.1 - 44.5).abs() < 1e-9, "{tip:?}");
        assert!(hand.1 > tip.1 + 0.5 && hand.1 < 48.0, "{hand:?}");
        assert!((tip.0 - 64.0).abs() < 1e-9 && (hand.0 - 64.0).abs() < 1e-9);
    }
}
