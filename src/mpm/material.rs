//! Constitutive models: Drucker-Prager sand on Hencky St. Venant-Kirchhoff elasticity, and
//! fixed-corotated elasticity for elastic test bodies.
//!
//! Every model works on the elastic deformation gradient `F` (dimensionless) of a particle and
//! gives the Kirchhoff stress `tau = J sigma` (Pa), which is what MLS-MPM's P2G needs
//! (`docs/physics.md`, sections 1-2). Both stresses have the form `tau = U diag(t) U^T` from the
//! rotation-variant SVD `F = U diag(sigma) V^T` ([`svd3`]), so they are symmetric bit for bit.
//!
//! References:
//! - Klar, Gast, Pradhana, Fu, Schroeder, Jiang, Teran 2016, "Drucker-Prager elastoplasticity
//!   for sand animation" (Hencky St. Venant-Kirchhoff energy, principal-space return mapping).
//! - Tampubolon, Gast, Klar, Fu, Teran, Jiang, Museth 2017, "Multi-species simulation of porous
//!   sand and water mixtures" (volume correction).
//! - Stomakhin, Schroeder, Chai, Teran, Selle 2013, "A material point method for snow
//!   simulation" (fixed-corotated energy).
//! - Mast et al. 2014 and Gao, Tampubolon, Jiang, Sifakis 2017, "An adaptive generalized
//!   interpolation material point method for simulating elastoplastic materials" (Hencky StVK
//!   with Drucker-Prager in MPM).

use crate::mpm::simd::{array3, exp, ln, mat3, Lanes, Wide};
use crate::mpm::svd::{svd_lanes, Frame, Mat, COLD_START};
use nalgebra::{Matrix3, Vector3};

/// Floor on singular values before taking logarithms (dimensionless): a particle compressed
/// below this stretch, or inverted (negative `sigma[2]` of the rotation-variant SVD, whose
/// absolute value is used), is treated as stretched by this much. ln(1e-6) = -13.8.
pub const MIN_SINGULAR_VALUE: f32 = 1e-6;

/// Lamé parameters (Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lame {
    /// Shear modulus mu (Pa).
    pub mu: f32,
    /// First Lamé parameter lambda (Pa).
    pub lambda: f32,
}

impl Lame {
    /// From Young's modulus E (Pa) and Poisson's ratio nu (dimensionless, -1 < nu < 0.5):
    /// `mu = E / (2 (1 + nu))`, `lambda = E nu / ((1 + nu) (1 - 2 nu))`.
    pub fn from_young_poisson(youngs_modulus_pa: f32, poisson_ratio: f32) -> Self {
        let (e, nu) = (youngs_modulus_pa, poisson_ratio);
        Self {
            mu: e / (2.0 * (1.0 + nu)),
            lambda: e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        }
    }
}

/// Drucker-Prager sand on Hencky St. Venant-Kirchhoff elasticity (Klar et al. 2016), cohesionless,
/// with optional volume correction (Tampubolon et al. 2017).
#[derive(Clone, Copy, Debug)]
pub struct DruckerPrager {
    /// Elastic moduli (Pa).
    pub lame: Lame,
    /// cone slope alpha (dimensionless), from the friction angle phi and the cone's fit
    /// ([`YieldCone::alpha`]).
    pub alpha: f32,
    /// Remember the volume removed by projections to the cone tip and give it back on later
    /// compression, so sand does not gain volume every time it is pulled apart.
    pub volume_correction: bool,
    /// Viscosity eta (Pa s, >= 0) of the sand inside its cone: a particle whose return mapping
    /// changed nothing adds the Kelvin-Voigt stress `J eta (L + L^T)` (L the velocity gradient)
    /// to its Kirchhoff stress, cut where needed to keep the total inside the cone
    /// (docs/physics.md, "Materials"). Damps elastic vibration; yielding sand does not see it.
    /// Only [`Constitutive::update_lanes_of`], which knows L, applies it.
    pub elastic_viscosity_pa_s: f32,
}

/// Where the Drucker-Prager cone meets Mohr-Coulomb's pyramid of the same friction angle phi
/// (docs/physics.md, "The yield cone's fit"). A round cone cannot match the six-sided pyramid in
/// every state of stress; the fit says in which it gives Mohr-Coulomb's strength.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum YieldCone {
    /// Through the pyramid's compression corners (Klar et al. 2016, the MLS-MPM paper):
    /// `alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi))`. Right in triaxial compression; in plane
    /// strain it is stronger than Mohr-Coulomb, and from phi = 42.2 deg on it admits, at any
    /// magnitude, the stress of sand pushed sideways against a free surface (one principal
    /// stress zero, the intermediate one the mean of the others), where Mohr-Coulomb has no
    /// strength at all.
    #[default]
    TriaxialCompression,
    /// Mohr-Coulomb's strength in plane strain with this model's plastic flow (deviatoric, no
    /// plastic volume change, so the intermediate stress is the mean of the other two):
    /// `alpha = sqrt(2) sin(phi) / 3`. Bodies ploughing sand near its surface meet a resistance
    /// bounded by the friction angle, not by the sand's elastic stiffness.
    PlaneStrain,
}

impl YieldCone {
    /// The cone slope alpha (dimensionless) for a friction angle (rad): the cone is
    /// `|dev tau| + alpha tr(tau) <= 0` in Kirchhoff stress tau.
    pub fn alpha(self, friction_angle_rad: f32) -> f32 {
        let sin_phi = libm::sinf(friction_angle_rad);
        match self {
            Self::TriaxialCompression => (2.0f32 / 3.0).sqrt() * 2.0 * sin_phi / (3.0 - sin_phi),
            Self::PlaneStrain => 2.0f32.sqrt() * sin_phi / 3.0,
        }
    }
}

impl DruckerPrager {
    /// `friction_angle_rad`: internal friction angle phi (rad), typically 30-40 deg for sand;
    /// the cone fitted in triaxial compression (Klar et al. 2016).
    pub fn new(lame: Lame, friction_angle_rad: f32, volume_correction: bool) -> Self {
        Self::with_cone(
            lame,
            friction_angle_rad,
            YieldCone::TriaxialCompression,
            volume_correction,
        )
    }

    /// As [`DruckerPrager::new`], with the cone fitted as `cone` says.
    pub fn with_cone(
        lame: Lame,
        friction_angle_rad: f32,
        cone: YieldCone,
        volume_correction: bool,
    ) -> Self {
        Self {
            lame,
            alpha: cone.alpha(friction_angle_rad),
            volume_correction,
            elastic_viscosity_pa_s: 0.0,
        }
    }
}

/// Fixed-corotated elasticity (elastic test bodies; Stomakhin et al. 2013):
/// `Psi = mu |F - R|^2 + lambda/2 (J - 1)^2`.
#[derive(Clone, Copy, Debug)]
pub struct FixedCorotated {
    /// Elastic moduli (Pa).
    pub lame: Lame,
}

