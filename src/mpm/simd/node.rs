//! [`F4`]: the four components of a grid node, `[p_x, p_y, p_z, m]`, as one SSE register on
//! x86-64 (part of its baseline, so always available) and a plain array elsewhere. P2G and G2P
//! add and scale whole nodes with it: two multiplies and two adds per node and particle.
//!
//! Its width is the node's, not the instruction set's. With AFLIP a node of the grid and the
//! same node of the transferred grid share their weights, and [`NodePair`] holds both: one AVX
//! register where the CPU has AVX2. Written with intrinsics because the compiler's
//! vectorisation of `[f32; 4]` arithmetic made G2P 25 % slower (measured 2026-12-03), and its
//! `[f32; 8]` pairs stayed scalar (2026-12-06).

use std::ops::{Add, Mul};

use crate::mpm::grid::ARENA_NODES;

/// Four f32 lanes: one grid node's momentum and mass.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
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

/// What P2G and G2P do with a node: [`F4`], or a pair of nodes ([`NodePair`]).
pub trait Node: Copy + Add<Output = Self> + Mul<Output = Self> {
    fn splat(x: f32) -> Self;
}

impl Node for F4 {
    #[inline(always)]
    fn splat(x: f32) -> Self {
        F4::splat(x)
    }
}

/// Two grid node vectors side by side (`[p_x, p_y, p_z, m]` in P2G, `[v_x, v_y, v_z, m]` in
/// G2P, then the same of the other grid): a node of the grid and the same node of AFLIP's
/// transferred grid, scattered and gathered with the same weights in one pass. Each half's
/// arithmetic is [`F4`]'s, so the same bits as two passes. The type is the instruction set's
/// ([`super::WithNodes`]): one AVX register where the CPU has AVX2 (`AvxPair`), two SSE
/// registers otherwise (`SsePair`).
pub trait NodePair: Node {
    fn from_halves(low: F4, high: F4) -> Self;
    /// The pairs of `arena` as their halves in memory, `[grid's, transferred grid's]`: where
    /// code compiled without the instruction set (the CPIC band's) adds to one half.
    fn halves_of(arena: &mut [Self; ARENA_NODES]) -> &mut [[F4; 2]; ARENA_NODES];
    /// The grid's node.
    fn low(self) -> F4;
    /// The transferred grid's node.
    fn high(self) -> F4;
}

/// [`NodePair`] as two [`F4`]: the baseline's.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct SsePair {
    low: F4,
    high: F4,
}

impl Add for SsePair {
    type Output = SsePair;
    #[inline(always)]
    fn add(self, o: SsePair) -> SsePair {
        SsePair {
            low: self.low + o.low,
            high: self.high + o.high,
        }
    }
}

impl Mul for SsePair {
    type Output = SsePair;
    #[inline(always)]
    fn mul(self, o: SsePair) -> SsePair {
        SsePair {
            low: self.low * o.low,
            high: self.high * o.high,
        }
    }
}

impl Node for SsePair {
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Self::from_halves(F4::splat(x), F4::splat(x))
    }
}

impl NodePair for SsePair {
    #[inline(always)]
    fn from_halves(low: F4, high: F4) -> Self {
        SsePair { low, high }
    }
    #[inline(always)]
    fn halves_of(arena: &mut [Self; ARENA_NODES]) -> &mut [[F4; 2]; ARENA_NODES] {
        // SAFETY: `SsePair` is `#[repr(C)]` with two `F4` fields, low first: the layout of
        // `[F4; 2]`.
        unsafe { &mut *(arena as *mut [Self; ARENA_NODES]).cast::<[[F4; 2]; ARENA_NODES]>() }
    }
    #[inline(always)]
    fn low(self) -> F4 {
        self.low
    }
    #[inline(always)]
    fn high(self) -> F4 {
        self.high
    }
}

/// [`NodePair`] as one AVX register. Its intrinsics need AVX, so it is private to this module
/// tree: only [`super::InstructionSet::dispatch_nodes`] names it, and only where the CPU has
/// AVX2 (its code is then compiled with those features). Measured with `sandstep bench`
/// (`docs/performance.md`): G2P 1.23 and P2G 1.35 times the particles per second of two
/// passes of [`F4`]; [`SsePair`] there gained nothing, and eight plain lanes (`Wide<8>`, left
/// scalar by the compiler) lost a third.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(super) struct AvxPair(std::arch::x86_64::__m256);

// SAFETY (every `unsafe` block below): an `AvxPair` is reachable only through
// `InstructionSet::dispatch_nodes`'s AVX2 and AVX-512 arms, after `pulp`'s token proved that
// the CPU has AVX2; none of the intrinsics dereferences a pointer.
#[cfg(target_arch = "x86_64")]
impl Add for AvxPair {
    type Output = AvxPair;
    #[inline(always)]
    fn add(self, o: AvxPair) -> AvxPair {
        AvxPair(unsafe { std::arch::x86_64::_mm256_add_ps(self.0, o.0) })
    }
}

#[cfg(target_arch = "x86_64")]
impl Mul for AvxPair {
    type Output = AvxPair;
    #[inline(always)]
    fn mul(self, o: AvxPair) -> AvxPair {
        AvxPair(unsafe { std::arch::x86_64::_mm256_mul_ps(self.0, o.0) })
    }
}

#[cfg(target_arch = "x86_64")]
impl Node for AvxPair {
    #[inline(always)]
    fn splat(x: f32) -> Self {
        AvxPair(unsafe { std::arch::x86_64::_mm256_set1_ps(x) })
    }
}

#[cfg(target_arch = "x86_64")]
impl NodePair for AvxPair {
    #[inline(always)]
    fn from_halves(low: F4, high: F4) -> Self {
        AvxPair(unsafe { std::arch::x86_64::_mm256_set_m128(high.0, low.0) })
    }
    #[inline(always)]
    fn halves_of(arena: &mut [Self; ARENA_NODES]) -> &mut [[F4; 2]; ARENA_NODES] {
        // SAFETY: an `__m256` is eight f32 in memory, its low 128 bits (the pair's `low`) first,
        // and `F4` is a transparent `__m128`: the layout of `[F4; 2]`, whose alignment (16) is
        // less than the register's (32).
        unsafe { &mut *(arena as *mut [Self; ARENA_NODES]).cast::<[[F4; 2]; ARENA_NODES]>() }
    }
    #[inline(always)]
    fn low(self) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm256_castps256_ps128(self.0) })
    }
    #[inline(always)]
    fn high(self) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm256_extractf128_ps(self.0, 1) })
    }
}
