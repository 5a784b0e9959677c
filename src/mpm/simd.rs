//! Four f32 lanes with the few operations the hot loops need: SSE on x86_64 (part of its
//! baseline, so always available), plain arrays elsewhere. Used for four particles at once (the
//! SVD) and for the four components of a grid node (`[p_x, p_y, p_z, m]`) in P2G and G2P.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Four f32 lanes. Comparisons return lane masks (all bits set or clear) stored as `F4`.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub struct F4(std::arch::x86_64::__m128);

// SAFETY (every `unsafe` block in this impl): SSE and SSE2 belong to the x86_64 baseline, so the
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
    #[inline(always)]
    pub fn select(mask: Self, a: Self, b: Self) -> Self {
        use std::arch::x86_64::*;
        Self(unsafe { _mm_or_ps(_mm_and_ps(mask.0, a.0), _mm_andnot_ps(mask.0, b.0)) })
    }
    #[inline(always)]
    pub fn lt(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_cmplt_ps(self.0, o.0) })
    }
    #[inline(always)]
    pub fn eq(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_cmpeq_ps(self.0, o.0) })
    }
    #[inline(always)]
    pub fn abs(self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_andnot_ps(Self::splat(-0.0).0, self.0) })
    }
    /// +1 or -1 with the sign bit of `self`.
    #[inline(always)]
    pub fn sign_one(self) -> Self {
        use std::arch::x86_64::*;
        let sign = unsafe { _mm_and_ps(Self::splat(-0.0).0, self.0) };
        Self(unsafe { _mm_or_ps(sign, Self::splat(1.0).0) })
    }
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_min_ps(self.0, o.0) })
    }
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_max_ps(self.0, o.0) })
    }
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_sqrt_ps(self.0) })
    }
    /// `1 / sqrt(x)`, correctly rounded twice (square root, then division), so every x86-64
    /// CPU gives the same bits. `_mm_rsqrt_ps` would be faster, but its 12-bit approximation
    /// differs between CPU vendors (and emulators), which made runs differ between machines.
    #[inline(always)]
    pub fn rsqrt(self) -> Self {
        use std::arch::x86_64::*;
        Self(unsafe { _mm_div_ps(_mm_set1_ps(1.0), _mm_sqrt_ps(self.0)) })
    }
    /// Lane-wise AND of two masks.
    #[inline(always)]
    pub fn and(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_and_ps(self.0, o.0) })
    }
    /// Lane-wise OR of two masks.
    #[inline(always)]
    pub fn or(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_or_ps(self.0, o.0) })
    }
    /// `floor(x)` for |x| < 2^31 (SSE2 has no rounding instruction: truncate, then step down
    /// where truncation rounded up).
    #[inline(always)]
    pub fn floor(self) -> Self {
        use std::arch::x86_64::*;
        unsafe {
            let t = _mm_cvtepi32_ps(_mm_cvttps_epi32(self.0));
            let above = _mm_and_ps(_mm_cmpgt_ps(t, self.0), _mm_set1_ps(1.0));
            Self(_mm_sub_ps(t, above))
        }
    }
    /// `(m, e)` with `x = m 2^e`, `m` in [0.5, 1), `e` an integer as f32; for positive normal x.
    #[inline(always)]
    pub fn frexp(self) -> (Self, Self) {
        use std::arch::x86_64::*;
        unsafe {
            let bits = _mm_castps_si128(self.0);
            let e = _mm_sub_epi32(_mm_srli_epi32::<23>(bits), _mm_set1_epi32(126));
            let m = _mm_or_si128(
                _mm_and_si128(bits, _mm_set1_epi32(0x807f_ffff_u32 as i32)),
                _mm_set1_epi32(0x3f00_0000),
            );
            (Self(_mm_castsi128_ps(m)), Self(_mm_cvtepi32_ps(e)))
        }
    }
    /// `2^n` for integer-valued `n` in [-126, 127].
    #[inline(always)]
    pub fn pow2(n: Self) -> Self {
        use std::arch::x86_64::*;
        unsafe {
            let e = _mm_add_epi32(_mm_cvttps_epi32(n.0), _mm_set1_epi32(127));
            Self(_mm_castsi128_ps(_mm_slli_epi32::<23>(e)))
        }
    }
    /// Whether any lane of a comparison mask is set.
    #[inline(always)]
    pub fn any(self) -> bool {
        unsafe { std::arch::x86_64::_mm_movemask_ps(self.0) != 0 }
    }
    /// (2^(127-e), 2^(e-127)) with e the biased exponent of `self`, clamped to [1, 253].
    #[inline(always)]
    pub fn pow2_normalizers(self) -> (Self, Self) {
        use std::arch::x86_64::*;
        unsafe {
            let e = _mm_srli_epi32::<23>(_mm_castps_si128(self.0));
            // e is in [0, 255]: 16-bit min/max are exact on these 32-bit lanes.
            let e = _mm_min_epi16(_mm_max_epi16(e, _mm_set1_epi32(1)), _mm_set1_epi32(253));
            let scale = _mm_slli_epi32::<23>(_mm_sub_epi32(_mm_set1_epi32(254), e));
            let unscale = _mm_slli_epi32::<23>(e);
            (
                Self(_mm_castsi128_ps(scale)),
                Self(_mm_castsi128_ps(unscale)),
            )
        }
    }
}