/// The constitutive model of a particle set.
#[derive(Clone, Copy, Debug)]
pub enum Constitutive {
    DruckerPrager(DruckerPrager),
    FixedCorotated(FixedCorotated),
}

impl Constitutive {
    /// End-of-substep constitutive update of one particle: projects the trial elastic deformation
    /// gradient `f` in place onto the admissible set (plasticity; no-op for elastic), updates the
    /// volume-correction scalar `volume_correction` (log-volume, sand only; untouched otherwise),
    /// and returns the Kirchhoff stress tau (Pa) of the projected F. One SVD per call, warm-started
    /// from the particle's Jacobi `frame` (see [`svd3_warm`]), which it updates.
    ///
    /// Sand: `F <- U exp(eps) V^T` with `eps` from [`drucker_prager_return`]; `f` is left bit for
    /// bit unchanged when the return mapping changes nothing (inside the cone, no stored volume).
    /// The projected F always has positive singular values, so an inverted particle is restored.
    /// With volume correction off the scalar is set to 0. No viscous stress (no velocity
    /// gradient here): [`Self::update_lanes_of`] adds it.
    pub fn update(
        &self,
        f: &mut Matrix3<f32>,
        volume_correction: &mut f32,
        frame: &mut Frame,
    ) -> Matrix3<f32> {
        let out = self.update_lanes(
            &mat3!(i, j => Wide::<1>::splat(f[(i, j)])),
            Wide::splat(*volume_correction),
            frame.map(Wide::splat),
        );
        *f = Matrix3::from_fn(|i, j| out.f[i][j].lane(0));
        *volume_correction = out.volume_correction.lane(0);
        *frame = out.frame.map(|q| q.lane(0));
        Matrix3::from_fn(|i, j| out.tau[i][j].lane(0))
    }

    /// The substep's deformation update of `N` particles at once: `f` holds F at the start of
    /// the substep and `step` = dt grad v (MLS-MPM: dt C_p) over the substep `dt_s` (s); the
    /// trial `F = (I + step) F` is formed and then updated as by [`Self::update`], and sand
    /// inside its cone adds its viscous stress ([`DruckerPrager::elastic_viscosity_pa_s`]).
    /// Each lane is the same bits at any `N`.
    #[inline(always)]
    pub fn update_lanes_of<const N: usize>(
        &self,
        step: &[Matrix3<f32>; N],
        f: &mut [Matrix3<f32>; N],
        volume_correction: &mut [f32; N],
        frames: &mut [Frame; N],
        dt_s: f32,
    ) -> [Matrix3<f32>; N]
    where
        Wide<N>: Lanes,
    {
        let step = mat3!(i, j => Wide::<N>::from_fn(|l| step[l][(i, j)]));
        let f_old = mat3!(i, j => Wide::<N>::from_fn(|l| f[l][(i, j)]));
        let one = Wide::splat(1.0);
        // (I + step) F, row i of the identity contributing F's row i.
        let f_trial = mat3!(i, j => {
            let a = array3!(k => if i == k { one + step[i][k] } else { step[i][k] });
            Wide::splat(0.0) + a[0] * f_old[0][j] + a[1] * f_old[1][j] + a[2] * f_old[2][j]
        });
        // Written out, as the sweep's select in `svd.rs` (a loop kept them in memory).
        let [qx, qy, qz] = array3!(k => Wide::from_fn(|l| frames[l][k]));
        let out = self.update_lanes(
            &f_trial,
            Wide::from_fn(|l| volume_correction[l]),
            [qx, qy, qz, Wide::from_fn(|l| frames[l][3])],
        );
        let tau = match (self, out.in_cone) {
            (Self::DruckerPrager(dp), Some(in_cone))
                if dp.elastic_viscosity_pa_s > 0.0 && dt_s > 0.0 =>
            {
                let viscous = viscous_stress_in_cone(dp, &out.tau, &step, dt_s, &in_cone);
                mat3!(i, j => out.tau[i][j] + viscous[i][j])
            }
            _ => out.tau,
        };
        for l in 0..N {
            f[l] = Matrix3::from_fn(|i, j| out.f[i][j].lane(l));
            volume_correction[l] = out.volume_correction.lane(l);
            frames[l] = out.frame.map(|q| q.lane(l));
        }
        std::array::from_fn(|l| Matrix3::from_fn(|i, j| tau[i][j].lane(l)))
    }

    /// Kirchhoff stress (Pa) of a given F without any projection (used at initialisation).
    ///
    /// Hencky StVK: `tau = U diag(2 mu eps + lambda tr(eps)) U^T`, `eps = ln max(|sigma|, floor)`.
    /// Fixed corotated: `tau = 2 mu (F - R) F^T + lambda (J - 1) J I` with `R = U V^T`, `J = det F`,
    /// evaluated as `U diag(2 mu (sigma - 1) sigma + lambda (J - 1) J) U^T` (the same tensor).
    pub fn kirchhoff_stress(&self, f: &Matrix3<f32>) -> Matrix3<f32> {
        let svd = svd_lanes(
            &mat3!(i, j => Wide::<1>::splat(f[(i, j)])),
            COLD_START.map(Wide::splat),
        );
        let principal = match self {
            Self::DruckerPrager(dp) => hencky_stress(dp.lame, hencky_strain(svd.sigma)),
            Self::FixedCorotated(fc) => corotated_stress(fc.lame, svd.sigma),
        };
        let tau = principal_to_tensor(&svd.u, principal);
        Matrix3::from_fn(|i, j| tau[i][j].lane(0))
    }

    /// The update on every lane: SVD, return mapping, projected F and stress, all lane-wise.
    #[inline(always)]
    fn update_lanes<L: Lanes>(
        &self,
        f: &Mat<L>,
        volume_correction: L,
        frame: [L; 4],
    ) -> LaneUpdate<L> {
        let svd = svd_lanes(f, frame);
        let (f, tau, volume_correction, in_cone) = match self {
            Self::FixedCorotated(fc) => {
                let tau = principal_to_tensor(&svd.u, corotated_stress(fc.lame, svd.sigma));
                (*f, tau, volume_correction, None)
            }
            Self::DruckerPrager(dp) => {
                let eps_trial = hencky_strain(svd.sigma);
                let (eps, vc) = drucker_prager_return_lanes(eps_trial, volume_correction, dp);
                // F <- U exp(eps) V^T, kept bit for bit where nothing changed.
                let stretch = array3!(k => exp(eps[k]));
                let rebuilt = mat3!(i, j => {
                    let uv = array3!(k => svd.u[i][k] * stretch[k] * svd.v[j][k]);
                    uv[0] + uv[1] + uv[2]
                });
                let not_floored = L::splat(MIN_SINGULAR_VALUE)
                    .lt(svd.sigma[2])
                    .or(svd.sigma[2].eq(L::splat(MIN_SINGULAR_VALUE)));
                let same = array3!(k => eps[k].eq(eps_trial[k]));
                let unchanged = not_floored.and(same[0]).and(same[1]).and(same[2]);
                let f = mat3!(i, j => L::select(unchanged, f[i][j], rebuilt[i][j]));
                let tau = principal_to_tensor(&svd.u, hencky_stress(dp.lame, eps));
                let in_cone = InCone {
                    mask: unchanged,
                    log_jacobian: eps[0] + eps[1] + eps[2],
                };
                (f, tau, vc, Some(in_cone))
            }
        };
        LaneUpdate {
            f,
            tau,
            volume_correction,
            frame: svd.frame,
            in_cone,
        }
    }

