//! Which instruction set the wide loops run with, chosen at run time: the fastest this CPU has
//! (detected by the `pulp` crate), or the one `SANDSTEP_SIMD` names. Every path gives the same
//! bits (module `simd`), so the choice changes speed only.

use std::fmt;
use std::marker::PhantomData;

#[cfg(target_arch = "x86_64")]
use super::node::AvxPair;
use super::node::SsePair;
use super::{Lanes, NodePair, Wide};

/// Environment variable that forces an instruction set: `avx512`, `avx2`, `portable` or `auto`
/// (the default: the fastest available).
pub const SIMD_ENV_VAR: &str = "SANDSTEP_SIMD";

/// An instruction set this CPU has, with the proof of it (`pulp`'s token) where it is not the
/// baseline. Values exist only for instruction sets the CPU supports.
#[derive(Clone, Copy, Debug)]
pub enum InstructionSet {
    /// x86-64-v4: AVX-512 (F, VL, DQ, BW, CD) with the AVX2 set.
    #[cfg(target_arch = "x86_64")]
    Avx512(pulp::x86::V4),
    /// x86-64-v3: AVX2 and FMA (FMA is never used: it would change the bits).
    #[cfg(target_arch = "x86_64")]
    Avx2(pulp::x86::V3),
    /// The target's baseline (SSE2 on x86-64): what every machine of the architecture runs.
    Portable,
}

/// Lanes of the wide loops, the same for every instruction set, chosen by measurement
/// (`docs/performance.md`): one AVX2 register. 16 lanes (two AVX2 registers) spilled and ran
/// 25 % slower; with AVX-512 the compiler left parts of 16- and 32-lane loops scalar, 35-60 %
/// slower than 8.
const LANES: usize = 8;

/// Work written once for any number of lanes, run by [`InstructionSet::dispatch`].
pub trait WithLanes {
    type Output;
    /// Runs with `N` lanes; must be `#[inline(always)]` to be compiled with the instruction
    /// set's features.
    fn run<const N: usize>(self) -> Self::Output
    where
        Wide<N>: Lanes;
}

/// Work on grid nodes (P2G, G2P), run by [`InstructionSet::dispatch_nodes`] with the
/// instruction set's [`NodePair`].
pub trait WithNodes {
    type Output;
    /// Runs with node pairs `P`; must be `#[inline(always)]` to be compiled with the
    /// instruction set's features.
    fn run<P: NodePair>(self) -> Self::Output;
}

/// An instruction set that cannot be used here.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SimdError {
    /// The name is none of `auto`, `avx512`, `avx2`, `portable`.
    UnknownName(String),
    /// The CPU (or the architecture) lacks it.
    Unavailable(&'static str),
}

impl fmt::Display for SimdError {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        match self {
            SimdError::UnknownName(name) => write!(
                f,
                "unknown instruction set {name:?}: expected auto, avx512, avx2 or portable"
            ),
            SimdError::Unavailable(name) => {
                write!(f, "this CPU does not support the {name} instruction set")
            }
        }
    }
}

impl std::error::Error for SimdError {}

