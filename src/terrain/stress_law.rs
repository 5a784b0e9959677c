//! RFT's stress law: the stress per unit depth `(alpha_x, alpha_z)` (N/m^3) on a plate element
//! at attack angle beta and intrusion angle gamma, signs and angles as in [`super::rft`].
//!
//! A law is given inside Li, Zhang and Goldman's measured range (`|gamma| <= pi/2`, any beta:
//! a plate is a line, so the law is pi-periodic in beta) and extended to every angle with
//! RFT's symmetries ([`StressLaw::alpha`]):
//! - the mirror image of a motion (x -> -x) has `beta -> -beta`, `gamma -> pi - gamma` and
//!   mirrored forces: `alpha_z(-b, pi - g) = alpha_z(b, g)`, `alpha_x(-b, pi - g) =
//!   -alpha_x(b, g)`; velocities with a backward component (`|gamma| > pi/2`) are mirrored into
//!   the range;
//! - vertical motion (`|gamma| = pi/2`) is its own mirror image, so `alpha_x` must be odd and
//!   `alpha_z` even in beta there: the law's odd and even parts are used (the generic fit has
//!   an even residual `Cm11 cos 2b` in alpha_x, 0.7 % of zeta; a measured table, the noise of
//!   its two rows).
//!
//! Two kinds of law:
//! - [`StressLaw::Fourier`]: Li et al.'s generic Fourier form (their Eq. 1 and supplement),
//!   nine coefficients per unit zeta times zeta: their generic coefficients ([`GENERIC`]) or
//!   those fitted to a sand's stress maps ([`super::stress_map`]);
//! - [`StressLaw::Table`]: the measured maps themselves, interpolated bilinearly over beta
//!   (periodically) and gamma, as Li et al. used their measured maps.

use serde::{Deserialize, Serialize};

/// The nine coefficients of the generic Fourier form (N/m^3, or per unit zeta in
/// [`StressLaw::Fourier`]):
///
/// - `alpha_z = A00 + A10 cos 2b + B11 sin(2b + g) + B01 sin g + Bm11 sin(-2b + g)`,
/// - `alpha_x = C11 cos(2b + g) + C01 cos g + Cm11 sin(-2b + g) + D10 sin 2b`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StressCoefficients {
    /// `alpha_z`'s constant term.
    pub a00: f64,
    /// `alpha_z`'s `cos 2b` term.
    pub a10: f64,
    /// `alpha_z`'s `sin(2b + g)` term.
    pub b11: f64,
    /// `alpha_z`'s `sin g` term.
    pub b01: f64,
    /// `alpha_z`'s `sin(-2b + g)` term.
    pub bm11: f64,
    /// `alpha_x`'s `cos(2b + g)` term.
    pub c11: f64,
    /// `alpha_x`'s `cos g` term.
    pub c01: f64,
    /// `alpha_x`'s `sin(-2b + g)` term.
    pub cm11: f64,
    /// `alpha_x`'s `sin 2b` term.
    pub d10: f64,
}

/// Li, Zhang and Goldman's generic coefficients per unit zeta (2013, supplement: the fit
/// shared by their granular media up to the scale factor zeta). The A and B terms sum to 1, so
/// zeta is `alpha_z(0, pi/2)`, the stress per unit depth under a horizontal plate pressed
/// straight down.
pub const GENERIC: StressCoefficients = StressCoefficients {
    a00: 0.206,
    a10: 0.169,
    b11: 0.212,
    b01: 0.358,
    bm11: 0.055,
    c11: -0.124,
    c01: 0.253,
    cm11: 0.007,
    d10: 0.088,
};

