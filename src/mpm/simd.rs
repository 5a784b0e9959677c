//! SIMD lanes written once, compiled per instruction set: [`Wide<N>`] holds `N` f32 lanes and
//! does every operation lane by lane in plain Rust, which the compiler turns into SSE, AVX2 or
//! AVX-512 instructions depending on the target features of the function it is inlined into.
//! [`InstructionSet::dispatch`] runs code under the fastest features this CPU has (chosen at run
//! time with the `pulp` crate, or forced with `SANDSTEP_SIMD`).
//!
//! Every operation is exact IEEE arithmetic lane by lane (no fused multiply-add, no estimated
//! reciprocals), so a lane's result does not depend on the width or the instruction set: every
//! path gives the same bits (`docs/determinism.md`; pinned in `tests/determinism.rs`).
//!
//! Used for many particles at once (the SVD and the constitutive update). The four components
//! of a grid node in P2G and G2P are [`F4`], and a node of each of AFLIP's two grids together a
//! [`NodePair`] (`node.rs`).

mod instruction_set;
mod node;

use std::ops::{Add, Div, Mul, Neg, Sub};

pub use instruction_set::{InstructionSet, SimdError, WithLanes, WithNodes, SIMD_ENV_VAR};
pub use node::{Node, NodePair, F4};

/// `[e(0), e(1), e(2)]` for `array3!(k => e(k))`, written out in place. Lane code builds its
/// small arrays with this instead of closures: a closure is a function of its own, and where the
/// compiler does not inline it (wide lanes make it large) it runs without the target features
/// of the code around it.
macro_rules! array3 {
    ($k:ident => $e:expr) => {
        [
            {
                let $k = 0usize;
                $e
            },
            {
                let $k = 1usize;
                $e
            },
            {
                let $k = 2usize;
                $e
            },
        ]
    };
}
pub(crate) use array3;

/// A 3x3 matrix `[[e(0, 0), e(0, 1), ..], ..]` for `mat3!(i, j => e(i, j))`, as [`array3`].
macro_rules! mat3 {
    ($i:ident, $j:ident => $e:expr) => {
        $crate::mpm::simd::array3!($i => $crate::mpm::simd::array3!($j => $e))
    };
}
pub(crate) use mat3;

/// 1.5 2^23: `(x + this) - this` is `x` rounded to an integer, exactly, for |x| < 2^22.
const ROUNDING_SHIFT: f32 = 12_582_912.0;
/// 2^23 + 127: `n + this` holds the biased exponent `n + 127` in its low mantissa bits.
const EXPONENT_SHIFT: f32 = 8_388_735.0;

/// `N` f32 lanes. Comparisons return lane masks (all bits set or clear) stored as lanes.
#[derive(Clone, Copy, Debug)]
pub struct Wide<const N: usize>(pub [f32; N]);

// Lane loops index all arrays alike: the form the compiler vectorises.
#[allow(clippy::needless_range_loop)]
impl<const N: usize> Wide<N> {
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> Self {
        let mut out = self.0;
        for k in 0..N {
            out[k] = f(self.0[k]);
        }
        Self(out)
    }
    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut out = self.0;
        for k in 0..N {
            out[k] = f(self.0[k], o.0[k]);
        }
        Self(out)
    }
    #[inline(always)]
    fn map_bits(self, f: impl Fn(u32) -> u32) -> Self {
        self.map(|x| f32::from_bits(f(x.to_bits())))
    }
    #[inline(always)]
    fn zip_bits(self, o: Self, f: impl Fn(u32, u32) -> u32) -> Self {
        self.zip(o, |x, y| f32::from_bits(f(x.to_bits(), y.to_bits())))
    }
    #[inline(always)]
    fn mask(c: bool) -> f32 {
        f32::from_bits(if c { !0 } else { 0 })
    }
    #[inline(always)]
    pub fn splat(x: f32) -> Self {
        Self([x; N])
    }
    #[inline(always)]
    pub fn from_array(a: [f32; N]) -> Self {
        Self(a)
    }
    #[inline(always)]
    pub fn to_array(self) -> [f32; N] {
        self.0
    }
}

macro_rules! wide_binop {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const N: usize> $tr for Wide<N> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                self.zip(o, |x, y| x $op y)
            }
        }
    };
}
wide_binop!(Add, add, +);
wide_binop!(Sub, sub, -);
wide_binop!(Mul, mul, *);
wide_binop!(Div, div, /);

impl<const N: usize> Neg for Wide<N> {
    type Output = Self;
    /// `0 - x` (as SSE code has it: `-0.0` becomes `+0.0`).
    #[inline(always)]
    fn neg(self) -> Self {
        Self::splat(0.0) - self
    }
}

impl<const N: usize> Mul<Wide<N>> for f32 {
    type Output = Wide<N>;
    #[inline(always)]
    fn mul(self, o: Wide<N>) -> Wide<N> {
        Wide::splat(self) * o
    }
}

