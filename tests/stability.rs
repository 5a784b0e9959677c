//! Stability where numerical methods are known to fail (`docs/stability.md`): each case runs the
//! weak method beside the project's, and asserts both the failure and the success.

use nalgebra::Vector3;
use sandstep::coupling::CouplingMethod;
use sandstep::mpm::{SimError, Solver};

mod sand_support;
use sand_support::{box_solver as solver, push_plate_through_layer, sand_solver, JELLY, SAND};

const PILE: &str = "[{material: sand, box: {min_m: [0.04, 0.04, 0.0], max_m: [0.09, 0.08, 0.08]}}]";

/// Case 1. A thin leg-like plate (0.2 cells thick) swept through sand: the plain grid boundary
/// imposes the plate's velocity only on nodes inside it, which a 1 mm plate almost never holds,
/// so sand passes through it; CPIC keeps all of it in front.
#[test]
fn thin_plate_leaks_sand_through_the_grid_boundary_but_not_through_cpic() {
    let (behind, swept) = push_plate_through_layer(CouplingMethod::Cpic);
    println!("CPIC: {behind} of {swept} swept particles behind the plate");
    assert!(
        swept > 100,
        "the plate must sweep into the layer ({swept} particles)"
    );
    assert_eq!(
        behind, 0,
        "CPIC: {behind} particles leaked behind the plate"
    );
    // Measured: 96 of 384 (the plate holds sand back only while a node plane lies inside it).
    let (behind, swept) = push_plate_through_layer(CouplingMethod::GridBoundary);
    println!("grid boundary: {behind} of {swept} swept particles behind the plate");
    assert!(
        behind > swept / 10,
        "grid boundary: only {behind} of {swept} particles leaked (expected a leak)"
    );
}

/// Angular momentum of the particles about their centre of mass (kg m^2/s): their own
/// `m (x - c) x v` plus, with APIC, what their affine fields carry, `m dx^2/4 (C_zy - C_yz, ..)`
/// (the quadratic B-spline's `D = dx^2/4 I`; 4.7 % of a rigid spin of this cube).
fn angular_momentum(s: &Solver) -> Vector3<f64> {
    let p = &s.particles;
    let centre = p.centre_of_mass();
    let inertia_factor = (s.grid().dx as f64).powi(2) / 4.0;
    (0..p.len())
        .map(|i| {
            let (m, c) = (p.mass[i] as f64, p.affine[i].cast::<f64>());
            let orbital =
                (p.position[i].cast::<f64>() - centre).cross(&p.velocity[i].cast::<f64>());
            let affine = Vector3::new(
                c[(2, 1)] - c[(1, 2)],
                c[(0, 2)] - c[(2, 0)],
                c[(1, 0)] - c[(0, 1)],
            );
            (orbital + affine * inertia_factor) * m
        })
        .sum()
}

/// An elastic 4 cm cube spinning at 10 rad/s about z, without gravity, for 0.2 s (a third of
/// a turn), with each transfer. Returns the fraction of its angular momentum left.
fn spinning_cube_keeps(transfer: &str) -> f64 {
    let mut s = solver(
        [0.0, 0.0, 0.0],
        &format!("transfer: {transfer}"),
        JELLY,
        "[{material: sand, box: {min_m: [0.06, 0.06, 0.06], max_m: [0.10, 0.10, 0.10]}}]",
    );
    let centre = s.particles.centre_of_mass().cast::<f32>();
    let spin = Vector3::new(0.0, 0.0, 10.0f32);
    for (x, v) in s
        .particles
        .position
        .iter()
        .zip(s.particles.velocity.iter_mut())
    {
        *v = spin.cross(&(x - centre));
    }
    let before = angular_momentum(&s).z;
    s.advance_to(0.2).unwrap();
    angular_momentum(&s).z / before
}