/// The Fourier form's functions from `cos 2b`, `sin 2b`, `cos g` and `sin g` (the angle-sum
/// identities): five for alpha_z, four for alpha_x (the fifth entry 0).
pub fn fourier_basis(cos_2b: f64, sin_2b: f64, cos_g: f64, sin_g: f64) -> [[f64; 5]; 2] {
    // sin(2b + g), cos(2b + g), sin(-2b + g).
    let sin_sum = sin_2b * cos_g + cos_2b * sin_g;
    let cos_sum = cos_2b * cos_g - sin_2b * sin_g;
    let sin_diff = sin_g * cos_2b - cos_g * sin_2b;
    [
        [1.0, cos_2b, sin_sum, sin_g, sin_diff],
        [cos_sum, cos_g, sin_diff, sin_2b, 0.0],
    ]
}

impl StressCoefficients {
    /// Checks that every coefficient is finite and that they give a zeta > 0 (the fitted law
    /// is per unit zeta).
    pub fn check(&self) -> Result<(), TableError> {
        let named = [
            ("a00", self.a00),
            ("a10", self.a10),
            ("b11", self.b11),
            ("b01", self.b01),
            ("bm11", self.bm11),
            ("c11", self.c11),
            ("c01", self.c01),
            ("cm11", self.cm11),
            ("d10", self.d10),
        ];
        if let Some((name, value)) = named.iter().find(|(_, v)| !v.is_finite()) {
            return Err(TableError {
                field: (*name).into(),
                message: format!("{value} must be finite"),
            });
        }
        let zeta = self.zeta_n_m3();
        if zeta > 0.0 {
            Ok(())
        } else {
            Err(TableError {
                field: "a00".into(),
                message: format!(
                    "the coefficients give zeta = alpha_z(0, 90 deg) = {zeta} N/m^3; it must \
                     be > 0 (a00 + a10 + b11 + b01 + bm11)"
                ),
            })
        }
    }

    /// Each coefficient through `f`.
    pub fn map(&self, f: impl Fn(f64) -> f64) -> Self {
        StressCoefficients {
            a00: f(self.a00),
            a10: f(self.a10),
            b11: f(self.b11),
            b01: f(self.b01),
            bm11: f(self.bm11),
            c11: f(self.c11),
            c01: f(self.c01),
            cm11: f(self.cm11),
            d10: f(self.d10),
        }
    }

    /// The coefficients times `factor`.
    pub fn scaled(&self, factor: f64) -> Self {
        self.map(|c| c * factor)
    }

    /// `(alpha_x, alpha_z)` from `cos 2b`, `sin 2b`, `cos g`, `sin g` ([`fourier_basis`]),
    /// the form as written, without the symmetries.
    pub fn alpha_cs(&self, cos_2b: f64, sin_2b: f64, cos_g: f64, sin_g: f64) -> (f64, f64) {
        let [z, x] = fourier_basis(cos_2b, sin_2b, cos_g, sin_g);
        let alpha_z = self.a00 * z[0]
            + self.a10 * z[1]
            + self.b11 * z[2]
            + self.b01 * z[3]
            + self.bm11 * z[4];
        let alpha_x = self.c11 * x[0] + self.c01 * x[1] + self.cm11 * x[2] + self.d10 * x[3];
        (alpha_x, alpha_z)
    }

    /// `(alpha_x, alpha_z)` at `beta_rad`, `gamma_rad`, the form as written.
    pub fn alpha(&self, beta_rad: f64, gamma_rad: f64) -> (f64, f64) {
        let (sin_2b, cos_2b) = libm::sincos(2.0 * beta_rad);
        let (sin_g, cos_g) = libm::sincos(gamma_rad);
        self.alpha_cs(cos_2b, sin_2b, cos_g, sin_g)
    }

    /// The scale zeta these coefficients give, `alpha_z(0, pi/2)`: the sum of the A and B
    /// terms.
    pub fn zeta_n_m3(&self) -> f64 {
        self.alpha(0.0, std::f64::consts::FRAC_PI_2).1
    }
}

