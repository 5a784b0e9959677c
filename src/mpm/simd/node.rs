//! [`F4`]: the four components of a grid node, `[p_x, p_y, p_z, m]`, as one SSE register on
//! x86-64 (part of its baseline, so always available) and a plain array elsewhere. P2G and G2P
//! add and scale whole nodes with it: two multiplies and two adds per node and particle.
//!
//! Its width is the node's, not the instruction set's: a wider register would hold the nodes
//! of two or four particles at once (the next lever, `docs/performance.md`). Written with
//! intrinsics because the compiler's vectorisation of `[f32; 4]` arithmetic made G2P 25 %
//! slower (measured 2026-12-03).

use std::ops::{Add, Mul};

/// Four f32 lanes: one grid node's momentum and mass.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub struct F4(std::arch::x86_64::__m128);

// SAFETY (every `unsafe` block in this impl): SSE belongs to the x86_64 baseline, so the
// intrinsics are always available; none of them dereferences a pointer.
#[cfg(target_arch = "x86_64")]
impl F4 {
    #[inline(always)]
    pub fn splat(x: f32) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_set1_ps(x) })
    }
    #[inline(always)]
    pub fn from_array(a: [f32; 4]) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_setr_ps(a[0], a[1], a[2], a[3]) })
    }
    #[inline(always)]
    pub fn to_array(self) -> [f32; 4] {
        unsafe { std::mem::transmute::<std::arch::x86_64::__m128, [f32; 4]>(self.0) }
    }
}

#[cfg(target_arch = "x86_64")]
impl Add for F4 {
    type Output = F4;
    #[inline(always)]
    fn add(self, o: F4) -> F4 {
        // SAFETY: SSE is part of the x86_64 baseline.
        F4(unsafe { std::arch::x86_64::_mm_add_ps(self.0, o.0) })
    }
}

#[cfg(target_arch = "x86_64")]
impl Mul for F4 {
    type Output = F4;
    #[inline(always)]
    fn mul(self, o: F4) -> F4 {
        // SAFETY: SSE is part of the x86_64 baseline.
        F4(unsafe { std::arch::x86_64::_mm_mul_ps(self.0, o.0) })
    }
}

/// Portable fallback of the same lanes.
#[cfg(not(target_arch = "x86_64"))]
pub type F4 = super::Wide<4>;
