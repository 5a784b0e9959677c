//! Material points in structure-of-arrays layout.
//!
//! Invariant: every array has the same length and the same order. The solver keeps that order
//! sorted by the grid block of each particle's stencil base node, so the particles of one block
//! are contiguous.

use nalgebra::{Matrix3, Vector3};

use super::svd::{Frame, COLD_START};

/// Index of a material in the solver's material list.
pub type MaterialId = u16;

#[derive(Clone, Debug, Default)]
pub struct Particles {
    /// Position x_p (m, world frame).
    pub position: Vec<Vector3<f32>>,
    /// Velocity v_p (m/s).
    pub velocity: Vec<Vector3<f32>>,
    /// APIC/MLS affine velocity matrix C_p (1/s).
    pub affine: Vec<Matrix3<f32>>,
    /// Elastic deformation gradient F_p (dimensionless).
    pub deformation: Vec<Matrix3<f32>>,
    /// Kirchhoff stress tau_p of the current F_p (Pa), computed at the end of each substep.
    pub stress: Vec<Matrix3<f32>>,
    /// Mass m_p (kg).
    pub mass: Vec<f32>,
    /// Initial (undeformed) volume V_p^0 (m^3).
    pub volume: Vec<f32>,
    /// Jacobi frame of the last SVD of F_p (unit quaternion): warm start of the next one.
    pub svd_frame: Vec<Frame>,
    /// CPIC tags: affinity (bit 2r) and side (bit 2r + 1) per collider r (see `mpm::cpic`).
    pub cpic_tags: Vec<u64>,
    /// Drucker-Prager volume-correction scalar (log of volume, dimensionless; 0 for elastic).
    pub volume_correction: Vec<f32>,
    /// Material of each particle.
    pub material: Vec<MaterialId>,
    /// Persistent particle id (creation order), so errors and outputs can name a particle
    /// although sorting moves it around.
    pub id: Vec<u32>,
    /// The id of the next particle pushed (ids are not reused after [`Particles::retain`]).
    next_id: u32,
}

/// Spare arrays for [`Particles::reorder`], one per element type (about 82 bytes per particle).
#[derive(Clone, Debug, Default)]
pub struct ReorderScratch {
    vectors: Vec<Vector3<f32>>,
    matrices: Vec<Matrix3<f32>>,
    scalars: Vec<f32>,
    frames: Vec<Frame>,
    tags: Vec<u64>,
    materials: Vec<MaterialId>,
    ids: Vec<u32>,
}

impl ReorderScratch {
    /// Bytes held (capacity).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.vectors.capacity() * size_of::<Vector3<f32>>()
            + self.matrices.capacity() * size_of::<Matrix3<f32>>()
            + self.scalars.capacity() * size_of::<f32>()
            + self.frames.capacity() * size_of::<Frame>()
            + self.tags.capacity() * size_of::<u64>()
            + self.materials.capacity() * size_of::<MaterialId>()
            + self.ids.capacity() * size_of::<u32>()
    }
}

/// One new particle, at rest in its undeformed state.
#[derive(Clone, Copy, Debug)]
pub struct NewParticle {
    pub position: Vector3<f32>,
    pub velocity: Vector3<f32>,
    pub mass: f32,
    pub volume: f32,
    pub material: MaterialId,
}

impl Particles {
    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Makes room for `additional` more particles.
    pub fn reserve(&mut self, additional: usize) {
        self.position.reserve(additional);
        self.velocity.reserve(additional);
        self.affine.reserve(additional);
        self.deformation.reserve(additional);
        self.stress.reserve(additional);
        self.svd_frame.reserve(additional);
        self.cpic_tags.reserve(additional);
        self.mass.reserve(additional);
        self.volume.reserve(additional);
        self.volume_correction.reserve(additional);
        self.material.reserve(additional);
        self.id.reserve(additional);
    }

    /// Appends an undeformed particle with zero stress and zero affine velocity.
    pub fn push(&mut self, p: NewParticle) {
        let id = self.next_id;
        self.next_id += 1;
        self.position.push(p.position);
        self.velocity.push(p.velocity);
        self.affine.push(Matrix3::zeros());
        self.deformation.push(Matrix3::identity());
        self.stress.push(Matrix3::zeros());
        self.svd_frame.push(COLD_START);
        self.cpic_tags.push(0);
        self.mass.push(p.mass);
        self.volume.push(p.volume);
        self.volume_correction.push(0.0);
        self.material.push(p.material);
        self.id.push(id);
    }

