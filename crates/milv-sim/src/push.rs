//! Quasi-static planar pushing (the paper's pushing task): a disk pusher (the
//! end-effector) pushes rigid convex objects (boxes, disks, triangles, convex polygons)
//! lying on the table towards a 12×12 cm target square.
//!
//! # Model
//!
//! * **Quasi-static.** Objects have no momentum: they move only while something
//!   penetrates them, and only as far as needed to remove that penetration. The pusher
//!   advances in substeps of at most [`SUBSTEP_CM`]; after each substep a Gauss–Seidel
//!   loop (up to 16 sweeps) resolves pusher–object, then object–object contacts.
//! * **Ellipsoidal limit surface** (Lynch, Maekawa & Tanie 1992; Goyal et al.). For an
//!   object with its centroid at the origin, a friction wrench `(f, m)` produces the
//!   twist `(v, ω) ∝ (f, m / c²)`, with `c = m_max / f_max`. Under a uniform support
//!   pressure `c` is the mean distance of the footprint from its centroid, computed here
//!   in closed form (`2r/3` for a disk). A force `f` applied at contact point `r` thus
//!   moves that point with velocity `M f`, `M = I + p pᵀ / c²`, `p = perp(r)`.
//! * **Motion cone.** For a desired contact displacement `v` (normal part = penetration
//!   depth, tangential part in the ratio of the pusher's relative motion), the sticking
//!   force is `M⁻¹ v`. If that force lies inside the friction cone (μ = [`PUSHER_MU`]
//!   for the pusher, [`BODY_MU`] between objects), the contact sticks. Otherwise it
//!   slides: the force lies on the nearer cone edge, scaled so that the contact's
//!   normal displacement still equals the depth. Pushing through the centroid
//!   (`r ∥ n`) therefore translates the object straight. Pushing off-centre rotates it.
//! * **Object–object contacts.** The body whose contact point moved further into the
//!   other during the substep acts as the pusher; the other yields under the same model.
//!   So a chain of objects is pushed along.
//! * **Mass and table friction.** `mass` and `mu_table` scale `f_max = μ m g` and
//!   `m_max = μ m g c` by the same factor. They cancel in `c`, so in quasi-static pushing
//!   by a position-controlled pusher they do **not** change any trajectory. They stay in
//!   [`ObjSpec`] as catalogue attributes (and for metrics or rendering), nothing more.
//! * **Workspace.** The pusher centre is clamped to `[0, 60]²`, and object outlines are
//!   translated back inside it. If a substep cannot be resolved (an object pinned against
//!   the edge or jammed between bodies), it is undone and the pusher stops there. This
//!   is like a force-limited robot.
//! * **Deterministic.** No randomness. The same moves give bit-identical states.

use serde::{Deserialize, Serialize};

use crate::geom::{MAX_STEP_CM, Vec2, WORKSPACE_CM, clamp_action, clamp_to_workspace};

/// Default pusher (end-effector) disk radius, cm.
pub const PUSHER_RADIUS_CM: f32 = 1.5;
/// Friction coefficient between the pusher and an object.
pub const PUSHER_MU: f32 = 0.3;
/// Friction coefficient between two objects.
pub const BODY_MU: f32 = 0.4;
/// Largest pusher advance per substep (cm).
pub const SUBSTEP_CM: f32 = 0.25;

/// Gauss–Seidel sweeps per substep; chains of 2–3 objects settle in a few.
const SOLVER_ITERS: usize = 16;
/// Penetrations below this are contact, not overlap (cm).
const CONTACT_EPS: f32 = 1e-4;
/// Residual overlap above this after a substep means the push jammed (cm).
const JAM_TOL: f32 = 0.05;
/// Outline resolution of disks for the renderer.
const DISK_SEGMENTS: usize = 24;
/// Guards against absurd pusher positions set from outside (60√2 / 0.25 ≈ 340 needed).
const MAX_SUBSTEPS: usize = 2000;
/// Floor for the limit-surface ratio, so degenerate shapes cannot divide by zero.
const MIN_C: f32 = 0.05;

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

/// Pusher waypoints that bring `body`'s centroid to `goal`, for a pusher that may be
/// anywhere: go to a staging point behind the object (relative to the goal), approach
/// it, then push through the centroid to the goal. Empty when the object is already
/// within 1 cm of `goal`. See [`push_plan_from`] for the closed-loop version that also
/// routes around the object from the current pusher position.
pub fn push_plan(body: &Body, goal: Vec2, pusher_radius: f32) -> Vec<Vec2> {
    match PushGeometry::new(body, goal, pusher_radius) {
        Some(g) => dedup(vec![g.staging, g.pre, g.end]),
        None => Vec::new(),
    }
}

