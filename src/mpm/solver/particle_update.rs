//! Particle update: the deformation gradient `F <- (I + dt C) F` (Hu et al. 2018, eq. 17), the
//! constitutive update with its plastic projection (as many particles per SIMD call of the 3x3
//! SVD as the instruction set holds, `simd::InstructionSet`), the stress for the next P2G, and
//! the blow-up check of every particle.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::{split_runs, SimError, Solver, SolverMaterial};
use crate::mpm::grid::ParticleBlock;
use crate::mpm::particles::{MaterialId, Particles};
use crate::mpm::simd::{Lanes, Wide, WithLanes};
use crate::mpm::svd::{Frame, COLD_START};

/// The first bad particle found, by sorted index.
#[derive(Clone, Debug)]
struct BadParticle {
    index: usize,
    what: String,
}

/// What the particle update of one block found.
#[derive(Clone, Debug, Default)]
struct BlockCheck {
    max_speed_sq: f32,
    bad: Option<BadParticle>,
}

impl Solver {
    /// Updates F, the plastic state and the stress of every awake particle from the velocity
    /// gradient G2P left in `self.velocity_gradient`, records each block's largest speed (for
    /// the next time step and sleeping sand) and fails on the first particle with a non-finite
    /// state or a speed above `settings.blowup_speed_m_s`. With `moved` (a stop request left
    /// G2P part done), only the blocks G2P moved are updated, so every particle stays whole.
    pub(super) fn update_particles(
        &mut self,
        dt: f32,
        moved: Option<&[bool]>,
    ) -> Result<(), SimError> {
        let blowup_speed_sq = self.settings.blowup_speed_m_s * self.settings.blowup_speed_m_s;
        let materials = &self.materials[..];
        let blocks = &self.grid.particle_blocks;
        let instruction_set = self.instruction_set;
        let views = UpdateView::split(&mut self.particles, &self.velocity_gradient, blocks);
        let checks = views
            .into_par_iter()
            .zip(blocks.par_iter())
            .enumerate()
            .filter(|(b, _)| moved.is_none_or(|moved| moved[*b]))
            .map(|(_, (view, pb))| {
                instruction_set.dispatch(BlockUpdate {
                    view,
                    pb,
                    materials,
                    dt,
                    blowup_speed_sq,
                })
            })
            .collect::<Vec<_>>();
        if moved.is_some() {
            return Ok(());
        }
        if let Some(sleep) = &mut self.sleep {
            let speeds: Vec<f32> = checks.iter().map(|c| c.max_speed_sq.sqrt()).collect();
            sleep.record_speeds(blocks, &self.keys, &speeds, dt);
        }
        let max_speed_sq = checks.iter().map(|c| c.max_speed_sq).fold(0.0, f32::max);
        self.max_speed_m_s = max_speed_sq.sqrt();
        // Blocks are in particle order, so the first block's bad particle has the lowest index.
        match checks.into_iter().find_map(|c| c.bad) {
            None => Ok(()),
            Some(bad) => Err(SimError::BlowUp {
                step: self.steps,
                time_s: self.time_s,
                dt_s: dt,
                particle: self.particles.id[bad.index],
                what: bad.what,
                position: self.particles.position[bad.index].into(),
                velocity: self.particles.velocity[bad.index].into(),
            }),
        }
    }
}

/// The particle update of one block, as the work of [`crate::mpm::simd::InstructionSet::dispatch`].
struct BlockUpdate<'a> {
    view: UpdateView<'a>,
    pb: &'a ParticleBlock,
    materials: &'a [SolverMaterial],
    dt: f32,
    blowup_speed_sq: f32,
}

impl WithLanes for BlockUpdate<'_> {
    type Output = BlockCheck;
    #[inline(always)]
    fn run<const N: usize>(self) -> BlockCheck
    where
        Wide<N>: Lanes,
    {
        update_block::<N>(self)
    }
}

