//! Fast 3x3 singular value decomposition in the "rotation-variant" form used by MPM and FEM.
//!
//! [`svd3`] returns `a = u * diag(sigma) * v^T` with `u`, `v` proper rotations (det +1) and
//! `sigma[0] >= sigma[1] >= |sigma[2]|`, where `sigma[2] < 0` exactly when `det(a) < 0`: an
//! inverted element shows up as a negative smallest singular value, never as a reflection hidden
//! in `u` or `v` (Irving et al. 2004; McAdams et al. 2011).
//!
//! Method of McAdams, Selle, Tamstorf, Teran and Sifakis 2011, "Computing the singular value
//! decomposition of 3x3 matrices with minimal branching and elementary floating point
//! operations" (UW-Madison CS TR1690):
//! 1. scale `a` by a power of two so that its largest entry lies in [1, 2) (exact; no overflow
//!    for any finite input, and underflow only of parts below ~1e-19 of the largest entry);
//! 2. [`JACOBI_SWEEPS`] cyclic Jacobi sweeps on the symmetric `a^T a`, with the paper's
//!    approximate (quaternion half-angle) Givens rotations and its rescaling trick, so the only
//!    square root is an inexact reciprocal one; `v` is accumulated as a quaternion;
//! 3. `b = a v`, columns sorted by decreasing norm (each swap negates one column: det v stays +1);
//! 4. Givens QR of `b` with exact rotations: `u` is their product, `sigma` the diagonal of `r`.
//!
//! No heap and no data-dependent branches: every choice is a lane-wise select. The arithmetic is
//! written on 4 lanes (SSE on x86_64, plain arrays elsewhere): [`svd3`] broadcasts one matrix,
//! [`svd3_x4`] decomposes four independent matrices for about the price of one.
//!
//! Accuracy (f32): reconstruction error below 1e-6 `|a|` on random matrices, `u` and `v`
//! orthonormal to about 1e-6. Forming `a^T a` squares the condition number, so for matrices with
//! `sigma[1] / sigma[0]` below about 1e-2 (nearly rank one but not exactly) the two small
//! singular directions lose accuracy (error about `1e-7 * sigma[0] / sigma[1]` relative to `|a|`);
//! deformation gradients are nowhere near that regime.

use nalgebra::{Matrix3, Vector3};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// `a = u * diag(sigma) * v^T`; see the module documentation for the conventions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Svd3 {
    /// Left singular vectors (columns), a proper rotation.
    pub u: Matrix3<f32>,
    /// Singular values, `sigma[0] >= sigma[1] >= |sigma[2]|`, `sigma[2] < 0` iff `det(a) < 0`.
    pub sigma: Vector3<f32>,
    /// Right singular vectors (columns), a proper rotation.
    pub v: Matrix3<f32>,
}

/// Singular value decomposition of one matrix; see the module documentation.
#[inline]
pub fn svd3(a: &Matrix3<f32>) -> Svd3 {
    let [r, ..] = svd_lanes(|i, j| F4::splat(a[(i, j)]));
    r
}

/// Four independent decompositions at once, each exactly as [`svd3`] would give it; costs about
/// as much as one call of [`svd3`], so batch particles when the SVD dominates.
#[inline]
pub fn svd3_x4(a: &[Matrix3<f32>; 4]) -> [Svd3; 4] {
    svd_lanes(|i, j| F4::from_array([a[0][(i, j)], a[1][(i, j)], a[2][(i, j)], a[3][(i, j)]]))
}

