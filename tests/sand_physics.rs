//! Whole-solver behaviour: bouncing elastic cube, determinism. (Blow-up detection:
//! `tests/stability.rs`.)

use sandstep::mpm::Solver;

mod sand_support;
use sand_support::{box_solver, JELLY, SAND};

/// A scene in a 16 cm box with slip walls under gravity; `material` and `bodies` are YAML
/// snippets.
fn scene(material: &str, bodies: &str, extra_solver: &str) -> Solver {
    box_solver([0.0, 0.0, -9.81], extra_solver, material, bodies)
}

#[test]
fn elastic_cube_bounces_and_keeps_its_volume() {
    let mut s = scene(
        JELLY,
        "[{material: sand, box: {min_m: [0.06, 0.06, 0.05], max_m: [0.10, 0.10, 0.09]}}]",
        "",
    );
    let v0 = s.particles.total_volume();
    let (mut fall_speed, mut rebound_speed, mut worst_volume) = (0.0f64, 0.0f64, 0.0f64);
    let mut t = 0.0;
    while t < 0.4 {
        t += 0.002;
        s.advance_to(t).unwrap();
        let vz = s.particles.total_momentum().z / s.particles.total_mass();
        if rebound_speed == 0.0 {
            fall_speed = fall_speed.max(-vz);
        }
        if fall_speed > 0.5 && vz > 0.0 {
            rebound_speed = rebound_speed.max(vz);
        }
        worst_volume = worst_volume.max((s.particles.total_volume() / v0 - 1.0).abs());
    }
    // Free fall from 5 cm: about 1 m/s at impact.
    assert!(fall_speed > 0.8, "fall speed {fall_speed}");
    assert!(
        rebound_speed > 0.3 * fall_speed,
        "rebound {rebound_speed} after {fall_speed}"
    );
    assert!(worst_volume < 0.05, "volume changed by {worst_volume}");
}

fn sand_pile() -> Solver {
    scene(
        SAND,
        "[{material: sand, box: {min_m: [0.04, 0.04, 0.0], max_m: [0.09, 0.08, 0.08]}}]",
        "",
    )
}

fn positions_after(threads: usize, steps: usize) -> Vec<[u32; 3]> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut s = sand_pile();
        for _ in 0..steps {
            s.substep().unwrap();
        }
        let mut by_id = vec![[0u32; 3]; s.particles.len()];
        for (x, &id) in s.particles.position.iter().zip(&s.particles.id) {
            by_id[id as usize] = [x.x.to_bits(), x.y.to_bits(), x.z.to_bits()];
        }
        by_id
    })
}

#[test]
fn runs_are_bit_identical() {
    let a = positions_after(2, 300);
    let b = positions_after(2, 300);
    assert!(a == b, "two runs with the same thread count differ");
    // The phase-ordered P2G makes the result independent of the thread count too.
    let c = positions_after(1, 300);
    assert!(a == c, "runs with 1 and 2 threads differ");
}
