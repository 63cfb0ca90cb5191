//! Objects, the target and the world that moves them: substeps of the pusher, contacts
//! resolved by Gauss–Seidel sweeps, jams undone.

use serde::{Deserialize, Serialize};

use super::*;

/// Footprint of an object, in its own frame centred at the centroid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ObjShape {
    /// Rectangle `w` (along local x) × `h` (cm).
    Box { w: f32, h: f32 },
    /// Disk of radius `r` (cm).
    Disk { r: f32 },
    /// Equilateral triangle, one vertex along local +y.
    Triangle { side: f32 },
    /// Convex polygon, CCW, local frame centred at the centroid.
    Polygon { verts: Vec<Vec2> },
}

impl ObjShape {
    /// Outline in the body frame, CCW (disks as a 24-gon).
    pub fn local_outline(&self) -> Vec<Vec2> {
        match self {
            ObjShape::Box { w, h } => {
                let (x, y) = (w.abs() * 0.5, h.abs() * 0.5);
                vec![
                    Vec2::new(-x, -y),
                    Vec2::new(x, -y),
                    Vec2::new(x, y),
                    Vec2::new(-x, y),
                ]
            }
            ObjShape::Disk { r } => regular_polygon(DISK_SEGMENTS, r.abs(), 0.0),
            ObjShape::Triangle { side } => {
                regular_polygon(3, side.abs() / 3f32.sqrt(), std::f32::consts::FRAC_PI_2)
            }
            ObjShape::Polygon { verts } => {
                // Accept CW input too: every contact routine assumes CCW.
                if signed_area(verts) < 0.0 {
                    verts.iter().rev().copied().collect()
                } else {
                    verts.clone()
                }
            }
        }
    }

    /// Limit-surface ratio `c = m_max / f_max` (cm): the mean distance of the footprint
    /// from the centroid under uniform pressure.
    pub fn limit_surface_c(&self) -> f32 {
        let c = match self {
            ObjShape::Disk { r } => 2.0 * r.abs() / 3.0,
            _ => mean_distance_from_origin(&self.local_outline()),
        };
        if c.is_finite() && c > MIN_C { c } else { MIN_C }
    }

    /// Largest distance of the outline from the centroid (cm).
    pub fn bounding_radius(&self) -> f32 {
        match self {
            ObjShape::Disk { r } => r.abs(),
            _ => self.local_outline().iter().map(|v| v.len()).fold(0.0, f32::max),
        }
    }
}

/// A catalogue object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjSpec {
    pub name: String,
    pub shape: ObjShape,
    /// Friction coefficient with the table (0.2..0.9); see the module doc for its effect.
    pub mu_table: f32,
    /// Grams.
    pub mass: f32,
    pub color: [u8; 3],
}

/// An object placed on the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Body {
    pub spec: ObjSpec,
    /// Centroid (cm).
    pub pos: Vec2,
    /// Radians, CCW.
    pub angle: f32,
}

impl Body {
    pub fn new(spec: ObjSpec, pos: Vec2, angle: f32) -> Self {
        Body { spec, pos, angle }
    }

    /// Outline in world coordinates, CCW (disks: 24-gon).
    pub fn world_polygon(&self) -> Vec<Vec2> {
        self.spec
            .shape
            .local_outline()
            .into_iter()
            .map(|v| v.rotated(self.angle) + self.pos)
            .collect()
    }

    /// Whether world point `p` lies on or inside the object.
    pub fn contains(&self, p: Vec2) -> bool {
        match self.spec.shape {
            ObjShape::Disk { r } => p.dist(self.pos) <= r.abs(),
            _ => {
                let poly = self.world_polygon();
                poly.len() >= 3 && edges(&poly).all(|(a, b)| (b - a).cross(p - a) >= 0.0)
            }
        }
    }

    /// Extent of the object from its centroid along `dir` (unit vector), cm.
    pub fn support(&self, dir: Vec2) -> f32 {
        match self.spec.shape {
            ObjShape::Disk { r } => r.abs() * dir.len(),
            _ => self
                .spec
                .shape
                .local_outline()
                .iter()
                .map(|v| v.rotated(self.angle).dot(dir))
                .fold(f32::NEG_INFINITY, f32::max)
                .max(0.0),
        }
    }

    /// Largest distance of the outline from the centroid (cm).
    pub fn bounding_radius(&self) -> f32 {
        self.spec.shape.bounding_radius()
    }
}

/// Target square: 12×12 cm, axis-aligned, given by its centre.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetSquare {
    pub center: Vec2,
}

impl TargetSquare {
    pub const SIZE: f32 = 12.0;