/// Cyclic Jacobi sweeps (3 rotations each). The paper uses 4; with its approximate rotations
/// 4 leave errors up to 1e-2 on random matrices, 5 up to 1e-5, 6 below 1e-6.
pub const JACOBI_SWEEPS: usize = 6;
/// `(1 + sqrt 2)^2`: the approximate Jacobi half-angle is trusted only below pi/8.
const GAMMA: f32 = 5.828_427;
const COS_PI_8: f32 = 0.923_879_5;
const SIN_PI_8: f32 = 0.382_683_43;
/// Squared magnitude below which a rotation is not attempted (the scaled `a^T a` has trace >= 1,
/// so such values are rounding noise).
const TINY: f32 = 1e-30;
/// Off-diagonal entries of the scaled `a^T a` (trace >= 1) below this are set to zero when
/// they enter the rotations of other pairs: they are below its rounding noise, and letting
/// them shrink further would produce subnormals, which are very slow.
const FLUSH: f32 = 1e-10;

type Mat = [[F4; 3]; 3];

/// Builds a matrix entry by entry (written out: `array::map` does not reliably inline).
#[inline(always)]
fn mat(f: impl Fn(usize, usize) -> F4) -> Mat {
    let row = |i| [f(i, 0), f(i, 1), f(i, 2)];
    [row(0), row(1), row(2)]
}

/// One approximate Jacobi rotation of the symmetric `s` in the (P, Q) plane ((P, Q, K) cyclic):
/// `s <- g^T s g` up to a positive factor (McAdams et al. algorithm 2 with their rescaling),
/// with `g` accumulated into the quaternion `quat` = [x, y, z, w] (`v <- v g`).
#[inline(always)]
fn jacobi_rotation<const P: usize, const Q: usize, const K: usize>(
    s: &mut Mat,
    quat: &mut [F4; 4],
) {
    let flush = |x: F4| F4::select(x.abs().lt(F4::splat(FLUSH)), F4::splat(0.0), x);
    let (spp, sqq, skk, spq) = (s[P][P], s[Q][Q], s[K][K], s[P][Q]);
    // Flushed here, off the critical path; s_pq is flushed whenever it enters another rotation.
    let (spk, sqk) = (flush(s[P][K]), flush(s[Q][K]));
    // Half-angle of the rotation that zeroes s_pq, to first order: tan = s_pq / (2 (s_pp - s_qq)).
    let (ch, sh) = (2.0 * (spp - sqq), spq);
    let (ch2, sh2) = (ch * ch, sh * sh);
    let w = (ch2 + sh2).rsqrt_approx();
    let use_approx = (GAMMA * sh2 + F4::splat(TINY)).lt(ch2);
    // Beyond pi/8 the paper's fixed pi/8; nothing to do where s_pq is exactly zero.
    let sh_zero = sh.eq(F4::splat(0.0));
    let ch_fixed = F4::select(sh_zero, F4::splat(1.0), F4::splat(COS_PI_8));
    let sh_fixed = F4::select(sh_zero, F4::splat(0.0), F4::splat(SIN_PI_8));
    let ch = F4::select(use_approx, w * ch, ch_fixed);
    let sh = F4::select(use_approx, w * sh, sh_fixed);
    // Rotation by twice the half-angle, scaled by g = ch^2 + sh^2 (1 up to the inexact rsqrt):
    // the whole of s is scaled by g^2 so that it stays a similarity transform.
    let (ch2, sh2) = (ch * ch, sh * sh);
    let g = ch2 + sh2;
    let (c, sn) = (ch2 - sh2, 2.0 * (ch * sh));
    let (cc, ss, cs) = (c * c, sn * sn, c * sn);
    let cs2 = 2.0 * cs;
    s[P][P] = cc * spp + cs2 * spq + ss * sqq;
    s[Q][Q] = ss * spp - cs2 * spq + cc * sqq;
    s[P][Q] = (cc - ss) * spq - cs * (spp - sqq);
    s[Q][P] = s[P][Q];
    let (gc, gs) = (g * c, g * sn);
    s[P][K] = gc * spk + gs * sqk;
    s[K][P] = s[P][K];
    s[Q][K] = gc * sqk - gs * spk;
    s[K][Q] = s[Q][K];
    s[K][K] = (g * g) * skk;
    let (vp, vq, vk, vw) = (quat[P], quat[Q], quat[K], quat[3]);
    quat[P] = ch * vp + sh * vq;
    quat[Q] = ch * vq - sh * vp;
    quat[K] = ch * vk + sh * vw;
    quat[3] = ch * vw - sh * vk;
}