#[cfg(target_arch = "x86_64")]
macro_rules! f4_binop {
    ($tr:ident, $f:ident, $intr:ident) => {
        impl $tr for F4 {
            type Output = F4;
            #[inline(always)]
            fn $f(self, o: F4) -> F4 {
                // SAFETY: SSE is part of the x86_64 baseline.
                F4(unsafe { std::arch::x86_64::$intr(self.0, o.0) })
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
f4_binop!(Add, add, _mm_add_ps);
#[cfg(target_arch = "x86_64")]
f4_binop!(Sub, sub, _mm_sub_ps);
#[cfg(target_arch = "x86_64")]
f4_binop!(Mul, mul, _mm_mul_ps);
#[cfg(target_arch = "x86_64")]
f4_binop!(Div, div, _mm_div_ps);

/// Portable fallback of the same lanes.
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy)]
pub struct F4([f32; 4]);

#[cfg(not(target_arch = "x86_64"))]
impl F4 {
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> Self {
        Self(self.0.map(f))
    }
    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        Self([0, 1, 2, 3].map(|i| f(self.0[i], o.0[i])))
    }
    #[inline(always)]
    fn mask(c: bool) -> f32 {
        f32::from_bits(if c { !0 } else { 0 })
    }
    pub fn splat(x: f32) -> Self {
        Self([x; 4])
    }
    pub fn from_array(a: [f32; 4]) -> Self {
        Self(a)
    }
    pub fn to_array(self) -> [f32; 4] {
        self.0
    }
    #[inline(always)]
    pub fn select(mask: Self, a: Self, b: Self) -> Self {
        Self([0, 1, 2, 3].map(|i| {
            let m = mask.0[i].to_bits();
            f32::from_bits((a.0[i].to_bits() & m) | (b.0[i].to_bits() & !m))
        }))
    }
    pub fn lt(self, o: Self) -> Self {
        self.zip(o, |x, y| Self::mask(x < y))
    }
    pub fn eq(self, o: Self) -> Self {
        self.zip(o, |x, y| Self::mask(x == y))
    }
    pub fn abs(self) -> Self {
        self.map(f32::abs)
    }
    pub fn sign_one(self) -> Self {
        self.map(|x| 1f32.copysign(x))
    }
    pub fn min(self, o: Self) -> Self {
        self.zip(o, |x, y| if x < y { x } else { y })
    }
    pub fn max(self, o: Self) -> Self {
        self.zip(o, |x, y| if x > y { x } else { y })
    }
    pub fn sqrt(self) -> Self {
        self.map(f32::sqrt)
    }
    pub fn rsqrt(self) -> Self {
        self.map(|x| 1.0 / x.sqrt())
    }
    pub fn and(self, o: Self) -> Self {
        Self([0, 1, 2, 3].map(|i| f32::from_bits(self.0[i].to_bits() & o.0[i].to_bits())))
    }
    pub fn or(self, o: Self) -> Self {
        Self([0, 1, 2, 3].map(|i| f32::from_bits(self.0[i].to_bits() | o.0[i].to_bits())))
    }
    pub fn floor(self) -> Self {
        self.map(f32::floor)
    }
    pub fn frexp(self) -> (Self, Self) {
        let bits = self.0.map(f32::to_bits);
        (
            Self(bits.map(|b| f32::from_bits((b & 0x807f_ffff) | 0x3f00_0000))),
            Self(bits.map(|b| ((b >> 23) & 0xff) as f32 - 126.0)),
        )
    }
    pub fn pow2(n: Self) -> Self {
        n.map(|n| f32::from_bits(((n as i32 + 127) as u32) << 23))
    }
    pub fn any(self) -> bool {
        self.0.iter().any(|x| x.to_bits() != 0)
    }
    pub fn pow2_normalizers(self) -> (Self, Self) {
        let e = self.0.map(|x| ((x.to_bits() >> 23) & 0xff).clamp(1, 253));
        (
            Self(e.map(|e| f32::from_bits((254 - e) << 23))),
            Self(e.map(|e| f32::from_bits(e << 23))),
        )
    }
}

#[cfg(not(target_arch = "x86_64"))]
macro_rules! f4_binop {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F4 {
            type Output = F4;
            #[inline(always)]
            fn $f(self, o: F4) -> F4 {
                self.zip(o, |x, y| x $op y)
            }
        }
    };
}
#[cfg(not(target_arch = "x86_64"))]
f4_binop!(Add, add, +);
#[cfg(not(target_arch = "x86_64"))]
f4_binop!(Sub, sub, -);
#[cfg(not(target_arch = "x86_64"))]
f4_binop!(Mul, mul, *);
#[cfg(not(target_arch = "x86_64"))]
f4_binop!(Div, div, /);

