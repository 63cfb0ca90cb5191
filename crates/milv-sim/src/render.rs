//! Rendering both embodiments with anti-aliasing (tiny-skia) through perspective cameras.
//!
//! Each domain has its own camera: a homography from the table plane to the image, fixed
//! by where the table's four corners land. Camera A (human) looks from the human's side,
//! camera B (robot) from the far side at another angle, so the two views differ by a real
//! perspective transform, not just colours. Geometry is projected point by point and then
//! rasterised, so lines stay straight and circles become the right ellipses.

use serde::{Deserialize, Serialize};
use tiny_skia::{Color, FillRule, LineCap, LineJoin, Paint, PathBuilder, Pixmap, Stroke, Transform};

use milv_geom::Homography;

use crate::geom::{Vec2, WORKSPACE_CM};

/// Which embodiment (and camera) a frame shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Domain {
    Human,
    Robot,
}

impl Domain {
    pub fn name(self) -> &'static str {
        match self {
            Domain::Human => "human",
            Domain::Robot => "robot",
        }
    }
}

/// A table-plane → pixel homography.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    h: Homography,
}

impl Camera {
    /// The homography mapping table corners (0,0), (W,0), (W,W), (0,W) to `quad` (pixels).
    pub fn from_corners(quad: [(f64, f64); 4]) -> Option<Camera> {
        let w = f64::from(WORKSPACE_CM);
        let src = [(0.0, 0.0), (w, 0.0), (w, w), (0.0, w)];
        Some(Camera {
            h: Homography::from_points(&src, &quad)?,
        })
    }

    /// The default camera of a domain for a `size`×`size` image.
    pub fn for_domain(domain: Domain, size: u32) -> Camera {
        let k = f64::from(size) / 128.0;
        let q = |pts: [(f64, f64); 4]| pts.map(|(x, y)| (x * k, y * k));
        let quad = match domain {
            // From the human's side: near edge wide at the bottom, far edge narrower.
            Domain::Human => q([(6.0, 122.0), (122.0, 122.0), (104.0, 18.0), (24.0, 18.0)]),
            // From the far side, rotated and skewed: the robot's camera.
            Domain::Robot => q([(100.0, 8.0), (30.0, 20.0), (10.0, 116.0), (120.0, 104.0)]),
        };
        // These quads are convex and non-degenerate, so the solve cannot fail; fall back
        // to an affine fit of the square rather than panicking anyway.
        Camera::from_corners(quad).unwrap_or(Camera {
            h: Homography {
                h: [[k * 2.0, 0.0, 4.0], [0.0, k * 2.0, 4.0], [0.0, 0.0, 1.0]],
            },
        })
    }

    /// Projects a table point to pixel coordinates.
    pub fn project(&self, p: Vec2) -> (f32, f32) {
        let (u, v) = self.h.apply((f64::from(p.x), f64::from(p.y)));
        (u as f32, v as f32)
    }

    /// Pixels per centimetre near `p` (for stroke widths).
    pub fn scale_at(&self, p: Vec2) -> f32 {
        let (a, b) = (self.project(p), self.project(p + Vec2::new(1.0, 0.0)));
        let (c, d) = (self.project(p), self.project(p + Vec2::new(0.0, 1.0)));
        (((b.0 - a.0).hypot(b.1 - a.1)) + ((d.0 - c.0).hypot(d.1 - c.1))) * 0.5
    }
}

/// Colours and materials of one domain's look.
#[derive(Clone, Copy, Debug)]
struct Look {
    background: [u8; 3],
    table: [u8; 3],
    texture: [u8; 3],
    ink: [u8; 3],
}

fn look(domain: Domain) -> Look {
    match domain {
        Domain::Human => Look {
            background: [62, 52, 46],
            table: [196, 160, 112],
            texture: [176, 140, 96],
            ink: [30, 30, 90],
        },
        Domain::Robot => Look {
            background: [36, 44, 56],
            table: [150, 162, 170],
            texture: [128, 140, 150],
            ink: [20, 20, 20],
        },
    }
}