    /// Elastic moduli of the model (Pa), e.g. for the time-step bound.
    pub fn lame(&self) -> Lame {
        match self {
            Self::DruckerPrager(dp) => dp.lame,
            Self::FixedCorotated(fc) => fc.lame,
        }
    }
}

/// Pure principal-space Drucker-Prager return mapping (for tests and reuse): given trial Hencky
/// strain `eps` (log of singular values) and the volume-correction scalar, returns the projected
/// strain and the new volume-correction value. Algorithm (physics.md section 2): eps += vc/3 if
/// volume correction is on; tr = sum eps; eps_hat = eps - tr/3; if tr >= 0 -> eps = 0 (tip);
/// else dgamma = |eps_hat| + (3 lambda + 2 mu)/(2 mu) * tr * alpha; dgamma <= 0 -> unchanged;
/// else eps -= dgamma * eps_hat/|eps_hat|. New vc = vc + log det(F_trial) - log det(F_new)
/// = vc + sum(eps_trial_original) - sum(eps_new) when volume correction is on, else 0.
///
/// Consequences: vc grows only at the tip (by the volume gain of the expansion) and is consumed
/// entirely by the next update that ends inside or on the side of the cone.
pub fn drucker_prager_return(
    eps: Vector3<f32>,
    volume_correction: f32,
    lame: Lame,
    alpha: f32,
    use_volume_correction: bool,
) -> (Vector3<f32>, f32) {
    let eps_trial = eps;
    let eps = if use_volume_correction {
        eps.add_scalar(volume_correction / 3.0)
    } else {
        eps
    };
    let tr = eps.sum();
    let projected = if tr >= 0.0 {
        Vector3::zeros()
    } else {
        let eps_hat = eps.add_scalar(-tr / 3.0);
        let eps_hat_norm = eps_hat.norm();
        let dgamma =
            eps_hat_norm + (3.0 * lame.lambda + 2.0 * lame.mu) / (2.0 * lame.mu) * tr * alpha;
        if dgamma <= 0.0 {
            eps
        } else {
            eps - eps_hat * (dgamma / eps_hat_norm)
        }
    };
    let vc = if use_volume_correction {
        volume_correction + eps_trial.sum() - projected.sum()
    } else {
        0.0
    };
    (projected, vc)
}

/// [`drucker_prager_return`] on every lane (the same operations, as lane-wise selects).
#[inline(always)]
fn drucker_prager_return_lanes<L: Lanes>(
    eps_trial: [L; 3],
    volume_correction: L,
    dp: &DruckerPrager,
) -> ([L; 3], L) {
    let zero = L::splat(0.0);
    let three = L::splat(3.0);
    let eps = if dp.volume_correction {
        let shift = volume_correction / three;
        array3!(k => eps_trial[k] + shift)
    } else {
        eps_trial
    };
    let tr = eps[0] + eps[1] + eps[2];
    let mean = tr / three;
    let eps_hat = array3!(k => eps[k] - mean);
    let eps_hat_norm =
        (eps_hat[0] * eps_hat[0] + eps_hat[1] * eps_hat[1] + eps_hat[2] * eps_hat[2]).sqrt();
    let Lame { mu, lambda } = dp.lame;
    let dgamma =
        eps_hat_norm + L::splat((3.0 * lambda + 2.0 * mu) / (2.0 * mu)) * tr * L::splat(dp.alpha);
    // Division by a zero norm only happens in lanes the selects discard.
    let shear = dgamma / eps_hat_norm;
    let (compressed, yielding) = (tr.lt(zero), zero.lt(dgamma));
    let projected: [L; 3] = array3!(k => {
        let on_cone = L::select(yielding, eps[k] - eps_hat[k] * shear, eps[k]);
        L::select(compressed, on_cone, zero)
    });
    let vc = if dp.volume_correction {
        volume_correction + (eps_trial[0] + eps_trial[1] + eps_trial[2])
            - (projected[0] + projected[1] + projected[2])
    } else {
        zero
    };
    (projected, vc)
}

/// The result of [`Constitutive::update_lanes`].
struct LaneUpdate<L> {
    f: Mat<L>,
    /// Kirchhoff stress (Pa).
    tau: Mat<L>,
    volume_correction: L,
    frame: [L; 4],
    /// Sand only: the lanes its return mapping left unchanged.
    in_cone: Option<InCone<L>>,
}

/// The lanes of a Drucker-Prager update inside the cone, for the in-cone viscosity.
#[derive(Clone, Copy)]
struct InCone<L> {
    /// All ones where the return mapping changed nothing.
    mask: L,
    /// ln J = tr(eps) of the updated F (the exponential only where the viscosity needs it).
    log_jacobian: L,
}