/// Like [`push_plan`], but starting from the pusher at `pusher`. If it is already behind
/// the object and on the line through the centroid, the plan is to push to the goal.
/// If it is clear behind, it approaches then pushes. Otherwise it retreats radially to a
/// safe circle and goes around the object on it (30° chords) until the straight way to
/// the staging or approach point is free. Re-planning every step re-aligns the push
/// when the object rotates or drifts.
pub fn push_plan_from(pusher: Vec2, body: &Body, goal: Vec2, pusher_radius: f32) -> Vec<Vec2> {
    let Some(g) = PushGeometry::new(body, goal, pusher_radius) else {
        return Vec::new();
    };
    let rel = pusher - body.pos;
    let along = rel.dot(g.u);
    let lateral = rel.dot(g.u.perp());
    // Off-line tolerance before re-aligning; larger objects tolerate more.
    let lateral_tol = (0.2 * body.bounding_radius()).clamp(0.3, 1.0);
    if along < -g.rp && lateral.abs() <= lateral_tol {
        return dedup(vec![g.end]);
    }
    if path_clear(body, pusher, g.pre, g.rp) {
        return dedup(vec![g.pre, g.end]);
    }
    let mut wps = Vec::new();
    let mut cur = pusher;
    let dist = rel.len();
    if dist < g.r_safe - 1e-3 {
        // Moving straight away from the centroid never reduces the distance to a convex
        // object, so this retreat cannot push it.
        let dir = if dist > 1e-4 { rel * (1.0 / dist) } else { -g.u };
        cur = clamp_to_workspace(body.pos + dir * g.r_safe);
        wps.push(cur);
    }
    if !path_clear(body, cur, g.staging, g.rp) {
        let a0 = angle_of(cur - body.pos);
        let a1 = angle_of(-g.u);
        let da = wrap_angle(a1 - a0);
        let n = (da.abs() / ARC_STEP).ceil().clamp(0.0, 12.0) as usize;
        for k in 1..=n {
            let a = a0 + da * k as f32 / n as f32;
            cur = clamp_to_workspace(body.pos + Vec2::from_angle(a) * g.r_safe);
            wps.push(cur);
            if path_clear(body, cur, g.pre, g.rp) {
                wps.extend([g.pre, g.end]);
                return dedup_from(pusher, wps);
            }
        }
    }
    wps.extend([g.staging, g.pre, g.end]);
    dedup_from(pusher, wps)
}

/// One expert action (Δx, Δy) towards the first waypoint of [`push_plan_from`], scaled
/// (not clipped per axis, which would bend the checked path) to at most
/// [`MAX_STEP_CM`] per axis. Zero when the object is at the goal.
pub fn expert_action(pusher: Vec2, body: &Body, goal: Vec2, pusher_radius: f32) -> Vec2 {
    let Some(&w) = push_plan_from(pusher, body, goal, pusher_radius).first() else {
        return Vec2::ZERO;
    };
    let d = w - pusher;
    let m = d.x.abs().max(d.y.abs());
    if m > MAX_STEP_CM {
        // Clamp too: the scaled axis may round a hair above the limit.
        clamp_action(d * (MAX_STEP_CM / m))
    } else if m.is_finite() {
        d
    } else {
        Vec2::ZERO
    }
}

/// 10 training and 8 test objects (the test ones are unseen shapes, sizes and colours).
pub fn object_catalog() -> (Vec<ObjSpec>, Vec<ObjSpec>) {
    let spec = |name: &str, shape: ObjShape, mu_table: f32, mass: f32, color: [u8; 3]| ObjSpec {
        name: name.to_string(),
        shape,
        mu_table,
        mass,
        color,
    };
    let poly = |verts: Vec<Vec2>| ObjShape::Polygon {
        verts: centered(verts),
    };
    let v = Vec2::new;
    let train = vec![
        spec(
            "red_box",
            ObjShape::Box { w: 6.0, h: 4.0 },
            0.5,
            120.0,
            [205, 45, 40],
        ),
        spec(
            "blue_cube",
            ObjShape::Box { w: 5.0, h: 5.0 },
            0.4,
            150.0,
            [40, 80, 205],
        ),
        spec("green_disk", ObjShape::Disk { r: 2.5 }, 0.35, 90.0, [50, 170, 70]),
        spec(
            "yellow_triangle",
            ObjShape::Triangle { side: 6.0 },
            0.6,
            80.0,
            [235, 205, 45],
        ),
        spec(
            "orange_bar",
            ObjShape::Box { w: 8.0, h: 3.0 },
            0.45,
            110.0,
            [240, 135, 30],
        ),
        spec(
            "purple_hexagon",
            poly(regular_polygon(6, 3.0, 0.0)),
            0.5,
            130.0,
            [130, 60, 170],
        ),
        spec("cyan_puck", ObjShape::Disk { r: 1.75 }, 0.3, 50.0, [40, 200, 210]),
        spec(
            "brown_block",
            ObjShape::Box { w: 7.0, h: 5.0 },
            0.7,
            200.0,
            [130, 85, 45],
        ),
        spec(
            "pink_pentagon",
            poly(regular_polygon(5, 3.0, std::f32::consts::FRAC_PI_2)),
            0.55,
            100.0,
            [235, 120, 170],
        ),
        spec(
            "grey_triangle",
            ObjShape::Triangle { side: 4.5 },
            0.25,
            60.0,
            [135, 135, 135],
        ),
    ];
    let test = vec![
        spec(
            "teal_trapezoid",
            poly(vec![v(-3.5, -2.0), v(3.5, -2.0), v(2.0, 2.0), v(-2.0, 2.0)]),
            0.45,
            115.0,
            [0, 128, 128],
        ),
        spec(
            "magenta_octagon",
            poly(regular_polygon(8, 3.5, std::f32::consts::PI / 8.0)),
            0.5,
            160.0,
            [220, 0, 200],
        ),
        spec(
            "lime_big_disk",
            ObjShape::Disk { r: 3.5 },
            0.4,
            170.0,
            [170, 230, 40],
        ),
        spec(
            "navy_slab",
            ObjShape::Box { w: 7.5, h: 2.5 },
            0.65,
            140.0,
            [20, 30, 110],
        ),
        spec(
            "olive_kite",
            poly(vec![v(0.0, -4.0), v(2.5, 0.5), v(0.0, 2.5), v(-2.5, 0.5)]),
            0.3,
            70.0,
            [128, 128, 0],
        ),
        spec(
            "gold_small_cube",
            ObjShape::Box { w: 3.5, h: 3.5 },
            0.8,
            90.0,
            [215, 175, 0],
        ),
        spec(
            "maroon_big_triangle",
            ObjShape::Triangle { side: 7.5 },
            0.55,
            150.0,
            [120, 20, 35],
        ),
        spec(
            "white_rhombus",
            poly(vec![v(0.0, -2.0), v(3.8, 0.0), v(0.0, 2.0), v(-3.8, 0.0)]),
            0.2,
            75.0,
            [235, 235, 230],
        ),
    ];
    (train, test)
}