impl Neg for F4 {
    type Output = F4;
    #[inline(always)]
    fn neg(self) -> F4 {
        F4::splat(0.0) - self
    }
}

impl Mul<F4> for f32 {
    type Output = F4;
    #[inline(always)]
    fn mul(self, o: F4) -> F4 {
        F4::splat(self) * o
    }
}

/// Lane-wise arithmetic shared by [`F4`] and [`F4x2`], so the SVD is written once for both.
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
    fn sign_one(self) -> Self;
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    fn sqrt(self) -> Self;
    fn rsqrt(self) -> Self;
    fn pow2_normalizers(self) -> (Self, Self);
    /// Whether any lane of a comparison mask is set.
    fn any(self) -> bool;
    fn and(self, o: Self) -> Self;
    fn or(self, o: Self) -> Self;
    fn floor(self) -> Self;
    fn frexp(self) -> (Self, Self);
    fn pow2(n: Self) -> Self;
}

impl Lanes for F4 {
    const N: usize = 4;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        F4::splat(x)
    }
    #[inline(always)]
    fn from_fn(f: impl FnMut(usize) -> f32) -> Self {
        F4::from_array(std::array::from_fn(f))
    }
    #[inline(always)]
    fn lane(self, k: usize) -> f32 {
        self.to_array()[k]
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        F4::select(mask, a, b)
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        F4::lt(self, o)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        F4::eq(self, o)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        F4::abs(self)
    }
    #[inline(always)]
    fn sign_one(self) -> Self {
        F4::sign_one(self)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        F4::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        F4::max(self, o)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        F4::sqrt(self)
    }
    #[inline(always)]
    fn rsqrt(self) -> Self {
        F4::rsqrt(self)
    }
    #[inline(always)]
    fn pow2_normalizers(self) -> (Self, Self) {
        F4::pow2_normalizers(self)
    }
    #[inline(always)]
    fn any(self) -> bool {
        F4::any(self)
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        F4::and(self, o)
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        F4::or(self, o)
    }
    #[inline(always)]
    fn floor(self) -> Self {
        F4::floor(self)
    }
    #[inline(always)]
    fn frexp(self) -> (Self, Self) {
        F4::frexp(self)
    }
    #[inline(always)]
    fn pow2(n: Self) -> Self {
        F4::pow2(n)
    }
}