impl InstructionSet {
    /// Every name [`Self::by_name`] accepts besides `auto`, fastest first as measured on a CPU
    /// with all three (`docs/performance.md`): AVX2, AVX-512 (at the same width, 0-10 % slower),
    /// the baseline (10-20 % slower).
    pub const NAMES: [&'static str; 3] = ["avx2", "avx512", "portable"];

    /// The fastest instruction set this CPU has.
    pub fn best() -> Self {
        Self::NAMES
            .iter()
            .find_map(|name| Self::by_name(name).ok())
            .unwrap_or(InstructionSet::Portable)
    }

    /// `name` (`auto`: [`Self::best`]) if this CPU has it.
    pub fn by_name(name: &str) -> Result<Self, SimdError> {
        match name {
            "auto" => Ok(Self::best()),
            "portable" => Ok(InstructionSet::Portable),
            #[cfg(target_arch = "x86_64")]
            "avx512" => pulp::x86::V4::try_new()
                .map(InstructionSet::Avx512)
                .ok_or(SimdError::Unavailable("avx512")),
            #[cfg(target_arch = "x86_64")]
            "avx2" => pulp::x86::V3::try_new()
                .map(InstructionSet::Avx2)
                .ok_or(SimdError::Unavailable("avx2")),
            #[cfg(not(target_arch = "x86_64"))]
            "avx512" => Err(SimdError::Unavailable("avx512")),
            #[cfg(not(target_arch = "x86_64"))]
            "avx2" => Err(SimdError::Unavailable("avx2")),
            other => Err(SimdError::UnknownName(other.to_string())),
        }
    }

    /// The instruction set [`SIMD_ENV_VAR`] names, or the best one if it is unset.
    pub fn from_env() -> Result<Self, SimdError> {
        match std::env::var(SIMD_ENV_VAR) {
            Ok(name) => Self::by_name(name.trim()),
            Err(_) => Ok(Self::best()),
        }
    }

    /// Every instruction set this CPU has, fastest first.
    pub fn available() -> Vec<Self> {
        Self::NAMES
            .iter()
            .filter_map(|name| Self::by_name(name).ok())
            .collect()
    }

    /// The name [`Self::by_name`] takes.
    pub fn name(self) -> &'static str {
        match self {
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx512(_) => "avx512",
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx2(_) => "avx2",
            InstructionSet::Portable => "portable",
        }
    }

    /// Lanes of its wide loops.
    pub fn lanes(self) -> usize {
        LANES
    }

    /// Runs `work` compiled for this instruction set, with [`Self::lanes`] lanes.
    #[inline(always)]
    pub fn dispatch<W: WithLanes>(self, work: W) -> W::Output {
        match self {
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx512(v4) => pulp::Simd::vectorize(v4, WithFeatures::<W, LANES>(work)),
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx2(v3) => pulp::Simd::vectorize(v3, WithFeatures::<W, LANES>(work)),
            InstructionSet::Portable => work.run::<LANES>(),
        }
    }

    /// Runs `work` compiled for this instruction set, with its [`NodePair`]: one AVX register
    /// with AVX2 or AVX-512, two SSE registers on the baseline.
    #[inline(always)]
    pub fn dispatch_nodes<W: WithNodes>(self, work: W) -> W::Output {
        match self {
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx512(v4) => {
                pulp::Simd::vectorize(v4, NodesWithFeatures::<W, AvxPair>(work, PhantomData))
            }
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx2(v3) => {
                pulp::Simd::vectorize(v3, NodesWithFeatures::<W, AvxPair>(work, PhantomData))
            }
            InstructionSet::Portable => work.run::<SsePair>(),
        }
    }
}

/// `work` with node pairs `P`, as `pulp` runs it: inlined into a function compiled with the
/// instruction set's target features.
struct NodesWithFeatures<W, P>(W, PhantomData<P>);

impl<W: WithNodes, P: NodePair> pulp::WithSimd for NodesWithFeatures<W, P> {
    type Output = W::Output;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> W::Output {
        self.0.run::<P>()
    }
}

/// `work` with `N` lanes, as `pulp` runs it: inlined into a function compiled with the
/// instruction set's target features.
struct WithFeatures<W, const N: usize>(W);

impl<W: WithLanes, const N: usize> pulp::WithSimd for WithFeatures<W, N>
where
    Wide<N>: Lanes,
{
    type Output = W::Output;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> W::Output {
        self.0.run::<N>()
    }
}

impl fmt::Display for InstructionSet {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{} ({} lanes)", self.name(), self.lanes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct LaneCount;
    impl WithLanes for LaneCount {
        type Output = usize;
        #[inline(always)]
        fn run<const N: usize>(self) -> usize
        where
            Wide<N>: Lanes,
        {
            N
        }
    }

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for set in InstructionSet::available() {
            assert_eq!(
                InstructionSet::by_name(set.name()).unwrap().name(),
                set.name()
            );
            assert_eq!(set.dispatch(LaneCount), set.lanes());
        }
        assert_eq!(
            InstructionSet::available().last().unwrap().name(),
            "portable"
        );
        assert_eq!(
            InstructionSet::by_name("auto").unwrap().name(),
            InstructionSet::available()[0].name()
        );
        let err = InstructionSet::by_name("sse9").unwrap_err().to_string();
        assert!(err.contains("sse9") && err.contains("avx2"), "{err}");
    }
}
