//! Drawing-task shapes (paper, Appendix A.1): 11 training shapes and 12 test shapes
//! (4 scale variants, 3 rotation variants, 5 unseen shapes), as closed or open paths on
//! the table, and the success metric.

use serde::{Deserialize, Serialize};

use crate::geom::{EPISODE_STEPS, Vec2};

/// Centre of the drawing area on the table (cm).
pub const CENTER: Vec2 = Vec2::new(30.0, 30.0);
/// Points the executed and the guide path are resampled to before matching.
pub const MATCH_POINTS: usize = 50;
/// Two resampled points match when closer than this (cm): about a pen-tip width plus the
/// tracking error of a 5 cm/step controller.
pub const MATCH_TOLERANCE_CM: f32 = 2.5;
/// A drawing succeeds when the longest common subsequence has at least this many points
/// (60 % of 50, as in the paper).
pub const SUCCESS_LCS: usize = 30;

/// A named drawing shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    pub name: String,
    /// The guide path in table coordinates, in drawing order.
    pub path: Vec<Vec2>,
}

fn regular(n: usize, radius: f32, rot: f32) -> Vec<Vec2> {
    let mut p: Vec<Vec2> = (0..=n)
        .map(|i| {
            let a = rot + std::f32::consts::TAU * i as f32 / n as f32 + std::f32::consts::FRAC_PI_2;
            CENTER + Vec2::from_angle(a) * radius
        })
        .collect();
    // Close exactly (no float drift between first and last point).
    if let Some(first) = p.first().copied()
        && let Some(last) = p.last_mut()
    {
        *last = first;
    }
    p
}

fn circle(radius: f32) -> Vec<Vec2> {
    regular(48, radius, 0.0)
}

fn star(r_out: f32, r_in: f32) -> Vec<Vec2> {
    let mut p: Vec<Vec2> = (0..=10)
        .map(|i| {
            let r = if i % 2 == 0 { r_out } else { r_in };
            let a = std::f32::consts::TAU * i as f32 / 10.0 + std::f32::consts::FRAC_PI_2;
            CENTER + Vec2::from_angle(a) * r
        })
        .collect();
    if let Some(first) = p.first().copied()
        && let Some(last) = p.last_mut()
    {
        *last = first;
    }
    p
}

fn from_points(pts: &[(f32, f32)], scale: f32) -> Vec<Vec2> {
    pts.iter()
        .map(|&(x, y)| CENTER + Vec2::new(x, y) * scale)
        .collect()
}

fn scaled(path: &[Vec2], k: f32) -> Vec<Vec2> {
    path.iter().map(|&p| CENTER + (p - CENTER) * k).collect()
}

fn rotated(path: &[Vec2], a: f32) -> Vec<Vec2> {
    path.iter().map(|&p| CENTER + (p - CENTER).rotated(a)).collect()
}

fn shape(name: &str, path: Vec<Vec2>) -> Shape {
    Shape {
        name: name.into(),
        path,
    }
}

/// The 11 training shapes.
pub fn training_shapes() -> Vec<Shape> {
    vec![
        shape("triangle_s", regular(3, 9.0, 0.0)),
        shape("triangle_l", regular(3, 14.0, 0.0)),
        shape("square_s", regular(4, 9.0, std::f32::consts::FRAC_PI_4)),
        shape("square_l", regular(4, 14.0, std::f32::consts::FRAC_PI_4)),
        shape("circle_s", circle(8.0)),
        shape("circle_l", circle(13.0)),
        shape("pentagon", regular(5, 12.0, 0.0)),
        shape("hexagon", regular(6, 12.0, 0.0)),
        shape(
            "diamond",
            from_points(
                &[(0.0, 12.0), (8.0, 0.0), (0.0, -12.0), (-8.0, 0.0), (0.0, 12.0)],
                1.0,
            ),
        ),
        shape("star", star(14.0, 6.0)),
        shape(
            "zigzag",
            from_points(
                &[(-14.0, -8.0), (-7.0, 8.0), (0.0, -8.0), (7.0, 8.0), (14.0, -8.0)],
                1.0,
            ),
        ),
    ]
}

/// The 12 test shapes: 4 scale variants, 3 rotation variants, 5 unseen shapes.
pub fn test_shapes() -> Vec<Shape> {
    let train = training_shapes();
    let by = |n: &str| {
        train
            .iter()
            .find(|s| s.name == n)
            .map(|s| s.path.clone())
            .unwrap_or_default()
    };
    let heart: Vec<Vec2> = (0..=48)
        .map(|i| {
            let t = std::f32::consts::TAU * i as f32 / 48.0;
            let x = 16.0 * t.sin().powi(3);
            let y = 13.0 * t.cos() - 5.0 * (2.0 * t).cos() - 2.0 * (3.0 * t).cos() - (4.0 * t).cos();
            CENTER + Vec2::new(x, y) * 0.8
        })
        .collect();
    let spiral: Vec<Vec2> = (0..=60)
        .map(|i| {
            let t = i as f32 / 60.0;
            CENTER + Vec2::from_angle(t * 3.0 * std::f32::consts::PI) * (3.0 + 11.0 * t)
        })
        .collect();
    let eight: Vec<Vec2> = (0..=48)
        .map(|i| {
            let t = std::f32::consts::TAU * i as f32 / 48.0;
            CENTER + Vec2::new(12.0 * t.sin(), 12.0 * t.sin() * t.cos())
        })
        .collect();
    vec![
        shape("triangle_x0.7", scaled(&by("triangle_l"), 0.7)),
        shape("square_x1.2", scaled(&by("square_l"), 1.2)),
        shape("circle_x1.5", scaled(&by("circle_s"), 1.5)),
        shape("hexagon_x0.7", scaled(&by("hexagon"), 0.7)),
        shape(
            "triangle_rot60",
            rotated(&by("triangle_l"), std::f32::consts::FRAC_PI_3),
        ),
        shape(
            "square_rot30",
            rotated(&by("square_l"), std::f32::consts::FRAC_PI_6),
        ),
        shape(
            "pentagon_rot36",
            rotated(&by("pentagon"), std::f32::consts::PI / 5.0),
        ),
        shape("heart", heart),
        shape("spiral", spiral),
        shape("figure_eight", eight),
        shape(
            "arrow",
            from_points(
                &[(-14.0, 0.0), (10.0, 0.0), (4.0, 6.0), (10.0, 0.0), (4.0, -6.0)],
                1.0,
            ),
        ),
        shape(
            "letter_m",
            from_points(
                &[
                    (-12.0, -10.0),
                    (-12.0, 10.0),
                    (0.0, -2.0),
                    (12.0, 10.0),
                    (12.0, -10.0),
                ],
                1.0,
            ),
        ),
    ]
}

