//! What a solver will hold, estimated before anything is allocated: a mistyped `dx` or domain
//! is refused with a figure instead of aborting the process inside an allocation.

use super::grid::BLOCK_EDGE;

/// Bytes a stepping solver holds per particle, its grid blocks, sort scratch and the particle
/// arrays' spare capacity included (at most twice the length). `sandstep bench --particles
/// 200000` measured 373 (195 k particles, 8 per cell; 2026-12-06); the unit test below keeps a
/// real solver under this bound.
pub const BYTES_PER_PARTICLE: f64 = 480.0;

/// Bytes per block of the domain's block table (`SparseGrid`'s slot, a `u32`), and of the
/// sleep state kept per block when sand sleeps (`Sleep`: quiet time, two flags, a count).
const TABLE_BYTES_PER_BLOCK: f64 = 4.0;
const SLEEP_BYTES_PER_BLOCK: f64 = 4.0 + 1.0 + 1.0 + 4.0;

/// Blocks of the table over a domain `extent_m` long per axis at spacing `dx_m`: as
/// `SparseGrid::new` sizes it (one block before the first node, one past the last).
pub fn table_blocks(dx_m: f64, extent_m: [f64; 3]) -> f64 {
    extent_m
        .iter()
        .map(|e| ((e / dx_m).ceil() / BLOCK_EDGE as f64).floor() + 3.0)
        .product()
}

/// Estimated bytes of a solver holding `particles` particles over a domain `extent_m` long per
/// axis at spacing `dx_m`. In f64 throughout, so that an absurd grid gives an absurd figure,
/// not an overflow.
pub fn estimated_bytes(dx_m: f64, extent_m: [f64; 3], particles: f64, sleep: bool) -> f64 {
    let per_block = TABLE_BYTES_PER_BLOCK + if sleep { SLEEP_BYTES_PER_BLOCK } else { 0.0 };
    table_blocks(dx_m, extent_m) * per_block + particles * BYTES_PER_PARTICLE
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::mpm::solver::tests::{jelly, settings};
    use crate::mpm::{NewParticle, Solver, Wall, Walls};

    /// A block of jelly, 8 particles per cell on a lattice, resting on the floor of the
    /// solver tests' domain (0.4 x 0.3 x 0.3 m at dx = 1 cm).
    fn block_solver() -> Solver {
        let mut solver = Solver::new(
            settings(Vector3::new(0.0, 0.0, -9.81), Walls::all(Wall::Slip)),
            vec![jelly()],
        );
        let spacing = solver.settings.dx / 2.0;
        let counts = [40usize, 30, 10];
        let mut new = Vec::new();
        for i in 0..counts[0] {
            for j in 0..counts[1] {
                for k in 0..counts[2] {
                    let at = |n: usize| (n as f32 + 0.5) * spacing;
                    new.push(NewParticle {
                        position: Vector3::new(0.1 + at(i), 0.075 + at(j), at(k)),
                        velocity: Vector3::zeros(),
                        mass: 1e-3 * spacing.powi(3) * 1e3,
                        volume: spacing.powi(3),
                        material: 0,
                    });
                }
            }
        }
        solver.add_particles(new);
        solver
    }

    /// A solver's own count of what it holds, after it has stepped (sort scratch and grid
    /// blocks allocated), stays under the estimate.
    #[test]
    fn a_stepping_solver_holds_less_than_estimated() {
        let mut solver = block_solver();
        for _ in 0..3 {
            solver.substep().unwrap();
        }
        let n = solver.particles.len() as f64;
        let held = solver.memory_bytes() as f64;
        let extent = (solver.settings.domain_max - solver.settings.domain_min).map(f64::from);
        let estimate = estimated_bytes(
            solver.settings.dx.into(),
            extent.into(),
            n,
            solver.settings.sleep.is_some(),
        );
        println!(
            "{n} particles hold {held} B ({:.0} per particle), estimated {estimate} B",
            held / n
        );
        assert!(
            held < estimate,
            "held {held} B ({} per particle) against the estimate {estimate} B",
            held / n
        );
        // And not wildly above it: the estimate is for refusing, not for padding.
        assert!(estimate < 2.0 * held, "{estimate} against {held} B");
    }

    #[test]
    fn the_table_matches_the_grid() {
        let dx = 0.01f32;
        let (min, max) = (
            nalgebra::Vector3::new(-0.12f32, -0.12, -0.06),
            nalgebra::Vector3::new(0.8f32, 0.12, 0.06),
        );
        let grid = crate::mpm::grid::SparseGrid::new(dx, min, max);
        let extent = (max - min).map(f64::from);
        assert_eq!(
            table_blocks(dx.into(), extent.into()),
            grid.lattice().len() as f64
        );
    }
}