/// Case 2. PIC transfers only each particle's velocity and averages away every rotation within
/// a cell, so a spinning block slows down; APIC carries the local velocity field and keeps it,
/// and so does AFLIP, which keeps the particle's deviation from the grid in both its velocity
/// and its affine field (keeping only the velocity's gained 2.4 % here).
#[test]
fn spinning_cube_loses_angular_momentum_with_pic_but_not_with_apic_or_aflip() {
    let pic = spinning_cube_keeps("pic");
    let apic = spinning_cube_keeps("apic");
    let aflip = spinning_cube_keeps("aflip");
    println!(
        "angular momentum left after 0.2 s: PIC {:.1} %, APIC {:.2} %, AFLIP {:.2} %",
        pic * 100.0,
        apic * 100.0,
        aflip * 100.0
    );
    assert!(pic < 0.8, "PIC kept {:.1} % (expected a loss)", pic * 100.0);
    for (transfer, kept) in [("APIC", apic), ("AFLIP", aflip)] {
        assert!(
            (kept - 1.0).abs() < 0.005,
            "{transfer} kept {:.2} % (expected all)",
            kept * 100.0
        );
    }
}

/// Case 5. A fixed step beyond the CFL limit lets the elastic waves outrun the grid: the
/// solver detects the blow-up and reports the step, time and particle; the adaptive step (CFL
/// 0.4) settles the same pile.
#[test]
fn a_fixed_step_beyond_cfl_blows_up_and_is_reported_the_adaptive_step_is_stable() {
    // Wave speed sqrt((lambda + 2 mu) / rho) = 17 m/s: the CFL step at CFL 1 is 2.9e-4 s.
    let mut fixed = solver([0.0, 0.0, -9.81], "fixed_dt_s: 6.0e-4", SAND, PILE);
    let err = fixed.advance_to(0.5).unwrap_err();
    let SimError::BlowUp {
        step,
        particle,
        time_s,
        ..
    } = &err
    else {
        panic!("a blow-up, not {err}");
    };
    let message = err.to_string();
    println!("fixed 6e-4 s: {message}");
    assert!(*step < 800, "detected only at step {step}");
    assert!(*time_s < 0.5);
    assert!((*particle as usize) < fixed.particles.len());
    assert!(
        message.contains("blew up at step") && message.contains("particle"),
        "{message}"
    );
    let mut adaptive = solver([0.0, 0.0, -9.81], "cfl: 0.4", SAND, PILE);
    adaptive.advance_to(0.5).unwrap();
    let fastest = fastest_particle_m_s(&adaptive);
    println!("adaptive: fastest particle {fastest:.3} m/s at 0.5 s");
    assert!(fastest < 0.5, "the pile must settle ({fastest} m/s)");
}

/// Case 5, viscous. An explicit viscous stress is stable only below a step of order
/// `rho dx^2 / eta`, but the sand's in-cone viscous stress is cut to what keeps the total stress
/// in the cone (`docs/physics.md`, "Materials"): no tension, no shear beyond friction. A sand
/// 200 times as viscous as the test sand (1e4 Pa s) settles at the elastic CFL step, ten times
/// the uncut stress's limit at that viscosity (uncut, measured 2026-12-04 at this step: 1400
/// Pa s blew up, 1000 Pa s jittered at 34 m/s), and the adaptive step does not shrink for it.
#[test]
fn a_viscous_sand_settles_at_the_elastic_step_its_stress_kept_in_the_cone() {
    let eta = 1e4;
    let viscous = SAND.replace(
        "elastic_viscosity_pa_s: 50",
        &format!("elastic_viscosity_pa_s: {eta}"),
    );
    assert_ne!(viscous, SAND);
    let adaptive = solver([0.0, 0.0, -9.81], "cfl: 0.4", &viscous, PILE);
    let undamped = SAND.replace("elastic_viscosity_pa_s: 50", "elastic_viscosity_pa_s: 0");
    let elastic_dt = solver([0.0, 0.0, -9.81], "cfl: 0.4", &undamped, PILE).next_dt();
    assert_eq!(
        adaptive.next_dt(),
        elastic_dt,
        "the viscosity must not bound the step"
    );
    // The elastic CFL step at CFL 0.4: 0.4 dx / 17 m/s = 1.17e-4 s; the uncut viscous stress's
    // limit, rho dx^2 / (0.36 eta), would be 1.1e-5 s.
    let mut elastic_step = solver([0.0, 0.0, -9.81], "fixed_dt_s: 1.1e-4", &viscous, PILE);
    let end_s = 0.3;
    elastic_step.advance_to(end_s).unwrap();
    let fastest = fastest_particle_m_s(&elastic_step);
    println!("pile of {eta} Pa s sand at {end_s} s, dt 1.1e-4 s: fastest particle {fastest} m/s");
    // Measured: 0.091 m/s (0.091 at 50 and 1000 Pa s, 0.20 at 1e5).
    assert!(fastest < 0.5, "the pile must settle ({fastest} m/s)");
}

