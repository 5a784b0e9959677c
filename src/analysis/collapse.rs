//! Granular column collapse: deposit length and height (Lube et al. 2005).
//!
//! The deposit is measured from the wall along +x in bins one cell wide. Scanning from the wall,
//! the deposit continues while a bin holds at least half a cell layer of particles across the
//! channel; the length is the farthest particle of those bins plus half a particle spacing, and
//! the height their highest particle plus half a spacing. Measured this way the initial column
//! gives back exactly its box, and a few grains that bounce ahead of the front do not count.

use nalgebra::Vector3;
use serde::Serialize;

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
    /// Particles per cell.
    pub particles_per_cell: u32,
}

/// Length and height of a deposit (m).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Deposit {
    pub length_m: f32,
    pub height_m: f32,
}

/// Measures the deposit formed by `positions`.
pub fn measure(g: &CollapseGeometry, positions: &[Vector3<f32>]) -> Deposit {
    let per_edge = libm::cbrtf(g.particles_per_cell as f32).round();
    let half_spacing = 0.5 * g.dx / per_edge;
    let bins = positions
        .iter()
        .map(|x| ((x.x - g.wall_x) / g.dx).max(0.0) as usize)
        .max();
    let mut count = vec![0usize; bins.map_or(0, |b| b + 1)];
    for x in positions {
        count[((x.x - g.wall_x) / g.dx).max(0.0) as usize] += 1;
    }
    // Half a layer of cells across the channel.
    let threshold = (0.5 * g.particles_per_cell as f32 * (g.width / g.dx)).max(1.0) as usize;
    let deposit_bins = count.iter().take_while(|&&c| c >= threshold).count();
    let end = g.wall_x + deposit_bins as f32 * g.dx;
    let (mut front, mut top) = (g.wall_x, g.floor_z);
    for x in positions.iter().filter(|x| x.x < end) {
        front = front.max(x.x);
        top = top.max(x.z);
    }
    Deposit {
        length_m: front + half_spacing - g.wall_x,
        height_m: top + half_spacing - g.floor_z,
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

    #[test]
    fn a_box_of_particles_measures_as_its_box() {
        let g = CollapseGeometry {
            wall_x: 0.0,
            floor_z: 0.0,
            width: 0.01,
            dx: 0.005,
            particles_per_cell: 8,
        };
        let s = 0.0025;
        let mut pts = Vec::new();
        for i in 0..20 {
            for j in 0..4 {
                for k in 0..40 {
                    pts.push(Vector3::new(
                        (i as f32 + 0.5) * s,
                        (j as f32 + 0.5) * s,
                        (k as f32 + 0.5) * s,
                    ));
                }
            }
        }
        // A stray grain far ahead does not count.
        pts.push(Vector3::new(0.2, 0.005, 0.001));
        let d = measure(&g, &pts);
        assert!((d.length_m - 0.05).abs() < 1e-5, "{d:?}");
        assert!((d.height_m - 0.1).abs() < 1e-5, "{d:?}");
    }

    #[test]
    fn lube_laws() {
        assert_eq!(lube_normalized_runout(1.0), Some(1.2));
        assert!((lube_normalized_runout(8.0).unwrap() - 7.6).abs() < 1e-4);
        assert_eq!(lube_normalized_runout(2.0), None);
    }
}