    pub fn contains(&self, p: Vec2) -> bool {
        let h = Self::SIZE * 0.5;
        (p.x - self.center.x).abs() <= h && (p.y - self.center.y).abs() <= h
    }
}

/// The pushing scene: objects and the pusher disk.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PushWorld {
    pub bodies: Vec<Body>,
    /// Pusher centre (cm).
    pub pusher: Vec2,
    /// Pusher radius (cm), [`PUSHER_RADIUS_CM`] by default.
    pub pusher_radius: f32,
}

impl PushWorld {
    pub fn new(bodies: Vec<Body>, pusher: Vec2) -> Self {
        PushWorld {
            bodies,
            pusher,
            pusher_radius: PUSHER_RADIUS_CM,
        }
    }

    /// Moves the pusher to `target` (clamped to the workspace) in substeps of at most
    /// [`SUBSTEP_CM`], pushing the objects it meets. Stops early where a push jams.
    /// Returns each body's displacement.
    pub fn move_pusher(&mut self, target: Vec2) -> Vec<Vec2> {
        let start: Vec<Vec2> = self.bodies.iter().map(|b| b.pos).collect();
        let finite = |v: Vec2| v.x.is_finite() && v.y.is_finite();
        if finite(target) {
            let rp = self.radius();
            // An out-of-range start set from outside would make the substep count explode.
            let from = if finite(self.pusher) {
                clamp_to_workspace(self.pusher)
            } else {
                clamp_to_workspace(target)
            };
            self.pusher = from;
            let to = clamp_to_workspace(target);
            let n = ((to.dist(from) / SUBSTEP_CM).ceil() as usize).clamp(1, MAX_SUBSTEPS);
            for k in 1..=n {
                let next = if k == n {
                    to
                } else {
                    from.lerp(to, k as f32 / n as f32)
                };
                if !self.substep(next, rp) {
                    break;
                }
            }
        }
        self.bodies.iter().zip(start).map(|(b, s)| b.pos - s).collect()
    }

    /// Largest penetration depth between any two bodies or the pusher and a body (cm).
    pub fn max_penetration(&self) -> f32 {
        self.max_pen(self.radius())
    }

    fn radius(&self) -> f32 {
        if self.pusher_radius.is_finite() {
            self.pusher_radius.max(0.0)
        } else {
            PUSHER_RADIUS_CM
        }
    }

    fn max_pen(&self, rp: f32) -> f32 {
        let pusher = Geo::Circle {
            c: self.pusher,
            r: rp,
        };
        let geos: Vec<Geo> = self.bodies.iter().map(geo).collect();
        let mut worst = 0.0f32;
        for (i, gi) in geos.iter().enumerate() {
            if let Some(ct) = contact(&pusher, gi) {
                worst = worst.max(ct.depth);
            }
            for gj in geos.iter().skip(i + 1) {
                if let Some(ct) = contact(gi, gj) {
                    worst = worst.max(ct.depth);
                }
            }
        }
        worst
    }

    /// Advances the pusher to `next` and resolves contacts; undoes it and returns false
    /// when the result would overlap more than before (a jam).
    fn substep(&mut self, next: Vec2, rp: f32) -> bool {
        let before = self.max_pen(rp);
        let saved: Vec<(Vec2, f32)> = self.bodies.iter().map(|b| (b.pos, b.angle)).collect();
        let saved_pusher = self.pusher;
        let step = next - self.pusher;
        self.pusher = next;
        self.solve(step, rp);
        if self.max_pen(rp) <= before.max(JAM_TOL) {
            return true;
        }
        for (b, (p, a)) in self.bodies.iter_mut().zip(saved) {
            b.pos = p;
            b.angle = a;
        }
        self.pusher = saved_pusher;
        false
    }