/// The fastest particle's speed (m/s).
fn fastest_particle_m_s(s: &Solver) -> f32 {
    s.particles
        .velocity
        .iter()
        .map(|v| v.norm())
        .fold(0.0f32, f32::max)
}

/// Root-mean-square distance of the particles from their centre of mass (m).
fn rms_radius_m(s: &Solver) -> f64 {
    let p = &s.particles;
    let centre = p.centre_of_mass();
    let sum: f64 = p
        .position
        .iter()
        .map(|x| (x.cast::<f64>() - centre).norm_squared())
        .sum();
    (sum / p.len() as f64).sqrt()
}

/// A 4 cm cube of sand, no gravity, pulled apart (`v = a (x - c)`, a = 2/s, for 20 ms: 12 %
/// more volume) and pushed back (velocities reversed), `cycles` times. Returns the smallest RMS
/// radius each push-back reaches, over the initial one.
fn pull_push_cycles(volume_correction: bool, cycles: usize) -> Vec<f64> {
    let sand = format!(
        "{{model: drucker_prager, density_kg_m3: 1600, youngs_modulus_pa: 3.5e5, \
         poisson_ratio: 0.3, friction_angle_deg: 35, volume_correction: {volume_correction}}}"
    );
    let mut s = solver(
        [0.0, 0.0, 0.0],
        "",
        &sand,
        "[{material: sand, box: {min_m: [0.06, 0.06, 0.06], max_m: [0.10, 0.10, 0.10]}}]",
    );
    let r0 = rms_radius_m(&s);
    let centre = s.particles.centre_of_mass().cast::<f32>();
    let rate = 2.0f32;
    for (x, v) in s
        .particles
        .position
        .iter()
        .zip(s.particles.velocity.iter_mut())
    {
        *v = (x - centre) * rate;
    }
    let mut smallest = Vec::new();
    for _ in 0..cycles {
        s.advance_to(s.time_s + 0.02).unwrap();
        for v in s.particles.velocity.iter_mut() {
            *v = -*v;
        }
        let mut least = f64::INFINITY;
        for _ in 0..40 {
            s.advance_to(s.time_s + 0.001).unwrap();
            least = least.min(rms_radius_m(&s));
        }
        smallest.push(least / r0);
        // Pull apart again from wherever the push stopped.
        let centre = s.particles.centre_of_mass().cast::<f32>();
        for (x, v) in s
            .particles
            .position
            .iter()
            .zip(s.particles.velocity.iter_mut())
        {
            *v = (x - centre) * rate;
        }
    }
    smallest
}

/// Case 4. Drucker-Prager projects sand pulled apart to the cone's tip (no stress) and forgets
/// the volume it gained: pushed back, it resists from the loosened state on, so every cycle
/// leaves it looser. The volume correction (Tampubolon et al. 2017) remembers the volume and
/// gives it back on compression: the cube returns to its size.
#[test]
fn sand_pulled_apart_and_pushed_back_gains_volume_without_volume_correction_only() {
    let without = pull_push_cycles(false, 3);
    let with = pull_push_cycles(true, 3);
    println!("smallest RMS radius per cycle / initial: without {without:.4?}, with {with:.4?}");
    // Measured: 1.037, 1.135, 1.244 without (volume x1.12, x1.46, x1.93); 0.999, 0.997, 0.996.
    assert!(
        without.windows(2).all(|w| w[1] > w[0] + 0.02) && without[2] > 1.1,
        "without volume correction the cube must loosen every cycle: {without:?}"
    );
    assert!(
        with.iter().all(|r| (r - 1.0).abs() < 0.01),
        "with volume correction the cube must return to its size: {with:?}"
    );
}