// ---------------------------------------------------------------------------------
// Planning helpers

/// Chord angle when going around an object (radians).
const ARC_STEP: f32 = std::f32::consts::PI / 6.0;
/// Clearance between pusher and object on the way round (cm).
const PLAN_CLEARANCE: f32 = 0.5;
/// Gap left at the approach point before the push starts (cm).
const APPROACH_GAP: f32 = 0.4;
/// The plan is done once the centroid is this close to the goal (cm).
const GOAL_TOL: f32 = 1.0;

/// Key points of a push of `body` to `goal`.
struct PushGeometry {
    /// Unit push direction.
    u: Vec2,
    rp: f32,
    /// Safe circle radius: chords of ARC_STEP stay PLAN_CLEARANCE clear of the object.
    r_safe: f32,
    staging: Vec2,
    pre: Vec2,
    end: Vec2,
}

impl PushGeometry {
    fn new(body: &Body, goal: Vec2, pusher_radius: f32) -> Option<Self> {
        let d = goal - body.pos;
        let dist = d.len();
        // NaN inputs give no plan.
        if !dist.is_finite() || dist <= GOAL_TOL {
            return None;
        }
        let rp = if pusher_radius.is_finite() {
            pusher_radius.max(0.0)
        } else {
            PUSHER_RADIUS_CM
        };
        let u = d * (1.0 / dist);
        let back = body.support(-u);
        let r_safe = (body.bounding_radius() + rp + PLAN_CLEARANCE) / (ARC_STEP * 0.5).cos();
        Some(PushGeometry {
            u,
            rp,
            r_safe,
            staging: clamp_to_workspace(body.pos - u * r_safe),
            pre: clamp_to_workspace(body.pos - u * (back + rp + APPROACH_GAP)),
            end: clamp_to_workspace(goal - u * (back + rp)),
        })
    }
}

/// Whether a pusher of radius `rp` moving straight from `a` to `b` keeps clear of `body`.
fn path_clear(body: &Body, a: Vec2, b: Vec2, rp: f32) -> bool {
    let g = geo(body);
    let n = ((a.dist(b) / SUBSTEP_CM).ceil() as usize).clamp(1, MAX_SUBSTEPS);
    (0..=n).all(|k| {
        let p = a.lerp(b, k as f32 / n as f32);
        contact(&Geo::Circle { c: p, r: rp + 0.1 }, &g).is_none()
    })
}

fn angle_of(v: Vec2) -> f32 {
    v.y.atan2(v.x)
}

/// Wraps to [-π, π).
fn wrap_angle(a: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    (a + PI).rem_euclid(TAU) - PI
}

/// Drops waypoints that repeat the previous one (a zero action would stall the expert).
fn dedup(wps: Vec<Vec2>) -> Vec<Vec2> {
    let mut out: Vec<Vec2> = Vec::with_capacity(wps.len());
    for w in wps {
        if out.last().is_none_or(|l| l.dist(w) > 1e-3) {
            out.push(w);
        }
    }
    out
}

fn dedup_from(start: Vec2, wps: Vec<Vec2>) -> Vec<Vec2> {
    dedup(wps)
        .into_iter()
        .skip_while(|w| w.dist(start) <= 1e-3)
        .collect()
}