/// The in-cone viscous stress (Pa) of one substep: `s J eta (L + L^T)` with `L = step / dt`
/// where the return mapping changed nothing and the sand is under pressure, zero elsewhere.
/// `s` is the largest share in [0, 1] that keeps the total stress `tau_e + s tau_v` inside the
/// cone `f(tau) = |dev tau| + alpha tr(tau) <= 0`, so the viscosity never puts sand in tension
/// nor beyond its friction (docs/physics.md, "Materials"). `f(tau_e + s tau_v)` is convex in
/// `s` and `<= 0` at 0, so `s` is 1 or the first positive root of
/// `A s^2 + 2 B s - R = 0`, i.e. `|a + s b|^2 = alpha^2 (t_e + s t_v)^2` (`a`, `b` the
/// deviators, `t` the traces; `A = |b|^2 - alpha^2 t_v^2`, `B = a:b - alpha^2 t_e t_v`, the
/// room `R = alpha^2 t_e^2 - |a|^2 >= 0`): `R / (B + sqrt(B^2 + A R))` where `tau_v` points
/// outwards (`B > 0`), `(sqrt(B^2 + A R) - B) / A` where it points inwards and `A > 0`, none
/// otherwise; each form free of cancellation. `R`, and with it `B^2 + A R`, is clamped at 0:
/// the strain-space mask can admit a state the f32 stress puts on the cone's far side of 0.
#[inline(always)]
fn viscous_stress_in_cone<L: Lanes>(
    dp: &DruckerPrager,
    elastic: &Mat<L>,
    step: &Mat<L>,
    dt_s: f32,
    in_cone: &InCone<L>,
) -> Mat<L> {
    let zero = L::splat(0.0);
    let scale = exp(in_cone.log_jacobian) * L::splat(dp.elastic_viscosity_pa_s / dt_s);
    let viscous = mat3!(i, j => scale * (step[i][j] + step[j][i]));
    let (a, t_e) = deviator_and_trace(elastic);
    let (b, t_v) = deviator_and_trace(&viscous);
    let alpha_squared = L::splat(dp.alpha * dp.alpha);
    let quadratic = contract(&b, &b) - alpha_squared * t_v * t_v; // A
    let linear = contract(&a, &b) - alpha_squared * t_e * t_v; // B
    let room = (alpha_squared * t_e * t_e - contract(&a, &a)).max(zero); // R
    let root = (linear * linear + quadratic * room).max(zero).sqrt();
    let outwards = zero.lt(linear);
    let first_root = L::select(
        outwards,
        room / (linear + root),
        (root - linear) / quadratic,
    );
    let crosses = L::select(
        outwards,
        room.lt(linear + root),
        zero.lt(quadratic).and((root - linear).lt(quadratic)),
    );
    let share = L::select(crosses, first_root, L::splat(1.0));
    // At the cone's apex (no pressure) the sand carries no stress, viscous or not.
    let acting = L::select(in_cone.mask.and(t_e.lt(zero)), share, zero);
    mat3!(i, j => acting * viscous[i][j])
}

/// The deviator and the trace of a symmetric 3x3 tensor.
#[inline(always)]
fn deviator_and_trace<L: Lanes>(m: &Mat<L>) -> (Mat<L>, L) {
    let trace = m[0][0] + m[1][1] + m[2][2];
    let mean = trace / L::splat(3.0);
    (
        mat3!(i, j => if i == j { m[i][j] - mean } else { m[i][j] }),
        trace,
    )
}

/// `a : b`, the sum of the products of the entries.
#[inline(always)]
fn contract<L: Lanes>(a: &Mat<L>, b: &Mat<L>) -> L {
    let rows = array3!(i => a[i][0] * b[i][0] + a[i][1] * b[i][1] + a[i][2] * b[i][2]);
    rows[0] + rows[1] + rows[2]
}

/// Hencky strain `ln max(|sigma|, MIN_SINGULAR_VALUE)` of singular values.
#[inline(always)]
fn hencky_strain<L: Lanes>(sigma: [L; 3]) -> [L; 3] {
    array3!(k => ln(sigma[k].abs().max(L::splat(MIN_SINGULAR_VALUE))))
}

/// Principal Kirchhoff stresses (Pa) of Hencky StVK: `2 mu eps + lambda tr(eps)`.
#[inline(always)]
fn hencky_stress<L: Lanes>(lame: Lame, eps: [L; 3]) -> [L; 3] {
    let volumetric = L::splat(lame.lambda) * (eps[0] + eps[1] + eps[2]);
    array3!(k => L::splat(2.0 * lame.mu) * eps[k] + volumetric)
}

/// Principal Kirchhoff stresses (Pa) of fixed corotated: `2 mu (sigma - 1) sigma + lambda (J - 1) J`.
#[inline(always)]
fn corotated_stress<L: Lanes>(lame: Lame, sigma: [L; 3]) -> [L; 3] {
    let j = sigma[0] * sigma[1] * sigma[2];
    let one = L::splat(1.0);
    let volumetric = L::splat(lame.lambda) * (j - one) * j;
    array3!(k => L::splat(2.0 * lame.mu) * (sigma[k] - one) * sigma[k] + volumetric)
}