/// Rotation matrix of a non-zero, not necessarily normalised quaternion [x, y, z, w].
#[inline(always)]
fn quat_to_mat([x, y, z, w]: [F4; 4]) -> Mat {
    let k = F4::splat(2.0) / (x * x + y * y + z * z + w * w);
    let (kx, ky, kz) = (k * x, k * y, k * z);
    let (xx, yy, zz, xy, yz, zx) = (kx * x, ky * y, kz * z, kx * y, ky * z, kz * x);
    let (wx, wy, wz) = (kx * w, ky * w, kz * w);
    let one = F4::splat(1.0);
    [
        [one - yy - zz, xy - wz, zx + wy],
        [xy + wz, one - xx - zz, yz - wx],
        [zx - wy, yz + wx, one - xx - yy],
    ]
}

/// Sorting-network step on columns I < J of `b` and `v`: if column J is longer, swap the two and
/// negate the one moved to J (keeps det v = +1 and b = a v).
#[inline(always)]
fn sort_columns<const I: usize, const J: usize>(b: &mut Mat, v: &mut Mat, norm2: &mut [F4; 3]) {
    let swap = norm2[I].lt(norm2[J]);
    for row in b.iter_mut().chain(v.iter_mut()) {
        let (x, y) = (row[I], row[J]);
        row[I] = F4::select(swap, y, x);
        row[J] = F4::select(swap, -x, y);
    }
    let (x, y) = (norm2[I], norm2[J]);
    norm2[I] = F4::select(swap, y, x);
    norm2[J] = F4::select(swap, x, y);
}

/// Givens QR step zeroing `b[Q][P]` (rows P < Q): `b <- g^T b`, `u <- u g`, with `g` the rotation
/// mapping (b_PP, b_QP) to (hypot, 0), so the new b_PP is non-negative.
#[inline(always)]
fn qr_rotation<const P: usize, const Q: usize>(b: &mut Mat, u: &mut Mat) {
    let (a1, a2) = (b[P][P], b[Q][P]);
    let rho2 = a1 * a1 + a2 * a2;
    let r = F4::splat(1.0) / rho2.sqrt();
    let big = F4::splat(TINY).lt(rho2);
    let c = F4::select(big, a1 * r, a1.sign_one());
    let s = F4::select(big, a2 * r, F4::splat(0.0));
    let (upper, lower) = b.split_at_mut(Q);
    for (x, y) in upper[P].iter_mut().zip(lower[0].iter_mut()).skip(P) {
        (*x, *y) = (c * *x + s * *y, c * *y - s * *x);
    }
    for row in u.iter_mut() {
        let (x, y) = (row[P], row[Q]);
        row[P] = c * x + s * y;
        row[Q] = c * y - s * x;
    }
}