/// Measured `alpha` on a grid of attack angles (rows) and intrusion angles (columns).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StressTable {
    /// Attack angles of the rows (deg), ascending, within one period: the last below the
    /// first plus 180. Interpolation wraps from the last row to the first (pi-periodic).
    pub betas_deg: Vec<f64>,
    /// Intrusion angles of the columns (deg), ascending from -90 to 90.
    pub gammas_deg: Vec<f64>,
    /// `alpha_x` (N/m^3), a row per beta, a value per gamma.
    pub alpha_x_n_m3: Vec<Vec<f64>>,
    /// `alpha_z` (N/m^3), a row per beta, a value per gamma.
    pub alpha_z_n_m3: Vec<Vec<f64>>,
}

/// Why a table cannot be used; each message names the field.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
#[error("{field}: {message}")]
pub struct TableError {
    pub field: String,
    pub message: String,
}

/// Half a turn of beta (deg): a plate is a line.
const BETA_PERIOD_DEG: f64 = 180.0;
/// Largest intrusion angle of the measured range (deg).
const GAMMA_RANGE_DEG: f64 = 90.0;

impl StressTable {
    /// Checks the grid's shape and angles and that every value is finite.
    pub fn check(&self) -> Result<(), TableError> {
        let err = |field: &str, message: String| {
            Err(TableError {
                field: field.into(),
                message,
            })
        };
        let ascending = |a: &[f64]| a.windows(2).all(|w| w[0] < w[1]);
        let b = &self.betas_deg;
        if b.len() < 2 || !ascending(b) || !b.iter().all(|v| v.is_finite()) {
            return err(
                "betas_deg",
                "needs at least two ascending finite angles".into(),
            );
        }
        if b[b.len() - 1] >= b[0] + BETA_PERIOD_DEG {
            return err(
                "betas_deg",
                format!("must span less than {BETA_PERIOD_DEG} deg (one period of beta)"),
            );
        }
        let g = &self.gammas_deg;
        if g.len() < 2
            || !ascending(g)
            || g[0] != -GAMMA_RANGE_DEG
            || g[g.len() - 1] != GAMMA_RANGE_DEG
        {
            return err(
                "gammas_deg",
                format!("must ascend from -{GAMMA_RANGE_DEG} to {GAMMA_RANGE_DEG} deg"),
            );
        }
        for (field, rows) in [
            ("alpha_x_n_m3", &self.alpha_x_n_m3),
            ("alpha_z_n_m3", &self.alpha_z_n_m3),
        ] {
            if rows.len() != b.len() {
                return err(field, format!("needs a row per beta ({})", b.len()));
            }
            for (i, row) in rows.iter().enumerate() {
                if row.len() != g.len() || !row.iter().all(|v| v.is_finite()) {
                    return err(
                        &format!("{field}.{i}"),
                        format!("needs {} finite values, one per gamma", g.len()),
                    );
                }
            }
        }
        Ok(())
    }

    /// `(alpha_x, alpha_z)` (N/m^3) at `beta_deg` (any) and `gamma_deg` in [-90, 90],
    /// bilinear between the grid's points.
    pub fn alpha(&self, beta_deg: f64, gamma_deg: f64) -> (f64, f64) {
        let betas = &self.betas_deg;
        // Beta into [first, first + 180), then its row interval, wrapping from the last row.
        let first = betas[0];
        let beta = beta_deg - BETA_PERIOD_DEG * ((beta_deg - first) / BETA_PERIOD_DEG).floor();
        let i = betas.partition_point(|&b| b <= beta).saturating_sub(1);
        let (i_next, beta_next) = if i + 1 < betas.len() {
            (i + 1, betas[i + 1])
        } else {
            (0, first + BETA_PERIOD_DEG)
        };
        let t = ((beta - betas[i]) / (beta_next - betas[i])).clamp(0.0, 1.0);
        let gammas = &self.gammas_deg;
        let gamma = gamma_deg.clamp(gammas[0], gammas[gammas.len() - 1]);
        let j = gammas
            .partition_point(|&g| g <= gamma)
            .clamp(1, gammas.len() - 1)
            - 1;
        let s = ((gamma - gammas[j]) / (gammas[j + 1] - gammas[j])).clamp(0.0, 1.0);
        let bilinear = |rows: &[Vec<f64>]| {
            let along = |row: &[f64]| row[j] + s * (row[j + 1] - row[j]);
            let (here, next) = (along(&rows[i]), along(&rows[i_next]));
            here + t * (next - here)
        };
        (bilinear(&self.alpha_x_n_m3), bilinear(&self.alpha_z_n_m3))
    }
}