/// Optional appearance randomisation (domain randomisation for robustness studies).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Randomization {
    pub seed: u64,
    /// Brightness and colour cast of the whole scene.
    pub lighting: bool,
    /// Table texture colours and spacing, the human's skin tone and sleeve colour.
    pub texture: bool,
    /// Camera corners moved by up to ±4 % of the image size.
    pub camera_jitter: bool,
    /// Up to four static clutter shapes near the table's edges.
    pub clutter: bool,
}

impl Randomization {
    /// Everything on, with this seed.
    pub fn all(seed: u64) -> Self {
        Randomization {
            seed,
            lighting: true,
            texture: true,
            camera_jitter: true,
            clutter: true,
        }
    }
}

/// What is on the table besides the embodiment.
#[derive(Clone, Debug, Default)]
pub struct SceneItems<'a> {
    /// The red guide shape of the drawing task.
    pub guide: Option<&'a [Vec2]>,
    /// The pen trace drawn so far.
    pub trace: &'a [Vec2],
    /// Filled object outlines with their colours (pushing task).
    pub objects: Vec<(Vec<Vec2>, [u8; 3])>,
    /// A target region outline (pushing task).
    pub target: Option<[Vec2; 4]>,
}

/// Renders frames of one domain at one size.
pub struct Renderer {
    domain: Domain,
    size: u32,
    camera: Camera,
    pixmap: Pixmap,
    look: Look,
    /// Texture line offset (cm) and brightness factor.
    texture_shift: f32,
    light: [f32; 3],
    skin: [u8; 3],
    sleeve: [u8; 3],
    clutter: Vec<(Vec<Vec2>, [u8; 3])>,
}

fn paint(rgb: [u8; 3]) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(rgb[0], rgb[1], rgb[2], 255);
    p.anti_alias = true;
    p
}

fn stroke(width: f32) -> Stroke {
    Stroke {
        width,
        line_cap: LineCap::Round,
        line_join: LineJoin::Round,
        ..Stroke::default()
    }
}

/// Skin tones and sleeve colours of the human (the first of each is the default look).
const SKIN_TONES: [[u8; 3]; 5] = [
    [224, 172, 138],
    [241, 194, 160],
    [198, 134, 96],
    [141, 85, 54],
    [255, 219, 180],
];
const SLEEVES: [[u8; 3]; 5] = [
    [52, 96, 168],
    [160, 40, 48],
    [40, 120, 70],
    [90, 90, 90],
    [200, 170, 40],
];

/// Length of the robot's two links (cm) and its base, beyond the far edge of the table.
pub const ROBOT_LINK_CM: f32 = 42.0;
pub const ROBOT_BASE: Vec2 = Vec2::new(30.0, 74.0);
/// Where the human's forearm comes from (the near side, off the table).
pub const HUMAN_SHOULDER: Vec2 = Vec2::new(38.0, -34.0);

/// Elbow of the robot's 2-link planar arm reaching `ee` (inverse kinematics; the reach is
/// clamped to the arm's length).
pub fn robot_elbow(ee: Vec2) -> Vec2 {
    let d = ee - ROBOT_BASE;
    let dist = d.len().clamp(1e-3, 2.0 * ROBOT_LINK_CM - 1e-3);
    // Law of cosines: angle between the base→ee line and the first link.
    let cos_a = (dist / (2.0 * ROBOT_LINK_CM)).clamp(-1.0, 1.0);
    let a = cos_a.acos();
    ROBOT_BASE + d.normalized().rotated(a) * ROBOT_LINK_CM
}

impl Renderer {
    pub fn new(domain: Domain, size: u32) -> Option<Renderer> {
        Renderer::with_randomization(domain, size, &Randomization::default())
    }