fn path_length(path: &[Vec2]) -> f32 {
    path.windows(2).map(|w| w[0].dist(w[1])).sum()
}

/// `n` points equally spaced by arc length along `path` (first and last included).
pub fn resample(path: &[Vec2], n: usize) -> Vec<Vec2> {
    let (Some(&first), true) = (path.first(), n > 0) else {
        return Vec::new();
    };
    let total = path_length(path);
    if total <= 1e-9 || n == 1 {
        return vec![first; n];
    }
    let mut out = Vec::with_capacity(n);
    let mut seg = 0;
    let mut seg_start = 0.0f32;
    for k in 0..n {
        let target = total * k as f32 / (n - 1) as f32;
        while seg + 1 < path.len() - 1 && seg_start + path[seg].dist(path[seg + 1]) < target {
            seg_start += path[seg].dist(path[seg + 1]);
            seg += 1;
        }
        let len = path[seg].dist(path[seg + 1]).max(1e-9);
        let t = ((target - seg_start) / len).clamp(0.0, 1.0);
        out.push(path[seg].lerp(path[seg + 1], t));
    }
    out
}

/// Longest common subsequence of two point sequences, points matching within `tol`.
pub fn lcs_len(a: &[Vec2], b: &[Vec2], tol: f32) -> usize {
    let mut prev = vec![0usize; b.len() + 1];
    let mut cur = vec![0usize; b.len() + 1];
    for &pa in a {
        for (j, &pb) in b.iter().enumerate() {
            cur[j + 1] = if pa.dist(pb) <= tol {
                prev[j] + 1
            } else {
                prev[j + 1].max(cur[j])
            };
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// The paper's drawing score: LCS of the executed and guide paths, both resampled to 50
/// points, matched within [`MATCH_TOLERANCE_CM`].
pub fn drawing_score(executed: &[Vec2], guide: &[Vec2]) -> usize {
    lcs_len(
        &resample(executed, MATCH_POINTS),
        &resample(guide, MATCH_POINTS),
        MATCH_TOLERANCE_CM,
    )
}

/// Expert waypoints: the guide path resampled to one point per step (`EPISODE_STEPS + 1`
/// positions, the first being the start).
pub fn expert_waypoints(guide: &[Vec2]) -> Vec<Vec2> {
    resample(guide, EPISODE_STEPS + 1)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_sizes_and_names() {
        let train = training_shapes();
        let test = test_shapes();
        assert_eq!((train.len(), test.len()), (11, 12));
        let mut names: Vec<_> = train.iter().chain(&test).map(|s| s.name.clone()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), 23);
        for s in train.iter().chain(&test) {
            assert!(s.path.len() >= 2, "{}", s.name);
            for p in &s.path {
                assert!(
                    (0.0..=60.0).contains(&p.x) && (0.0..=60.0).contains(&p.y),
                    "{} leaves the table",
                    s.name
                );
            }
        }
    }

    #[test]
    fn resampling_is_uniform() {
        let line = [Vec2::new(0.0, 0.0), Vec2::new(10.0, 0.0), Vec2::new(10.0, 10.0)];
        let r = resample(&line, 5);
        assert_eq!(r.len(), 5);
        assert!(r[2].dist(Vec2::new(10.0, 0.0)) < 1e-5);
        assert!(r[4].dist(Vec2::new(10.0, 10.0)) < 1e-5);
    }

    #[test]
    fn a_path_on_the_shape_succeeds_and_an_offset_one_fails() {
        for s in training_shapes().iter().chain(&test_shapes()) {
            let exact = drawing_score(&s.path, &s.path);
            assert_eq!(exact, MATCH_POINTS, "{}", s.name);
            let offset: Vec<Vec2> = s.path.iter().map(|&p| p + Vec2::new(5.0, 0.0)).collect();
            let off = drawing_score(&offset, &s.path);
            assert!(off < SUCCESS_LCS, "{}: offset by 5 cm scored {off}", s.name);
        }
    }

    #[test]
    fn lcs_counts_in_order_matches_only() {
        let a = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(2.0, 0.0)];
        let b = [Vec2::new(2.0, 0.0), Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0)];
        assert_eq!(lcs_len(&a, &b, 0.1), 2);
        assert_eq!(lcs_len(&a, &[], 0.1), 0);
    }
}
