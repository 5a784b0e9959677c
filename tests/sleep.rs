//! Sleeping sand (`sand.solver.sleep`, `docs/physics.md` "Sleeping sand"): blocks at rest are
//! left out of the substep, and must wake in time for the result not to change. Each case runs
//! with and without sleeping and asserts both that sleeping saved work and that the physics is
//! the same: a plate ploughing a settled layer (sand wakes as a collider approaches and sleeps
//! again behind it), and a cube of sand dropped onto a settled bed (the bed wakes because its
//! neighbours move). About 40 s on 2 cores.

use nalgebra::Vector3;
use sandstep::mpm::Solver;

mod sand_support;
use sand_support::{sand_solver, DX, SAND};

/// Sleep settings of the cases: the scene defaults, but sand wakes only 1 cm from a collider's
/// box (2 cm by default), so that the sand beside the plate's furrow can sleep.
const SLEEP: &str = "sleep: {wake_margin_m: 0.01}";

/// The dropped cube's bed settles as the plough's layer does before anything happens (s).
const SETTLE_S: f64 = sand_support::PLOUGH_SETTLE_S;

/// The mean over the run of the particles stepped, as a fraction of all particles.
fn awake_fraction(sand: &Solver) -> f64 {
    awake_fraction_since(sand, (0, 0))
}

/// [`awake_fraction`] since the solver's `(steps, awake_particle_steps)` were `since`.
fn awake_fraction_since(sand: &Solver, (steps, awake): (u64, u64)) -> f64 {
    (sand.awake_particle_steps - awake) as f64
        / ((sand.steps - steps) as f64 * sand.particles.len() as f64)
}

/// Centre of mass of the sand (m).
fn centre_of_mass(sand: &Solver) -> Vector3<f64> {
    let p = &sand.particles;
    let mut sum = Vector3::zeros();
    let mut mass = 0.0;
    for (x, &m) in p.position.iter().zip(&p.mass) {
        sum += x.cast::<f64>() * m as f64;
        mass += m as f64;
    }
    sum / mass
}

/// Height of the sand's top surface along the furrow (4 cm < y < 6 cm), in 1 cm columns over x
/// (m): the highest particle per column.
fn surface_profile(sand: &Solver, columns: usize) -> Vec<f32> {
    let mut top = vec![0.0f32; columns];
    for x in sand
        .particles
        .position
        .iter()
        .filter(|x| (0.04..0.06).contains(&x.y))
    {
        let c = ((x.x / 0.01) as usize).min(columns - 1);
        top[c] = top[c].max(x.z);
    }
    top
}

/// What the plate case measured.
struct Ploughed {
    /// Mean x force of the sand on the plate while it pushes (N).
    mean_drag_n: f64,
    centre_of_mass_m: Vector3<f64>,
    profile_m: Vec<f32>,
    /// [`awake_fraction`] from the push on.
    awake_fraction: f64,
    blocks_woken: usize,
    blocks_asleep_at_end: usize,
}

/// [`sand_support::plough`] with the plate standing for 0.15 s at the end, measured.
fn plough(solver_settings: &str) -> Ploughed {
    let ploughed = sand_support::plough(solver_settings, 0.15);
    let sand = &ploughed.sand;
    Ploughed {
        mean_drag_n: ploughed.mean_drag_n,
        centre_of_mass_m: centre_of_mass(sand),
        profile_m: surface_profile(sand, 20),
        awake_fraction: awake_fraction_since(sand, ploughed.pushing_from),
        blocks_woken: sand.sleep_changes.woken,
        blocks_asleep_at_end: sand.asleep_blocks(),
    }
}

