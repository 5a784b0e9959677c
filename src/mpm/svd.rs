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
//! 2. cyclic Jacobi sweeps on the symmetric `v0^T a^T a v0`, with the paper's approximate
//!    (quaternion half-angle) Givens rotations and its rescaling trick, so the only square root
//!    is a reciprocal one (correctly rounded, not the paper's `rsqrtps` estimate, whose bits
//!    differ between CPUs: `docs/determinism.md`); `v` is accumulated as a quaternion starting
//!    from `v0`;
//! 3. `b = a v`, columns sorted by decreasing norm (each swap negates one column: det v stays +1);
//! 4. Givens QR of `b` with exact rotations: `u` is their product, `sigma` the diagonal of `r`.
//!
//! Warm start (an addition to the paper): a particle's deformation gradient changes little in one
//! substep, so the Jacobi frame of its previous decomposition (a quaternion the caller keeps)
//! nearly diagonalises the new `a^T a`. Sweeps stop as soon as every lane's off-diagonal part is
//! below [`JACOBI_TOLERANCE`] of the trace (at least [`MIN_SWEEPS`], at most [`MAX_SWEEPS`]):
//! warm, one or two sweeps suffice instead of the six a cold start needs.
//!
//! No heap and no data-dependent branches apart from that stopping test: every choice is a
//! lane-wise select. The arithmetic is written once over [`Lanes`]: [`svd3`] decomposes one
//! matrix, [`svd3_lanes`] `N` independent ones at once (the constitutive update runs as many
//! as its instruction set holds, `simd::InstructionSet`). A lane stops sweeping when it has
//! converged, whatever the other lanes do, so each lane's result is the same bits at any width.
//!
//! Accuracy (f32): reconstruction error below 2e-6 `|a|` on random matrices, `u` and `v`
//! orthonormal to about 1e-6. Forming `a^T a` squares the condition number, so for matrices with
//! `sigma[1] / sigma[0]` below about 1e-2 (nearly rank one but not exactly) the two small
//! singular directions lose accuracy (error about `1e-7 * sigma[0] / sigma[1]` relative to `|a|`);
//! deformation gradients are nowhere near that regime.

use nalgebra::{Matrix3, Vector3};

use super::simd::{array3, mat3, Lanes, Wide};

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

/// A rotation as a unit quaternion `[x, y, z, w]`: the Jacobi frame of a decomposition, kept by
/// the caller to warm-start the next one.
pub type Frame = [f32; 4];
/// The identity rotation: a cold start.
pub const COLD_START: Frame = [0.0, 0.0, 0.0, 1.0];

/// Singular value decomposition of one matrix, from a cold start.
#[inline]
pub fn svd3(a: &Matrix3<f32>) -> Svd3 {
    svd3_warm(a, &mut COLD_START.clone())
}

/// [`svd3`] warm-started from `frame`, which is replaced by the new Jacobi frame.
#[inline]
pub fn svd3_warm(a: &Matrix3<f32>, frame: &mut Frame) -> Svd3 {
    let mut frames = [*frame];
    let [out] = svd3_lanes(&[*a], &mut frames);
    *frame = frames[0];
    out
}

/// `N` independent warm-started decompositions at once, each the same bits as [`svd3_warm`].
#[inline(always)]
pub fn svd3_lanes<const N: usize>(a: &[Matrix3<f32>; N], frames: &mut [Frame; N]) -> [Svd3; N]
where
    Wide<N>: Lanes,
{
    let lanes = mat3!(i, j => Wide::<N>::from_fn(|l| a[l][(i, j)]));
    let frame = [0, 1, 2, 3].map(|k| Wide::from_fn(|l| frames[l][k]));
    let out = svd_lanes(&lanes, frame);
    *frames = std::array::from_fn(|l| out.frame(l));
    std::array::from_fn(|l| out.svd(l))
}

/// Sweeps at least this many times (a warm start from the previous substep needs about one).
pub const MIN_SWEEPS: usize = 1;
/// Never more than this many sweeps: from a cold start the paper's approximate rotations leave
/// errors up to 1e-2 after 4 sweeps, 1e-5 after 5, below 1e-6 after 6 (random matrices).
pub const MAX_SWEEPS: usize = 6;
/// Converged when `|offdiag(s)| < JACOBI_TOLERANCE * trace(s)` in every lane; the relative
/// reconstruction error is then about this size. Just above the rounding noise of `s`.
pub const JACOBI_TOLERANCE: f32 = 2e-7;
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

/// A 3x3 matrix of lanes, row-major.
pub(crate) type Mat<L> = [[L; 3]; 3];