/// Lane-wise arithmetic, so the SVD and the constitutive update are written once for every width.
pub trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// Number of lanes.
    const N: usize;
    fn splat(x: f32) -> Self;
    /// Lane `k` is `f(k)`.
    fn from_fn(f: impl FnMut(usize) -> f32) -> Self;
    fn lane(self, k: usize) -> f32;
    fn select(mask: Self, a: Self, b: Self) -> Self;
    fn lt(self, o: Self) -> Self;
    fn eq(self, o: Self) -> Self;
    fn abs(self) -> Self;
    /// +1 or -1 with the sign bit of `self`.
    fn sign_one(self) -> Self;
    /// `if self < o { self } else { o }` (SSE's `minps`).
    fn min(self, o: Self) -> Self;
    /// `if self > o { self } else { o }` (SSE's `maxps`).
    fn max(self, o: Self) -> Self;
    fn sqrt(self) -> Self;
    /// `1 / sqrt(x)`, correctly rounded twice (square root, then division), so every CPU gives
    /// the same bits. `rsqrtps` would be faster, but its 12-bit estimate differs between CPU
    /// vendors (and emulators), which made runs differ between machines.
    fn rsqrt(self) -> Self;
    /// (2^(127-e), 2^(e-127)) with e the biased exponent of `self`, clamped to [1, 253].
    fn pow2_normalizers(self) -> (Self, Self);
    /// Whether any lane of a comparison mask is set.
    fn any(self) -> bool;
    /// Lane-wise AND of two masks.
    fn and(self, o: Self) -> Self;
    /// Lane-wise OR of two masks.
    fn or(self, o: Self) -> Self;
    /// `floor(x)` for |x| < 2^22: rounded to the nearest integer by adding and subtracting
    /// 1.5 2^23 (exact), then stepped down where that rounded up.
    fn floor(self) -> Self;
    /// `(m, e)` with `x = m 2^e`, `m` in [0.5, 1), `e` an integer as f32; for positive normal x.
    fn frexp(self) -> (Self, Self);
    /// `2^n` for integer-valued `n` in [-126, 127].
    fn pow2(n: Self) -> Self;
}

#[allow(clippy::needless_range_loop)]
impl<const N: usize> Lanes for Wide<N> {
    const N: usize = N;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Wide::splat(x)
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f32) -> Self {
        let mut out = [0.0; N];
        for (k, x) in out.iter_mut().enumerate() {
            *x = f(k);
        }
        Self(out)
    }
    #[inline(always)]
    fn lane(self, k: usize) -> f32 {
        self.0[k]
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        let mut out = b.0;
        for k in 0..N {
            let m = mask.0[k].to_bits();
            out[k] = f32::from_bits((a.0[k].to_bits() & m) | (b.0[k].to_bits() & !m));
        }
        Self(out)
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        self.zip(o, |x, y| Self::mask(x < y))
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        self.zip(o, |x, y| Self::mask(x == y))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self.map_bits(|b| b & 0x7fff_ffff)
    }
    #[inline(always)]
    fn sign_one(self) -> Self {
        self.map_bits(|b| (b & 0x8000_0000) | 1f32.to_bits())
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.zip(o, |x, y| if x < y { x } else { y })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.zip(o, |x, y| if x > y { x } else { y })
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn rsqrt(self) -> Self {
        self.map(|x| 1.0 / x.sqrt())
    }
    #[inline(always)]
    fn pow2_normalizers(self) -> (Self, Self) {
        let exponent = |b: u32| ((b >> 23) & 0xff).clamp(1, 253);
        (
            self.map_bits(|b| (254 - exponent(b)) << 23),
            self.map_bits(|b| exponent(b) << 23),
        )
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().fold(0, |acc, x| acc | x.to_bits()) != 0
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        self.zip_bits(o, |x, y| x & y)
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self.zip_bits(o, |x, y| x | y)
    }
    #[inline(always)]
    fn floor(self) -> Self {
        let rounded = (self + Self::splat(ROUNDING_SHIFT)) - Self::splat(ROUNDING_SHIFT);
        let above = rounded.zip(self, |r, x| if r > x { 1.0 } else { 0.0 });
        rounded - above
    }
    #[inline(always)]
    fn frexp(self) -> (Self, Self) {
        (
            self.map_bits(|b| (b & 0x807f_ffff) | 0x3f00_0000),
            self.map(|x| ((x.to_bits() >> 23) & 0xff) as i32 as f32 - 126.0),
        )
    }
    #[inline(always)]
    fn pow2(n: Self) -> Self {
        // n + 127 + 2^23 holds the biased exponent n + 127 in its low mantissa bits (exact).
        (n + Self::splat(EXPONENT_SHIFT)).map_bits(|b| b << 23)
    }
}

