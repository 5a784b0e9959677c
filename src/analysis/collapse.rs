//! Granular column collapse: deposit length and height (Lube et al. 2005).
//!
//! The deposit is measured from the wall along +x with a window one cell wide that slides in
//! steps of `1 / WINDOW_STEPS_PER_CELL` of a cell. Scanning from the wall, the deposit continues
//! while the window holds at least half a particle layer across the channel (a toe one particle
//! thick counts; it did not when the threshold was half a cell layer, which at 8 particles per
//! cell is exactly one particle layer, so the tall column's runout flipped between 3.15 and 3.63
//! with perturbations of one part in a million); it ends at the centre of the first window that
//! does not. The length is the farthest particle before
//! that end plus half a particle spacing, and the height the highest particle before it plus
//! half a spacing. Measured this way the initial column gives back exactly its box, a few
//! grains that bounce ahead of the front do not count, and the length follows a thinning toe
//! continuously: with windows fixed to the cells it jumped by whole cells (6 % of the runout
//! at a = 1, dx = 3 mm) as the last cell's count crossed the threshold.

use nalgebra::Vector3;
use serde::Serialize;

use crate::mpm::lattice::Lattice;

/// Where the column stands and how it is sampled.
#[derive(Clone, Copy, Debug)]
pub struct CollapseGeometry {
    /// x of the wall the column leans on (m).
    pub wall_x: f32,
    /// z of the floor (m).
    pub floor_z: f32,
    /// Channel width along y (m).
    pub width: f32,
    /// Grid spacing (m): the bin width.
    pub dx: f32,
    /// The lattice the column was filled on.
    pub lattice: Lattice,
}

/// Length and height of a deposit (m).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Deposit {
    pub length_m: f32,
    pub height_m: f32,
}

/// Steps per cell of the sliding window that finds the deposit's end.
const WINDOW_STEPS_PER_CELL: usize = 8;

/// Measures the deposit formed by `positions`.
pub fn measure(g: &CollapseGeometry, positions: &[Vector3<f32>]) -> Deposit {
    let per_edge = g.lattice.mean_per_edge();
    // From the outermost particle to the face of the sand it stands for.
    let margin = g.lattice.face_margin(g.dx);
    let step = g.dx / WINDOW_STEPS_PER_CELL as f32;
    let sub_bin = |x: &Vector3<f32>| ((x.x - g.wall_x) / step).max(0.0) as usize;
    let last = positions.iter().map(sub_bin).max();
    // One spare window past the farthest particle, so the scan always finds an end.
    let mut count = vec![0usize; last.map_or(0, |b| b + 1) + WINDOW_STEPS_PER_CELL];
    for x in positions {
        count[sub_bin(x)] += 1;
    }
    // Half a particle layer across the channel, one cell long.
    let particles_per_layer = per_edge * per_edge * (g.width / g.dx);
    let threshold = (0.5 * particles_per_layer).round().max(1.0) as usize;
    let deposit_steps = count
        .windows(WINDOW_STEPS_PER_CELL)
        .take_while(|window| window.iter().sum::<usize>() >= threshold)
        .count();
    let end = g.wall_x + deposit_steps as f32 * step + 0.5 * g.dx;
    let (mut front, mut top) = (g.wall_x, g.floor_z);
    for x in positions.iter().filter(|x| x.x < end) {
        front = front.max(x.x);
        top = top.max(x.z);
    }
    Deposit {
        length_m: front + margin - g.wall_x,
        height_m: top + margin - g.floor_z,
    }
}

