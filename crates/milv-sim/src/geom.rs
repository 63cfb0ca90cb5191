//! Planar geometry in table coordinates: centimetres, x to the right, y away from the
//! human's side of the table, angles in radians counter-clockwise.

use serde::{Deserialize, Serialize};

/// A point or vector on the table plane (cm).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vec2 {
    pub x: f32,
    pub y: f32,
}

impl Vec2 {
    pub const ZERO: Vec2 = Vec2 { x: 0.0, y: 0.0 };

    pub const fn new(x: f32, y: f32) -> Self {
        Vec2 { x, y }
    }

    pub fn from_angle(a: f32) -> Self {
        Vec2::new(a.cos(), a.sin())
    }

    pub fn dot(self, o: Vec2) -> f32 {
        self.x * o.x + self.y * o.y
    }

    /// z of the 3-D cross product.
    pub fn cross(self, o: Vec2) -> f32 {
        self.x * o.y - self.y * o.x
    }

    pub fn len(self) -> f32 {
        self.dot(self).sqrt()
    }

    pub fn dist(self, o: Vec2) -> f32 {
        (self - o).len()
    }

    /// Unit vector, or zero for a (near-)zero vector.
    pub fn normalized(self) -> Vec2 {
        let l = self.len();
        if l > 1e-9 { self * (1.0 / l) } else { Vec2::ZERO }
    }

    /// Rotated by `a` radians counter-clockwise.
    pub fn rotated(self, a: f32) -> Vec2 {
        let (s, c) = a.sin_cos();
        Vec2::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }

    /// Perpendicular (rotated +90°).
    pub fn perp(self) -> Vec2 {
        Vec2::new(-self.y, self.x)
    }

    pub fn lerp(self, o: Vec2, t: f32) -> Vec2 {
        self + (o - self) * t
    }
}

impl std::ops::Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl std::ops::AddAssign for Vec2 {
    fn add_assign(&mut self, o: Vec2) {
        *self = *self + o;
    }
}

impl std::ops::Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl std::ops::SubAssign for Vec2 {
    fn sub_assign(&mut self, o: Vec2) {
        *self = *self - o;
    }
}

impl std::ops::Mul<f32> for Vec2 {
    type Output = Vec2;
    fn mul(self, k: f32) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}

impl std::ops::Neg for Vec2 {
    type Output = Vec2;
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}

/// Workspace: the table region the end-effector may reach, [0, SIZE]² cm.
pub const WORKSPACE_CM: f32 = 60.0;
/// Largest end-effector displacement per step and axis (cm).
pub const MAX_STEP_CM: f32 = 5.0;
/// Steps per episode.
pub const EPISODE_STEPS: usize = 50;

/// Clamps an action to the per-axis limit.
pub fn clamp_action(a: Vec2) -> Vec2 {
    Vec2::new(
        a.x.clamp(-MAX_STEP_CM, MAX_STEP_CM),
        a.y.clamp(-MAX_STEP_CM, MAX_STEP_CM),
    )
}

/// Clamps a point to the workspace.
pub fn clamp_to_workspace(p: Vec2) -> Vec2 {
    Vec2::new(p.x.clamp(0.0, WORKSPACE_CM), p.y.clamp(0.0, WORKSPACE_CM))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_and_products() {
        let v = Vec2::new(1.0, 0.0).rotated(std::f32::consts::FRAC_PI_2);
        assert!((v.x).abs() < 1e-6 && (v.y - 1.0).abs() < 1e-6);
        assert_eq!(Vec2::new(1.0, 2.0).dot(Vec2::new(3.0, 4.0)), 11.0);
        assert_eq!(Vec2::new(1.0, 0.0).cross(Vec2::new(0.0, 1.0)), 1.0);
        assert_eq!(clamp_action(Vec2::new(9.0, -7.0)), Vec2::new(5.0, -5.0));
        assert_eq!(Vec2::ZERO.normalized(), Vec2::ZERO);
    }
}