/// `U diag(t) U^T`, computed on one triangle and mirrored (exactly symmetric).
#[inline(always)]
fn principal_to_tensor<L: Lanes>(u: &Mat<L>, t: [L; 3]) -> Mat<L> {
    // All nine formed, the lower three unused (the compiler drops them).
    let upper = mat3!(i, j => {
        u[i][0] * t[0] * u[j][0] + u[i][1] * t[1] * u[j][1] + u[i][2] * t[2] * u[j][2]
    });
    [
        [upper[0][0], upper[0][1], upper[0][2]],
        [upper[0][1], upper[1][1], upper[1][2]],
        [upper[0][2], upper[1][2], upper[2][2]],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpm::svd::{svd3, svd3_warm};
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    const PHI: f32 = 35.0 * std::f32::consts::PI / 180.0;

    fn lame() -> Lame {
        Lame::from_young_poisson(3.5e5, 0.3)
    }

    fn sand(volume_correction: bool) -> Constitutive {
        Constitutive::DruckerPrager(DruckerPrager::new(lame(), PHI, volume_correction))
    }

    fn jello() -> Constitutive {
        Constitutive::FixedCorotated(FixedCorotated { lame: lame() })
    }

    fn rotation(rng: &mut SmallRng) -> Matrix3<f32> {
        let q = nalgebra::Quaternion::from(nalgebra::Vector4::from_fn(|_, _| {
            rng.sample::<f32, _>(StandardNormal)
        }));
        *nalgebra::UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .matrix()
    }

    fn gaussian(rng: &mut SmallRng) -> Matrix3<f32> {
        Matrix3::from_fn(|_, _| rng.sample(StandardNormal))
    }

    fn random_strain(rng: &mut SmallRng, amp: f32) -> Vector3<f32> {
        Vector3::from_fn(|_, _| rng.random_range(-amp..amp))
    }

    /// Cone function: <= 0 inside, 0 on the cone.
    fn yield_value(eps: &Vector3<f32>, l: Lame, alpha: f32) -> f32 {
        let tr = eps.sum();
        eps.add_scalar(-tr / 3.0).norm() + (3.0 * l.lambda + 2.0 * l.mu) / (2.0 * l.mu) * tr * alpha
    }

    /// The cone function in Kirchhoff stress, `|dev tau| + alpha tr(tau)` (Pa): <= 0 inside.
    fn stress_cone_value(tau: &Matrix3<f32>, alpha: f32) -> f32 {
        let mean = tau.trace() / 3.0;
        (tau - Matrix3::identity() * mean).norm() + alpha * tau.trace()
    }

    /// Mohr-Coulomb in plane strain with deviatoric flow: principal stresses (compression
    /// negative) `s1 <= s2 = (s1 + s3)/2 <= s3` at the limit `(s3 - s1) = -(s1 + s3) sin(phi)`.
    fn plane_strain_limit(phi: f32, mean_pa: f32) -> Matrix3<f32> {
        let radius = mean_pa * libm::sinf(phi);
        Matrix3::from_diagonal(&Vector3::new(
            -mean_pa - radius,
            -mean_pa,
            -mean_pa + radius,
        ))
    }

    #[test]
    fn plane_strain_cone_holds_mohr_coulomb_plane_strain_limit() {
        for phi_deg in [20.0f32, 30.0, 35.0, 45.0] {
            let phi = phi_deg.to_radians();
            let alpha = YieldCone::PlaneStrain.alpha(phi);
            let on_limit = plane_strain_limit(phi, 1000.0);
            // On the cone (to rounding), and 1 % more shear is outside it.
            assert!(
                stress_cone_value(&on_limit, alpha).abs() < 1e-3,
                "{phi_deg} deg"
            );
            let beyond = on_limit
                + Matrix3::from_diagonal(&Vector3::new(-1.0, 0.0, 1.0)) * (10.0 * libm::sinf(phi));
            assert!(stress_cone_value(&beyond, alpha) > 0.0, "{phi_deg} deg");
            // The triaxial-compression cone is the wider one in plane strain.
            assert!(
                YieldCone::TriaxialCompression.alpha(phi) > alpha,
                "{phi_deg} deg"
            );
        }
    }

    /// Sand pushed sideways against a free surface: principal stresses `(-s, -s/2, 0)`. Mohr-
    /// Coulomb gives it no strength; the triaxial-compression cone holds it at 45 deg (at any
    /// magnitude `s`), from 42.2 deg on; the plane-strain cone never.
    #[test]
    fn triaxial_cone_holds_a_free_surface_pushed_sideways_from_42_deg() {
        let pushed = Matrix3::from_diagonal(&Vector3::new(-1000.0, -500.0, 0.0));
        let holds = |cone: YieldCone, deg: f32| {
            stress_cone_value(&pushed, cone.alpha(deg.to_radians())) <= 0.0
        };
        assert!(holds(YieldCone::TriaxialCompression, 45.0));
        assert!(holds(YieldCone::TriaxialCompression, 42.3));
        assert!(!holds(YieldCone::TriaxialCompression, 42.1));
        assert!(!holds(YieldCone::TriaxialCompression, 35.0));
        for deg in [30.0, 45.0, 60.0, 80.0] {
            assert!(!holds(YieldCone::PlaneStrain, deg), "{deg} deg");
        }
    }

    #[test]
    fn lame_from_young_poisson() {
        let l = Lame::from_young_poisson(1e6, 0.3);
        assert!((l.mu - 1e6 / 2.6).abs() < 1e-6 * l.mu, "{l:?}");
        assert!(
            (l.lambda - 0.3e6 / (1.3 * 0.4)).abs() < 1e-6 * l.lambda,
            "{l:?}"
        );
        let alpha = DruckerPrager::new(l, PHI, true).alpha as f64;
        let sin = (PHI as f64).sin();
        assert!((alpha - (2.0f64 / 3.0).sqrt() * 2.0 * sin / (3.0 - sin)).abs() < 1e-6);
        assert_eq!(sand(true).lame(), lame());
        assert_eq!(jello().lame(), lame());
    }

    #[test]
    fn return_mapping_lands_in_cone() {
        let mut rng = SmallRng::seed_from_u64(10);
        for i in 0..20_000 {
            let l =
                Lame::from_young_poisson(rng.random_range(1e4..1e8), rng.random_range(0.0..0.45));
            let alpha = DruckerPrager::new(l, rng.random_range(0.0..0.8), true).alpha;
            let eps = random_strain(&mut rng, [1e-3, 0.1, 1.0][i % 3]);
            let vc = if i % 2 == 0 {
                rng.random_range(0.0..0.3)
            } else {
                0.0
            };
            for use_vc in [false, true] {
                let (new, _) = drucker_prager_return(eps, vc, l, alpha, use_vc);
                let tol = 1e-6 * (1.0 + eps.norm() + vc);
                assert!(new.sum() <= tol, "{eps:?} -> {new:?}");
                assert!(yield_value(&new, l, alpha) <= tol, "{eps:?} -> {new:?}");
            }
        }
    }

    #[test]
    fn inside_cone_is_unchanged() {
        let l = lame();
        let alpha = DruckerPrager::new(l, PHI, true).alpha;
        let mut rng = SmallRng::seed_from_u64(11);
        let mut tested = 0;
        for _ in 0..20_000 {
            let eps = random_strain(&mut rng, 0.2);
            if eps.sum() >= 0.0 || yield_value(&eps, l, alpha) > -1e-4 {
                continue;
            }
            tested += 1;
            for use_vc in [false, true] {
                assert_eq!(
                    drucker_prager_return(eps, 0.0, l, alpha, use_vc),
                    (eps, 0.0)
                );
            }
        }
        assert!(tested > 1000, "{tested}");
    }

    #[test]
    fn expansion_goes_to_tip() {
        let l = lame();
        let alpha = DruckerPrager::new(l, PHI, true).alpha;
        let mut rng = SmallRng::seed_from_u64(12);
        let mut tested = 0;
        for _ in 0..10_000 {
            let eps = random_strain(&mut rng, 0.3);
            if eps.sum() < 0.0 {
                continue;
            }
            tested += 1;
            assert_eq!(
                drucker_prager_return(eps, 0.0, l, alpha, false),
                (Vector3::zeros(), 0.0)
            );
            let (new, vc) = drucker_prager_return(eps, 0.1, l, alpha, true);
            assert_eq!(new, Vector3::zeros());
            assert!((vc - (0.1 + eps.sum())).abs() < 1e-6, "{vc}");
        }
        assert!(tested > 1000, "{tested}");
        // Exactly hydrostatic zero strain is the tip itself.
        assert_eq!(
            drucker_prager_return(Vector3::zeros(), 0.0, l, alpha, false).0,
            Vector3::zeros()
        );
    }

    #[test]
    fn volume_correction_gives_volume_back() {
        let mut rng = SmallRng::seed_from_u64(13);
        let stretch = 1.05f32;
        for trial in 0..50 {
            let (r1, r2) = (rotation(&mut rng), rotation(&mut rng));
            let mut final_det = [0.0f32; 2];
            for (k, use_vc) in [false, true].into_iter().enumerate() {
                let model = sand(use_vc);
                let mut vc = 0.0;
                // Pull apart: lands on the tip, stores the volume gain 3 ln(stretch).
                let mut f = r1 * stretch;
                let tau = model.update(&mut f, &mut vc, &mut COLD_START.clone());
                assert!(tau.norm() < 1e-3, "{tau}");
                assert!((f.determinant() - 1.0).abs() < 1e-5);
                let expect_vc = if use_vc { 3.0 * stretch.ln() } else { 0.0 };
                assert!((vc - expect_vc).abs() < 1e-5, "{vc}");
                // Compress by the same amount, with a little shear.
                let shear = if trial % 2 == 0 { 0.0 } else { 0.01 };
                let mut g = Matrix3::identity();
                g[(0, 1)] = shear;
                f = r2 * g * f / stretch;
                model.update(&mut f, &mut vc, &mut COLD_START.clone());
                final_det[k] = f.determinant();
            }
            let [without, with] = final_det;
            assert!((with - 1.0).abs() < 1e-3, "with correction det F = {with}");
            assert!(
                (without - 1.0 / stretch.powi(3)).abs() < 1e-3,
                "without: {without}"
            );
            assert!(
                (1.0 - without) - (with - 1.0).abs() > 0.1,
                "{with} vs {without}"
            );
        }
    }

    #[test]
    fn elastic_update_and_rotations() {
        let mut rng = SmallRng::seed_from_u64(14);
        let l = lame();
        for _ in 0..2_000 {
            let f0 = rotation(&mut rng) * (Matrix3::identity() + 0.2 * gaussian(&mut rng));
            let (mut f, mut vc) = (f0, 0.25);
            let tau = jello().update(&mut f, &mut vc, &mut COLD_START.clone());
            assert_eq!(
                (f, vc),
                (f0, 0.25),
                "fixed corotated must not touch F or vc"
            );
            assert_eq!(tau, jello().kirchhoff_stress(&f0));
            for model in [jello(), sand(true)] {
                let tau = model.kirchhoff_stress(&f0);
                assert_eq!(tau, tau.transpose(), "stress must be symmetric");
                let r = rotation(&mut rng);
                let tau = model.kirchhoff_stress(&r);
                assert!(tau.norm() < 1e-5 * (l.mu + l.lambda), "{model:?} {tau}");
            }
            // A sand update of a rotation is a no-op with zero stress, up to rounding: the f32 SVD
            // of a rotation gives singular values within 5 ulps of 1 (6e-7; 1 ulp on average),
            // and vc sums their three logs.
            let r = rotation(&mut rng);
            let (mut f, mut vc) = (r, 0.0);
            let tau = sand(true).update(&mut f, &mut vc, &mut COLD_START.clone());
            assert!(
                tau.norm() < 1e-5 * (l.mu + l.lambda) && (f - r).norm() < 1e-6 && vc.abs() < 3e-6,
                "tau {tau} f - r {} vc {vc} svd {:?}",
                f - r,
                svd3(&r)
            );
        }
    }

    /// The in-cone viscosity adds `J eta (L + L^T)` where the return mapping changes nothing,
    /// and nothing where the sand yields.
    #[test]
    fn elastic_viscosity_acts_inside_the_cone_only() {
        let (eta, dt) = (50.0f32, 1e-4f32);
        let viscous = match sand(true) {
            Constitutive::DruckerPrager(dp) => Constitutive::DruckerPrager(DruckerPrager {
                elastic_viscosity_pa_s: eta,
                ..dp
            }),
            _ => unreachable!(),
        };
        let update = |model: &Constitutive, f0: Matrix3<f32>, l: Matrix3<f32>| {
            let (mut f, mut vc, mut frame) = ([f0], [0.0], [COLD_START]);
            let [tau] = model.update_lanes_of(&[l * dt], &mut f, &mut vc, &mut frame, dt);
            (tau, f[0])
        };
        // Compressed by 1 %, sheared slowly (1/s): inside the cone.
        let compressed = Matrix3::identity() * 0.99;
        let shear = Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.5);
        let (plain, f) = update(&sand(true), compressed, shear);
        let (damped, _) = update(&viscous, compressed, shear);
        let expected = (shear + shear.transpose()) * (eta * f.determinant());
        let error = (damped - plain - expected).norm() / expected.norm();
        assert!(
            error < 1e-3,
            "viscous stress {} against {expected}",
            damped - plain
        );
        // Sheared by 50 % in one step: the sand yields and sees no viscosity.
        let (plain, f_plain) = update(&sand(true), compressed, shear * (0.5 / dt));
        let (damped, f_damped) = update(&viscous, compressed, shear * (0.5 / dt));
        assert_ne!(
            f_plain,
            compressed * (Matrix3::identity() + shear * 0.5),
            "must yield"
        );
        assert_eq!((damped, f_damped), (plain, f_plain));
    }

    /// However fast the in-cone sand deforms, its viscous stress is cut to what keeps the total
    /// stress inside the cone: no tension, no shear beyond friction. Slow rates keep it whole.
    #[test]
    fn elastic_viscosity_keeps_the_stress_in_the_cone() {
        let dt = 1e-4f32;
        let Constitutive::DruckerPrager(dp) = sand(false) else {
            unreachable!()
        };
        let viscous = Constitutive::DruckerPrager(DruckerPrager {
            elastic_viscosity_pa_s: 1e4,
            ..dp
        });
        let outside = |tau: &Matrix3<f32>| stress_cone_value(tau, dp.alpha);
        let mut rng = SmallRng::seed_from_u64(19);
        let (mut capped, mut whole) = (0, 0);
        for i in 0..4_000 {
            // Compressed sand sheared within its cone, deformed at up to 10 / s.
            let strain = Vector3::new(-0.01, -0.01, -0.01) + random_strain(&mut rng, 0.004);
            let q = rotation(&mut rng);
            let f0 = q * Matrix3::from_diagonal(&strain.map(f32::exp)) * q.transpose();
            let rate = [0.01, 1.0, 10.0][i % 3];
            let l = gaussian(&mut rng) * rate;
            let (mut f, mut vc, mut frame) = ([f0], [0.0], [COLD_START]);
            let [tau] = viscous.update_lanes_of(&[l * dt], &mut f, &mut vc, &mut frame, dt);
            let elastic = viscous.kirchhoff_stress(&f[0]);
            if yield_value(&hencky_of(&f[0]), dp.lame, dp.alpha) > -1e-5 {
                continue; // on the cone: yielded this step, no viscosity
            }
            let full = (l + l.transpose()) * (1e4 * f[0].determinant());
            let added = tau - elastic;
            let scale = elastic.norm().max(full.norm());
            assert!(
                outside(&tau) <= 2e-5 * scale,
                "case {i}: total stress {tau} outside the cone by {} Pa",
                outside(&tau)
            );
            if (added - full).norm() <= 1e-3 * full.norm() {
                whole += 1;
            } else {
                capped += 1;
                // Cut, never turned: the same direction, a smaller size.
                let share = added.dot(&full) / full.norm_squared();
                assert!(
                    (0.0..1.0).contains(&share)
                        && (added - full * share).norm() <= 1e-3 * full.norm(),
                    "case {i}: viscous stress {added} is not a share of {full}"
                );
            }
        }
        assert!(
            capped > 100 && whole > 100,
            "capped {capped}, whole {whole}"
        );
    }

    /// The share of the viscous stress kept, in the cases where rounding or the cone's apex
    /// could mislead its closed form: states on the cone (and a rounding outside it), pointing
    /// out, in, and across; no pressure; radial unloading through the apex; a masked lane.
    #[test]
    fn viscous_share_at_the_cone_and_its_apex() {
        let Constitutive::DruckerPrager(dp) = sand(false) else {
            unreachable!()
        };
        let dp = DruckerPrager {
            elastic_viscosity_pa_s: 1e3,
            ..dp
        };
        let dt = 1e-4f32;
        let outside = |tau: &Matrix3<f32>| stress_cone_value(tau, dp.alpha);
        // The viscous stress kept for elastic stress `tau_e` and full viscous stress `tau_v`.
        let kept = |tau_e: Matrix3<f32>, tau_v: Matrix3<f32>, in_mask: bool| {
            let wide = |m: Matrix3<f32>| mat3!(i, j => Wide::<1>::splat(m[(i, j)]));
            let zero = Wide::<1>::splat(0.0);
            let in_cone = InCone {
                mask: if in_mask {
                    zero.eq(zero)
                } else {
                    zero.lt(zero)
                },
                log_jacobian: zero,
            };
            let step = tau_v * (dt / (2.0 * dp.elastic_viscosity_pa_s));
            let added = viscous_stress_in_cone(&dp, &wide(tau_e), &wide(step), dt, &in_cone);
            Matrix3::from_fn(|i, j| added[i][j].lane(0))
        };
        let pressure = 1e3f32;
        let shear = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, 0.0)) / 2f32.sqrt();
        let on_cone = Matrix3::identity() * -pressure + shear * (3.0 * dp.alpha * pressure);
        let just_outside =
            Matrix3::identity() * -pressure + shear * (3.0 * dp.alpha * pressure * (1.0 + 1e-6));
        let inside = Matrix3::identity() * -pressure + shear * (1.5 * dp.alpha * pressure);
        let cases = [
            (
                "on the cone, out along the shear",
                on_cone,
                shear * 100.0,
                0.0,
            ),
            (
                "rounding outside, out along the shear",
                just_outside,
                shear * 100.0,
                0.0,
            ),
            (
                "on the cone, compressed a little",
                on_cone,
                Matrix3::identity() * -100.0,
                1.0,
            ),
            (
                "on the cone, compressed much",
                on_cone,
                Matrix3::identity() * -1e5,
                1.0,
            ),
            (
                "rounding outside, compressed",
                just_outside,
                Matrix3::identity() * -100.0,
                1.0,
            ),
            // |1 - 3 s| |d| <= 3 alpha p: across the axis and out on the far side at s = 2/3.
            (
                "on the cone, sheared across",
                on_cone,
                shear * (-9.0 * dp.alpha * pressure),
                2.0 / 3.0,
            ),
            (
                "no pressure, pulled apart",
                Matrix3::zeros(),
                Matrix3::identity() * 100.0,
                0.0,
            ),
            ("unloading through the apex", inside, inside * -2.0, 0.5),
        ];
        for (name, tau_e, tau_v, expected) in cases {
            let added = kept(tau_e, tau_v, true);
            let share = added.dot(&tau_v) / tau_v.norm_squared();
            let scale = tau_e.norm().max(tau_v.norm());
            assert!(
                (share - expected).abs() < 1e-4 && (added - tau_v * share).norm() < 1e-5 * scale,
                "{name}: kept {added} of {tau_v}, share {share}, expected {expected}"
            );
            assert!(
                outside(&(tau_e + added)) <= 1e-5 * scale.max(outside(&tau_e)),
                "{name}: total {} outside the cone by {} Pa",
                tau_e + added,
                outside(&(tau_e + added))
            );
        }
        let masked = kept(inside, Matrix3::identity() * -100.0, false);
        assert_eq!(
            masked,
            Matrix3::zeros(),
            "a yielding lane keeps no viscosity"
        );
    }

    fn hencky_of(f: &Matrix3<f32>) -> Vector3<f32> {
        svd3(f).sigma.map(|s| s.abs().ln())
    }

    #[test]
    fn small_stretch_matches_linear_elasticity() {
        let l = lame();
        for model in [jello(), sand(false)] {
            for axis in 0..3 {
                for delta in [5e-4f32, -5e-4] {
                    let mut f = Matrix3::identity();
                    f[(axis, axis)] += delta;
                    // Linear elasticity on the small strain of this (f32) F, in f64.
                    let e = f.cast::<f64>() - Matrix3::identity();
                    let linear = Matrix3::identity() * (l.lambda as f64 * e.trace())
                        + e * (2.0 * l.mu as f64);
                    let tau = model.kirchhoff_stress(&f).cast::<f64>();
                    let rel = (tau - linear).norm() / linear.norm();
                    assert!(rel < 1e-3, "{model:?} delta {delta}: relative error {rel}");
                }
            }
            // Stretches along arbitrary directions: the same stress, rotated (objectivity).
            let mut rng = SmallRng::seed_from_u64(15);
            let f = Matrix3::from_diagonal(&Vector3::new(1.002, 1.0, 1.0));
            let tau = model.kirchhoff_stress(&f);
            for _ in 0..200 {
                let q = rotation(&mut rng);
                let rotated = model.kirchhoff_stress(&(q * f * q.transpose()));
                let rel = (rotated - q * tau * q.transpose()).norm() / tau.norm();
                assert!(rel < 1e-3, "{model:?}: relative error {rel}");
            }
        }
    }

    #[test]
    fn sand_update_is_consistent() {
        // The updated F lies in the cone, and the returned stress is the stress of that F.
        let mut rng = SmallRng::seed_from_u64(16);
        let model = sand(true);
        let Constitutive::DruckerPrager(dp) = model else {
            unreachable!()
        };
        for i in 0..5_000 {
            let amp = [0.01, 0.1, 0.3][i % 3];
            let f0 = rotation(&mut rng) * (Matrix3::identity() + amp * gaussian(&mut rng));
            let (mut f, mut vc) = (f0, if i % 2 == 0 { 0.05 } else { 0.0 });
            let tau = model.update(&mut f, &mut vc, &mut COLD_START.clone());
            assert!(vc >= -1e-6 && f.iter().all(|x| x.is_finite()));
            let eps = svd3(&f).sigma.map(|s| s.abs().max(MIN_SINGULAR_VALUE).ln());
            assert!(
                eps.sum() <= 1e-5 && yield_value(&eps, dp.lame, dp.alpha) <= 1e-5,
                "{eps:?}"
            );
            let again = model.kirchhoff_stress(&f);
            assert!(
                (tau - again).norm() <= 1e-4 * (dp.lame.mu + dp.lame.lambda),
                "{tau} {again}"
            );
        }
        // Inverted and collapsed particles come back with finite, non-inverted F.
        for f0 in [
            Matrix3::from_diagonal(&Vector3::new(0.9, 0.9, -0.9)),
            Matrix3::zeros(),
        ] {
            let (mut f, mut vc) = (f0, 0.0);
            let tau = model.update(&mut f, &mut vc, &mut COLD_START.clone());
            assert!(
                f.determinant() > 0.0 && tau.iter().all(|x| x.is_finite()),
                "{f}"
            );
        }
    }

    /// Stress difference (Pa) two f32 decompositions of one F may show: singular values agree to
    /// about 1e-6 relative, so strains to 1e-6 and stresses to 1e-6 (2 mu + 3 lambda).
    fn stress_tolerance(model: &Constitutive) -> f32 {
        let Lame { mu, lambda } = model.lame();
        2e-6 * (2.0 * mu + 3.0 * lambda)
    }

    /// Sixteen lanes at once: each lane is the same bits as the particle updated alone, and
    /// agrees with [`Constitutive::update`] of the trial F formed by nalgebra.
    #[test]
    fn update_lanes_of_matches_update() {
        let mut rng = SmallRng::seed_from_u64(17);
        for model in [sand(true), sand(false), jello()] {
            for _ in 0..250 {
                let f0: [Matrix3<f32>; 16] = std::array::from_fn(|_| {
                    rotation(&mut rng) * (Matrix3::identity() + 0.1 * gaussian(&mut rng))
                });
                let vc0: [f32; 16] = std::array::from_fn(|_| rng.random_range(0.0..0.1));
                let step: [Matrix3<f32>; 16] = std::array::from_fn(|_| 0.01 * gaussian(&mut rng));
                let (mut f16, mut vc16, mut frames) = (f0, vc0, [COLD_START; 16]);
                let tau16 = model.update_lanes_of(&step, &mut f16, &mut vc16, &mut frames, 1e-4);
                for l in 0..16 {
                    let (mut f1, mut vc1, mut frame1) = ([f0[l]], [vc0[l]], [COLD_START]);
                    let [tau1] =
                        model.update_lanes_of(&[step[l]], &mut f1, &mut vc1, &mut frame1, 1e-4);
                    assert_eq!(
                        (tau1, f1[0], vc1[0], frame1[0]),
                        (tau16[l], f16[l], vc16[l], frames[l]),
                        "lane {l}"
                    );
                    let (mut f, mut vc) = ((Matrix3::identity() + step[l]) * f0[l], vc0[l]);
                    let tau = model.update(&mut f, &mut vc, &mut COLD_START.clone());
                    let tol = stress_tolerance(&model);
                    assert!((tau - tau16[l]).norm() < tol, "{tau} vs {}", tau16[l]);
                    assert!((f - f16[l]).norm() < 1e-5 * f.norm(), "{f} vs {}", f16[l]);
                    assert!((vc - vc16[l]).abs() < 5e-6, "{vc} vs {}", vc16[l]);
                }
            }
        }
    }

    /// Warm-started updates along a deformation path agree with cold ones.
    #[test]
    fn warm_start_matches_cold_start() {
        let mut rng = SmallRng::seed_from_u64(19);
        for model in [sand(true), jello()] {
            for _ in 0..50 {
                let (mut f_warm, mut vc_warm, mut frame) = (rotation(&mut rng), 0.0, COLD_START);
                for _ in 0..100 {
                    let velocity_gradient = 0.01 * gaussian(&mut rng);
                    let step = Matrix3::identity() + velocity_gradient;
                    let (mut f_cold, mut vc_cold) = (step * f_warm, vc_warm);
                    f_warm = step * f_warm;
                    let tau_warm = model.update(&mut f_warm, &mut vc_warm, &mut frame);
                    let tau_cold = model.update(&mut f_cold, &mut vc_cold, &mut COLD_START.clone());
                    let tol = stress_tolerance(&model);
                    assert!(
                        (tau_warm - tau_cold).norm() < tol,
                        "{tau_warm} vs {tau_cold}"
                    );
                    assert!((f_warm - f_cold).norm() < 1e-5 * f_cold.norm());
                    f_warm = f_cold;
                    vc_warm = vc_cold;
                }
            }
        }
    }

    /// `cargo test --release --lib mpm::material::tests::bench -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn bench_update() {
        let mut rng = SmallRng::seed_from_u64(18);
        let f0: Vec<Matrix3<f32>> = (0..4096)
            .map(|_| rotation(&mut rng) * (Matrix3::identity() + 0.01 * gaussian(&mut rng)))
            .collect();
        let model = sand(true);
        type Run<'a> = &'a dyn Fn(&mut [Matrix3<f32>], &mut [f32]) -> f32;
        let time = |name: &str, f: Run| {
            let mut best = f64::INFINITY;
            for _ in 0..200 {
                let (mut fs, mut vcs) = (f0.clone(), vec![0.0; f0.len()]);
                let start = std::time::Instant::now();
                std::hint::black_box(f(&mut fs, &mut vcs));
                best = best.min(start.elapsed().as_secs_f64());
            }
            println!(
                "{name}: {:.1} ns per particle",
                best * 1e9 / f0.len() as f64
            );
        };
        time("Constitutive::update (sand, cold)", &|fs, vcs| {
            fs.iter_mut()
                .zip(vcs.iter_mut())
                .map(|(f, vc)| model.update(f, vc, &mut COLD_START.clone())[(0, 1)])
                .sum()
        });
        time(
            "Constitutive::update_lanes_of::<8> (sand, cold)",
            &|fs, vcs| {
                let groups = fs.chunks_exact_mut(8).zip(vcs.chunks_exact_mut(8));
                groups
                    .map(|(f, vc)| {
                        let mut frames = [COLD_START; 8];
                        let f = f.try_into().unwrap();
                        let tau = model.update_lanes_of(
                            &[Matrix3::zeros(); 8],
                            f,
                            vc.try_into().unwrap(),
                            &mut frames,
                            1e-4,
                        );
                        tau[0][(0, 1)]
                    })
                    .sum()
            },
        );
        // Warm: frames from a decomposition of the same F a substep earlier (I + 1e-3 noise).
        let frames: Vec<Frame> = f0
            .iter()
            .map(|f| {
                let mut frame = COLD_START;
                let earlier = f * (Matrix3::identity() + 1e-3 * gaussian(&mut rng));
                svd3_warm(&earlier, &mut frame);
                frame
            })
            .collect();
        time(
            "Constitutive::update_lanes_of::<8> (sand, warm)",
            &|fs, vcs| {
                let groups = fs.chunks_exact_mut(8).zip(vcs.chunks_exact_mut(8));
                groups
                    .zip(frames.chunks_exact(8))
                    .map(|((f, vc), fr)| {
                        let mut fr: [Frame; 8] = fr.try_into().unwrap();
                        let f = f.try_into().unwrap();
                        let tau = model.update_lanes_of(
                            &[Matrix3::zeros(); 8],
                            f,
                            vc.try_into().unwrap(),
                            &mut fr,
                            1e-4,
                        );
                        tau[0][(0, 1)]
                    })
                    .sum()
            },
        );
    }
}