/// Normalized runout `(L_inf - L_i) / L_i` predicted by Lube et al. (2005) for aspect ratio
/// `a`: `1.2 a` for `a < 1.8`, `1.9 a^(2/3)` for `a > 2.8`; between the two regimes, `None`.
pub fn lube_normalized_runout(aspect_ratio: f32) -> Option<f32> {
    if aspect_ratio < 1.8 {
        Some(1.2 * aspect_ratio)
    } else if aspect_ratio > 2.8 {
        Some(1.9 * libm::powf(aspect_ratio, 2.0 / 3.0))
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A channel 1 cm wide on a 5 mm grid, 8 particles per cell.
    fn test_channel() -> CollapseGeometry {
        CollapseGeometry {
            wall_x: 0.0,
            floor_z: 0.0,
            width: 0.01,
            dx: 0.005,
            lattice: Lattice::of(8).unwrap(),
        }
    }

    /// A box filled on any lattice of more than one particle per cell measures as its box, a
    /// stray grain far ahead not counted: the margin from the outermost particles to the box's
    /// faces is the lattice's own. (At one per
    /// cell the untouched columns stand exactly one window apart, and rounding can leave a
    /// window empty: the measure is for deposits, whose particles have moved.)
    #[test]
    fn a_box_on_every_lattice_measures_as_its_box() {
        for n in [2, 4, 8, 16, 27, 32, 64] {
            let g = CollapseGeometry {
                lattice: Lattice::of(n).unwrap(),
                ..test_channel()
            };
            let mut pts = Vec::new();
            let extent = Vector3::new(0.05, g.width, 0.1);
            g.lattice
                .points(&Vector3::zeros(), &extent, g.dx, || true, |x| pts.push(x));
            pts.push(Vector3::new(0.2, 0.005, 0.001));
            let d = measure(&g, &pts);
            assert!((d.length_m - 0.05).abs() < 1e-5, "{n} per cell: {d:?}");
            assert!((d.height_m - 0.1).abs() < 1e-5, "{n} per cell: {d:?}");
        }
    }

    /// A deposit thinning linearly from 2 cells at the wall to nothing 10 cells out, sampled
    /// as MPM samples it: 2 x 2 x 2 particles per cell, each moved by up to a quarter spacing
    /// (a fixed pseudo-random sequence), then stretched along x by `stretch`.
    fn wedge(g: &CollapseGeometry, stretch: f32) -> Vec<Vector3<f32>> {
        let (length, height) = (10.0 * g.dx, 2.0 * g.dx);
        let spacing = 0.5 * g.dx;
        let mut state = 12345u32;
        let mut jitter = || {
            state = state.wrapping_mul(1664525).wrapping_add(1013904223);
            ((state >> 8) as f32 / (1u32 << 24) as f32 - 0.5) * 0.5 * spacing
        };
        let per = |extent: f32| (extent / spacing).round() as usize;
        let mut pts = Vec::new();
        for i in 0..per(length) {
            for j in 0..per(g.width) {
                for k in 0..per(height) {
                    let centre = |n: usize| (n as f32 + 0.5) * spacing;
                    let p = Vector3::new(
                        centre(i) + jitter(),
                        centre(j) + jitter(),
                        centre(k) + jitter(),
                    );
                    if p.z < height * (1.0 - p.x / length) {
                        pts.push(Vector3::new(p.x * stretch, p.y, p.z));
                    }
                }
            }
        }
        pts
    }

    #[test]
    fn the_length_follows_a_thinning_toe_without_jumping_by_cells() {
        let g = test_channel();
        let lengths: Vec<f32> = (0..=40)
            .map(|k| measure(&g, &wedge(&g, 1.0 + 0.005 * k as f32)).length_m)
            .collect();
        // Each 0.5 % stretch moves the toe's quarter-cell-thick point (8.75 cells out) by 0.044
        // cells, 1.75 cells over the 40 stretches. The length follows it: measured, the
        // largest change from one stretch to the next is 0.044 cells (0.51 with the old
        // threshold of half a cell layer); with windows fixed to the cells it was 2.4 cells.
        let largest_jump = lengths
            .windows(2)
            .map(|p| (p[1] - p[0]).abs())
            .fold(0.0, f32::max);
        assert!(largest_jump < 0.25 * g.dx, "{lengths:?}");
        assert!(lengths[40] > lengths[0], "{lengths:?}");
    }

    /// A deposit two cells high whose toe runs on as a single particle layer (what the tall
    /// column leaves): the toe counts, a gap of one cell ends the deposit.
    #[test]
    fn a_toe_one_particle_thick_counts() {
        let g = test_channel();
        let s = 0.5 * g.dx;
        let grain = |i: usize, j: usize, k: usize| {
            Vector3::new(
                (i as f32 + 0.5) * s,
                (j as f32 + 0.5) * s,
                (k as f32 + 0.5) * s,
            )
        };
        let mut pts = Vec::new();
        for j in 0..4 {
            for i in 0..8 {
                pts.extend((0..4).map(|k| grain(i, j, k)));
            }
            // The toe: one layer from 8 to 20 spacings, then a gap of two spacings and a
            // patch that is not part of the deposit.
            pts.extend((8..20).map(|i| grain(i, j, 0)));
            pts.extend((22..26).map(|i| grain(i, j, 0)));
        }
        let d = measure(&g, &pts);
        assert!((d.length_m - 20.0 * s).abs() < 1e-5, "{d:?}");
        assert!((d.height_m - 4.0 * s).abs() < 1e-5, "{d:?}");
    }

    #[test]
    fn lube_laws() {
        assert_eq!(lube_normalized_runout(1.0), Some(1.2));
        assert!((lube_normalized_runout(8.0).unwrap() - 7.6).abs() < 1e-4);
        assert_eq!(lube_normalized_runout(2.0), None);
    }
}
