//! The substep's stages against their invariants (P2G keeps mass, momentum and angular
//! momentum; G2P gives back the grid's), and the sparse substep against a dense reference
//! substep written as simply as possible.

use nalgebra::{Matrix3, Vector3};

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::*;
use crate::mpm::grid::BLOCK_EDGE;
use crate::mpm::kernel::{Kernel, Stencil};
use crate::mpm::material::{Constitutive, FixedCorotated, Lame};
use crate::mpm::{NewParticle, Wall, Walls};
use rand::{rngs::SmallRng, Rng, SeedableRng};

const DX: f32 = 0.01;

pub(crate) fn jelly() -> SolverMaterial {
    SolverMaterial {
        name: "jelly".into(),
        density_kg_m3: 1000.0,
        model: Constitutive::FixedCorotated(FixedCorotated {
            lame: Lame::from_young_poisson(1e5, 0.3),
        }),
    }
}

pub(crate) fn settings(gravity: Vector3<f32>, walls: Walls) -> SolverSettings {
    SolverSettings {
        dx: DX,
        domain_min: Vector3::zeros(),
        domain_max: Vector3::new(0.4, 0.3, 0.3),
        walls,
        gravity,
        time_step: TimeStep::Fixed { dt_s: 1e-4 },
        blowup_speed_m_s: 100.0,
        transfer: Transfer::Apic,
        flip_relaxation_s: 0.0,
        cpic_band: CpicBand::default(),
        cpic_band_relaxation_s: DEFAULT_CPIC_BAND_RELAXATION_S,
        kernel: Kernel::QuadraticBspline,
        sleep: None,
    }
}

/// A blob of particles with random velocities, affine matrices and symmetric stresses.
fn random_solver(seed: u64, gravity: Vector3<f32>, walls: Walls) -> Solver {
    random_solver_of(3000, seed, gravity, walls)
}

/// [`random_solver`] with `particles` particles.
fn random_solver_of(particles: usize, seed: u64, gravity: Vector3<f32>, walls: Walls) -> Solver {
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut s = Solver::new(settings(gravity, walls), vec![jelly()]);
    let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
    let new: Vec<NewParticle> = (0..particles)
        .map(|_| NewParticle {
            position: Vector3::new(r(0.05, 0.35), r(0.05, 0.25), r(0.05, 0.25)),
            velocity: Vector3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)),
            mass: r(0.5, 1.5) * 1e-3,
            volume: 1e-6,
            material: 0,
        })
        .collect();
    s.add_particles(new);
    let mut rng = SmallRng::seed_from_u64(seed + 1);
    for p in 0..s.particles.len() {
        s.particles.affine[p] = Matrix3::from_fn(|_, _| rng.random_range(-5.0..5.0));
        let a = Matrix3::from_fn(|_, _| rng.random_range(-1e3..1e3f32));
        s.particles.stress[p] = a + a.transpose();
    }
    s
}

fn grid_totals(s: &Solver) -> (f64, Vector3<f64>, Vector3<f64>) {
    let (mut m, mut p, mut l) = (0.0, Vector3::zeros(), Vector3::zeros());
    for (block, coord) in s.grid.blocks.iter().zip(&s.grid.coords) {
        for (n, node) in block.iter().enumerate() {
            let idx = [n / 16, (n / 4) % 4, n % 4];
            let x = Vector3::from_fn(|a, _| ((coord[a] * BLOCK_EDGE) as usize + idx[a]) as f64)
                * DX as f64
                + s.grid.origin.cast::<f64>();
            let mom = Vector3::new(node[0] as f64, node[1] as f64, node[2] as f64);
            m += node[3] as f64;
            p += mom;
            l += x.cross(&mom);
        }
    }
    (m, p, l)
}

fn close(a: Vector3<f64>, b: Vector3<f64>, scale: f64) -> bool {
    (a - b).norm() <= 1e-5 * scale
}