// ---------------------------------------------------------------------------------
// Contact physics

/// Collision geometry in world coordinates.
enum Geo {
    Circle {
        c: Vec2,
        r: f32,
    },
    /// Convex, CCW.
    Poly(Vec<Vec2>),
}

fn geo(b: &Body) -> Geo {
    match b.spec.shape {
        // Disks collide exactly, not as their 24-gon outline.
        ObjShape::Disk { r } => Geo::Circle { c: b.pos, r: r.abs() },
        _ => Geo::Poly(b.world_polygon()),
    }
}

/// Overlap of A and B.
#[derive(Clone, Copy, Debug)]
struct Contact {
    depth: f32,
    /// Unit direction in which B must move to separate from A.
    normal: Vec2,
    /// World contact point.
    point: Vec2,
}

fn contact(a: &Geo, b: &Geo) -> Option<Contact> {
    match (a, b) {
        (Geo::Circle { c: ca, r: ra }, Geo::Circle { c: cb, r: rb }) => circle_circle(*ca, *ra, *cb, *rb),
        (Geo::Circle { c, r }, Geo::Poly(p)) => circle_poly(*c, *r, p),
        (Geo::Poly(p), Geo::Circle { c, r }) => circle_poly(*c, *r, p).map(|ct| Contact {
            normal: -ct.normal,
            ..ct
        }),
        (Geo::Poly(pa), Geo::Poly(pb)) => poly_poly(pa, pb),
    }
}

fn circle_circle(a: Vec2, ra: f32, b: Vec2, rb: f32) -> Option<Contact> {
    let d = b - a;
    let dist = d.len();
    let depth = ra + rb - dist;
    if depth.is_nan() || depth <= 0.0 {
        return None;
    }
    let normal = if dist > 1e-6 {
        d * (1.0 / dist)
    } else {
        Vec2::new(1.0, 0.0)
    };
    // Middle of the overlap along the centre line.
    let point = ((a + normal * ra) + (b - normal * rb)) * 0.5;
    Some(Contact { depth, normal, point })
}

/// Circle (A) against convex polygon (B); the normal points from the circle into B.
fn circle_poly(q: Vec2, rad: f32, poly: &[Vec2]) -> Option<Contact> {
    if poly.len() < 3 {
        return None;
    }
    let mut inside = true;
    let mut best_s = f32::NEG_INFINITY;
    let mut best_out = Vec2::ZERO;
    let mut best_d2 = f32::INFINITY;
    let mut closest = Vec2::ZERO;
    for (a, b) in edges(poly) {
        let e = b - a;
        let ee = e.dot(e);
        if ee.is_nan() || ee <= 1e-12 {
            continue;
        }
        let out = Vec2::new(e.y, -e.x).normalized();
        let s = (q - a).dot(out);
        if s > 0.0 {
            inside = false;
        }
        if s > best_s {
            best_s = s;
            best_out = out;
        }
        let t = ((q - a).dot(e) / ee).clamp(0.0, 1.0);
        let cp = a + e * t;
        let d2 = (q - cp).dot(q - cp);
        if d2 < best_d2 {
            best_d2 = d2;
            closest = cp;
        }
    }
    if !inside {
        let dist = best_d2.sqrt();
        if dist.partial_cmp(&rad) != Some(std::cmp::Ordering::Less) {
            return None;
        }
        if dist > 1e-6 {
            return Some(Contact {
                depth: rad - dist,
                normal: (closest - q) * (1.0 / dist),
                point: closest,
            });
        }
    }
    if best_out == Vec2::ZERO {
        return None;
    }
    // Centre inside: push B out through its nearest face.
    Some(Contact {
        depth: rad - best_s,
        normal: -best_out,
        point: q - best_out * best_s,
    })
}

/// Separating-axis test of two convex CCW polygons; the contact point is the centroid
/// of their intersection, so offset face-to-face contacts produce the right torque.
fn poly_poly(a: &[Vec2], b: &[Vec2]) -> Option<Contact> {
    if a.len() < 3 || b.len() < 3 {
        return None;
    }
    let mut best = f32::INFINITY;
    let mut normal = Vec2::ZERO;
    // Faces of A: B moves along A's outward normal. Faces of B: B moves against its own.
    for (reference, other, sign) in [(a, b, 1.0f32), (b, a, -1.0f32)] {
        for (p, q) in edges(reference) {
            let e = q - p;
            let out = Vec2::new(e.y, -e.x).normalized();
            if out == Vec2::ZERO {
                continue;
            }
            let face = p.dot(out);
            let min_other = other.iter().map(|v| v.dot(out)).fold(f32::INFINITY, f32::min);
            let pen = face - min_other;
            if pen.is_nan() || pen <= 0.0 {
                return None;
            }
            if pen < best {
                best = pen;
                normal = out * sign;
            }
        }
    }
    if normal == Vec2::ZERO {
        return None;
    }
    let overlap = clip_convex(b, a);
    let (area, centroid) = area_centroid(&overlap);
    let point = if area > 1e-9 {
        centroid
    } else if !overlap.is_empty() {
        overlap.iter().fold(Vec2::ZERO, |s, v| s + *v) * (1.0 / overlap.len() as f32)
    } else {
        // Numerically touching only: the deepest vertex of B along the normal.
        b.iter()
            .copied()
            .min_by(|x, y| x.dot(normal).total_cmp(&y.dot(normal)))
            .unwrap_or(Vec2::ZERO)
    };
    Some(Contact {
        depth: best,
        normal,
        point,
    })
}

