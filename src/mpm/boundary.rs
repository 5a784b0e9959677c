//! Domain walls and the Coulomb friction projection shared by walls and colliders.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// How one wall of the domain box acts on the sand.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Wall {
    /// Grid velocity set to zero at and beyond the wall (no slip, no separation).
    Sticky,
    /// Frictionless: the velocity component into the wall is removed; sand may separate.
    Slip,
    /// Coulomb friction with the given coefficient (dimensionless, >= 0); sand may separate.
    Friction(f32),
}

impl Wall {
    /// Applies the wall to a grid velocity `v` (m/s); `normal` points into the domain.
    #[inline]
    pub fn apply(self, v: Vector3<f32>, normal: Vector3<f32>) -> Vector3<f32> {
        match self {
            Wall::Sticky => Vector3::zeros(),
            Wall::Slip => friction_project(v, Vector3::zeros(), normal, 0.0),
            Wall::Friction(mu) => friction_project(v, Vector3::zeros(), normal, mu),
        }
    }
}

/// The six walls of the axis-aligned domain box.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Walls {
    pub x_min: Wall,
    pub x_max: Wall,
    pub y_min: Wall,
    pub y_max: Wall,
    pub z_min: Wall,
    pub z_max: Wall,
}

impl Walls {
    /// All six walls of one kind.
    pub fn all(wall: Wall) -> Self {
        Walls {
            x_min: wall,
            x_max: wall,
            y_min: wall,
            y_max: wall,
            z_min: wall,
            z_max: wall,
        }
    }

    /// Applies the walls to the velocity `v` (m/s) of grid node `index`: node `nodes[0][axis]`
    /// lies on each min wall and `nodes[1][axis]` on each max wall; nodes on or beyond a wall
    /// get its rule.
    #[inline]
    pub fn apply_at_node(
        &self,
        mut v: Vector3<f32>,
        index: [i32; 3],
        nodes: &WallNodes,
    ) -> Vector3<f32> {
        for axis in 0..3 {
            let [min_wall, max_wall] = self.axis(axis);
            let mut normal = Vector3::zeros();
            if index[axis] <= nodes[0][axis] {
                normal[axis] = 1.0;
                v = min_wall.apply(v, normal);
            } else if index[axis] >= nodes[1][axis] {
                normal[axis] = -1.0;
                v = max_wall.apply(v, normal);
            }
        }
        v
    }

    /// `[min wall, max wall]` of one axis.
    pub fn axis(&self, axis: usize) -> [Wall; 2] {
        match axis {
            0 => [self.x_min, self.x_max],
            1 => [self.y_min, self.y_max],
            _ => [self.z_min, self.z_max],
        }
    }
}

/// Grid node index of the min walls (`[0]`) and of the max walls (`[1]`), per axis.
pub type WallNodes = [[i32; 3]; 2];

/// Coulomb friction projection of a velocity `v` against a surface moving with `v_body`
/// (physics.md section 4): a separating velocity is returned unchanged; otherwise the normal
/// part of the relative velocity is removed and the tangential part shrunk by `mu |v_n|`.
/// `normal` is a unit vector pointing away from the surface; `mu = f32::INFINITY` is sticky.
#[inline]
pub fn friction_project(
    v: Vector3<f32>,
    v_body: Vector3<f32>,
    normal: Vector3<f32>,
    mu: f32,
) -> Vector3<f32> {
    let v_rel = v - v_body;
    let v_n = v_rel.dot(&normal);
    if v_n >= 0.0 {
        return v;
    }
    let v_t = v_rel - v_n * normal;
    let v_t_norm = v_t.norm();
    if v_t_norm <= f32::EPSILON {
        return v_body;
    }
    let scale = (1.0 + mu * v_n / v_t_norm).max(0.0);
    v_body + v_t * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn friction_projection() {
        let n = Vector3::z();
        // Separating: untouched.
        let v = Vector3::new(1.0, 0.0, 0.5);
        assert_eq!(friction_project(v, Vector3::zeros(), n, 0.5), v);
        // Slip removes only the normal part.
        let v = Vector3::new(1.0, 0.0, -0.5);
        assert_eq!(
            friction_project(v, Vector3::zeros(), n, 0.0),
            Vector3::new(1.0, 0.0, 0.0)
        );
        // Friction shrinks the tangential part by mu |v_n|.
        let out = friction_project(v, Vector3::zeros(), n, 0.4);
        assert!((out - Vector3::new(0.8, 0.0, 0.0)).norm() < 1e-6);
        // Enough friction stops it (sticky).
        let out = friction_project(v, Vector3::zeros(), n, f32::INFINITY);
        assert_eq!(out, Vector3::zeros());
        // Relative to a moving surface.
        let vb = Vector3::new(0.0, 1.0, 0.0);
        let out = friction_project(Vector3::new(0.0, 1.0, -1.0), vb, n, 0.3);
        assert!((out - vb).norm() < 1e-6);
    }
}