/// Natural logarithm of positive normal lanes (Cephes `logf`: about 1 ulp). Zero, negative,
/// subnormal and non-finite inputs give meaningless finite or non-finite results; callers clamp.
#[inline(always)]
pub fn ln<L: Lanes>(x: L) -> L {
    const SQRT_HALF: f32 = std::f32::consts::FRAC_1_SQRT_2;
    // ln 2 split into an exact high part and a correction.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    const P: [f32; 9] = [
        7.037_683_6e-2,
        -1.151_461e-1,
        1.167_699_9e-1,
        -1.242_014_1e-1,
        1.424_932_3e-1,
        -1.666_805_8e-1,
        2.000_071_5e-1,
        -2.499_999_4e-1,
        3.333_333e-1,
    ];
    let (m, e) = x.frexp();
    // m in [sqrt(1/2), sqrt 2): m - 1 is small either way.
    let small = m.lt(L::splat(SQRT_HALF));
    let one = L::splat(1.0);
    let e = e - L::select(small, one, L::splat(0.0));
    let m = L::select(small, m + m, m) - one;
    let z = m * m;
    let mut poly = L::splat(P[0]);
    for &c in &P[1..] {
        poly = poly * m + L::splat(c);
    }
    let y = poly * m * z + e * L::splat(LN2_LO) - L::splat(0.5) * z;
    m + y + e * L::splat(LN2_HI)
}

/// `e^x` (Cephes `expf`: about 1 ulp), for x clamped to [-87, 88] (results stay normal).
#[inline(always)]
pub fn exp<L: Lanes>(x: L) -> L {
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    const P: [f32; 6] = [
        1.987_569_1e-4,
        1.398_2e-3,
        8.333_452e-3,
        4.166_579_6e-2,
        1.666_666_5e-1,
        0.5,
    ];
    let x = x.max(L::splat(-87.0)).min(L::splat(88.0));
    let n = (x * L::splat(std::f32::consts::LOG2_E) + L::splat(0.5)).floor();
    let r = x - n * L::splat(LN2_HI) - n * L::splat(LN2_LO);
    let mut poly = L::splat(P[0]);
    for &c in &P[1..] {
        poly = poly * r + L::splat(c);
    }
    let y = poly * r * r + r + L::splat(1.0);
    y * L::pow2(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bit tricks of `floor`, `pow2`, `frexp` and `pow2_normalizers` are exact.
    #[test]
    fn exact_lane_tricks() {
        let mut x = -4_194_303.0f32;
        while x < 4_194_303.0 {
            for x in [x, -x, x * 1e-6, x * 1e-6 + 0.5, (x * 1e-6).round()] {
                let got = Wide::<8>::splat(x).floor().lane(3);
                assert_eq!(got, x.floor(), "floor {x}");
            }
            x += 1234.567;
        }
        for n in -126..=127 {
            let got = Wide::<4>::pow2(Wide::splat(n as f32)).lane(0);
            assert_eq!(got, 2f32.powi(n), "2^{n}");
        }
        for x in [1e-30f32, 0.3, 1.0, 1.5, 7.0, 3e30] {
            let (m, e) = Wide::<4>::splat(x).frexp();
            assert!((0.5..1.0).contains(&m.lane(1)), "{x}");
            assert_eq!(m.lane(1) * 2f32.powi(e.lane(1) as i32), x);
            let (scale, unscale) = Wide::<4>::splat(x).pow2_normalizers();
            assert!((1.0..2.0).contains(&(x * scale.lane(2))), "{x}");
            assert_eq!(scale.lane(2) * unscale.lane(2), 1.0);
        }
    }

    /// ln and exp against f64 over the ranges the constitutive update uses.
    #[test]
    fn ln_and_exp_are_accurate() {
        let mut worst_ln = 0.0f64;
        let mut x = 1e-6f32;
        while x < 1e6 {
            let xs = [x, x * 1.000_1, x * 1.3, x * 1.7];
            let got = ln(Wide::from_array(xs)).to_array();
            for (g, x) in got.iter().zip(xs) {
                let exact = (x as f64).ln();
                worst_ln = worst_ln.max((*g as f64 - exact).abs() / exact.abs().max(1.0));
            }
            x *= 1.013;
        }
        assert!(worst_ln < 2e-7, "ln: worst error {worst_ln:e}");
        let mut worst_exp = 0.0f64;
        let mut x = -80.0f32;
        while x < 80.0 {
            let xs = [x, x + 1e-4, x + 0.3, -x * 1e-3];
            let got = exp(Wide::<8>::from_fn(|k| if k < 4 { xs[k] } else { 0.0 }));
            for (k, x) in xs.iter().enumerate() {
                let exact = (*x as f64).exp();
                worst_exp = worst_exp.max((got.lane(k) as f64 - exact).abs() / exact);
            }
            x += 0.0137;
        }
        assert!(worst_exp < 3e-7, "exp: worst relative error {worst_exp:e}");
        // Near 1 the logarithm is small: its absolute error must be too (Hencky strains).
        for k in 1..1000 {
            let x = 1.0 + (k as f32 - 500.0) * 1e-6;
            let g = ln(Wide::<1>::splat(x)).to_array()[0] as f64;
            assert!((g - (x as f64).ln()).abs() < 1.2e-7 * (x as f64).ln().abs() + 1e-12);
        }
    }
}
