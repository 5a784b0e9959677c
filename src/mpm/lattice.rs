//! Where a body's particles start: a lattice of cubic units from the body's min corner (on the
//! grid when that corner is), `particles_per_cell` to a grid cell.
//!
//! Cube numbers (1, 8, 27, 64) fill each cell with a simple cubic lattice of `n^(1/3)` points
//! per edge. Twice a cube (2, 16) is the body-centred cubic lattice and four times a cube (4, 32)
//! the face-centred one: the densest packings with 2 and 4 points to a cubic unit, so a
//! particle's neighbours stay as evenly spread as at 8 per cell with a half or a quarter of the
//! particles. Every basis is centred in its unit, as the simple cubic point is; the outer
//! points of the centred bases sit a quarter unit from the unit's faces, so where a box is not a
//! whole number of units the points past its faces are left out ([`Lattice::points`]).

use nalgebra::Vector3;

/// Basis points of one cubic unit, in units of its edge.
const SIMPLE_CUBIC: &[[f32; 3]] = &[[0.5, 0.5, 0.5]];
const BODY_CENTRED: &[[f32; 3]] = &[[0.25, 0.25, 0.25], [0.75, 0.75, 0.75]];
const FACE_CENTRED: &[[f32; 3]] = &[
    [0.25, 0.25, 0.25],
    [0.75, 0.75, 0.25],
    [0.75, 0.25, 0.75],
    [0.25, 0.75, 0.75],
];

/// The starting lattice of `particles_per_cell` particles per grid cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    /// Cubic units along a grid cell's edge.
    units_per_edge: u32,
    /// The points of one unit.
    basis: &'static [[f32; 3]],
}

impl Lattice {
    /// The values `particles_per_cell` takes, for error messages.
    pub const ALLOWED: &'static str = "1, 8, 27 or 64 (simple cubic), 2 or 16 (body-centred \
                                       cubic) or 4 or 32 (face-centred cubic)";

