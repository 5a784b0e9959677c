//! Sand solvers, coupled stepping and a plate pushed through sand, shared by the coupling and
//! stability tests.
#![allow(dead_code)]

use std::path::Path;

use rapier3d::glamx::Vec3;
use rapier3d::prelude::{Pose, RigidBodyBuilder, RigidBodyHandle, RigidBodySet, SharedShape};
use sandstep::coupling::{Coupling, CouplingMethod, CouplingMode, CpicSurface, SandCollider};
use sandstep::mpm::Solver;
use sandstep::scene::Scene;

pub const DX: f32 = 0.005;
/// The test sand: soft (E = 0.35 MPa), damped inside its cone as the shipped scenes' sand
/// (without it a ball resting on it rings: `docs/speed-vs-accuracy.md`, "The CPIC band").
pub const SAND: &str = "{model: drucker_prager, density_kg_m3: 1600, youngs_modulus_pa: 3.5e5, \
                    poisson_ratio: 0.3, friction_angle_deg: 35, elastic_viscosity_pa_s: 50}";

/// A solver from YAML snippets: the domain's max corner (the min is the origin, walls slip),
/// gravity, the `solver:` mapping's entries, the one material `sand` and the bodies.
pub fn sand_solver(
    max_m: [f32; 3],
    gravity: [f32; 3],
    solver: &str,
    material: &str,
    bodies: &str,
) -> Solver {
    let text = format!(
        "name: test\nduration_s: 1.0\ngravity_m_s2: {gravity:?}\nsand:\n  dx_m: {DX}\n  domain:\n    \
         min_m: [0, 0, 0]\n    max_m: {max_m:?}\n  solver: {{{solver}}}\n  materials:\n    \
         sand: {material}\n  bodies: {bodies}\n"
    );
    Scene::from_yaml(&text, Path::new("test.yaml"), &[])
        .unwrap()
        .build_solver()
        .unwrap()
}

/// [`sand_solver`] with the default solver settings and [`SAND`].
pub fn solver(max_m: [f32; 3], gravity: [f32; 3], bodies: &str) -> Solver {
    sand_solver(max_m, gravity, "", SAND, bodies)
}

/// Advances sand and bodies together to `until_s`. The one dynamic body given with its mass
/// (kg) is integrated here (semi-implicit Euler with the force the coupling set; translation
/// only, no rapier contacts needed); the other bodies move at their velocity.
pub fn run(
    solver: &mut Solver,
    coupling: &mut Coupling,
    bodies: &mut RigidBodySet,
    until_s: f64,
    dynamic: Option<(RigidBodyHandle, f32)>,
) {
    while solver.time_s < until_s {
        let dt = solver.next_dt().min(coupling.max_dt_s(bodies, DX));
        coupling.substep(solver, bodies, dt).unwrap();
        for (handle, rb) in bodies.iter_mut() {
            if let Some((_, mass)) = dynamic.filter(|(h, _)| *h == handle) {
                let a = rb.user_force() / mass;
                rb.set_linvel(rb.linvel() + a * dt, true);
            }
            let moved = rb.translation() + rb.linvel() * dt;
            rb.set_translation(moved, true);
        }
    }
}

/// A vertical plate 0.2 dx thick, pushed along +x at 0.2 m/s through a sand layer 2 cm deep.
/// Returns (particles behind the plate at the end, particles the plate swept past).
pub fn push_plate_through_layer(method: CouplingMethod) -> (usize, usize) {
    let mut sand = solver(
        [0.12, 0.03, 0.06],
        [0.0, 0.0, -9.81],
        "[{material: sand, box: {min_m: [0.04, 0, 0], max_m: [0.10, 0.03, 0.02]}}]",
    );
    let half_extents = [0.1 * DX, 0.02, 0.03];
    let surface = match method {
        CouplingMethod::Cpic => CpicSurface::thin_box(half_extents),
        CouplingMethod::GridBoundary => CpicSurface::Solid(SharedShape::cuboid(
            half_extents[0],
            half_extents[1],
            half_extents[2],
        )),
    };
    let speed = 0.2;
    let x0 = 0.03;
    let mut bodies = RigidBodySet::new();
    let plate = bodies.insert(
        RigidBodyBuilder::kinematic_velocity_based()
            .translation(Vec3::new(x0, 0.015, 0.02))
            .linvel(Vec3::new(speed, 0.0, 0.0)),
    );
    let mut coupling = Coupling::new(
        vec![collider("plate", plate, surface, CouplingMode::OneWay)],
        &bodies,
    )
    .unwrap()
    .with_method(method);
    let start_x: Vec<f32> = sand.particles.position.iter().map(|x| x.x).collect();
    let duration = 0.1;
    run(&mut sand, &mut coupling, &mut bodies, duration, None);
    let plate_x = bodies[plate].translation().x;
    assert!((plate_x - (x0 + speed * duration as f32)).abs() < 0.01 * DX + speed * 2e-3);
    let behind = sand
        .particles
        .position
        .iter()
        .filter(|x| x.x < plate_x)
        .count();
    // Particles start unsorted, in id order.
    let swept = start_x.iter().filter(|&&x| x < plate_x).count();
    (behind, swept)
}

