//! What the solver is told besides its particles: materials, grid and domain, walls, gravity,
//! how the time step is chosen, the transfer and the kernel.

use nalgebra::Vector3;

use crate::mpm::boundary::Walls;
use crate::mpm::kernel::Kernel;
use crate::mpm::material::Constitutive;
use crate::mpm::sleep::SleepSettings;

/// A material the particles can be made of.
#[derive(Clone, Debug)]
pub struct SolverMaterial {
    /// Name from the scene file, for messages.
    pub name: String,
    /// Mass density rho (kg/m^3) of the undeformed material.
    pub density_kg_m3: f32,
    /// Elasticity and plasticity.
    pub model: Constitutive,
}

impl SolverMaterial {
    /// Dilatational wave speed `sqrt((lambda + 2 mu) / rho)` (m/s), which bounds the time step.
    pub fn wave_speed_m_s(&self) -> f32 {
        let lame = self.model.lame();
        ((lame.lambda + 2.0 * lame.mu) / self.density_kg_m3).sqrt()
    }
}

/// How the time step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimeStep {
    /// `dt = cfl * dx / (c + max |v_p|)`, at most `max_dt_s`.
    Adaptive { cfl: f32, max_dt_s: f32 },
    /// A fixed step (s), whatever the CFL condition says.
    Fixed { dt_s: f32 },
}

/// How particle velocities reach the grid (physics.md section 1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Transfer {
    /// Affine particle-in-cell (Jiang et al. 2015), MLS-MPM's: each particle carries its local
    /// velocity field `v + C (x - x_p)`, which keeps angular momentum. Every transfer loses
    /// part of the flow's energy, so fewer substeps (softer sand, a larger CFL number) give a
    /// longer collapse runout (docs/speed-vs-accuracy.md). The default until 2026-12-03.
    Apic,
    /// Plain particle-in-cell: only `v` is transferred (C is still the velocity gradient that
    /// updates F), which damps every rotation and shear of the velocity field. For comparison.
    Pic,
    /// Affine FLIP (AFLIP, Fei et al. 2021, "Revisiting integration in the material point
    /// method", section 4): APIC's affine transfer to the grid; back on the particle, the grid's
    /// velocity plus a share of the particle's own deviation from the grid velocity its
    /// transfer gave, `v_p <- sum w v_i' + blend (v_p - sum w v_i)` (`v_i` without the stress
    /// impulse), so a transfer no longer filters the velocity each substep. The affine field
    /// keeps the same share of its rotation's deviation (so angular momentum is kept) and the
    /// share squared of its strain rate's. The share is `blend = exp(-dt / tau)` with the
    /// relaxation time `tau` = [`SolverSettings::flip_relaxation_s`]: the deviation decays at
    /// one rate per second whatever the step, where a fixed share per substep (Fei et al.'s)
    /// would decay faster the more substeps. Positions move with the grid velocity `sum w v_i'`.
    /// Near colliders the transfer is [`SolverSettings::cpic_band`]'s. The default: chosen by
    /// measurement (docs/speed-vs-accuracy.md, issue 19).
    #[default]
    Aflip,
}

/// How particles in the CPIC band (a collider within their stencil) are transferred.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CpicBand {
    /// Plain PIC: CPIC's velocity (ghosts at the nodes across a collider), no affine field, no
    /// kept deviation. Loses the band's velocity variation at every substep, so a plough's drag
    /// grows with the substep count (+11 % for 3 x the substeps, docs/speed-vs-accuracy.md).
    /// The default until 2026-12-04; for comparison.
    Pic,
    /// As the bulk ([`Transfer`]): the affine field CPIC's gather gives, and with AFLIP the
    /// particle's velocity deviation from the transferred grid over its compatible nodes
    /// (momentum balanced with the bulk's), relaxed over
    /// [`SolverSettings::cpic_band_relaxation_s`]. With AFLIP a plough's drag then moves by
    /// 0.2 % over 3 x the substeps (with APIC still 12 %). A ball or a light plate resting on
    /// sand rings unless the sand is damped: the band's shorter relaxation and the sand's
    /// in-cone viscosity (`DruckerPrager::elastic_viscosity_pa_s`) bring them to rest
    /// (docs/speed-vs-accuracy.md, "The CPIC band"). The default.
    #[default]
    Bulk,
}