/// A medium's stress law (module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum StressLaw {
    /// The generic Fourier form: coefficients per unit zeta, times `zeta_n_m3` (N/m^3).
    Fourier {
        per_zeta: StressCoefficients,
        zeta_n_m3: f64,
    },
    /// Measured maps, interpolated ([`StressTable::alpha`]).
    Table(StressTable),
}

/// Angles gamma within this of +-pi/2 (rad) are vertical motion, for the mirror-symmetric
/// treatment (round-off of `pi - gamma` and the like).
const VERTICAL_GAMMA_TOLERANCE_RAD: f64 = 1e-12;

impl StressLaw {
    /// Li et al.'s generic shape scaled by `zeta_n_m3` (N/m^3).
    pub fn generic(zeta_n_m3: f64) -> Self {
        StressLaw::Fourier {
            per_zeta: GENERIC,
            zeta_n_m3,
        }
    }

    /// Fitted coefficients (N/m^3) as a law: per unit of the zeta they give.
    pub fn fitted(coefficients: &StressCoefficients) -> Self {
        let zeta_n_m3 = coefficients.zeta_n_m3();
        StressLaw::Fourier {
            per_zeta: coefficients.scaled(1.0 / zeta_n_m3),
            zeta_n_m3,
        }
    }

    /// The unit of [`Self::alpha_in_range_cs`] (N/m^3): zeta for the Fourier form, 1 for a
    /// table (its values are N/m^3).
    pub fn unit_n_m3(&self) -> f64 {
        match self {
            StressLaw::Fourier { zeta_n_m3, .. } => *zeta_n_m3,
            StressLaw::Table(_) => 1.0,
        }
    }

    /// The law's scale zeta, `alpha_z(0, pi/2)` (N/m^3).
    pub fn zeta_n_m3(&self) -> f64 {
        let (_, z) = self.alpha_vertical_cs(1.0, 0.0, 1.0);
        z * self.unit_n_m3()
    }

    /// `(alpha_x, alpha_z)` in units of [`Self::unit_n_m3`] for `|gamma| < pi/2` (`cos g >=
    /// 0`), from `cos 2b`, `sin 2b`, `cos g`, `sin g`; the law as given.
    pub fn alpha_in_range_cs(
        &self,
        cos_2b: f64,
        sin_2b: f64,
        cos_g: f64,
        sin_g: f64,
    ) -> (f64, f64) {
        match self {
            StressLaw::Fourier { per_zeta, .. } => per_zeta.alpha_cs(cos_2b, sin_2b, cos_g, sin_g),
            StressLaw::Table(table) => {
                let beta_deg = 0.5 * libm::atan2(sin_2b, cos_2b).to_degrees();
                table.alpha(beta_deg, libm::atan2(sin_g, cos_g).to_degrees())
            }
        }
    }

    /// [`Self::alpha_in_range_cs`] for vertical motion (`cos g = 0`, `sin g = +-1`): its
    /// mirror image is itself, so alpha_x is the law's part odd in beta and alpha_z its part
    /// even in beta (module docs; the Fourier form's alpha_z is even there already, to the
    /// bit).
    pub fn alpha_vertical_cs(&self, cos_2b: f64, sin_2b: f64, sin_g: f64) -> (f64, f64) {
        let (x_here, z_here) = self.alpha_in_range_cs(cos_2b, sin_2b, 0.0, sin_g);
        let (x_mirror, z_mirror) = self.alpha_in_range_cs(cos_2b, -sin_2b, 0.0, sin_g);
        (0.5 * (x_here - x_mirror), 0.5 * (z_here + z_mirror))
    }