#[test]
fn p2g_conserves_mass_momentum_and_angular_momentum() {
    let mut s = random_solver(1, Vector3::zeros(), Walls::all(Wall::Slip));
    let (m0, p0, l0) = (
        s.particles.total_mass(),
        s.particles.total_momentum(),
        s.particles.total_angular_momentum(DX),
    );
    s.sort_particles_by_block();
    s.grid.rebuild(&s.keys, |_| false);
    // Stress enters P2G but, being symmetric and summed against zero-mean offsets, adds no
    // net force or torque.
    s.particle_to_grid(1e-4, &[]);
    let (m, p, l) = grid_totals(&s);
    let p_scale = s.particles.mass.iter().map(|&m| m as f64).sum::<f64>();
    assert!((m - m0).abs() < 1e-6 * m0, "mass {m} vs {m0}");
    assert!(close(p, p0, p_scale), "momentum {p:?} vs {p0:?}");
    assert!(
        close(l, l0, p_scale * 0.4),
        "angular momentum {l:?} vs {l0:?}"
    );
}

#[test]
fn g2p_gives_back_the_grid_angular_momentum() {
    let mut s = random_solver(2, Vector3::zeros(), Walls::all(Wall::Slip));
    for p in 0..s.particles.len() {
        s.particles.stress[p] = Matrix3::zeros();
    }
    s.sort_particles_by_block();
    s.grid.rebuild(&s.keys, |_| false);
    s.particle_to_grid(0.0, &[]);
    s.update_grid(0.0, &[]);
    // After the grid update the nodes hold velocities; weight them by mass.
    let (mut p_grid, mut l_grid) = (Vector3::zeros(), Vector3::zeros());
    for (block, coord) in s.grid.blocks.iter().zip(&s.grid.coords) {
        for (n, node) in block.iter().enumerate() {
            let idx = [n / 16, (n / 4) % 4, n % 4];
            let x = Vector3::from_fn(|a, _| ((coord[a] * BLOCK_EDGE) as usize + idx[a]) as f64)
                * DX as f64;
            let mom = Vector3::new(node[0] as f64, node[1] as f64, node[2] as f64) * node[3] as f64;
            p_grid += mom;
            l_grid += x.cross(&mom);
        }
    }
    s.grid_to_particle(0.0, &[]);
    let scale = s.particles.total_mass();
    assert!(close(s.particles.total_momentum(), p_grid, scale));
    assert!(close(
        s.particles.total_angular_momentum(DX),
        l_grid,
        scale * 0.4
    ));
}

/// The same substep on a plain dense grid, written as simply as possible.
fn dense_reference_step(s: &mut Solver, dt: f32) {
    // Nodes -1 ..= extent/dx + 1 per axis, stored with an offset of 1.
    let n = [44usize, 34, 34];
    let at = |i: [i32; 3]| -> usize {
        let u = i.map(|v| (v + 1) as usize);
        (u[0] * n[1] + u[1]) * n[2] + u[2]
    };
    let mut grid = vec![[0.0f32; 4]; n[0] * n[1] * n[2]];
    let p = &s.particles;
    for q in 0..p.len() {
        let st = Stencil::new(p.position[q] / DX);
        let m = p.mass[q];
        let qm = p.stress[q] * (-dt * 4.0 / DX * p.volume[q]) + p.affine[q] * (m * DX);
        for (i, j, k) in stencil_nodes() {
            let w = st.weight(i, j, k);
            let mom = (p.velocity[q] * m + qm * st.offset_cells(i, j, k)) * w;
            let g = &mut grid[at([
                st.base[0] + i as i32,
                st.base[1] + j as i32,
                st.base[2] + k as i32,
            ])];
            g[0] += mom.x;
            g[1] += mom.y;
            g[2] += mom.z;
            g[3] += w * m;
        }
    }
    let wall_nodes = s.wall_nodes;
    for x in -1..(n[0] as i32 - 1) {
        for y in -1..(n[1] as i32 - 1) {
            for z in -1..(n[2] as i32 - 1) {
                let g = &mut grid[at([x, y, z])];
                if g[3] <= 0.0 {
                    continue;
                }
                let v = Vector3::new(g[0], g[1], g[2]) / g[3] + s.settings.gravity * dt;
                let v = s.settings.walls.apply_at_node(v, [x, y, z], &wall_nodes);
                g[0] = v.x;
                g[1] = v.y;
                g[2] = v.z;
            }
        }
    }
    let (lo, hi) = (s.settings.domain_min, s.settings.domain_max);
    let p = &mut s.particles;
    for q in 0..p.len() {
        let st = Stencil::new(p.position[q] / DX);
        let (mut v, mut b) = (Vector3::zeros(), Matrix3::zeros());
        for (i, j, k) in stencil_nodes() {
            let g = grid[at([
                st.base[0] + i as i32,
                st.base[1] + j as i32,
                st.base[2] + k as i32,
            ])];
            let vi = Vector3::new(g[0], g[1], g[2]) * st.weight(i, j, k);
            v += vi;
            b += vi * st.offset_cells(i, j, k).transpose();
        }
        let c = b * (4.0 / DX);
        p.deformation[q] = (Matrix3::identity() + c * dt) * p.deformation[q];
        p.position[q] = (p.position[q] + v * dt).sup(&lo).inf(&hi);
        p.velocity[q] = v;
        p.affine[q] = c;
        let mut vc = p.volume_correction[q];
        let model = &s.materials[0].model;
        p.stress[q] = model.update(&mut p.deformation[q], &mut vc, &mut p.svd_frame[q]);
        p.volume_correction[q] = vc;
    }
}