/// The decomposition on 4 lanes; `entry(i, j)` gives a_ij of each lane.
#[inline(always)]
fn svd_lanes(entry: impl Fn(usize, usize) -> F4) -> [Svd3; 4] {
    // 1. Exact power-of-two scaling: largest |entry| into [1, 2).
    let a = mat(entry);
    let m = |i: usize| a[i][0].abs().max(a[i][1].abs()).max(a[i][2].abs());
    let max_abs = m(0).max(m(1)).max(m(2));
    let (scale, unscale) = max_abs.pow2_normalizers();
    let a = mat(|i, j| a[i][j] * scale);

    // 2. Jacobi eigen-decomposition of s = a^T a, v accumulated as a quaternion.
    let mut s = mat(|i, j| a[0][i] * a[0][j] + a[1][i] * a[1][j] + a[2][i] * a[2][j]);
    let (zero, one) = (F4::splat(0.0), F4::splat(1.0));
    let mut quat = [zero, zero, zero, one];
    for _ in 0..JACOBI_SWEEPS {
        jacobi_rotation::<0, 1, 2>(&mut s, &mut quat);
        jacobi_rotation::<1, 2, 0>(&mut s, &mut quat);
        jacobi_rotation::<2, 0, 1>(&mut s, &mut quat);
    }
    let mut v = quat_to_mat(quat);

    // 3. b = a v, columns by decreasing norm.
    let mut b = mat(|i, j| a[i][0] * v[0][j] + a[i][1] * v[1][j] + a[i][2] * v[2][j]);
    let norm2 = |j: usize| b[0][j] * b[0][j] + b[1][j] * b[1][j] + b[2][j] * b[2][j];
    let mut norm2 = [norm2(0), norm2(1), norm2(2)];
    sort_columns::<0, 1>(&mut b, &mut v, &mut norm2);
    sort_columns::<0, 2>(&mut b, &mut v, &mut norm2);
    sort_columns::<1, 2>(&mut b, &mut v, &mut norm2);

    // 4. QR: b = u r, sigma = diag(r) (r_00, r_11 >= 0; r_22 carries the sign of det a).
    let mut u = mat(|i, j| if i == j { one } else { zero });
    qr_rotation::<0, 1>(&mut b, &mut u);
    qr_rotation::<0, 2>(&mut b, &mut u);
    qr_rotation::<1, 2>(&mut b, &mut u);
    // Enforce the ordering exactly (violations are rounding-level only).
    let s0 = b[0][0] * unscale;
    let s1 = (b[1][1] * unscale).min(s0);
    let s2 = (b[2][2] * unscale).min(s1).max(-s1);

    let mut out = [Svd3 {
        u: Matrix3::zeros(),
        sigma: Vector3::zeros(),
        v: Matrix3::zeros(),
    }; 4];
    for (k, x) in [s0, s1, s2].into_iter().enumerate() {
        for (o, x) in out.iter_mut().zip(x.to_array()) {
            o.sigma[k] = x;
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            for (o, (x, y)) in out
                .iter_mut()
                .zip(u[i][j].to_array().into_iter().zip(v[i][j].to_array()))
            {
                (o.u[(i, j)], o.v[(i, j)]) = (x, y);
            }
        }
    }
    out
}

/// Four f32 lanes. Comparisons return lane masks (all bits set or clear) stored as `F4`.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct F4(std::arch::x86_64::__m128);