/// AFLIP's default relaxation time (s) of a particle's deviation from the grid
/// ([`SolverSettings::flip_relaxation_s`]). Chosen by measurement (docs/speed-vs-accuracy.md):
/// the quasi-2D collapse at a = 1, dx = 3 mm, CFL 0.2 to 0.8 and E 0.1 to 3.5 MPa spreads by
/// 2.0 % at 2 ms (1.3 % with the deposit's toe counted), 3.9 % at 1.34 ms, 8.5 % at 0.67 ms
/// and 12 % at 1 s (almost FLIP).
pub const DEFAULT_FLIP_RELAXATION_S: f32 = 2.0e-3;

/// The default relaxation time (s) of a CPIC band particle's velocity deviation with
/// [`CpicBand::Bulk`] ([`SolverSettings::cpic_band_relaxation_s`]). Chosen by measurement
/// (docs/speed-vs-accuracy.md, "The CPIC band"): at the bulk's 2 ms a ball resting on sand
/// rings at 0.05 m/s; at 0.5 ms it comes to rest, and a plough's drag still moves by under
/// 0.3 % with 3 x the substeps.
pub const DEFAULT_CPIC_BAND_RELAXATION_S: f32 = 5.0e-4;

/// AFLIP's shares of a particle's deviation from the grid kept over one substep.
#[derive(Clone, Copy, Debug)]
pub(crate) struct KeptShares {
    /// Away from colliders, `exp(-dt / flip_relaxation_s)`.
    pub bulk: f32,
    /// In the CPIC band with [`CpicBand::Bulk`], `exp(-dt / cpic_band_relaxation_s)`.
    pub band: f32,
}

/// The share of a deviation kept over a substep of `dt` (s) for the relaxation time `tau_s`
/// (s): `exp(-dt / tau)`, none for `tau_s = 0`.
fn kept_share(dt: f32, tau_s: f32) -> f32 {
    if tau_s > 0.0 {
        libm::expf(-dt / tau_s)
    } else {
        0.0
    }
}

/// Everything the solver needs besides particles and materials.
#[derive(Clone, Debug)]
pub struct SolverSettings {
    /// Grid node spacing (m).
    pub dx: f32,
    /// Min corner of the domain box (m); also the grid origin.
    pub domain_min: Vector3<f32>,
    /// Max corner of the domain box (m).
    pub domain_max: Vector3<f32>,
    /// How each wall of the box acts on the sand.
    pub walls: Walls,
    /// Gravitational acceleration (m/s^2).
    pub gravity: Vector3<f32>,
    pub time_step: TimeStep,
    /// A particle faster than this (m/s) means the simulation has blown up.
    pub blowup_speed_m_s: f32,
    pub transfer: Transfer,
    /// Relaxation time `tau` (s, >= 0) of a particle's deviation from the grid under
    /// [`Transfer::Aflip`]: each substep keeps `exp(-dt / tau)` of its velocity's and its affine
    /// field's rotation's, the square of that of its strain rate's (0 is APIC's update away from
    /// colliders; the CPIC band keeps its own, [`Self::cpic_band_relaxation_s`]).
    pub flip_relaxation_s: f32,
    /// The transfer of particles near colliders.
    pub cpic_band: CpicBand,
    /// With [`CpicBand::Bulk`] and AFLIP, the relaxation time `tau` (s, >= 0) of the velocity
    /// deviation of a particle in the CPIC band: each substep keeps `exp(-dt / tau)` of it.
    pub cpic_band_relaxation_s: f32,
    pub kernel: Kernel,
    /// Sleeping sand (blocks at rest left out of the substep), or none: every particle is
    /// stepped every substep.
    pub sleep: Option<SleepSettings>,
}

impl SolverSettings {
    /// AFLIP's kept shares over a substep of `dt` (s).
    pub(crate) fn kept_shares(&self, dt: f32) -> KeptShares {
        KeptShares {
            bulk: kept_share(dt, self.flip_relaxation_s),
            band: kept_share(dt, self.cpic_band_relaxation_s),
        }
    }
}