fn stencil_nodes() -> impl Iterator<Item = (usize, usize, usize)> {
    (0..3).flat_map(|i| (0..3).flat_map(move |j| (0..3).map(move |k| (i, j, k))))
}

#[test]
fn sparse_grid_matches_a_dense_reference_grid() {
    let walls = Walls {
        z_min: Wall::Sticky,
        x_max: Wall::Friction(0.5),
        ..Walls::all(Wall::Slip)
    };
    let gravity = Vector3::new(0.0, 0.0, -9.81);
    let mut sparse = random_solver(3, gravity, walls);
    // Push some particles against the walls so the boundary code runs.
    for p in 0..300 {
        sparse.particles.position[p].z = 0.001 * (p % 7) as f32;
        sparse.particles.position[p].x = 0.4 - 0.001 * (p % 5) as f32;
    }
    let mut dense = Solver::new(sparse.settings.clone(), sparse.materials.clone());
    dense.particles = sparse.particles.clone();
    dense.wall_nodes = sparse.wall_nodes;
    for _ in 0..5 {
        sparse.substep().unwrap();
        dense_reference_step(&mut dense, 1e-4);
    }
    let mut by_id = vec![0usize; sparse.particles.len()];
    for (q, &id) in sparse.particles.id.iter().enumerate() {
        by_id[id as usize] = q;
    }
    let (mut dx_max, mut dv_max) = (0.0f32, 0.0f32);
    for q in 0..dense.particles.len() {
        let r = by_id[dense.particles.id[q] as usize];
        dx_max = dx_max.max((sparse.particles.position[r] - dense.particles.position[q]).norm());
        dv_max = dv_max.max((sparse.particles.velocity[r] - dense.particles.velocity[q]).norm());
    }
    assert!(dx_max < 1e-6, "positions differ by {dx_max} m");
    assert!(dv_max < 1e-3, "velocities differ by {dv_max} m/s");
}

/// The state of each particle by persistent id: position, velocity and deformation gradient.
fn states_by_id(s: &Solver) -> Vec<(Vector3<f32>, Vector3<f32>, Matrix3<f32>)> {
    let p = &s.particles;
    let mut states = vec![Default::default(); p.len()];
    for i in 0..p.len() {
        states[p.id[i] as usize] = (p.position[i], p.velocity[i], p.deformation[i]);
    }
    states
}