// SAFETY (every `unsafe` block in this impl): SSE and SSE2 belong to the x86_64 baseline, so the
// intrinsics are always available; none of them dereferences a pointer.
#[cfg(target_arch = "x86_64")]
impl F4 {
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_set1_ps(x) })
    }
    #[inline(always)]
    fn from_array(a: [f32; 4]) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_setr_ps(a[0], a[1], a[2], a[3]) })
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 4] {
        unsafe { std::mem::transmute::<std::arch::x86_64::__m128, [f32; 4]>(self.0) }
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        use std::arch::x86_64::*;
        Self(unsafe { _mm_or_ps(_mm_and_ps(mask.0, a.0), _mm_andnot_ps(mask.0, b.0)) })
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_cmplt_ps(self.0, o.0) })
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_cmpeq_ps(self.0, o.0) })
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_andnot_ps(Self::splat(-0.0).0, self.0) })
    }
    /// +1 or -1 with the sign bit of `self`.
    #[inline(always)]
    fn sign_one(self) -> Self {
        use std::arch::x86_64::*;
        let sign = unsafe { _mm_and_ps(Self::splat(-0.0).0, self.0) };
        Self(unsafe { _mm_or_ps(sign, Self::splat(1.0).0) })
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_min_ps(self.0, o.0) })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_max_ps(self.0, o.0) })
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_sqrt_ps(self.0) })
    }
    /// About 12 bits; exactness is not needed where it is used.
    #[inline(always)]
    fn rsqrt_approx(self) -> Self {
        Self(unsafe { std::arch::x86_64::_mm_rsqrt_ps(self.0) })
    }
    /// (2^(127-e), 2^(e-127)) with e the biased exponent of `self`, clamped to [1, 253].
    #[inline(always)]
    fn pow2_normalizers(self) -> (Self, Self) {
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
struct F4([f32; 4]);

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
    fn splat(x: f32) -> Self {
        Self([x; 4])
    }
    fn from_array(a: [f32; 4]) -> Self {
        Self(a)
    }
    fn to_array(self) -> [f32; 4] {
        self.0
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        Self([0, 1, 2, 3].map(|i| {
            let m = mask.0[i].to_bits();
            f32::from_bits((a.0[i].to_bits() & m) | (b.0[i].to_bits() & !m))
        }))
    }
    fn lt(self, o: Self) -> Self {
        self.zip(o, |x, y| Self::mask(x < y))
    }
    fn eq(self, o: Self) -> Self {
        self.zip(o, |x, y| Self::mask(x == y))
    }
    fn abs(self) -> Self {
        self.map(f32::abs)
    }
    fn sign_one(self) -> Self {
        self.map(|x| 1f32.copysign(x))
    }
    fn min(self, o: Self) -> Self {
        self.zip(o, |x, y| if x < y { x } else { y })
    }
    fn max(self, o: Self) -> Self {
        self.zip(o, |x, y| if x > y { x } else { y })
    }
    fn sqrt(self) -> Self {
        self.map(f32::sqrt)
    }
    fn rsqrt_approx(self) -> Self {
        self.map(|x| 1.0 / x.sqrt())
    }
    fn pow2_normalizers(self) -> (Self, Self) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    use std::hint::black_box;
    use std::time::Instant;

    fn gaussian(rng: &mut SmallRng) -> Matrix3<f32> {
        Matrix3::from_fn(|_, _| rng.sample(StandardNormal))
    }

    fn rotation(rng: &mut SmallRng) -> Matrix3<f32> {
        let q = nalgebra::Quaternion::new(
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
        );
        *nalgebra::UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .matrix()
    }

    /// Checks every property of the contract; returns the relative reconstruction error.
    fn check(a: &Matrix3<f32>) -> f32 {
        let r = svd3(a);
        let ctx = || format!("a = {a:?}, svd = {r:?}");
        let norm = a.norm();
        let rec = r.u * Matrix3::from_diagonal(&r.sigma) * r.v.transpose();
        let err = (rec - a).norm();
        assert!(err <= 1e-5 * norm, "reconstruction error {err}: {}", ctx());
        for m in [&r.u, &r.v] {
            let ortho = (m.transpose() * m - Matrix3::identity()).norm();
            assert!(ortho < 2e-6, "orthonormality {ortho}: {}", ctx());
            assert!((m.determinant() - 1.0).abs() < 2e-6, "det: {}", ctx());
        }
        let s = r.sigma;
        assert!(s[0] >= s[1] && s[1] >= s[2].abs(), "ordering: {}", ctx());
        assert!(s.iter().all(|x| x.is_finite()), "finite: {}", ctx());
        // Sign convention, wherever the sign of det(a) is numerically meaningful.
        let det = a.cast::<f64>().determinant();
        let vol = s[0] as f64 * s[1] as f64 * (norm as f64);
        if det.abs() > 1e-4 * vol {
            assert_eq!(s[2] < 0.0, det < 0.0, "sign of sigma[2]: {}", ctx());
        }
        err / norm.max(f32::MIN_POSITIVE)
    }

    #[test]
    fn random_near_rotations() {
        let mut rng = SmallRng::seed_from_u64(1);
        let mut worst = 0.0f32;
        for i in 0..20_000 {
            // Elastic-plastic deformation gradients: rotation times a moderate perturbation.
            let amp = [1e-6, 1e-3, 0.1, 0.5][i % 4];
            let f = rotation(&mut rng) * (Matrix3::identity() + amp * gaussian(&mut rng));
            worst = worst.max(check(&f));
        }
        assert!(worst < 2e-6, "worst relative error {worst}");
    }

    #[test]
    fn random_general() {
        let mut rng = SmallRng::seed_from_u64(2);
        let mut worst = 0.0f32;
        for i in 0..20_000 {
            let a = if i % 2 == 0 {
                gaussian(&mut rng)
            } else {
                Matrix3::from_fn(|_, _| rng.random_range(-1.0..1.0))
            };
            worst = worst.max(check(&a));
        }
        assert!(worst < 3e-6, "worst relative error {worst}");
    }

    #[test]
    fn prescribed_singular_values() {
        // Random rotations around chosen spectra: repeated, rank-deficient, inverted, anisotropic.
        let spectra: [[f32; 3]; 14] = [
            [1.0, 1.0, 1.0],
            [1.0, 1.0, -1.0],
            [2.0, 2.0, 1.0],
            [2.0, 1.0, 1.0],
            [2.0, 1.0, -1.0],
            [3.0, 2.0, 0.0],
            [1.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1e-4, 1e-4],
            [1.0, 0.5, 1e-6],
            [1.0, 0.3, -1e-3],
            [10.0, 1.0, 0.1],
            [1.0 + 1e-6, 1.0, 1.0 - 1e-6],
            [0.0, 0.0, 0.0],
        ];
        let mut rng = SmallRng::seed_from_u64(3);
        for sv in spectra {
            for _ in 0..500 {
                let a = rotation(&mut rng)
                    * Matrix3::from_diagonal(&Vector3::from(sv))
                    * rotation(&mut rng).transpose();
                check(&a);
                let s = svd3(&a).sigma;
                let scale = sv[0].max(1.0);
                for k in 0..3 {
                    assert!((s[k] - sv[k]).abs() < 2e-6 * scale, "{sv:?} -> {s:?}");
                }
            }
        }
    }

    #[test]
    fn degenerate_cases() {
        let i = Matrix3::identity();
        let d = |x: f32, y: f32, z: f32| Matrix3::from_diagonal(&Vector3::new(x, y, z));
        let mut rng = SmallRng::seed_from_u64(4);
        let n = Vector3::new(1.0, 2.0, -2.0) / 3.0;
        let mut cases = vec![
            i,
            -i,
            Matrix3::zeros(),
            d(1.0, 1.0, -1.0),
            d(-1.0, 1.0, 1.0),
            d(-1.0, -1.0, 1.0),
            d(0.5, -3.0, 2.0),
            d(0.0, 0.0, 5.0),
            d(0.0, -2.0, 0.0),
            i - 2.0 * n * n.transpose(), // Householder reflection
            n * Vector3::new(3.0, -1.0, 2.0).transpose(), // rank one
            Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0), // permutation, det +1
            Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0), // permutation, det -1
            Matrix3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0), // rank two
            Matrix3::from_element(1.0),
            Matrix3::new(1e-30, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        ];
        for _ in 0..200 {
            cases.push(rotation(&mut rng));
            cases.push(rotation(&mut rng) * d(1.0, 1.0, -1.0)); // improper orthogonal
        }
        for a in &cases {
            check(a);
        }
        // Orthogonal matrices have all |sigma| = 1, with sign det.
        for a in &cases[cases.len() - 400..] {
            let s = svd3(a).sigma;
            let expect = Vector3::new(1.0, 1.0, a.determinant().signum());
            assert!((s - expect).norm() < 2e-6, "{a:?} -> {s:?}");
        }
        let z = svd3(&Matrix3::zeros());
        assert_eq!(z.sigma, Vector3::zeros());
        assert_eq!(svd3(&-i).sigma, Vector3::new(1.0, 1.0, -1.0));
        assert_eq!(svd3(&i).sigma, Vector3::new(1.0, 1.0, 1.0));
    }

    #[test]
    fn tiny_and_huge_scales() {
        let mut rng = SmallRng::seed_from_u64(5);
        for exp in (-36..=36).step_by(3) {
            let scale = 10f32.powi(exp);
            for _ in 0..200 {
                let a = gaussian(&mut rng);
                let big = a * scale;
                check(&big);
                let (r, rb) = (svd3(&a), svd3(&big));
                assert!(
                    (rb.sigma / scale - r.sigma).norm() < 1e-5 * r.sigma[0],
                    "{exp}"
                );
            }
        }
        // Mixed magnitudes within one matrix.
        let a = Matrix3::new(1e10, 0.0, 0.0, 0.0, 1e-10, 0.0, 0.0, 0.0, -1.0);
        let s = svd3(&a).sigma;
        let expect = Vector3::new(1e10, 1.0, -1e-10);
        assert!(
            (s - expect)
                .abs()
                .iter()
                .zip(&expect)
                .all(|(d, e)| *d <= 1e-6 * e.abs()),
            "{s:?}"
        );
        check(&a);
    }

    #[test]
    fn singular_values_agree_with_nalgebra() {
        let mut rng = SmallRng::seed_from_u64(6);
        for i in 0..5_000 {
            let a = if i % 2 == 0 {
                gaussian(&mut rng)
            } else {
                rotation(&mut rng) * (Matrix3::identity() + 0.2 * gaussian(&mut rng))
            };
            let ours = svd3(&a).sigma;
            let mut reference: Vec<f32> = a
                .svd(false, false)
                .singular_values
                .iter()
                .copied()
                .collect();
            reference.sort_by(|x, y| y.total_cmp(x));
            let mut exact: Vec<f64> = a
                .cast::<f64>()
                .svd(false, false)
                .singular_values
                .iter()
                .copied()
                .collect();
            exact.sort_by(|x, y| y.total_cmp(x));
            for k in 0..3 {
                let o = ours[k].abs();
                assert!((o - reference[k]).abs() < 2e-6 * reference[0], "{a:?}");
                assert!((o as f64 - exact[k]).abs() < 1e-6 * exact[0], "{a:?}");
            }
        }
    }

    /// `cargo test --release --lib mpm::svd::tests::bench -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn bench_svd3_vs_nalgebra() {
        let mut rng = SmallRng::seed_from_u64(7);
        let inputs: Vec<Matrix3<f32>> = (0..4096)
            .map(|_| rotation(&mut rng) * (Matrix3::identity() + 0.1 * gaussian(&mut rng)))
            .collect();
        // Best of many short runs over the same inputs: robust to other load on the machine.
        let time = |name: &str, runs: usize, f: &dyn Fn(&[Matrix3<f32>]) -> f32| {
            let mut best = f64::INFINITY;
            for _ in 0..runs {
                let start = Instant::now();
                black_box(f(black_box(&inputs)));
                best = best.min(start.elapsed().as_secs_f64());
            }
            println!(
                "{name}: {:.1} ns per matrix",
                best * 1e9 / inputs.len() as f64
            );
        };
        let sum = |r: &Svd3| r.sigma[2] + r.u[(1, 2)] + r.v[(2, 1)];
        time("svd3, independent calls", 300, &|xs| {
            xs.iter().map(|a| sum(&svd3(a))).sum()
        });
        time("svd3_x4, 4 matrices per call", 300, &|xs| {
            let quads = xs
                .chunks_exact(4)
                .map(|c| <&[Matrix3<f32>; 4]>::try_from(c).unwrap());
            quads.map(|q| svd3_x4(q).iter().map(sum).sum::<f32>()).sum()
        });
        time("svd3, dependent chain (latency)", 300, &|xs| {
            xs.iter()
                .fold(0.0, |carry, a| sum(&svd3(&a.add_scalar(carry * 0.0))))
        });
        time("nalgebra svd (f32, with u and v)", 30, &|xs| {
            let f = |a: &Matrix3<f32>| {
                let r = a.svd(true, true);
                r.singular_values[2] + r.u.unwrap()[(1, 2)] + r.v_t.unwrap()[(2, 1)]
            };
            xs.iter().map(f).sum()
        });
    }
}