    /// `(alpha_x, alpha_z)` (N/m^3) for attack angle `beta_rad` and intrusion angle
    /// `gamma_rad`, any values (module docs: the symmetries). Multiply by depth (m) and area
    /// (m^2) for a force (N).
    pub fn alpha(&self, beta_rad: f64, gamma_rad: f64) -> (f64, f64) {
        use std::f64::consts::{FRAC_PI_2, PI, TAU};
        let gamma = if gamma_rad > PI || gamma_rad <= -PI {
            gamma_rad - TAU * ((gamma_rad + PI) / TAU).floor()
        } else {
            gamma_rad
        };
        // The range of floor() above is [-pi, pi): move -pi to pi.
        let gamma = if gamma <= -PI { gamma + TAU } else { gamma };
        let in_range = |beta: f64, gamma: f64| {
            let (sin_2b, cos_2b) = libm::sincos(2.0 * beta);
            let (sin_g, cos_g) = libm::sincos(gamma);
            self.alpha_in_range_cs(cos_2b, sin_2b, cos_g, sin_g)
        };
        let (x, z) = if (gamma.abs() - FRAC_PI_2).abs() <= VERTICAL_GAMMA_TOLERANCE_RAD {
            let (sin_2b, cos_2b) = libm::sincos(2.0 * beta_rad);
            self.alpha_vertical_cs(cos_2b, sin_2b, 1.0f64.copysign(gamma))
        } else if gamma.abs() < FRAC_PI_2 {
            in_range(beta_rad, gamma)
        } else {
            let (x, z) = in_range(-beta_rad, PI.copysign(gamma) - gamma);
            (-x, z)
        };
        let unit = self.unit_n_m3();
        (x * unit, z * unit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    /// A table of the generic shape at zeta 2e6 on the maps' default grid.
    fn generic_table() -> StressTable {
        let betas_deg = vec![-60.0, -30.0, 0.0, 30.0, 60.0, 90.0];
        let gammas_deg = vec![-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0];
        let law = StressLaw::generic(2.0e6);
        let rows = |axis: usize| -> Vec<Vec<f64>> {
            betas_deg
                .iter()
                .map(|&b: &f64| {
                    gammas_deg
                        .iter()
                        .map(|&g: &f64| {
                            let (x, z) = law.alpha(b.to_radians(), g.to_radians());
                            [x, z][axis]
                        })
                        .collect()
                })
                .collect()
        };
        StressTable {
            alpha_x_n_m3: rows(0),
            alpha_z_n_m3: rows(1),
            betas_deg,
            gammas_deg,
        }
    }

    #[test]
    fn a_table_gives_its_points_and_interpolates_between_them() {
        let table = generic_table();
        table.check().unwrap();
        let law = StressLaw::generic(2.0e6);
        for (i, &b) in table.betas_deg.iter().enumerate() {
            for (j, &g) in table.gammas_deg.iter().enumerate() {
                let (x, z) = table.alpha(b, g);
                let (tx, tz) = (table.alpha_x_n_m3[i][j], table.alpha_z_n_m3[i][j]);
                assert!((x - tx).abs() < 1e-6 && (z - tz).abs() < 1e-6, "{b}, {g}");
                // One period on, the same row.
                let (xp, zp) = table.alpha(b + 180.0, g);
                assert!((xp - x).abs() < 1e-6 && (zp - z).abs() < 1e-6);
            }
        }
        // Midway between rows 90 and -60 (wrapping through 105 = -75 deg) and columns.
        let (x, z) = table.alpha(105.0, 15.0);
        let corners = [
            (90.0, 0.0),
            (90.0, 30.0),
            (-60.0 + 180.0, 0.0),
            (120.0, 30.0),
        ];
        let mean = |axis: usize| {
            corners
                .iter()
                .map(|&(b, g): &(f64, f64)| {
                    let (x, z) = law.alpha(b.to_radians(), g.to_radians());
                    [x, z][axis]
                })
                .sum::<f64>()
                / 4.0
        };
        assert!((x - mean(0)).abs() < 1e-6 && (z - mean(1)).abs() < 1e-6);
        // Between the points a 30 deg grid is within a tenth of zeta of the smooth form.
        for (b, g) in [(10.0, 20.0), (-45.0, 75.0), (80.0, -50.0)] {
            let (tx, tz) = table.alpha(b, g);
            let (fx, fz) = law.alpha(f64::to_radians(b), f64::to_radians(g));
            assert!((tx - fx).abs() < 0.1 * 2.0e6 && (tz - fz).abs() < 0.1 * 2.0e6);
        }
    }

    #[test]
    fn every_law_has_rft_s_symmetries() {
        let table = StressLaw::Table(generic_table());
        let fitted = StressLaw::fitted(&GENERIC.scaled(3.0e6));
        for law in [StressLaw::generic(1.0), fitted, table] {
            let scale = law.zeta_n_m3();
            let steps = 24;
            for i in 0..=steps {
                for j in 0..=steps {
                    let beta = -PI + TAU * i as f64 / steps as f64 + 0.01;
                    let gamma = -PI + TAU * j as f64 / steps as f64 + 1e-3 * (j % 3) as f64;
                    let (x, z) = law.alpha(beta, gamma);
                    let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * scale;
                    let (xp, zp) = law.alpha(beta + PI, gamma);
                    assert!(close(x, xp) && close(z, zp), "pi-periodic in beta");
                    let (xg, zg) = law.alpha(beta, gamma + TAU);
                    assert!(close(x, xg) && close(z, zg), "2 pi-periodic in gamma");
                    let (xm, zm) = law.alpha(-beta, PI - gamma);
                    assert!(close(x, -xm) && close(z, zm), "mirror at {beta}, {gamma}");
                }
            }
            for beta in [0.1, 0.5, 1.0, 1.5] {
                for gamma in [FRAC_PI_2, -FRAC_PI_2] {
                    let (x, z) = law.alpha(beta, gamma);
                    let (xm, zm) = law.alpha(-beta, gamma);
                    assert!((x + xm).abs() < 1e-9 * scale && (z - zm).abs() < 1e-9 * scale);
                }
            }
        }
    }

    #[test]
    fn a_fitted_law_gives_its_coefficients_alpha_and_zeta() {
        let coefficients = GENERIC.scaled(3.0e6);
        let law = StressLaw::fitted(&coefficients);
        assert!((law.zeta_n_m3() - 3.0e6).abs() < 1e-6);
        for (b, g) in [(0.3, 0.2), (-0.7, 1.1), (1.2, -0.4)] {
            let (x, z) = law.alpha(b, g);
            let (cx, cz) = coefficients.alpha(b, g);
            assert!((x - cx).abs() < 1e-6 && (z - cz).abs() < 1e-6);
        }
    }

    #[test]
    fn coefficients_must_be_finite_and_give_a_positive_zeta() {
        assert!(GENERIC.scaled(2.0e6).check().is_ok());
        let mut nan = GENERIC;
        nan.c01 = f64::NAN;
        assert_eq!(nan.check().unwrap_err().field, "c01");
        assert_eq!(GENERIC.scaled(-1.0).check().unwrap_err().field, "a00");
    }

    #[test]
    fn malformed_tables_are_refused_by_field() {
        let good = generic_table();
        let mut t = good.clone();
        t.betas_deg[5] = 130.0;
        assert_eq!(t.check().unwrap_err().field, "betas_deg");
        let mut t = good.clone();
        t.gammas_deg[6] = 80.0;
        assert_eq!(t.check().unwrap_err().field, "gammas_deg");
        let mut t = good.clone();
        t.alpha_z_n_m3[2].pop();
        assert_eq!(t.check().unwrap_err().field, "alpha_z_n_m3.2");
        let mut t = good;
        t.alpha_x_n_m3[1][1] = f64::NAN;
        assert_eq!(t.check().unwrap_err().field, "alpha_x_n_m3.1");
    }
}