/// Eight lanes as two independent [`F4`]: each operation is issued twice with no dependency
/// between the halves, which hides the latency of long dependent chains (the Jacobi sweeps).
#[derive(Clone, Copy)]
pub struct F4x2(pub F4, pub F4);

macro_rules! f4x2_binop {
    ($tr:ident, $f:ident) => {
        impl $tr for F4x2 {
            type Output = F4x2;
            #[inline(always)]
            fn $f(self, o: F4x2) -> F4x2 {
                F4x2(self.0.$f(o.0), self.1.$f(o.1))
            }
        }
    };
}
f4x2_binop!(Add, add);
f4x2_binop!(Sub, sub);
f4x2_binop!(Mul, mul);
f4x2_binop!(Div, div);

impl Neg for F4x2 {
    type Output = F4x2;
    #[inline(always)]
    fn neg(self) -> F4x2 {
        F4x2(-self.0, -self.1)
    }
}

impl Lanes for F4x2 {
    const N: usize = 8;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        F4x2(F4::splat(x), F4::splat(x))
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f32) -> Self {
        let lo = <F4 as Lanes>::from_fn(&mut f);
        F4x2(lo, <F4 as Lanes>::from_fn(|k| f(k + 4)))
    }
    #[inline(always)]
    fn lane(self, k: usize) -> f32 {
        if k < 4 {
            self.0.to_array()[k]
        } else {
            self.1.to_array()[k - 4]
        }
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        F4x2(F4::select(mask.0, a.0, b.0), F4::select(mask.1, a.1, b.1))
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        F4x2(self.0.lt(o.0), self.1.lt(o.1))
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        F4x2(self.0.eq(o.0), self.1.eq(o.1))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        F4x2(self.0.abs(), self.1.abs())
    }
    #[inline(always)]
    fn sign_one(self) -> Self {
        F4x2(self.0.sign_one(), self.1.sign_one())
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        F4x2(self.0.min(o.0), self.1.min(o.1))
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        F4x2(self.0.max(o.0), self.1.max(o.1))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        F4x2(self.0.sqrt(), self.1.sqrt())
    }
    #[inline(always)]
    fn rsqrt(self) -> Self {
        F4x2(self.0.rsqrt(), self.1.rsqrt())
    }
    #[inline(always)]
    fn pow2_normalizers(self) -> (Self, Self) {
        let ((s0, u0), (s1, u1)) = (self.0.pow2_normalizers(), self.1.pow2_normalizers());
        (F4x2(s0, s1), F4x2(u0, u1))
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.0.any() || self.1.any()
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        F4x2(self.0.and(o.0), self.1.and(o.1))
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        F4x2(self.0.or(o.0), self.1.or(o.1))
    }
    #[inline(always)]
    fn floor(self) -> Self {
        F4x2(self.0.floor(), self.1.floor())
    }
    #[inline(always)]
    fn frexp(self) -> (Self, Self) {
        let ((m0, e0), (m1, e1)) = (self.0.frexp(), self.1.frexp());
        (F4x2(m0, m1), F4x2(e0, e1))
    }
    #[inline(always)]
    fn pow2(n: Self) -> Self {
        F4x2(F4::pow2(n.0), F4::pow2(n.1))
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

    /// ln and exp against f64 over the ranges the constitutive update uses.
    #[test]
    fn ln_and_exp_are_accurate() {
        let mut worst_ln = 0.0f64;
        let mut x = 1e-6f32;
        while x < 1e6 {
            let xs = [x, x * 1.000_1, x * 1.3, x * 1.7];
            let got = ln(F4::from_array(xs)).to_array();
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
            let got = exp(F4x2(F4::from_array(xs), F4::splat(0.0)));
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
            let g = ln(F4::splat(x)).to_array()[0] as f64;
            assert!((g - (x as f64).ln()).abs() < 1.2e-7 * (x as f64).ln().abs() + 1e-12);
        }
    }
}
