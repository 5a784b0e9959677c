//! Quadratic B-spline interpolation weights (Hu et al. 2018; Jiang et al. 2015, APIC).
//!
//! A particle at grid coordinate `xg = (x - origin) / dx` touches the 3 nodes per axis
//! `base, base + 1, base + 2` with `base = floor(xg - 0.5)`. With `fx = xg - base` in
//! [0.5, 1.5) the weights are `0.5 (1.5 - fx)^2`, `0.75 - (fx - 1)^2`, `0.5 (fx - 0.5)^2`.
//! They sum to one and have zero first moment, and `sum_i w_i (x_i - x_p)^2 = dx^2 / 4`, which
//! is why the MLS/APIC inertia tensor inverse is the scalar `4 / dx^2`.
//!
//! [`Kernel::Linear`], the linear hat on the same window, exists to show what the B-spline
//! avoids (cell-crossing noise, `docs/stability.md`).

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
    /// Inverse of the MLS moment `D = sum_i w_i (x_i - x_p)(x_i - x_p)^T`, which is diagonal,
    /// per axis in 1/cells^2: 4 for the quadratic B-spline, `1 / (f (1 - f))` for the linear hat.
    pub inverse_moment: Vector3<f32>,
}

/// Interpolation kernel of the particle-grid transfers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// Quadratic B-spline (MLS-MPM's): C1, with the constant moment `D = dx^2/4`.
    #[default]
    QuadraticBspline,
    /// Linear hat (tent), for comparison: its gradient jumps where a particle crosses a cell
    /// boundary, where the moment `D = f (1 - f) dx^2` vanishes (with MLS transfers,
    /// `w D^-1 (x_i - x_p)` is exactly the hat's gradient).
    Linear,
}

/// Smallest `f (1 - f)` of the linear hat's moment (cells^2): a particle within 1e-4 cells of a
/// node plane counts as that far (the products `w D^-1 (x_i - x_p)` stay within +-1 anyway).
const MIN_LINEAR_MOMENT: f32 = 1e-4;

/// A kernel fixed at compile time, for a particle loop monomorphised on it: in the quadratic
/// B-spline's loop the moment `D^-1` is the constant 4, so what is computed from it and from
/// loop constants alone (G2P's `D^-1 / dx` and its inverses) can be taken out of the loop by
/// the compiler (it was: G2P 5.5 % faster, `docs/performance.md`): the same operations on the
/// same values, so the same bits.
pub trait KernelKind {
    /// [`Stencil::of`] for this kernel.
    fn stencil(xg: Vector3<f32>) -> Stencil;
}

/// [`Kernel::QuadraticBspline`] as a [`KernelKind`].
pub struct QuadraticBsplineKernel;

impl KernelKind for QuadraticBsplineKernel {
    #[inline(always)]
    fn stencil(xg: Vector3<f32>) -> Stencil {
        Stencil::new(xg)
    }
}

/// [`Kernel::Linear`] as a [`KernelKind`].
pub struct LinearKernel;

impl KernelKind for LinearKernel {
    #[inline(always)]
    fn stencil(xg: Vector3<f32>) -> Stencil {
        Stencil::linear(xg)
    }
}

impl Stencil {
    /// The stencil of a particle at `xg` (grid units) for `kernel`.
    #[inline(always)]
    pub fn of(kernel: Kernel, xg: Vector3<f32>) -> Self {
        match kernel {
            Kernel::QuadraticBspline => Self::new(xg),
            Kernel::Linear => Self::linear(xg),
        }
    }

    /// The linear hat's weights on the quadratic stencil's 3-node window (`fx` in [0.5, 1.5)):
    /// `1 - |fx - n|` on the two nodes around the particle, zero on the third.
    pub fn linear(xg: Vector3<f32>) -> Self {
        let mut stencil = Self::new(xg);
        for axis in 0..3 {
            let f = stencil.fx[axis];
            stencil.weights[axis] = [0, 1, 2].map(|n| (1.0 - (f - n as f32).abs()).max(0.0));
            let frac = f - f.floor();
            stencil.inverse_moment[axis] = 1.0 / (frac * (1.0 - frac)).max(MIN_LINEAR_MOMENT);
        }
        stencil
    }

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
        Stencil {
            base,
            fx,
            weights,
            inverse_moment: Vector3::repeat(4.0),
        }
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

    /// The linear hat: weights sum to one with zero first moment, and `w D^-1 (x_i - x_p)`
    /// along an axis is the hat's gradient, -1 and +1 (in 1/cells) on the two nodes around the
    /// particle.
    #[test]
    fn linear_hat_weights_and_gradient() {
        let mut rng = SmallRng::seed_from_u64(11);
        for _ in 0..1000 {
            let xg = Vector3::from_fn(|_, _| rng.random_range(-50.0..50.0f32));
            let s = Stencil::linear(xg);
            for axis in 0..3 {
                let w = s.weights[axis];
                let d = [0.0f32, 1.0, 2.0].map(|n| n - s.fx[axis]);
                assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
                let first: f32 = w.iter().zip(&d).map(|(w, d)| w * d).sum();
                assert!(first.abs() < 1e-5, "first moment {first}");
                // Within MIN_LINEAR_MOMENT (about 1e-4 cells) of a node plane the moment is
                // clamped and the gradient shrinks.
                let frac = s.fx[axis] - s.fx[axis].floor();
                if frac.min(1.0 - frac) < 2.0 * MIN_LINEAR_MOMENT {
                    continue;
                }
                let gradient: Vec<f32> = w
                    .iter()
                    .zip(&d)
                    .filter(|(&w, _)| w > 1e-3)
                    .map(|(w, d)| w * d * s.inverse_moment[axis])
                    .collect();
                for g in &gradient {
                    assert!(
                        (g.abs() - 1.0).abs() < 2e-2,
                        "gradient {gradient:?} at {xg}"
                    );
                }
            }
        }
    }
}