#[test]
fn sand_wakes_ahead_of_a_plough_and_sleeps_beside_and_behind_it_without_changing_the_drag() {
    let all = plough("");
    let sleeping = plough(SLEEP);
    let profile_change = all
        .profile_m
        .iter()
        .zip(&sleeping.profile_m)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!(
        "drag {:.4} N (all) vs {:.4} N (sleeping); centre of mass x {:.5} vs {:.5} m; largest \
         surface change {:.2} mm; sleeping: {:.0} % of the particles stepped, {} blocks woken, {} \
         asleep at the end",
        all.mean_drag_n,
        sleeping.mean_drag_n,
        all.centre_of_mass_m.x,
        sleeping.centre_of_mass_m.x,
        profile_change * 1e3,
        100.0 * sleeping.awake_fraction,
        sleeping.blocks_woken,
        sleeping.blocks_asleep_at_end
    );
    assert!(
        all.mean_drag_n < -0.05,
        "the sand resists the plate: {} N",
        all.mean_drag_n
    );
    let drag_change = (sleeping.mean_drag_n - all.mean_drag_n).abs() / all.mean_drag_n.abs();
    assert!(
        drag_change < 0.03,
        "sleeping changes the drag by {:.1} %",
        100.0 * drag_change
    );
    assert!(
        (sleeping.centre_of_mass_m - all.centre_of_mass_m).norm() < 0.1 * DX as f64,
        "the sand ends elsewhere"
    );
    assert!(profile_change < DX, "surface changed by {profile_change} m");
    // The layer ahead slept until the plate came (it woke), and slept again behind it.
    assert_eq!(all.awake_fraction, 1.0);
    // (82 % measured: the furrow, the sand pushed ahead and the elastic response around them
    // keep most blocks moving while the plate ploughs; the bed is still for the rest.)
    assert!(sleeping.awake_fraction < 0.9, "{}", sleeping.awake_fraction);
    assert!(sleeping.blocks_woken > 10, "{}", sleeping.blocks_woken);
    assert!(
        sleeping.blocks_asleep_at_end > 10,
        "{}",
        sleeping.blocks_asleep_at_end
    );
}

/// A 3 cm cube of sand falling from 3 cm onto a settled bed, MPM alone (no collider to
/// wake the bed): returns the solver after the impact has settled.
fn drop_sand_cube(solver_settings: &str) -> Solver {
    let mut sand = sand_solver(
        [0.16, 0.16, 0.12],
        [0.0, 0.0, -9.81],
        solver_settings,
        SAND,
        "[{material: sand, box: {min_m: [0, 0, 0], max_m: [0.16, 0.16, 0.02]}}]",
    );
    sand.advance_to(SETTLE_S).unwrap();
    let cube = sand_solver(
        [0.16, 0.16, 0.12],
        [0.0, 0.0, -9.81],
        "",
        SAND,
        "[{material: sand, box: {min_m: [0.065, 0.065, 0.05], max_m: [0.095, 0.095, 0.08]}}]",
    );
    sand.add_particles(cube.particles.position.iter().map(|&position| {
        sandstep::mpm::NewParticle {
            position,
            velocity: Vector3::zeros(),
            mass: cube.particles.mass[0],
            volume: cube.particles.volume[0],
            material: 0,
        }
    }));
    sand.advance_to(SETTLE_S + 0.35).unwrap();
    sand
}

#[test]
fn a_settled_bed_wakes_where_sand_lands_on_it() {
    let all = drop_sand_cube("");
    let sleeping = drop_sand_cube(SLEEP);
    let (a, s) = (centre_of_mass(&all), centre_of_mass(&sleeping));
    let max_height = |sand: &Solver| {
        sand.particles
            .position
            .iter()
            .map(|x| x.z)
            .fold(0.0, f32::max)
    };
    println!(
        "centre of mass z {:.5} (all) vs {:.5} m (sleeping); top {:.4} vs {:.4} m; sleeping: \
         {:.0} % stepped, {} blocks woken",
        a.z,
        s.z,
        max_height(&all),
        max_height(&sleeping),
        100.0 * awake_fraction(&sleeping),
        sleeping.sleep_changes.woken
    );
    assert!(
        (a - s).norm() < 0.05 * DX as f64,
        "centre of mass {a:?} vs {s:?}"
    );
    assert!((max_height(&all) - max_height(&sleeping)).abs() < 0.5 * DX);
    assert!(
        sleeping.sleep_changes.woken > 10,
        "{}",
        sleeping.sleep_changes.woken
    );
    assert!(
        awake_fraction(&sleeping) < 0.7,
        "{}",
        awake_fraction(&sleeping)
    );
}