    /// A renderer whose look is randomised as `rnd` asks (deterministic by its seed).
    pub fn with_randomization(domain: Domain, size: u32, rnd: &Randomization) -> Option<Renderer> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(rnd.seed ^ (domain as u64) << 32);
        let mut camera = Camera::for_domain(domain, size);
        if rnd.camera_jitter {
            let w = f64::from(WORKSPACE_CM);
            let corners = [(0.0, 0.0), (w, 0.0), (w, w), (0.0, w)].map(|(x, y)| {
                let (u, v) = camera.project(Vec2::new(x as f32, y as f32));
                let j = f64::from(size) * 0.04;
                (
                    f64::from(u) + rng.random_range(-j..j),
                    f64::from(v) + rng.random_range(-j..j),
                )
            });
            camera = Camera::from_corners(corners).unwrap_or(camera);
        }
        let mut lk = look(domain);
        let mut texture_shift = 0.0;
        let (mut skin, mut sleeve) = (SKIN_TONES[0], SLEEVES[0]);
        if rnd.texture {
            let tint = |c: [u8; 3], rng: &mut rand::rngs::StdRng| {
                c.map(|v| (f32::from(v) * rng.random_range(0.85..1.15)).clamp(0.0, 255.0) as u8)
            };
            lk.table = tint(lk.table, &mut rng);
            lk.texture = tint(lk.texture, &mut rng);
            texture_shift = rng.random_range(-4.0..4.0);
            skin = SKIN_TONES[rng.random_range(0..SKIN_TONES.len())];
            sleeve = SLEEVES[rng.random_range(0..SLEEVES.len())];
        }
        let light = if rnd.lighting {
            let b = rng.random_range(0.75..1.2);
            [
                b * rng.random_range(0.92..1.08),
                b * rng.random_range(0.92..1.08),
                b * rng.random_range(0.92..1.08),
            ]
        } else {
            [1.0; 3]
        };
        let mut clutter = Vec::new();
        if rnd.clutter {
            for _ in 0..rng.random_range(1..=4) {
                // Near an edge, away from where tasks happen.
                let along = rng.random_range(4.0..56.0);
                let c = match rng.random_range(0..4) {
                    0 => Vec2::new(along, 3.0),
                    1 => Vec2::new(along, 57.0),
                    2 => Vec2::new(3.0, along),
                    _ => Vec2::new(57.0, along),
                };
                let r = rng.random_range(1.0..2.5);
                let n = rng.random_range(3..7);
                let rot = rng.random_range(0.0..std::f32::consts::TAU);
                let poly = (0..n)
                    .map(|k| c + Vec2::from_angle(rot + std::f32::consts::TAU * k as f32 / n as f32) * r)
                    .collect();
                let grey = rng.random_range(60..200);
                clutter.push((poly, [grey, grey, rng.random_range(60..200)]));
            }
        }
        Some(Renderer {
            domain,
            size,
            camera,
            pixmap: Pixmap::new(size, size)?,
            look: lk,
            texture_shift,
            light,
            skin,
            sleeve,
            clutter,
        })
    }

    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    fn polyline(&self, pts: &[Vec2], closed: bool) -> Option<tiny_skia::Path> {
        let mut pb = PathBuilder::new();
        let mut it = pts.iter().map(|&p| self.camera.project(p));
        let (x, y) = it.next()?;
        pb.move_to(x, y);
        for (x, y) in it {
            pb.line_to(x, y);
        }
        if closed {
            pb.close();
        }
        pb.finish()
    }

    fn fill_poly(&mut self, pts: &[Vec2], rgb: [u8; 3]) {
        if let Some(path) = self.polyline(pts, true) {
            self.pixmap
                .fill_path(&path, &paint(rgb), FillRule::Winding, Transform::identity(), None);
        }
    }

    fn stroke_line(&mut self, pts: &[Vec2], rgb: [u8; 3], width_cm: f32) {
        if pts.len() < 2 {
            return;
        }
        let mid = pts[pts.len() / 2];
        let width = (width_cm * self.camera.scale_at(mid)).max(0.6);
        if let Some(path) = self.polyline(pts, false) {
            self.pixmap
                .stroke_path(&path, &paint(rgb), &stroke(width), Transform::identity(), None);
        }
    }

    fn disk(&mut self, c: Vec2, r_cm: f32, rgb: [u8; 3]) {
        let pts: Vec<Vec2> = (0..24)
            .map(|i| c + Vec2::from_angle(std::f32::consts::TAU * i as f32 / 24.0) * r_cm)
            .collect();
        self.fill_poly(&pts, rgb);
    }

    /// Renders one frame: the scene with the end-effector at `ee`; returns packed RGB24.
    pub fn render(&mut self, ee: Vec2, items: &SceneItems<'_>) -> Vec<u8> {
        let lk = self.look;
        let [r, g, b] = lk.background;
        self.pixmap.fill(Color::from_rgba8(r, g, b, 255));
        let w = WORKSPACE_CM;
        self.fill_poly(
            &[Vec2::ZERO, Vec2::new(w, 0.0), Vec2::new(w, w), Vec2::new(0.0, w)],
            lk.table,
        );
        match self.domain {
            // Wood grain: irregular planks along x.
            Domain::Human => {
                for i in 1..8 {
                    let y = i as f32 * 7.5 + (i as f32 * 1.7).sin() + self.texture_shift;
                    self.stroke_line(&[Vec2::new(0.0, y), Vec2::new(w, y + 0.6)], lk.texture, 0.35);
                }
            }
            // A tiled work surface: a grid.
            Domain::Robot => {
                for i in 1..6 {
                    let t = i as f32 * 10.0 + self.texture_shift;
                    self.stroke_line(&[Vec2::new(t, 0.0), Vec2::new(t, w)], lk.texture, 0.25);
                    self.stroke_line(&[Vec2::new(0.0, t), Vec2::new(w, t)], lk.texture, 0.25);
                }
            }
        }
        // Taken out and put back: drawing needs `&mut self`.
        let clutter = std::mem::take(&mut self.clutter);
        for (poly, rgb) in &clutter {
            self.fill_poly(poly, *rgb);
        }
        self.clutter = clutter;
        if let Some(t) = &items.target {
            let mut closed = t.to_vec();
            closed.push(t[0]);
            self.stroke_line(&closed, [40, 170, 60], 0.6);
        }
        if let Some(guide) = items.guide {
            self.stroke_line(guide, [210, 30, 30], 0.8);
        }
        for (outline, rgb) in &items.objects {
            self.fill_poly(outline, *rgb);
        }
        self.stroke_line(items.trace, lk.ink, 0.7);
        match self.domain {
            Domain::Human => self.draw_human(ee),
            Domain::Robot => self.draw_robot(ee),
        }
        let mut out = Vec::with_capacity((self.size * self.size * 3) as usize);
        let light = self.light;
        for px in self.pixmap.data().chunks_exact(4) {
            // Every pixel is opaque (the background covers the frame), so premultiplied
            // RGBA is plain RGBA here.
            if light == [1.0; 3] {
                out.extend_from_slice(&px[..3]);
            } else {
                for c in 0..3 {
                    out.push((f32::from(px[c]) * light[c]).clamp(0.0, 255.0) as u8);
                }
            }
        }
        out
    }

    fn draw_human(&mut self, ee: Vec2) {
        let back = (HUMAN_SHOULDER - ee).normalized();
        let elbow = ee + back * 30.0;
        let sleeve_start = ee + back * 14.0;
        let skin = self.skin;
        let finger = skin.map(|c| c.saturating_sub(12));
        // Forearm, then the sleeve over its upper half, then the hand and fingers.
        self.stroke_line(&[ee, elbow], skin, 5.0);
        self.stroke_line(&[sleeve_start, elbow + back * 10.0], self.sleeve, 7.0);
        let fwd = -back;
        let side = fwd.perp();
        let palm: Vec<Vec2> = [
            (-1.5, -3.2),
            (2.5, -3.0),
            (3.5, 0.0),
            (2.5, 3.0),
            (-1.5, 3.2),
            (-2.5, 0.0),
        ]
        .iter()
        .map(|&(a, s)| ee + fwd * a + side * s)
        .collect();
        self.fill_poly(&palm, skin);
        for (i, len) in [3.0f32, 3.8, 3.6, 3.0].iter().enumerate() {
            let s = -2.4 + 1.6 * i as f32;
            let base = ee + fwd * 2.8 + side * s;
            self.stroke_line(&[base, base + fwd * *len], finger, 1.1);
        }
        let thumb = ee + side * 3.0;
        self.stroke_line(&[thumb, thumb + (fwd + side).normalized() * 3.0], finger, 1.3);
    }

    fn draw_robot(&mut self, ee: Vec2) {
        let elbow = robot_elbow(ee);
        let metal = [96, 100, 108];
        let joint = [40, 44, 52];
        self.stroke_line(&[ROBOT_BASE, elbow], [230, 140, 30], 5.5);
        self.stroke_line(&[elbow, ee], metal, 4.0);
        self.disk(elbow, 3.0, joint);
        // Gripper: a wrist block and two fingers along the last link.
        let dir = (ee - elbow).normalized();
        let side = dir.perp();
        self.disk(ee - dir * 1.0, 2.2, joint);
        for s in [-1.6f32, 1.6] {
            let base = ee + side * s;
            self.stroke_line(&[base, base + dir * 3.2], [200, 200, 210], 1.0);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn cameras_map_corners_and_differ() {
        let a = Camera::for_domain(Domain::Human, 128);
        let (u, v) = a.project(Vec2::new(60.0, 60.0));
        assert!((u - 104.0).abs() < 1e-3 && (v - 18.0).abs() < 1e-3);
        let b = Camera::for_domain(Domain::Robot, 128);
        let c = Vec2::new(30.0, 30.0);
        assert!(a.project(c) != b.project(c));
        // A real perspective: equal table distances shrink with depth in camera A.
        assert!(a.scale_at(Vec2::new(30.0, 5.0)) > a.scale_at(Vec2::new(30.0, 55.0)) * 1.2);
    }

    #[test]
    fn robot_ik_reaches_the_workspace() {
        for &(x, y) in &[(0.0, 0.0), (60.0, 0.0), (30.0, 30.0), (60.0, 60.0), (0.0, 60.0)] {
            let ee = Vec2::new(x, y);
            let e = robot_elbow(ee);
            assert!((e.dist(ROBOT_BASE) - ROBOT_LINK_CM).abs() < 1e-3);
            assert!((e.dist(ee) - ROBOT_LINK_CM).abs() < 1e-2, "{x},{y}");
        }
    }

    #[test]
    fn randomization_changes_the_look_deterministically() {
        let items = SceneItems::default();
        let ee = Vec2::new(30.0, 30.0);
        let plain = Renderer::new(Domain::Robot, 48).unwrap().render(ee, &items);
        let a = Renderer::with_randomization(Domain::Robot, 48, &Randomization::all(1))
            .unwrap()
            .render(ee, &items);
        let a2 = Renderer::with_randomization(Domain::Robot, 48, &Randomization::all(1))
            .unwrap()
            .render(ee, &items);
        let b = Renderer::with_randomization(Domain::Robot, 48, &Randomization::all(2))
            .unwrap()
            .render(ee, &items);
        assert_eq!(a, a2);
        assert_ne!(a, plain);
        assert_ne!(a, b);
    }

    #[test]
    fn frames_are_deterministic_and_domains_look_different() {
        let guide = crate::shapes::training_shapes()[0].path.clone();
        let items = SceneItems {
            guide: Some(&guide),
            trace: &guide[..2],
            ..Default::default()
        };
        let mut h = Renderer::new(Domain::Human, 64).unwrap();
        let mut r = Renderer::new(Domain::Robot, 64).unwrap();
        let ee = Vec2::new(20.0, 25.0);
        let a = h.render(ee, &items);
        assert_eq!(a.len(), 64 * 64 * 3);
        assert_eq!(a, h.render(ee, &items));
        let b = r.render(ee, &items);
        let diff = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(diff > a.len() / 2, "domains should differ in most pixels");
        // Moving the end-effector changes the picture.
        assert_ne!(a, h.render(Vec2::new(40.0, 40.0), &items));
    }
}