/// How long the plough's layer settles (s): long enough to come to rest and, with sleeping
/// sand, fall asleep (`after_s` 0.05 s after its particles are slower than 1 cm/s).
pub const PLOUGH_SETTLE_S: f64 = 0.15;

/// A plate ploughing a settled layer, and what it measured.
pub struct Plough {
    /// The sand at the end.
    pub sand: Solver,
    /// Mean x force of the sand on the plate while it pushes (N).
    pub mean_drag_n: f64,
    /// The solver's `(steps, awake_particle_steps)` when the push began.
    pub pushing_from: (u64, u64),
}

/// A vertical plate (0.2 dx thick, 2 cm wide, 2 cm tall) ploughing the top 1 cm of a layer
/// (20 x 10 x 1.5 cm) settled for [`PLOUGH_SETTLE_S`], along the channel's middle at 0.3 m/s
/// for 0.4 s, then standing for `rest_s`.
pub fn plough(solver_settings: &str, rest_s: f64) -> Plough {
    let mut sand = sand_solver(
        [0.20, 0.10, 0.05],
        [0.0, 0.0, -9.81],
        solver_settings,
        SAND,
        "[{material: sand, box: {min_m: [0, 0, 0], max_m: [0.20, 0.10, 0.015]}}]",
    );
    let settle_s = PLOUGH_SETTLE_S;
    sand.advance_to(settle_s).unwrap();
    let speed = 0.3;
    let mut bodies = RigidBodySet::new();
    let plate = bodies.insert(
        RigidBodyBuilder::kinematic_velocity_based()
            .translation(Vec3::new(0.02, 0.05, 0.015))
            .linvel(Vec3::new(speed, 0.0, 0.0)),
    );
    let surface = CpicSurface::thin_box([0.1 * DX, 0.01, 0.01]);
    let mut coupling = Coupling::new(
        vec![collider("plate", plate, surface, CouplingMode::OneWay)],
        &bodies,
    )
    .unwrap();
    let until_s = settle_s + 0.4;
    let (mut impulse_x, start_s) = (0.0f64, sand.time_s);
    let pushing_from = (sand.steps, sand.awake_particle_steps);
    while sand.time_s < until_s {
        let dt = sand.next_dt().min(coupling.max_dt_s(&bodies, DX));
        let impulses = coupling.substep(&mut sand, &mut bodies, dt).unwrap();
        impulse_x += impulses[0].linear_n_s.x;
        let rb = &mut bodies[plate];
        rb.set_translation(rb.translation() + rb.linvel() * dt, true);
    }
    // The plate stops; the sand behind and ahead comes to rest.
    bodies[plate].set_linvel(Vec3::ZERO, true);
    let rest_until_s = until_s + rest_s;
    while sand.time_s < rest_until_s {
        let dt = sand.next_dt();
        coupling.substep(&mut sand, &mut bodies, dt).unwrap();
    }
    Plough {
        sand,
        mean_drag_n: impulse_x / (until_s - start_s),
        pushing_from,
    }
}

pub fn collider(
    name: &str,
    body: RigidBodyHandle,
    surface: CpicSurface,
    mode: CouplingMode,
) -> SandCollider {
    SandCollider {
        name: name.into(),
        body,
        body_to_surface: Pose::IDENTITY,
        surface,
        friction: 0.3,
        mode,
    }
}

pub const JELLY: &str =
    "{model: fixed_corotated, density_kg_m3: 1000, youngs_modulus_pa: 1.0e5, poisson_ratio: 0.3}";

/// [`sand_solver`] in a 16 cm box.
pub fn box_solver(gravity: [f32; 3], solver: &str, material: &str, bodies: &str) -> Solver {
    sand_solver([0.16; 3], gravity, solver, material, bodies)
}