    /// Keeps the particles for which `keep(position)` holds, in their order; returns how many
    /// were removed.
    pub fn retain(&mut self, keep: impl Fn(&Vector3<f32>) -> bool) -> usize {
        let mask: Vec<bool> = self.position.iter().map(keep).collect();
        fn retain_by<T>(v: &mut Vec<T>, mask: &[bool]) {
            let mut i = 0;
            v.retain(|_| {
                i += 1;
                mask[i - 1]
            });
        }
        let before = self.len();
        retain_by(&mut self.position, &mask);
        retain_by(&mut self.velocity, &mask);
        retain_by(&mut self.affine, &mask);
        retain_by(&mut self.deformation, &mask);
        retain_by(&mut self.stress, &mask);
        retain_by(&mut self.mass, &mask);
        retain_by(&mut self.volume, &mask);
        retain_by(&mut self.svd_frame, &mask);
        retain_by(&mut self.cpic_tags, &mask);
        retain_by(&mut self.volume_correction, &mask);
        retain_by(&mut self.material, &mask);
        retain_by(&mut self.id, &mask);
        before - self.len()
    }

    /// Reorders every array by `order`: particle `i` of the result is particle `order[i]` now.
    /// `scratch` holds one spare array per element type, reused from call to call, so sorting
    /// allocates nothing once the arrays have reached their size.
    pub fn reorder(&mut self, order: &[u32], scratch: &mut ReorderScratch) {
        fn gather<T: Copy + Send + Sync>(v: &mut Vec<T>, order: &[u32], spare: &mut Vec<T>) {
            use rayon::prelude::*;
            spare.clear();
            spare.par_extend(order.par_iter().map(|&i| v[i as usize]));
            std::mem::swap(v, spare);
        }
        let s = scratch;
        gather(&mut self.position, order, &mut s.vectors);
        gather(&mut self.velocity, order, &mut s.vectors);
        gather(&mut self.affine, order, &mut s.matrices);
        gather(&mut self.deformation, order, &mut s.matrices);
        gather(&mut self.stress, order, &mut s.matrices);
        gather(&mut self.svd_frame, order, &mut s.frames);
        gather(&mut self.cpic_tags, order, &mut s.tags);
        gather(&mut self.mass, order, &mut s.scalars);
        gather(&mut self.volume, order, &mut s.scalars);
        gather(&mut self.volume_correction, order, &mut s.scalars);
        gather(&mut self.material, order, &mut s.materials);
        gather(&mut self.id, order, &mut s.ids);
    }

    /// Bytes held by the particle arrays (capacity, not length).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.position.capacity() * size_of::<Vector3<f32>>()
            + self.velocity.capacity() * size_of::<Vector3<f32>>()
            + self.affine.capacity() * size_of::<Matrix3<f32>>()
            + self.deformation.capacity() * size_of::<Matrix3<f32>>()
            + self.stress.capacity() * size_of::<Matrix3<f32>>()
            + self.svd_frame.capacity() * size_of::<Frame>()
            + self.cpic_tags.capacity() * size_of::<u64>()
            + (self.mass.capacity() + self.volume.capacity() + self.volume_correction.capacity())
                * size_of::<f32>()
            + self.material.capacity() * size_of::<MaterialId>()
            + self.id.capacity() * size_of::<u32>()
    }

    /// Total mass (kg), summed in f64.
    pub fn total_mass(&self) -> f64 {
        self.mass.iter().map(|&m| m as f64).sum()
    }

    /// Total linear momentum (kg m/s), summed in f64.
    pub fn total_momentum(&self) -> Vector3<f64> {
        self.mass
            .iter()
            .zip(&self.velocity)
            .map(|(&m, v)| v.cast::<f64>() * m as f64)
            .sum()
    }

    /// Centre of mass (m).
    pub fn centre_of_mass(&self) -> Vector3<f64> {
        let weighted: Vector3<f64> = self
            .mass
            .iter()
            .zip(&self.position)
            .map(|(&m, x)| x.cast::<f64>() * m as f64)
            .sum();
        weighted / self.total_mass()
    }

    /// Total angular momentum about the origin (kg m^2/s) including the APIC spin of each
    /// particle's affine field: `x_p x m_p v_p + m_p dx^2/4 axial(C_p - C_p^T)` (Jiang et al.
    /// 2015), the quantity APIC transfers conserve on a grid of spacing `dx`.
    pub fn total_angular_momentum(&self, dx: f32) -> Vector3<f64> {
        let d = (dx as f64) * (dx as f64) / 4.0;
        let mut total = Vector3::zeros();
        for p in 0..self.len() {
            let m = self.mass[p] as f64;
            let x = self.position[p].cast::<f64>();
            let v = self.velocity[p].cast::<f64>();
            let c = self.affine[p].cast::<f64>();
            let spin = Vector3::new(
                c[(2, 1)] - c[(1, 2)],
                c[(0, 2)] - c[(2, 0)],
                c[(1, 0)] - c[(0, 1)],
            );
            total += x.cross(&(m * v)) + m * d * spin;
        }
        total
    }

    /// Current volume sum_p V_p^0 det(F_p) (m^3).
    pub fn total_volume(&self) -> f64 {
        self.volume
            .iter()
            .zip(&self.deformation)
            .map(|(&v, f)| v as f64 * f.determinant() as f64)
            .sum()
    }
}