    /// The lattice of `particles_per_cell`, or `None` if it is none of [`Lattice::ALLOWED`].
    pub fn of(particles_per_cell: u32) -> Option<Lattice> {
        let cube_side = |n: u32| (1..=4).find(|k| k * k * k == n);
        let simple = cube_side(particles_per_cell).map(|k| (k, SIMPLE_CUBIC));
        let with_basis = |basis: &'static [[f32; 3]]| {
            let points = basis.len() as u32;
            particles_per_cell
                .is_multiple_of(points)
                .then(|| cube_side(particles_per_cell / points))
                .flatten()
                .filter(|&k| k <= 2)
                .map(|k| (k, basis))
        };
        simple
            .or_else(|| with_basis(BODY_CENTRED))
            .or_else(|| with_basis(FACE_CENTRED))
            .map(|(units_per_edge, basis)| Lattice {
                units_per_edge,
                basis,
            })
    }

    /// Edge of one cubic unit (m) at grid spacing `dx` (m).
    pub fn unit_edge(&self, dx: f32) -> f32 {
        dx / self.units_per_edge as f32
    }

    /// Volume each particle stands for (m^3) at grid spacing `dx` (m).
    pub fn particle_volume(&self, dx: f32) -> f32 {
        let unit = self.unit_edge(dx);
        unit * unit * unit / self.basis.len() as f32
    }

    /// Particles in a box of `extent` (m) at grid spacing `dx` (m) at most: the units
    /// [`Lattice::points`] walks, each whole (f64, so that a mistyped `dx` gives a huge count,
    /// not an overflow).
    pub fn count_in(&self, extent: &Vector3<f32>, dx: f32) -> f64 {
        let unit = self.unit_edge(dx) as f64;
        let units: f64 = extent
            .iter()
            .map(|&e| (e as f64 / unit).round().max(1.0))
            .product();
        units * self.basis.len() as f64
    }

    /// Mean particles along a grid cell's edge, `particles_per_cell^(1/3)`: whole for the
    /// simple cubic lattices.
    pub fn mean_per_edge(&self) -> f32 {
        self.units_per_edge as f32 * libm::cbrtf(self.basis.len() as f32)
    }

    /// How far the outermost points of a box filled by [`Lattice::points`] stand inside its
    /// min faces (m) at grid spacing `dx` (m): half a spacing on the simple cubic lattice, a
    /// quarter unit on the centred ones.
    pub fn face_margin(&self, dx: f32) -> f32 {
        let nearest = self
            .basis
            .iter()
            .map(|b| b[0])
            .fold(f32::INFINITY, f32::min);
        nearest * self.unit_edge(dx)
    }

    /// The points (m) of the units filling the box from `lo` with `extent` (m), unit by unit,
    /// the units in x-major order: as many units as round `extent` (at least one) along each
    /// axis, less the points that would lie past the box's max faces (none on the simple cubic
    /// lattice, whose last point is at most half a unit past the last whole unit).
    /// `each_plane` is called before every plane of units along x and stops the walk when it
    /// returns false.
    pub fn points(
        &self,
        lo: &Vector3<f32>,
        extent: &Vector3<f32>,
        dx: f32,
        mut each_plane: impl FnMut() -> bool,
        mut point: impl FnMut(Vector3<f32>),
    ) -> bool {
        let unit = self.unit_edge(dx);
        let units = extent / unit;
        let counts = units.map(|u| u.round().max(1.0) as usize);
        // Points up to the box's faces, in units; a box thinner than half a unit keeps the
        // unit's centre.
        let reach = units.map(|u| u.max(0.5));
        for i in 0..counts.x {
            if !each_plane() {
                return false;
            }
            for j in 0..counts.y {
                for k in 0..counts.z {
                    let corner = Vector3::new(i as f32, j as f32, k as f32);
                    for b in self.basis {
                        let p = corner + Vector3::from(*b);
                        if p.x <= reach.x && p.y <= reach.y && p.z <= reach.z {
                            point(lo + p * unit);
                        }
                    }
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_allowed_count_gives_its_lattice_and_nothing_else_does() {
        let allowed = [1, 2, 4, 8, 16, 27, 32, 64];
        for n in 0..=128 {
            let lattice = Lattice::of(n);
            assert_eq!(lattice.is_some(), allowed.contains(&n), "{n} per cell");
            if let Some(l) = lattice {
                assert_eq!(l.count_in(&Vector3::repeat(0.01), 0.01), n as f64);
            }
        }
    }

    /// The points fill one cell with their volumes and keep their centroid at the cell's
    /// centre; over two cells along each axis none is closer to another than the simple cubic
    /// lattice of the same count puts them (the face-centred lattice's nearest are 1.12 times
    /// that apart, the body-centred's 1.09 times).
    #[test]
    fn the_points_fill_a_cell_evenly() {
        let dx = 0.01_f32;
        for n in [1, 2, 4, 8, 16, 27, 32, 64] {
            let lattice = Lattice::of(n).unwrap();
            let mut points = Vec::new();
            let cell = Vector3::repeat(dx);
            lattice.points(&Vector3::zeros(), &cell, dx, || true, |x| points.push(x));
            assert_eq!(points.len() as u32, n);
            assert_eq!(lattice.count_in(&cell, dx), n as f64);
            let volume = lattice.particle_volume(dx) * n as f32;
            assert!(
                (volume / dx.powi(3) - 1.0).abs() < 1e-5,
                "{n}: volume {volume}"
            );
            let centroid = points.iter().sum::<Vector3<f32>>() / n as f32;
            assert!(
                (centroid - cell * 0.5).norm() < 1e-4 * dx,
                "{n}: {centroid:?}"
            );
            let cubic_spacing = dx / libm::cbrtf(n as f32);
            points.clear();
            lattice.points(
                &Vector3::zeros(),
                &(cell * 2.0),
                dx,
                || true,
                |x| points.push(x),
            );
            assert_eq!(points.len() as u32, 8 * n);
            for (a, p) in points.iter().enumerate() {
                for q in &points[a + 1..] {
                    let d = (p - q).norm();
                    assert!(
                        d > 0.999 * cubic_spacing,
                        "{n} per cell: points {d} m apart"
                    );
                }
            }
        }
    }

    /// A box that is no whole number of units keeps every point inside it, the simple cubic
    /// lattice every point it had, and each lattice its margin at the min faces.
    #[test]
    fn no_point_lies_past_the_box() {
        let dx = 0.01_f32;
        let lo = Vector3::new(-0.02, 0.003, -0.05);
        for extent in [
            Vector3::new(0.0296, 0.0333, 0.0262),
            Vector3::new(0.004, 0.02, 0.0371),
        ] {
            for n in [1, 2, 4, 8, 16, 27, 32, 64] {
                let lattice = Lattice::of(n).unwrap();
                let mut points = Vec::new();
                lattice.points(&lo, &extent, dx, || true, |x| points.push(x));
                let hi = lo + extent;
                let thin = |a: usize| extent[a] < 0.5 * lattice.unit_edge(dx);
                for x in &points {
                    for a in 0..3 {
                        assert!(x[a] >= lo[a], "{n} per cell: {x:?} below {lo:?}");
                        assert!(x[a] <= hi[a] || thin(a), "{n} per cell: {x:?} past {hi:?}");
                    }
                }
                let margin = lattice.face_margin(dx);
                for a in 0..3 {
                    let lowest = points.iter().map(|x| x[a]).fold(f32::INFINITY, f32::min);
                    assert!(
                        (lowest - lo[a] - margin).abs() < 1e-6,
                        "{n} per cell, axis {a}"
                    );
                }
                if n == 1 || n == 8 || n == 27 || n == 64 {
                    assert_eq!(points.len() as f64, lattice.count_in(&extent, dx), "{n}");
                }
            }
        }
    }
}