/// `a * b`.
#[inline(always)]
fn mat_mul<L: Lanes>(a: &Mat<L>, b: &Mat<L>) -> Mat<L> {
    mat3!(i, j => a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j])
}

/// One approximate Jacobi rotation of the symmetric `s` in the (P, Q) plane ((P, Q, K) cyclic):
/// `s <- g^T s g` up to a positive factor (McAdams et al. algorithm 2 with their rescaling),
/// with `g` accumulated into the quaternion `quat` = [x, y, z, w] (`v <- v g`).
#[inline(always)]
fn jacobi_rotation<L: Lanes, const P: usize, const Q: usize, const K: usize>(
    s: &mut Mat<L>,
    quat: &mut [L; 4],
) {
    let two = L::splat(2.0);
    let (spp, sqq, skk, spq) = (s[P][P], s[Q][Q], s[K][K], s[P][Q]);
    // Flushed here, off the critical path; s_pq is flushed whenever it enters another rotation.
    let (spk, sqk) = (flush(s[P][K]), flush(s[Q][K]));
    // Half-angle of the rotation that zeroes s_pq, to first order: tan = s_pq / (2 (s_pp - s_qq)).
    let (ch, sh) = (two * (spp - sqq), spq);
    let (ch2, sh2) = (ch * ch, sh * sh);
    let w = (ch2 + sh2).rsqrt();
    let use_approx = (L::splat(GAMMA) * sh2 + L::splat(TINY)).lt(ch2);
    // Beyond pi/8 the paper's fixed pi/8; nothing to do where s_pq is exactly zero.
    let sh_zero = sh.eq(L::splat(0.0));
    let ch_fixed = L::select(sh_zero, L::splat(1.0), L::splat(COS_PI_8));
    let sh_fixed = L::select(sh_zero, L::splat(0.0), L::splat(SIN_PI_8));
    let ch = L::select(use_approx, w * ch, ch_fixed);
    let sh = L::select(use_approx, w * sh, sh_fixed);
    // Rotation by twice the half-angle, scaled by g = ch^2 + sh^2 (1 up to rounding):
    // the whole of s is scaled by g^2 so that it stays a similarity transform.
    let (ch2, sh2) = (ch * ch, sh * sh);
    let g = ch2 + sh2;
    let (c, sn) = (ch2 - sh2, two * (ch * sh));
    let (cc, ss, cs) = (c * c, sn * sn, c * sn);
    let cs2 = two * cs;
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

/// Zero where `|x|` is below [`FLUSH`].
#[inline(always)]
fn flush<L: Lanes>(x: L) -> L {
    L::select(x.abs().lt(L::splat(FLUSH)), L::splat(0.0), x)
}

/// One cyclic Jacobi sweep: the rotations in the (0, 1), (1, 2) and (2, 0) planes.
#[inline(always)]
fn sweep<L: Lanes>(s: &mut Mat<L>, quat: &mut [L; 4]) {
    jacobi_rotation::<L, 0, 1, 2>(s, quat);
    jacobi_rotation::<L, 1, 2, 0>(s, quat);
    jacobi_rotation::<L, 2, 0, 1>(s, quat);
}

/// Mask of the lanes whose `s` is not yet diagonal to [`JACOBI_TOLERANCE`].
#[inline(always)]
fn not_converged<L: Lanes>(s: &Mat<L>) -> L {
    let off = s[0][1] * s[0][1] + s[0][2] * s[0][2] + s[1][2] * s[1][2];
    let trace = s[0][0] + s[1][1] + s[2][2];
    let bound = L::splat(JACOBI_TOLERANCE) * trace;
    (bound * bound).lt(off)
}

/// The quaternion scaled to unit length (the approximate rotations let its norm drift).
#[inline(always)]
fn normalized<L: Lanes>([x, y, z, w]: [L; 4]) -> [L; 4] {
    let k = L::splat(1.0) / (x * x + y * y + z * z + w * w).sqrt();
    [x * k, y * k, z * k, w * k]
}

/// Rotation matrix of a non-zero, not necessarily normalised quaternion [x, y, z, w].
#[inline(always)]
fn quat_to_mat<L: Lanes>([x, y, z, w]: [L; 4]) -> Mat<L> {
    let k = L::splat(2.0) / (x * x + y * y + z * z + w * w);
    let (kx, ky, kz) = (k * x, k * y, k * z);
    let (xx, yy, zz, xy, yz, zx) = (kx * x, ky * y, kz * z, kx * y, ky * z, kz * x);
    let (wx, wy, wz) = (kx * w, ky * w, kz * w);
    let one = L::splat(1.0);
    [
        [one - yy - zz, xy - wz, zx + wy],
        [xy + wz, one - xx - zz, yz - wx],
        [zx - wy, yz + wx, one - xx - yy],
    ]
}

/// Sorting-network step on columns I < J of `b` and `v`: if column J is longer, swap the two and
/// negate the one moved to J (keeps det v = +1 and b = a v).
#[inline(always)]
fn sort_columns<L: Lanes, const I: usize, const J: usize>(
    b: &mut Mat<L>,
    v: &mut Mat<L>,
    norm2: &mut [L; 3],
) {
    let swap = norm2[I].lt(norm2[J]);
    for row in b.iter_mut().chain(v.iter_mut()) {
        let (x, y) = (row[I], row[J]);
        row[I] = L::select(swap, y, x);
        row[J] = L::select(swap, -x, y);
    }
    let (x, y) = (norm2[I], norm2[J]);
    norm2[I] = L::select(swap, y, x);
    norm2[J] = L::select(swap, x, y);
}

/// Givens QR step zeroing `b[Q][P]` (rows P < Q): `b <- g^T b`, `u <- u g`, with `g` the rotation
/// mapping (b_PP, b_QP) to (hypot, 0), so the new b_PP is non-negative.
#[inline(always)]
fn qr_rotation<L: Lanes, const P: usize, const Q: usize>(b: &mut Mat<L>, u: &mut Mat<L>) {
    let (a1, a2) = (b[P][P], b[Q][P]);
    let rho2 = a1 * a1 + a2 * a2;
    let r = L::splat(1.0) / rho2.sqrt();
    let big = L::splat(TINY).lt(rho2);
    let c = L::select(big, a1 * r, a1.sign_one());
    let s = L::select(big, a2 * r, L::splat(0.0));
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

/// The decompositions of all lanes, still in lane form.
pub(crate) struct LaneSvd<L> {
    pub u: Mat<L>,
    pub sigma: [L; 3],
    pub v: Mat<L>,
    /// The new Jacobi frame (unit quaternion).
    pub frame: [L; 4],
    /// Jacobi sweeps it took (read by the tests that pin the warm start).
    #[cfg_attr(not(test), allow(dead_code))]
    pub sweeps: usize,
}

impl<L: Lanes> LaneSvd<L> {
    fn svd(&self, l: usize) -> Svd3 {
        Svd3 {
            u: Matrix3::from_fn(|i, j| self.u[i][j].lane(l)),
            sigma: Vector3::from_fn(|k, _| self.sigma[k].lane(l)),
            v: Matrix3::from_fn(|i, j| self.v[i][j].lane(l)),
        }
    }

    fn frame(&self, l: usize) -> Frame {
        self.frame.map(|q| q.lane(l))
    }
}

/// The decomposition of `a` on all lanes, warm-started from the quaternion `frame`.
#[inline(always)]
pub(crate) fn svd_lanes<L: Lanes>(a: &Mat<L>, frame: [L; 4]) -> LaneSvd<L> {
    // 1. Exact power-of-two scaling: largest |entry| into [1, 2).
    let row_max = array3!(i => a[i][0].abs().max(a[i][1].abs()).max(a[i][2].abs()));
    let max_abs = row_max[0].max(row_max[1]).max(row_max[2]);
    let (scale, unscale) = max_abs.pow2_normalizers();
    let a = mat3!(i, j => a[i][j] * scale);

    // 2. Jacobi eigen-decomposition of s = v0^T a^T a v0, v accumulated as a quaternion.
    let mut quat = frame;
    let b0 = mat_mul(&a, &quat_to_mat(quat));
    let mut s = mat3!(i, j => b0[0][i] * b0[0][j] + b0[1][i] * b0[1][j] + b0[2][i] * b0[2][j]);
    for _ in 0..MIN_SWEEPS {
        sweep(&mut s, &mut quat);
    }
    let mut sweeps = MIN_SWEEPS;
    // Further sweeps only change the lanes not yet converged: a lane's sweeps, and so its bits,
    // do not depend on its neighbours.
    while sweeps < MAX_SWEEPS {
        let active = not_converged(&s);
        if !active.any() {
            break;
        }
        let (mut s_next, mut quat_next) = (s, quat);
        sweep(&mut s_next, &mut quat_next);
        s = mat3!(i, j => L::select(active, s_next[i][j], s[i][j]));
        // Written out: a loop over the four here kept them in memory (the update 17 % slower).
        let [x, y, z] = array3!(k => L::select(active, quat_next[k], quat[k]));
        quat = [x, y, z, L::select(active, quat_next[3], quat[3])];
        sweeps += 1;
    }
    let mut v = quat_to_mat(quat);

    // 3. b = a v, columns by decreasing norm.
    let mut b = mat_mul(&a, &v);
    let mut norm2 = array3!(j => b[0][j] * b[0][j] + b[1][j] * b[1][j] + b[2][j] * b[2][j]);
    sort_columns::<L, 0, 1>(&mut b, &mut v, &mut norm2);
    sort_columns::<L, 0, 2>(&mut b, &mut v, &mut norm2);
    sort_columns::<L, 1, 2>(&mut b, &mut v, &mut norm2);

    // 4. QR: b = u r, sigma = diag(r) (r_00, r_11 >= 0; r_22 carries the sign of det a).
    let (zero, one) = (L::splat(0.0), L::splat(1.0));
    let mut u = mat3!(i, j => if i == j { one } else { zero });
    qr_rotation::<L, 0, 1>(&mut b, &mut u);
    qr_rotation::<L, 0, 2>(&mut b, &mut u);
    qr_rotation::<L, 1, 2>(&mut b, &mut u);
    // Enforce the ordering exactly (violations are rounding-level only).
    let s0 = b[0][0] * unscale;
    let s1 = (b[1][1] * unscale).min(s0);
    let s2 = (b[2][2] * unscale).min(s1).max(-s1);
    LaneSvd {
        u,
        sigma: [s0, s1, s2],
        v,
        frame: normalized(quat),
        sweeps,
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

    /// Each lane of a wide decomposition is the same bits as the matrix decomposed alone, though
    /// its neighbours need more sweeps (random matrices, cold, beside near-rotations, warm).
    #[test]
    fn lanes_are_independent_of_their_neighbours() {
        let mut rng = SmallRng::seed_from_u64(12);
        for _ in 0..200 {
            let a: [Matrix3<f32>; 16] = std::array::from_fn(|l| {
                if l % 3 == 0 {
                    gaussian(&mut rng)
                } else {
                    rotation(&mut rng) * (Matrix3::identity() + 0.01 * gaussian(&mut rng))
                }
            });
            let frames: [Frame; 16] = std::array::from_fn(|l| {
                let q = Vector3::from_fn(|_, _| rng.random_range(-0.2..0.2f32));
                if l % 3 == 0 {
                    COLD_START
                } else {
                    [q.x, q.y, q.z, 1.0]
                }
            });
            let mut wide_frames = frames;
            let wide = svd3_lanes(&a, &mut wide_frames);
            for l in 0..16 {
                let mut frame = frames[l];
                let alone = svd3_warm(&a[l], &mut frame);
                assert_eq!(wide[l], alone, "lane {l}");
                assert_eq!(wide_frames[l], frame, "lane {l}");
            }
        }
    }

    /// A frame from the previous substep halves the sweeps, with cold-start accuracy.
    #[test]
    fn warm_start_needs_fewer_sweeps() {
        let mut rng = SmallRng::seed_from_u64(8);
        let (mut cold_sweeps, mut warm_sweeps) = (0, 0);
        for _ in 0..2_000 {
            let f = rotation(&mut rng) * (Matrix3::identity() + 0.05 * gaussian(&mut rng));
            let lanes = |a: &Matrix3<f32>| mat3!(i, j => Wide::<1>::splat(a[(i, j)]));
            let first = svd_lanes(&lanes(&f), COLD_START.map(Wide::splat));
            cold_sweeps += first.sweeps;
            // One substep later: F <- (I + dt C) F with |dt C| about 1e-3.
            let next = (Matrix3::identity() + 1e-3 * gaussian(&mut rng)) * f;
            let warm = svd_lanes(&lanes(&next), first.frame);
            warm_sweeps += warm.sweeps;
            let mut frame = first.frame.map(|q| q.lane(0));
            let r = svd3_warm(&next, &mut frame);
            let rec = r.u * Matrix3::from_diagonal(&r.sigma) * r.v.transpose();
            assert!((rec - next).norm() < 2e-6 * next.norm());
        }
        // Measured: 1.9 sweeps warm, 3.5 cold on average (the cold ones here are easy: F is
        // near a rotation; random matrices take all six).
        let (warm, cold) = (warm_sweeps as f64 / 2e3, cold_sweeps as f64 / 2e3);
        assert!(
            warm <= 2.0 && cold > 1.6 * warm,
            "mean sweeps: warm {warm}, cold {cold}"
        );
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
        time("svd3_lanes, 8 matrices per call, cold", 300, &|xs| {
            let groups = xs
                .chunks_exact(8)
                .map(|c| <&[Matrix3<f32>; 8]>::try_from(c).unwrap());
            let mut cold = [COLD_START; 8];
            groups
                .map(|g| svd3_lanes(g, &mut cold).iter().map(sum).sum::<f32>())
                .sum()
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