/// Interval between the column's stress snapshots (s).
const COLUMN_SNAPSHOT_S: f64 = 0.01;
/// How long the column is followed (s): five of its oscillations.
const COLUMN_DURATION_S: f64 = 0.5;

/// A 4 cm square column of soft sand (E = 5 kPa: it compresses by up to a fifth, so its
/// particles cross cell boundaries) 6 cm tall on the floor of a 4 cm box with slip walls,
/// released at rest and unstressed with `kernel`. Confined and without damping, it never
/// settles: it oscillates between unstressed and twice its weight (period about 0.1 s), and
/// compression fronts run up and down it. Returns the vertical stress's scatter over
/// `rho g H`: per 1-cell layer the standard deviation of the particles' stress about its
/// linear trend in z within the layer (the trend is the column's real stress gradient, steep
/// where a front crosses the layer), averaged over the layers and over snapshots every
/// `COLUMN_SNAPSHOT_S` through `COLUMN_DURATION_S`, every phase of the oscillation.
fn column_stress_scatter(kernel: &str) -> f64 {
    let soft_sand = "{model: drucker_prager, density_kg_m3: 1600, youngs_modulus_pa: 5.0e3, \
                     poisson_ratio: 0.3, friction_angle_deg: 35}";
    let mut s = sand_solver(
        [0.04, 0.04, 0.08],
        [0.0, 0.0, -9.81],
        &format!("kernel: {kernel}"),
        soft_sand,
        "[{material: sand, box: {min_m: [0, 0, 0], max_m: [0.04, 0.04, 0.06]}}]",
    );
    let rho_g_h = 1600.0 * 9.81 * 0.06;
    let snapshots = (COLUMN_DURATION_S / COLUMN_SNAPSHOT_S).round() as usize;
    let mut scatter_sum = 0.0;
    for k in 1..=snapshots {
        s.advance_to(k as f64 * COLUMN_SNAPSHOT_S).unwrap();
        let p = &s.particles;
        let dx = s.grid().dx;
        // (z, Cauchy stress zz) of the particles of each 1-cell layer.
        let mut layers: Vec<Vec<(f64, f64)>> = Vec::new();
        for i in 0..p.len() {
            let layer = (p.position[i].z / dx) as usize;
            if layers.len() <= layer {
                layers.resize(layer + 1, Vec::new());
            }
            let cauchy_zz = p.stress[i][(2, 2)] as f64 / p.deformation[i].determinant() as f64;
            layers[layer].push((p.position[i].z as f64, cauchy_zz));
        }
        let scatters: Vec<f64> = layers
            .iter()
            .filter(|l| l.len() > 10)
            .map(|l| scatter_about_linear_trend(l))
            .collect();
        scatter_sum += scatters.iter().sum::<f64>() / scatters.len() as f64 / rho_g_h;
    }
    scatter_sum / snapshots as f64
}

/// Standard deviation of `y` about its least-squares line in `x`, over points `(x, y)`.
fn scatter_about_linear_trend(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n;
    let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let residual = |p: &(f64, f64)| p.1 - mean_y - slope * (p.0 - mean_x);
    (points.iter().map(|p| residual(p).powi(2)).sum::<f64>() / n).sqrt()
}

/// Case 3. The linear hat's gradient jumps where a particle crosses a cell boundary, so the
/// forces of a compressing column jitter as its particles move through the grid, and the
/// stress within each layer scatters; the quadratic B-spline's gradient is continuous.
#[test]
fn oscillating_column_has_cell_crossing_stress_noise_with_linear_weights_only() {
    let quadratic = column_stress_scatter("quadratic_bspline");
    let linear = column_stress_scatter("linear");
    println!(
        "vertical stress scatter within 1-cell layers about their trend, mean over 0.5 s, over \
         rho g H: quadratic B-spline {quadratic:.4}, linear hat {linear:.4}"
    );
    // Measured: 0.0109 and 0.119.
    assert!(
        linear > 0.06,
        "linear hat: scatter {linear} (expected noise)"
    );
    assert!(quadratic < 0.025, "quadratic B-spline: scatter {quadratic}");
}