/// The particle update of one block, `N` particles at a time: their constitutive updates share
/// one `N`-lane SVD when they are of one material; a mixed group goes one particle at a time
/// (the same bits: lanes do not interact).
#[inline(always)]
fn update_block<const N: usize>(work: BlockUpdate) -> BlockCheck
where
    Wide<N>: Lanes,
{
    let BlockUpdate {
        view,
        pb,
        materials,
        dt,
        blowup_speed_sq,
    } = work;
    let mut check = BlockCheck::default();
    for chunk in (0..view.deformation.len()).step_by(N) {
        let lanes = (view.deformation.len() - chunk).min(N);
        // Unused lanes carry an undeformed, unmoved F: harmless for every model.
        let mut f = [Matrix3::identity(); N];
        let mut step = [Matrix3::zeros(); N];
        let mut vc = [0.0f32; N];
        let mut frames = [COLD_START; N];
        for lane in 0..lanes {
            let i = chunk + lane;
            f[lane] = view.deformation[i];
            step[lane] = view.velocity_gradient[i] * dt;
            vc[lane] = view.volume_correction[i];
            frames[lane] = view.svd_frame[i];
        }
        let material = view.material[chunk];
        let tau = if view.material[chunk..chunk + lanes]
            .iter()
            .all(|&m| m == material)
        {
            materials[material as usize].model.update_lanes_of(
                &step,
                &mut f,
                &mut vc,
                &mut frames,
                dt,
            )
        } else {
            std::array::from_fn(|lane| {
                let m = view.material.get(chunk + lane).copied().unwrap_or(material);
                let (mut f1, mut vc1, mut frame1) = ([f[lane]], [vc[lane]], [frames[lane]]);
                let [tau] = materials[m as usize].model.update_lanes_of::<1>(
                    &[step[lane]],
                    &mut f1,
                    &mut vc1,
                    &mut frame1,
                    dt,
                );
                (f[lane], vc[lane], frames[lane]) = (f1[0], vc1[0], frame1[0]);
                tau
            })
        };
        for lane in 0..lanes {
            let i = chunk + lane;
            view.deformation[i] = f[lane];
            view.volume_correction[i] = vc[lane];
            view.svd_frame[i] = frames[lane];
            view.stress[i] = tau[lane];
            let (x, v) = (view.position[i], view.velocity[i]);
            let speed_sq = v.norm_squared();
            check.max_speed_sq = check.max_speed_sq.max(speed_sq);
            if check.bad.is_none() {
                let finite = (x.sum() + speed_sq + tau[lane].sum() + f[lane].sum()).is_finite();
                let what = if !finite {
                    Some("has a non-finite state".to_string())
                } else if speed_sq > blowup_speed_sq {
                    Some(format!("moves at {:.3e} m/s", speed_sq.sqrt()))
                } else {
                    None
                };
                check.bad = what.map(|what| BadParticle {
                    index: pb.start + i,
                    what,
                });
            }
        }
    }
    check
}

/// The particle arrays the particle update reads and writes, for one particle block.
struct UpdateView<'a> {
    deformation: &'a mut [Matrix3<f32>],
    stress: &'a mut [Matrix3<f32>],
    volume_correction: &'a mut [f32],
    svd_frame: &'a mut [Frame],
    velocity_gradient: &'a [Matrix3<f32>],
    position: &'a [Vector3<f32>],
    velocity: &'a [Vector3<f32>],
    material: &'a [MaterialId],
}

impl<'a> UpdateView<'a> {
    fn split(
        p: &'a mut Particles,
        velocity_gradient: &'a [Matrix3<f32>],
        blocks: &[ParticleBlock],
    ) -> Vec<UpdateView<'a>> {
        let mut deformation = split_runs(&mut p.deformation, blocks).into_iter();
        let mut stress = split_runs(&mut p.stress, blocks).into_iter();
        let mut volume_correction = split_runs(&mut p.volume_correction, blocks).into_iter();
        let mut svd_frame = split_runs(&mut p.svd_frame, blocks).into_iter();
        let (position, velocity, material) = (&p.position[..], &p.velocity[..], &p.material[..]);
        blocks
            .iter()
            .map(|pb| UpdateView {
                deformation: deformation.next().unwrap(),
                stress: stress.next().unwrap(),
                volume_correction: volume_correction.next().unwrap(),
                svd_frame: svd_frame.next().unwrap(),
                velocity_gradient: &velocity_gradient[pb.start..pb.end],
                position: &position[pb.start..pb.end],
                velocity: &velocity[pb.start..pb.end],
                material: &material[pb.start..pb.end],
            })
            .collect()
    }
}