    /// Gauss–Seidel resolution of all contacts after the pusher moved by `step`.
    fn solve(&mut self, step: Vec2, rp: f32) {
        let nb = self.bodies.len();
        let cs: Vec<f32> = self
            .bodies
            .iter()
            .map(|b| b.spec.shape.limit_surface_c())
            .collect();
        // Motion of each body so far in this substep, for the relative contact velocities.
        let mut moved: Vec<(Vec2, f32)> = vec![(Vec2::ZERO, 0.0); nb];
        let pusher = Geo::Circle {
            c: self.pusher,
            r: rp,
        };
        for _ in 0..SOLVER_ITERS {
            let mut worst = 0.0f32;
            for ((body, &c), m) in self.bodies.iter_mut().zip(&cs).zip(moved.iter_mut()) {
                if let Some(ct) = contact(&pusher, &geo(body))
                    && ct.depth > CONTACT_EPS
                {
                    worst = worst.max(ct.depth);
                    let v = contact_motion(ct.normal, ct.depth, step);
                    yield_to_push(body, m, c, &ct, v, PUSHER_MU);
                }
            }
            for j in 1..nb {
                let (left, right) = self.bodies.split_at_mut(j);
                let (mleft, mright) = moved.split_at_mut(j);
                let (Some(bj), Some(mj), Some(&cj)) = (right.first_mut(), mright.first_mut(), cs.get(j))
                else {
                    continue;
                };
                for ((bi, mi), &ci) in left.iter_mut().zip(mleft.iter_mut()).zip(&cs) {
                    let Some(ct) = contact(&geo(bi), &geo(bj)) else {
                        continue;
                    };
                    if ct.depth <= CONTACT_EPS {
                        continue;
                    }
                    worst = worst.max(ct.depth);
                    let va = point_velocity(bi, *mi, ct.point);
                    let vb = point_velocity(bj, *mj, ct.point);
                    let n = ct.normal;
                    // The body driving further into the other is the pusher; ties (e.g.
                    // an initial overlap) push the later body, for determinism.
                    if va.dot(n) >= -vb.dot(n) {
                        let v = contact_motion(n, ct.depth, va - vb);
                        yield_to_push(bj, mj, cj, &ct, v, BODY_MU);
                    } else {
                        let flipped = Contact { normal: -n, ..ct };
                        let v = contact_motion(-n, ct.depth, vb - va);
                        yield_to_push(bi, mi, ci, &flipped, v, BODY_MU);
                    }
                }
            }
            if worst <= CONTACT_EPS {
                break;
            }
        }
    }
}

/// Translates the body so its outline lies in the workspace; returns the shift.
pub(super) fn keep_inside(body: &mut Body) -> Vec2 {
    let (lo, hi) = match body.spec.shape {
        ObjShape::Disk { r } => {
            let r = Vec2::new(r.abs(), r.abs());
            (body.pos - r, body.pos + r)
        }
        _ => body.world_polygon().iter().fold(
            (
                Vec2::new(f32::INFINITY, f32::INFINITY),
                Vec2::new(f32::NEG_INFINITY, f32::NEG_INFINITY),
            ),
            |(lo, hi), v| {
                (
                    Vec2::new(lo.x.min(v.x), lo.y.min(v.y)),
                    Vec2::new(hi.x.max(v.x), hi.y.max(v.y)),
                )
            },
        ),
    };
    let axis = |lo: f32, hi: f32| {
        if lo < 0.0 {
            -lo
        } else if hi > WORKSPACE_CM {
            WORKSPACE_CM - hi
        } else {
            0.0
        }
    };
    let shift = Vec2::new(axis(lo.x, hi.x), axis(lo.y, hi.y));
    if shift.x.is_finite() && shift.y.is_finite() {
        body.pos += shift;
        shift
    } else {
        Vec2::ZERO
    }
}

pub(super) fn regular_polygon(n: usize, radius: f32, rot: f32) -> Vec<Vec2> {
    (0..n)
        .map(|k| Vec2::from_angle(rot + std::f32::consts::TAU * k as f32 / n as f32) * radius)
        .collect()
}

/// Shifts vertices so their area centroid is the origin (catalogue polygons).
pub(super) fn centered(verts: Vec<Vec2>) -> Vec<Vec2> {
    let (area, c) = area_centroid(&verts);
    if area.abs() > 1e-9 {
        verts.into_iter().map(|v| v - c).collect()
    } else {
        verts
    }
}

/// Mean distance of the polygon's area from the origin, exact: over each fan triangle
/// (origin, a, b), ∫|x| dA = (h/6)·[s·ρ + h²·asinh(s/h)] between the edge ends, with h
/// the origin's distance to the edge line, s the position along it and ρ = √(h²+s²).
pub(super) fn mean_distance_from_origin(poly: &[Vec2]) -> f32 {
    let mut integral = 0.0f32;
    for (a, b) in edges(poly) {
        let e = b - a;
        let len = e.len();
        if len.is_nan() || len <= 1e-9 {
            continue;
        }
        let e = e * (1.0 / len);
        let h_signed = a.cross(e);
        let h = h_signed.abs();
        if h.is_nan() || h <= 1e-9 {
            continue;
        }
        let prim = |s: f32| h / 6.0 * (s * (h * h + s * s).sqrt() + h * h * (s / h).asinh());
        integral += h_signed.signum() * (prim(b.dot(e)) - prim(a.dot(e)));
    }
    let area = signed_area(poly);
    if area.abs() > 1e-9 { integral / area } else { 0.0 }
}