/// How long the pile is watched (s).
const PILE_WATCH_S: f64 = 2.0;
/// Slope of the pile's flank (deg), well below the sand's 35 deg friction angle.
const PILE_SLOPE_DEG: f32 = 20.0;
/// Base radius of the conical pile (m).
const PILE_RADIUS_M: f32 = 0.06;

/// A cone of sand (20 deg flanks, 6 cm base radius, 2.2 cm tall) released at rest on a rough
/// floor (Coulomb 0.5) and watched for `PILE_WATCH_S` with `transfer`. Returns the particles'
/// displacements from where they started (m), sorted.
fn pile_displacements_m(transfer: &str) -> Vec<f32> {
    let (centre, height) = (0.08f32, PILE_RADIUS_M * PILE_SLOPE_DEG.to_radians().tan());
    let text = format!(
        "name: pile\nduration_s: {PILE_WATCH_S}\ngravity_m_s2: [0, 0, -9.81]\nsand:\n  dx_m: 0.005\n  \
         domain:\n    min_m: [0, 0, 0]\n    max_m: [0.16, 0.16, 0.08]\n    walls: {{z_min: \
         {{friction: 0.5}}}}\n  solver: {{transfer: {transfer}}}\n  materials:\n    sand: \
         {SAND}\n  bodies: [{{material: sand, box: {{min_m: [0.02, 0.02, 0.0], max_m: [0.14, \
         0.14, {height}]}}}}]\n"
    );
    let mut s = sandstep::scene::Scene::from_yaml(&text, std::path::Path::new("pile.yaml"), &[])
        .unwrap()
        .build_solver()
        .unwrap();
    s.remove_particles(|x| {
        let r = ((x.x - centre).powi(2) + (x.y - centre).powi(2)).sqrt();
        x.z < (PILE_RADIUS_M - r) * PILE_SLOPE_DEG.to_radians().tan()
    });
    let mut start =
        vec![Vector3::zeros(); s.particles.id.iter().max().map_or(0, |&m| m as usize + 1)];
    for (x, &id) in s.particles.position.iter().zip(&s.particles.id) {
        start[id as usize] = *x;
    }
    s.advance_to(PILE_WATCH_S).unwrap();
    // Particles are re-sorted by block: match them by id.
    let mut moved: Vec<f32> = s
        .particles
        .position
        .iter()
        .zip(&s.particles.id)
        .map(|(x, &id)| (x - start[id as usize]).norm())
        .collect();
    moved.sort_by(f32::total_cmp);
    moved
}

/// Case 6. FLIP-like transfers keep each particle's deviation from the grid's velocity, which
/// can keep sand that should rest jiggling and creeping; a pile with flanks below the angle of
/// repose, released at rest on a rough floor, must keep its shape.
#[test]
fn pile_at_rest_on_a_rough_floor_keeps_its_shape() {
    for transfer in ["apic", "aflip"] {
        let moved = pile_displacements_m(transfer);
        let rms = (moved.iter().map(|d| d * d).sum::<f32>() / moved.len() as f32).sqrt();
        let p99 = moved[moved.len() * 99 / 100];
        println!(
            "{transfer}: {} particles moved over {PILE_WATCH_S} s: RMS {:.3} mm, 99th percentile \
             {:.3} mm, most {:.3} mm",
            moved.len(),
            rms * 1e3,
            p99 * 1e3,
            moved.last().unwrap() * 1e3
        );
        // Measured: APIC RMS 0.006 mm, most 0.054 mm; AFLIP RMS 0.014 mm, most 0.066 mm.
        let most = *moved.last().unwrap();
        assert!(most < 5e-4, "{transfer}: a particle moved {most} m");
    }
}
