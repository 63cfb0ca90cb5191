//! # milv-sim — a procedural two-embodiment tabletop
//!
//! The experiment shape of the paper's Appendix A.1 on a CPU: a 60×60 cm table, 50 steps
//! an episode, an end-effector moved by `(Δx, Δy)` ≤ 5 cm per axis, seen as a **human**
//! forearm and hand from camera A (source domain) or a **robot** arm with a gripper from
//! camera B (target domain).
//!
//! | module | what it holds |
//! |---|---|
//! | [`env`] | `Sim` (reset / step / observe / success), scripted experts, rollouts |
//! | [`geom`] | `Vec2` in table centimetres, workspace and action limits |
//! | [`shapes`] | drawing shapes (11 train, 12 test), resampling, the LCS success metric |
//! | [`push`] | quasi-static planar pushing: bodies, contacts, the object catalogue |
//! | [`render`] | anti-aliased rendering (tiny-skia) of both embodiments through perspective cameras |

pub mod env;
pub mod geom;
pub mod push;
pub mod render;
pub mod shapes;

pub use geom::Vec2;
