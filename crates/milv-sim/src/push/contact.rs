//! Contacts: overlap of two bodies (circles exactly, convex polygons by separating axes
//! and clipping), and how a pushed body yields (ellipsoidal limit surface, friction cone).

use super::*;

/// Collision geometry in world coordinates.
pub(super) enum Geo {
    Circle {
        c: Vec2,
        r: f32,
    },
    /// Convex, CCW.
    Poly(Vec<Vec2>),
}

pub(super) fn geo(b: &Body) -> Geo {
    match b.spec.shape {
        // Disks collide exactly, not as their 24-gon outline.
        ObjShape::Disk { r } => Geo::Circle { c: b.pos, r: r.abs() },
        _ => Geo::Poly(b.world_polygon()),
    }
}

/// Overlap of A and B.
#[derive(Clone, Copy, Debug)]
pub(super) struct Contact {
    pub(super) depth: f32,
    /// Unit direction in which B must move to separate from A.
    pub(super) normal: Vec2,
    /// World contact point.
    pub(super) point: Vec2,
}

pub(super) fn contact(a: &Geo, b: &Geo) -> Option<Contact> {
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

pub(super) fn circle_circle(a: Vec2, ra: f32, b: Vec2, rb: f32) -> Option<Contact> {
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
pub(super) fn circle_poly(q: Vec2, rad: f32, poly: &[Vec2]) -> Option<Contact> {
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
pub(super) fn poly_poly(a: &[Vec2], b: &[Vec2]) -> Option<Contact> {
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
pub(super) fn clip_convex(subject: &[Vec2], clip: &[Vec2]) -> Vec<Vec2> {
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
pub(super) fn area_centroid(poly: &[Vec2]) -> (f32, Vec2) {
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
pub(super) fn contact_motion(n: Vec2, depth: f32, rel: Vec2) -> Vec2 {
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
pub(super) fn yield_to_push(
    body: &mut Body,
    moved: &mut (Vec2, f32),
    c: f32,
    ct: &Contact,
    v: Vec2,
    mu: f32,
) {
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
pub(super) fn limit_surface_twist(r: Vec2, n: Vec2, v: Vec2, c: f32, mu: f32) -> (Vec2, f32) {
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

pub(super) fn point_velocity(body: &Body, moved: (Vec2, f32), point: Vec2) -> Vec2 {
    moved.0 + (point - body.pos).perp() * moved.1
}

// ---------------------------------------------------------------------------------
// Polygon helpers

/// Consecutive vertex pairs of a closed polygon.
pub(super) fn edges(poly: &[Vec2]) -> impl Iterator<Item = (Vec2, Vec2)> + '_ {
    poly.iter().copied().zip(poly.iter().copied().cycle().skip(1))
}

pub(super) fn signed_area(poly: &[Vec2]) -> f32 {
    edges(poly).map(|(p, q)| p.cross(q)).sum::<f32>() * 0.5
}