/// Sutherland–Hodgman: `subject` clipped by the convex CCW polygon `clip`.
fn clip_convex(subject: &[Vec2], clip: &[Vec2]) -> Vec<Vec2> {
    let mut out: Vec<Vec2> = subject.to_vec();
    for (p, q) in edges(clip) {
        if out.is_empty() {
            break;
        }
        let e = q - p;
        let side = |v: Vec2| e.cross(v - p);
        let input = std::mem::take(&mut out);
        let n = input.len();
        for (k, &cur) in input.iter().enumerate() {
            let prev = input.get((k + n - 1) % n).copied().unwrap_or(cur);
            let (sc, sp) = (side(cur), side(prev));
            if sc >= 0.0 {
                if sp < 0.0 {
                    out.push(prev.lerp(cur, sp / (sp - sc)));
                }
                out.push(cur);
            } else if sp >= 0.0 && sp != sc {
                out.push(prev.lerp(cur, sp / (sp - sc)));
            }
        }
    }
    out
}

/// Area and centroid of a simple polygon.
fn area_centroid(poly: &[Vec2]) -> (f32, Vec2) {
    let mut a2 = 0.0f32;
    let mut c = Vec2::ZERO;
    for (p, q) in edges(poly) {
        let cr = p.cross(q);
        a2 += cr;
        c += (p + q) * cr;
    }
    if a2.abs() > 1e-12 {
        (a2 * 0.5, c * (1.0 / (3.0 * a2)))
    } else {
        (0.0, Vec2::ZERO)
    }
}

/// Desired contact displacement for a contact of `depth` along `n`: the normal part
/// removes the penetration; the tangential part keeps the ratio of the pusher's
/// relative motion `rel` (it only decides stick versus slide and the sliding side).
fn contact_motion(n: Vec2, depth: f32, rel: Vec2) -> Vec2 {
    let t = n.perp();
    let vn = rel.dot(n);
    let ratio = if vn > 1e-6 {
        (rel.dot(t) / vn).clamp(-100.0, 100.0)
    } else {
        // Not driving into the body (e.g. the body rotated into the pusher): push straight out.
        0.0
    };
    n * depth + t * (ratio * depth)
}

/// Moves `body` by the quasi-static response to contact `ct` with desired contact
/// displacement `v` (ellipsoidal limit surface + motion cone), keeps it inside the
/// workspace, and accumulates its motion in `moved`.
fn yield_to_push(body: &mut Body, moved: &mut (Vec2, f32), c: f32, ct: &Contact, v: Vec2, mu: f32) {
    let (dp, da) = limit_surface_twist(ct.point - body.pos, ct.normal, v, c, mu);
    if !(dp.x.is_finite() && dp.y.is_finite() && da.is_finite()) {
        return;
    }
    body.pos += dp;
    body.angle = wrap_angle(body.angle + da);
    let shift = keep_inside(body);
    moved.0 += dp + shift;
    moved.1 += da;
}

/// Object twist (Δpos, Δangle) when the contact at `r` (from the centroid) with
/// inward normal `n` must move by `v`.
fn limit_surface_twist(r: Vec2, n: Vec2, v: Vec2, c: f32, mu: f32) -> (Vec2, f32) {
    let c2 = c * c;
    let p = r.perp();
    // Sticking: solve M f = v with M = I + p pᵀ/c² (Sherman–Morrison).
    let stick = v - p * (p.dot(v) / (c2 + p.dot(p)));
    let t = n.perp();
    let (fn_, ft) = (stick.dot(n), stick.dot(t));
    let f = if fn_ > 0.0 && ft.abs() <= mu * fn_ {
        stick
    } else {
        // Sliding: force on the cone edge on the side the contact slips towards.
        let edge = n + t * (mu * if ft >= 0.0 { 1.0 } else { -1.0 });
        let vc = edge + p * (p.dot(edge) / c2);
        let vn = vc.dot(n);
        if vn > 1e-6 {
            edge * (v.dot(n) / vn)
        } else {
            n * v.dot(n)
        }
    };
    (f, r.cross(f) / c2)
}

fn point_velocity(body: &Body, moved: (Vec2, f32), point: Vec2) -> Vec2 {
    moved.0 + (point - body.pos).perp() * moved.1
}

