//! Quadratic B-spline interpolation weights (Hu et al. 2018; Jiang et al. 2015, APIC).
//!
//! A particle at grid coordinate `xg = (x - origin) / dx` touches the 3 nodes per axis
//! `base, base + 1, base + 2` with `base = floor(xg - 0.5)`. With `fx = xg - base` in
//! [0.5, 1.5) the weights are `0.5 (1.5 - fx)^2`, `0.75 - (fx - 1)^2`, `0.5 (fx - 0.5)^2`.
//! They sum to one and have zero first moment, and `sum_i w_i (x_i - x_p)^2 = dx^2 / 4`, which
//! is why the MLS/APIC inertia tensor inverse is the scalar `4 / dx^2`.

use nalgebra::Vector3;

/// Nodes per axis in the quadratic stencil.
pub const STENCIL: usize = 3;

/// `floor(x)` as an integer, for |x| < 2^31, without a libm call (the baseline x86-64 target
/// has no rounding instruction, and `f32::floor` is then a function call per axis and particle).
#[inline(always)]
pub fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t - ((t as f32) > x) as i32
}

/// The 27-node quadratic B-spline stencil of one particle.
#[derive(Clone, Copy, Debug)]
pub struct Stencil {
    /// Grid index of the first stencil node along each axis.
    pub base: [i32; 3],
    /// Particle offset from the base node in cells, each in [0.5, 1.5).
    pub fx: Vector3<f32>,
    /// `weights[axis][n]`: weight of node `base + n` along `axis`.
    pub weights: [[f32; STENCIL]; 3],
}

impl Stencil {
    /// Stencil of a particle at `xg`, its position in grid units (cells from the grid origin).
    #[inline(always)]
    pub fn new(xg: Vector3<f32>) -> Self {
        let mut base = [0i32; 3];
        let mut fx = Vector3::zeros();
        let mut weights = [[0.0f32; STENCIL]; 3];
        for axis in 0..3 {
            let b = floor_i32(xg[axis] - 0.5);
            let f = xg[axis] - b as f32;
            base[axis] = b;
            fx[axis] = f;
            weights[axis] = [
                0.5 * (1.5 - f) * (1.5 - f),
                0.75 - (f - 1.0) * (f - 1.0),
                0.5 * (f - 0.5) * (f - 0.5),
            ];
        }
        Stencil { base, fx, weights }
    }

    /// Weight of stencil node `(i, j, k)`, each in `0..3`.
    #[inline(always)]
    pub fn weight(&self, i: usize, j: usize, k: usize) -> f32 {
        self.weights[0][i] * self.weights[1][j] * self.weights[2][k]
    }

    /// Offset `x_i - x_p` of stencil node `(i, j, k)` from the particle, in cells.
    #[inline(always)]
    pub fn offset_cells(&self, i: usize, j: usize, k: usize) -> Vector3<f32> {
        Vector3::new(i as f32, j as f32, k as f32) - self.fx
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    #[test]
    fn integer_floor() {
        for x in [
            -2.5f32,
            -1.0,
            -0.5,
            -1e-7,
            0.0,
            1e-7,
            0.5,
            1.0,
            2.999,
            1e6 + 0.5,
        ] {
            assert_eq!(floor_i32(x), x.floor() as i32, "floor of {x}");
        }
    }

    #[test]
    fn partition_of_unity_and_zero_first_moment() {
        let mut rng = SmallRng::seed_from_u64(7);
        for _ in 0..10_000 {
            let xg = Vector3::new(
                rng.random_range(-50.0..50.0f32),
                rng.random_range(-50.0..50.0f32),
                rng.random_range(-50.0..50.0f32),
            );
            let s = Stencil::new(xg);
            let (mut sum, mut first, mut second) = (0.0f64, Vector3::<f64>::zeros(), 0.0f64);
            for i in 0..3 {
                for j in 0..3 {
                    for k in 0..3 {
                        let w = s.weight(i, j, k) as f64;
                        let d = s.offset_cells(i, j, k).cast::<f64>();
                        sum += w;
                        first += w * d;
                        second += w * d.x * d.x;
                    }
                }
            }
            assert!((sum - 1.0).abs() < 1e-5, "sum of weights {sum} at {xg:?}");
            assert!(first.norm() < 1e-5, "first moment {first:?} at {xg:?}");
            // D_p = dx^2/4 I, the property the 4/dx^2 factor of MLS-MPM relies on.
            assert!(
                (second - 0.25).abs() < 1e-4,
                "second moment {second} at {xg:?}"
            );
            for axis in 0..3 {
                assert!((0.5..1.5).contains(&s.fx[axis]));
                assert!(s.weights[axis].iter().all(|&w| w >= 0.0));
            }
        }
    }
}
