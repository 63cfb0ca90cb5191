//! The scripted pusher: where to stand behind an object, how to get there around it, and
//! the push through its centroid to the goal.

use super::*;

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

// ---------------------------------------------------------------------------------
// Planning helpers

/// Chord angle when going around an object (radians).
pub(super) const ARC_STEP: f32 = std::f32::consts::PI / 6.0;
/// Clearance between pusher and object on the way round (cm).
pub(super) const PLAN_CLEARANCE: f32 = 0.5;
/// Gap left at the approach point before the push starts (cm).
pub(super) const APPROACH_GAP: f32 = 0.4;
/// The plan is done once the centroid is this close to the goal (cm).
pub(super) const GOAL_TOL: f32 = 1.0;

/// Key points of a push of `body` to `goal`.
pub(super) struct PushGeometry {
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
pub(super) fn path_clear(body: &Body, a: Vec2, b: Vec2, rp: f32) -> bool {
    let g = geo(body);
    let n = ((a.dist(b) / SUBSTEP_CM).ceil() as usize).clamp(1, MAX_SUBSTEPS);
    (0..=n).all(|k| {
        let p = a.lerp(b, k as f32 / n as f32);
        contact(&Geo::Circle { c: p, r: rp + 0.1 }, &g).is_none()
    })
}

pub(super) fn angle_of(v: Vec2) -> f32 {
    v.y.atan2(v.x)
}

/// Wraps to [-π, π).
pub(super) fn wrap_angle(a: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    (a + PI).rem_euclid(TAU) - PI
}

/// Drops waypoints that repeat the previous one (a zero action would stall the expert).
pub(super) fn dedup(wps: Vec<Vec2>) -> Vec<Vec2> {
    let mut out: Vec<Vec2> = Vec::with_capacity(wps.len());
    for w in wps {
        if out.last().is_none_or(|l| l.dist(w) > 1e-3) {
            out.push(w);
        }
    }
    out
}

pub(super) fn dedup_from(start: Vec2, wps: Vec<Vec2>) -> Vec<Vec2> {
    dedup(wps)
        .into_iter()
        .skip_while(|w| w.dist(start) <= 1e-3)
        .collect()
}

// ---------------------------------------------------------------------------------
// Contact physics
