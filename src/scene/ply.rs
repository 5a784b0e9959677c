//! Particle snapshots as binary little-endian PLY (positions and velocities), which ParaView,
//! Blender, MeshLab and Open3D read.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::mpm::Particles;

/// Writes `vertex` elements with `x y z` (m) and `vx vy vz` (m/s) as float32.
pub fn write_ply(path: &Path, particles: &Particles) -> std::io::Result<()> {
    let mut out = BufWriter::new(std::fs::File::create(path)?);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment sandstep particles, SI units\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float vx\nproperty float vy\nproperty float vz\nend_header\n",
        particles.len()
    )?;
    for (x, v) in particles.position.iter().zip(&particles.velocity) {
        for value in x.iter().chain(v.iter()) {
            out.write_all(&value.to_le_bytes())?;
        }
    }
    out.flush()
}