/// A stop request that arrives inside a substep (from another thread, at whatever stage the
/// substep is in) ends it with every particle whole: each one's state is, bit for bit, the
/// state of an unstopped solver at the last whole substep or at the next one, and the clock
/// says the last whole substep. A solver torn inside G2P steps no further. The stop lands
/// where the thread's timing puts it; attempts go on until one has landed inside G2P (about
/// half a substep's time is G2P and the particle update).
#[test]
fn a_stop_inside_a_substep_leaves_every_particle_whole() {
    const PARTICLES: usize = 40_000;
    const MOST_ATTEMPTS: u64 = 40;
    let walls = Walls::all(Wall::Slip);
    let gravity = Vector3::new(0.0, 0.0, -9.81);
    let new_solver = || random_solver_of(PARTICLES, 3, gravity, walls);
    let mut torn_seen = false;
    for attempt in 0..MOST_ATTEMPTS {
        let mut stopped = new_solver();
        let stop = Arc::new(AtomicBool::new(false));
        stopped.stop_on(stop.clone());
        let request = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                std::thread::sleep(std::time::Duration::from_micros(5_000 + 1_700 * attempt));
                stop.store(true, Ordering::Relaxed);
            })
        };
        stopped.advance_to(1.0).expect("a stop is not a failure");
        request.join().unwrap();
        let whole_steps = stopped.steps;

        let mut reference = new_solver();
        for _ in 0..whole_steps {
            reference.substep().unwrap();
        }
        assert_eq!(
            stopped.time_s, reference.time_s,
            "the clock of the last whole substep"
        );
        let before = states_by_id(&reference);
        reference.substep().unwrap();
        let after = states_by_id(&reference);
        let state = states_by_id(&stopped);
        let moved_on = (0..PARTICLES)
            .filter(|&id| {
                assert!(
                    state[id] == before[id] || state[id] == after[id],
                    "particle {id} is neither at step {whole_steps} nor at the next"
                );
                state[id] != before[id]
            })
            .count();
        match stopped.substep() {
            Err(SimError::StoppedMidTransfer { moved, blocks, .. }) => {
                assert!(moved < blocks, "{moved} of {blocks} blocks moved");
                assert_eq!(moved_on > 0, moved > 0, "{moved_on} particles moved on");
                torn_seen = true;
            }
            Err(SimError::Stopped { .. }) => assert_eq!(moved_on, 0, "nothing moved"),
            other => panic!("a stopped solver steps no further: {other:?}"),
        }
        if torn_seen {
            break;
        }
    }
    assert!(
        torn_seen,
        "no stop landed inside G2P in {MOST_ATTEMPTS} attempts"
    );
}

/// The sort keeps a sleeping particle's block key instead of taking it afresh (the particle
/// has not moved): after every sort each key is its particle's own, as blocks fall asleep and
/// wake, and as particles are removed and added (which make the sort take every key afresh).
#[test]
fn sleeping_particles_keep_their_own_block_keys() {
    let mut settings = settings(Vector3::zeros(), Walls::all(Wall::Slip));
    settings.sleep = Some(crate::mpm::SleepSettings {
        speed_m_s: 0.01,
        after_s: 1e-3,
        wake_margin_m: 0.0,
    });
    let mut s = Solver::new(settings, vec![jelly()]);
    let mut rng = SmallRng::seed_from_u64(5);
    // At rest on the low-x side (falls asleep), moving on the high-x side (some of it drifts
    // into the resting sand and wakes it).
    let mut particle = |x_lo: f32, x_hi: f32, speed: f32| NewParticle {
        position: Vector3::new(
            rng.random_range(x_lo..x_hi),
            rng.random_range(0.05..0.25),
            rng.random_range(0.05..0.25),
        ),
        velocity: Vector3::new(-speed, rng.random_range(-1.0..1.0) * speed, 0.0),
        mass: 1e-3,
        volume: 1e-6,
        material: 0,
    };
    let resting: Vec<NewParticle> = (0..2000).map(|_| particle(0.05, 0.2, 0.0)).collect();
    let moving: Vec<NewParticle> = (0..1000).map(|_| particle(0.22, 0.35, 0.3)).collect();
    s.add_particles(resting);
    s.add_particles(moving);
    let mut most_asleep = 0;
    for step in 0..120 {
        if step == 60 {
            // As many in as out: the count alone does not show that the keys moved.
            // The first in sorted order go, so the others' indices shift.
            let removed = s.remove_particles(|x| x.x >= 0.08);
            assert!(removed > 0);
            s.add_particles(
                (0..removed)
                    .map(|_| particle(0.05, 0.1, 0.0))
                    .collect::<Vec<_>>(),
            );
        }
        s.begin_substep(&[]);
        let fresh: Vec<u32> = s
            .particles
            .position
            .iter()
            .map(|x| s.grid.block_key(x))
            .collect();
        assert!(
            s.keys == fresh,
            "substep {step}: a key is not its particle's"
        );
        most_asleep = most_asleep.max(s.asleep_blocks());
        s.finish_substep(1e-4, &[]).unwrap();
    }
    assert!(most_asleep > 5, "{most_asleep} blocks asleep at most");
    assert!(s.sleep_changes.woken > 0, "no block woke");
}
