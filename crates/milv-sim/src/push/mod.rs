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

//!
//! | module | what |
//! |---|---|
//! | [`world`] | objects ([`ObjShape`], [`ObjSpec`], [`Body`]), the target, [`PushWorld`] and its substep solver |
//! | [`contact`] | contact detection (circle/convex-polygon overlaps) and the limit-surface response |
//! | [`catalogue`] | the 10 training and 8 test objects |
//! | [`expert`] | the scripted pusher: plans around and through an object to the target |

mod catalogue;
mod contact;
mod expert;
mod world;

pub use catalogue::object_catalog;
pub use expert::{expert_action, push_plan, push_plan_from};
pub use world::{Body, ObjShape, ObjSpec, PushWorld, TargetSquare};

use contact::*;
use expert::*;
use world::*;

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
pub(crate) const SOLVER_ITERS: usize = 16;
/// Penetrations below this are contact, not overlap (cm).
pub(crate) const CONTACT_EPS: f32 = 1e-4;
/// Residual overlap above this after a substep means the push jammed (cm).
pub(crate) const JAM_TOL: f32 = 0.05;
/// Outline resolution of disks for the renderer.
pub(crate) const DISK_SEGMENTS: usize = 24;
/// Guards against absurd pusher positions set from outside (60√2 / 0.25 ≈ 340 needed).
pub(crate) const MAX_SUBSTEPS: usize = 2000;
/// Floor for the limit-surface ratio, so degenerate shapes cannot divide by zero.
pub(crate) const MIN_C: f32 = 0.05;

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