/// Translates the body so its outline lies in the workspace; returns the shift.
fn keep_inside(body: &mut Body) -> Vec2 {
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

// ---------------------------------------------------------------------------------
// Polygon helpers

/// Consecutive vertex pairs of a closed polygon.
fn edges(poly: &[Vec2]) -> impl Iterator<Item = (Vec2, Vec2)> + '_ {
    poly.iter().copied().zip(poly.iter().copied().cycle().skip(1))
}

fn signed_area(poly: &[Vec2]) -> f32 {
    edges(poly).map(|(p, q)| p.cross(q)).sum::<f32>() * 0.5
}

fn regular_polygon(n: usize, radius: f32, rot: f32) -> Vec<Vec2> {
    (0..n)
        .map(|k| Vec2::from_angle(rot + std::f32::consts::TAU * k as f32 / n as f32) * radius)
        .collect()
}

/// Shifts vertices so their area centroid is the origin (catalogue polygons).
fn centered(verts: Vec<Vec2>) -> Vec<Vec2> {
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
fn mean_distance_from_origin(poly: &[Vec2]) -> f32 {
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn spec(name: &str) -> ObjSpec {
        let (train, test) = object_catalog();
        train.into_iter().chain(test).find(|s| s.name == name).unwrap()
    }

    fn body(name: &str, x: f32, y: f32, angle: f32) -> Body {
        Body::new(spec(name), Vec2::new(x, y), angle)
    }

    fn pair_penetration(a: &Body, b: &Body) -> f32 {
        contact(&geo(a), &geo(b)).map_or(0.0, |c| c.depth)
    }

    #[test]
    fn no_contact_no_motion() {
        let b = body("red_box", 30.0, 30.0, 0.3);
        let mut w = PushWorld::new(vec![b.clone()], Vec2::new(5.0, 20.0));
        // Passes 1.5 cm below the box's lowest corner (well clear).
        let d = w.move_pusher(Vec2::new(55.0, 20.0));
        w.move_pusher(Vec2::new(55.0, 55.0));
        w.move_pusher(Vec2::new(5.0, 55.0));
        assert_eq!(d, vec![Vec2::ZERO]);
        assert_eq!(w.bodies[0], b);
    }

    #[test]
    fn head_on_push_translates() {
        for name in ["red_box", "green_disk", "purple_hexagon"] {
            let b = body(name, 30.0, 30.0, 0.0);
            let back = b.support(Vec2::new(-1.0, 0.0));
            let touch = 30.0 - back - PUSHER_RADIUS_CM;
            let mut w = PushWorld::new(vec![b], Vec2::new(20.0, 30.0));
            let d = w.move_pusher(Vec2::new(touch + 10.0, 30.0));
            assert!((d[0].x - 10.0).abs() < 0.05, "{name}: {:?}", d[0]);
            assert!(d[0].y.abs() < 0.2, "{name}: {:?}", d[0]);
            assert!(w.bodies[0].angle.abs() < 2f32.to_radians(), "{name}");
            assert!(w.max_penetration() < 0.05);
        }
    }

    #[test]
    fn off_centre_push_rotates_with_the_right_sign() {
        for (dy, sign) in [(1.5f32, -1.0f32), (-1.5, 1.0)] {
            let mut w = PushWorld::new(vec![body("red_box", 30.0, 30.0, 0.0)], Vec2::new(20.0, 30.0 + dy));
            let d = w.move_pusher(Vec2::new(33.0, 30.0 + dy));
            let a = w.bodies[0].angle;
            // Pushing +x above the centroid turns the box clockwise, below counter-clockwise.
            assert!(a * sign > 5f32.to_radians(), "dy {dy}: angle {a}");
            assert!(d[0].x > 2.0);
        }
        // A sliding (tangential) pusher motion over a disk spins it a little too, but a
        // straight push through a disk's centre never does.
        let mut w = PushWorld::new(vec![body("green_disk", 30.0, 30.0, 0.0)], Vec2::new(24.0, 30.0));
        w.move_pusher(Vec2::new(34.0, 30.0));
        assert_eq!(w.bodies[0].angle, 0.0);
    }

    fn random_world() -> PushWorld {
        PushWorld::new(
            vec![
                body("red_box", 20.0, 30.0, 0.2),
                body("green_disk", 35.0, 30.0, 0.0),
                body("yellow_triangle", 30.0, 42.0, 1.0),
                body("navy_slab", 45.0, 15.0, -0.4),
            ],
            Vec2::new(5.0, 5.0),
        )
    }

    fn random_moves(seed: u64, n: usize) -> Vec<Vec2> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut p = Vec2::new(5.0, 5.0);
        (0..n)
            .map(|k| {
                p = if k % 4 == 0 {
                    // Sometimes far beyond the edges, to drive objects into walls.
                    Vec2::new(rng.random_range(-10.0..70.0), rng.random_range(-10.0..70.0))
                } else {
                    clamp_to_workspace(
                        p + Vec2::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0)),
                    )
                };
                p
            })
            .collect()
    }

    #[test]
    fn random_moves_keep_invariants() {
        for seed in 0..3 {
            let mut w = random_world();
            let mut moved_any = false;
            for t in random_moves(seed, 250) {
                let d = w.move_pusher(t);
                moved_any |= d.iter().any(|v| v.len() > 0.0);
                let pen = w.max_penetration();
                assert!(pen < 0.3, "seed {seed}: penetration {pen}");
                for b in &w.bodies {
                    for v in b.world_polygon() {
                        assert!(
                            (-1e-3..=WORKSPACE_CM + 1e-3).contains(&v.x)
                                && (-1e-3..=WORKSPACE_CM + 1e-3).contains(&v.y),
                            "seed {seed}: {} left the workspace at {v:?}",
                            b.spec.name
                        );
                    }
                }
            }
            assert!(moved_any, "seed {seed}: random pushing never touched anything");
        }
    }

    #[test]
    fn deterministic() {
        let run = || {
            let mut w = random_world();
            for t in random_moves(11, 150) {
                w.move_pusher(t);
            }
            w.bodies
                .iter()
                .map(|b| (b.pos.x.to_bits(), b.pos.y.to_bits(), b.angle.to_bits()))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(), run());
    }

    #[test]
    fn chain_push_moves_the_second_body() {
        let mut w = PushWorld::new(
            vec![
                body("red_box", 25.0, 30.0, 0.0),
                body("blue_cube", 34.0, 30.5, 0.1),
            ],
            Vec2::new(18.0, 30.0),
        );
        let d = w.move_pusher(Vec2::new(36.0, 30.0));
        assert!(d[1].x > 5.0, "{d:?}");
        assert!(pair_penetration(&w.bodies[0], &w.bodies[1]) < 0.05);
        assert!(w.max_penetration() < 0.05);
        // B in front, A behind: order is kept.
        assert!(w.bodies[1].pos.x > w.bodies[0].pos.x + 4.0);
    }

    #[test]
    fn jammed_against_the_wall_stops_the_pusher() {
        let mut w = PushWorld::new(vec![body("blue_cube", 50.0, 30.0, 0.0)], Vec2::new(40.0, 30.0));
        w.move_pusher(Vec2::new(60.0, 30.0));
        let b = &w.bodies[0];
        assert!((b.pos.x - 57.5).abs() < 1e-3, "{:?}", b.pos);
        assert!(w.pusher.x < 55.0 + 0.3);
        assert!(w.max_penetration() < JAM_TOL + 1e-4);
    }

    #[test]
    fn scripted_push_reaches_the_target() {
        let target = TargetSquare {
            center: Vec2::new(42.0, 30.0),
        };
        let mut w = PushWorld::new(vec![body("red_box", 20.0, 30.0, 0.0)], Vec2::new(10.0, 30.0));
        assert!(!target.contains(w.bodies[0].pos));
        for x in [15.0, 20.0, 25.0, 30.0, 35.0, 37.5] {
            w.move_pusher(Vec2::new(x, 30.0));
        }
        assert!(target.contains(w.bodies[0].pos), "{:?}", w.bodies[0].pos);
    }

    #[test]
    fn catalog_is_well_formed() {
        let (train, test) = object_catalog();
        assert_eq!((train.len(), test.len()), (10, 8));
        let mut names: Vec<&str> = train.iter().chain(&test).map(|s| s.name.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), 18);
        assert!(
            test.iter()
                .all(|t| train.iter().all(|s| s.name != t.name && s.color != t.color))
        );
        for s in train.iter().chain(&test) {
            let b = Body::new(s.clone(), Vec2::new(30.0, 30.0), 0.0);
            let across = 2.0 * b.bounding_radius();
            assert!((3.0..=9.0).contains(&across), "{}: {across}", s.name);
            assert!((0.2..=0.9).contains(&s.mu_table) && s.mass > 0.0);
            // Centroid at the local origin, CCW outline.
            let (area, c) = area_centroid(&s.shape.local_outline());
            assert!(area > 0.0 && c.len() < 1e-3, "{}: {c:?}", s.name);
            assert!(b.contains(b.pos));
        }
    }

    #[test]
    fn limit_surface_ratio_matches_numeric_integral() {
        let grid_mean = |shape: &ObjShape| {
            let b = Body::new(
                ObjSpec {
                    name: String::new(),
                    shape: shape.clone(),
                    mu_table: 0.5,
                    mass: 1.0,
                    color: [0; 3],
                },
                Vec2::ZERO,
                0.0,
            );
            let (mut sum, mut n) = (0.0f64, 0u32);
            for i in 0..400 {
                for j in 0..400 {
                    let p = Vec2::new(-5.0 + (i as f32 + 0.5) * 0.025, -5.0 + (j as f32 + 0.5) * 0.025);
                    if b.contains(p) {
                        sum += f64::from(p.len());
                        n += 1;
                    }
                }
            }
            (sum / f64::from(n)) as f32
        };
        for name in [
            "red_box",
            "yellow_triangle",
            "purple_hexagon",
            "teal_trapezoid",
            "olive_kite",
        ] {
            let s = spec(name).shape;
            let (exact, numeric) = (s.limit_surface_c(), grid_mean(&s));
            assert!(
                (exact - numeric).abs() < 0.01 * numeric,
                "{name}: {exact} vs {numeric}"
            );
        }
        let disk = ObjShape::Disk { r: 2.5 };
        assert!((disk.limit_surface_c() - 2.5 * 2.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn expert_follows_plan_into_the_target() {
        for name in ["red_box", "green_disk", "orange_bar", "gold_small_cube"] {
            for seed in 0..5u64 {
                let mut rng = StdRng::seed_from_u64(seed * 31 + 7);
                let start = Vec2::new(rng.random_range(15.0..45.0), rng.random_range(15.0..45.0));
                let target = loop {
                    let c = Vec2::new(rng.random_range(12.0..48.0), rng.random_range(12.0..48.0));
                    if c.dist(start) > 12.0 {
                        break TargetSquare { center: c };
                    }
                };
                let b = body(name, start.x, start.y, rng.random_range(-3.0..3.0));
                let pusher = loop {
                    let p = Vec2::new(rng.random_range(3.0..57.0), rng.random_range(3.0..57.0));
                    if p.dist(start) > b.bounding_radius() + 2.0 {
                        break p;
                    }
                };
                let mut w = PushWorld::new(vec![b], pusher);
                let mut steps = 0;
                while steps < 50 {
                    let a = expert_action(w.pusher, &w.bodies[0], target.center, w.pusher_radius);
                    if a == Vec2::ZERO {
                        break;
                    }
                    assert_eq!(clamp_action(a), a);
                    w.move_pusher(w.pusher + a);
                    assert!(w.max_penetration() < 0.3);
                    steps += 1;
                }
                assert!(
                    target.contains(w.bodies[0].pos),
                    "{name} seed {seed}: ended at {:?}, target {:?} after {steps} steps",
                    w.bodies[0].pos,
                    target.center
                );
            }
        }
    }

    #[test]
    fn plan_without_pusher_ends_behind_the_goal() {
        let b = body("red_box", 20.0, 30.0, 0.0);
        let plan = push_plan(&b, Vec2::new(40.0, 30.0), PUSHER_RADIUS_CM);
        assert_eq!(plan.len(), 3);
        // Staging and approach behind (x < box), push end 4.5 cm short of the goal.
        assert!(plan[0].x < plan[1].x && plan[1].x < 20.0 - 3.0 - PUSHER_RADIUS_CM);
        assert!((plan[2] - Vec2::new(35.5, 30.0)).len() < 1e-4);
        assert!(push_plan(&b, Vec2::new(20.5, 30.0), PUSHER_RADIUS_CM).is_empty());
    }

    #[test]
    fn odd_inputs_do_not_panic() {
        let mut w = random_world();
        for t in [
            Vec2::new(f32::NAN, 3.0),
            Vec2::new(f32::INFINITY, f32::NEG_INFINITY),
            Vec2::new(1e30, -1e30),
        ] {
            w.move_pusher(t);
        }
        w.pusher = Vec2::new(f32::NAN, 0.0);
        w.pusher_radius = -3.0;
        w.move_pusher(Vec2::new(30.0, 30.0));
        let mut odd = spec("red_box");
        for verts in [vec![], vec![Vec2::ZERO], vec![Vec2::ZERO, Vec2::new(1.0, 0.0)]] {
            odd.shape = ObjShape::Polygon { verts };
            let b = Body::new(odd.clone(), Vec2::new(30.0, 30.0), 0.0);
            assert!(!b.contains(b.pos) || b.world_polygon().len() >= 3);
            let mut w = PushWorld::new(vec![b.clone(), b.clone()], Vec2::new(25.0, 30.0));
            w.move_pusher(Vec2::new(35.0, 30.0));
            w.max_penetration();
            push_plan_from(Vec2::ZERO, &b, Vec2::new(50.0, 50.0), 1.5);
            expert_action(Vec2::ZERO, &b, Vec2::new(f32::NAN, 50.0), f32::NAN);
        }
        let nan_body = Body::new(spec("green_disk"), Vec2::new(f32::NAN, 1.0), f32::NAN);
        let mut w = PushWorld::new(
            vec![nan_body.clone(), body("red_box", 30.0, 30.0, 0.0)],
            Vec2::ZERO,
        );
        w.move_pusher(Vec2::new(40.0, 40.0));
        expert_action(Vec2::ZERO, &nan_body, Vec2::new(30.0, 30.0), 1.5);
        // Overlapping start: resolved, not stuck.
        let mut w = PushWorld::new(
            vec![
                body("red_box", 30.0, 30.0, 0.0),
                body("blue_cube", 31.0, 30.0, 0.0),
            ],
            Vec2::new(30.0, 10.0),
        );
        w.move_pusher(Vec2::new(30.0, 11.0));
        assert!(w.max_penetration() < 0.05);
    }
}
