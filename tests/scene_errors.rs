//! Bad scene input gets a clear error naming the file and the field.

use std::path::Path;

use sandstep::scene::{Scene, SceneError};

const SCENE: &str = include_str!("../config/column_collapse.yaml");

fn error_of(text: &str, overrides: &[&str]) -> String {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    match Scene::from_yaml(text, Path::new("scenes/test.yaml"), &overrides) {
        Ok(_) => panic!("scene with {overrides:?} was accepted"),
        Err(e) => e.to_string(),
    }
}

fn assert_names(message: &str, parts: &[&str]) {
    for part in parts {
        assert!(
            message.contains(part),
            "error `{message}` does not mention `{part}`"
        );
    }
}

#[test]
fn the_shipped_scene_loads() {
    let scene = Scene::load(Path::new("config/column_collapse.yaml"), &[]).unwrap();
    assert!(scene.build_solver().unwrap().particles.len() > 1000);
}

#[test]
fn unknown_key() {
    let text = SCENE.replacen("\nsand:\n", "\nsand:\n  grid_size: 3\n", 1);
    assert_names(
        &error_of(&text, &[]),
        &["scenes/test.yaml", "sand", "grid_size", "line"],
    );
    let e = error_of(SCENE, &["sand.materials.sand.frction_angle_deg=30"]);
    assert_names(
        &e,
        &[
            "scenes/test.yaml",
            "sand.materials.sand",
            "frction_angle_deg",
        ],
    );
}

/// The in-cone viscosity is set one way: as a viscosity or as a relaxation time.
#[test]
fn a_viscosity_and_a_relaxation_time_are_refused_together() {
    let e = error_of(
        SCENE,
        &[
            "sand.materials.sand.elastic_viscosity_pa_s=50",
            "sand.materials.sand.elastic_relaxation_s=7.35e-5",
        ],
    );
    assert_names(
        &e,
        &[
            "scenes/test.yaml",
            "sand.materials.sand.elastic_relaxation_s",
            "not both",
        ],
    );
}

/// A relaxation time gives the viscosity the shear modulus times it: the shipped robot scene's
/// 7.35e-5 s is 50 Pa s at its 1.7685 MPa (Poisson 0.3), and a third of E a third of that.
#[test]
fn the_relaxation_time_scales_the_viscosity_with_the_stiffness() {
    use sandstep::mpm::material::Constitutive;
    let viscosity = |overrides: &[&str]| {
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &overrides).unwrap();
        let solver = scene.build_solver().unwrap();
        match &solver.materials[0].model {
            Constitutive::DruckerPrager(dp) => dp.elastic_viscosity_pa_s,
            other => panic!("sand is Drucker-Prager, not {other:?}"),
        }
    };
    let shipped = viscosity(&["sand.bodies.0.box={min_m: [0, 0, -0.02], max_m: [0.02, 0.02, 0]}"]);
    assert!((shipped - 50.0).abs() < 0.01, "{shipped} Pa s");
    let soft = viscosity(&[
        "sand.bodies.0.box={min_m: [0, 0, -0.02], max_m: [0.02, 0.02, 0]}",
        "sand.materials.sand.youngs_modulus_pa=5.895e5",
    ]);
    assert!((soft - 50.0 / 3.0).abs() < 0.01, "{soft} Pa s");
}

/// `yield_cone` reaches the solver's cone slope (`docs/physics.md`, "The yield cone's fit"): the
/// shipped sand's triaxial fit at 45 deg, 0.5036; the plane-strain fit, sqrt(2) sin(45 deg) / 3
/// = 1/3; an unknown fit is refused by name.
#[test]
fn the_yield_cone_option_sets_the_cone() {
    use sandstep::mpm::material::Constitutive;
    let alpha = |overrides: &[&str]| {
        let mut all = vec!["sand.bodies.0.box={min_m: [0, 0, -0.02], max_m: [0.02, 0.02, 0]}"];
        all.extend_from_slice(overrides);
        let all: Vec<String> = all.iter().map(|s| s.to_string()).collect();
        let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &all).unwrap();
        match &scene.build_solver().unwrap().materials[0].model {
            Constitutive::DruckerPrager(dp) => dp.alpha,
            other => panic!("sand is Drucker-Prager, not {other:?}"),
        }
    };
    let triaxial = alpha(&[]);
    assert!((triaxial - 0.5036).abs() < 1e-4, "{triaxial}");
    let plane_strain = alpha(&["sand.materials.sand.yield_cone=plane_strain"]);
    assert!((plane_strain - 1.0 / 3.0).abs() < 1e-5, "{plane_strain}");
    let e = error_of(SCENE, &["sand.materials.sand.yield_cone=round"]);
    assert_names(
        &e,
        &[
            "scenes/test.yaml",
            "sand.materials.sand",
            "round",
            "plane_strain",
        ],
    );
}

#[test]
fn out_of_range_values() {
    for (set, field) in [
        ("sand.dx_m=0", "sand.dx_m"),
        ("sand.dx_m=-0.01", "sand.dx_m"),
        (
            "sand.materials.sand.friction_angle_deg=90",
            "sand.materials.sand.friction_angle_deg",
        ),
        (
            "sand.materials.sand.friction_angle_deg=0",
            "sand.materials.sand.friction_angle_deg",
        ),
        (
            "sand.materials.sand.poisson_ratio=0.5",
            "sand.materials.sand.poisson_ratio",
        ),
        (
            "sand.materials.sand.youngs_modulus_pa=0",
            "sand.materials.sand.youngs_modulus_pa",
        ),
        ("sand.solver.cfl=1.5", "sand.solver.cfl"),
        (
            "sand.solver.flip_relaxation_s=-1e-3",
            "sand.solver.flip_relaxation_s",
        ),
        (
            "sand.solver.cpic_band_relaxation_s=-1e-3",
            "sand.solver.cpic_band_relaxation_s",
        ),
        (
            "sand.materials.sand.elastic_viscosity_pa_s=-5",
            "sand.materials.sand.elastic_viscosity_pa_s",
        ),
        (
            "sand.materials.sand.elastic_viscosity_pa_s=.inf",
            "sand.materials.sand.elastic_viscosity_pa_s",
        ),
        (
            "sand.materials.sand.elastic_relaxation_s=-1e-4",
            "sand.materials.sand.elastic_relaxation_s",
        ),
        (
            "sand.domain.walls.z_min={friction: -1}",
            "sand.domain.walls.z_min",
        ),
        ("duration_s=0", "duration_s"),
        ("node.state_rate_hz=0", "node.state_rate_hz"),
        ("node.surface_rate_hz=-1", "node.surface_rate_hz"),
        ("node.command_timeout_s=-0.5", "node.command_timeout_s"),
        ("node.stride_length_m=0", "node.stride_length_m"),
        ("node.name=9lives", "node.name"),
        ("node.namespace=robot1", "node.namespace"),
        ("node.namespace=/a//b", "node.namespace"),
        (
            "column_collapse.material=gravel",
            "column_collapse.material",
        ),
        (
            "column_collapse.particles_per_cell=5",
            "column_collapse.particles_per_cell",
        ),
    ] {
        assert_names(&error_of(SCENE, &[set]), &["scenes/test.yaml", field]);
    }
}

#[test]
fn wall_syntax() {
    let e = error_of(SCENE, &["sand.domain.walls.x_max=sticcy"]);
    assert_names(
        &e,
        &["sand.domain.walls.x_max", "sticky", "slip", "friction"],
    );
}

#[test]
fn body_outside_the_domain() {
    // A column taller than the domain.
    let e = error_of(SCENE, &["column_collapse.aspect_ratio=10"]);
    assert_names(
        &e,
        &[
            "scenes/test.yaml",
            "column_collapse",
            "outside the domain",
            "axis 2",
        ],
    );
    let e = error_of(
        SCENE,
        &["sand.bodies=[{material: sand, box: {min_m: [0.1, 0, 0], max_m: [0.5, 0.009, 0.05]}}]"],
    );
    assert_names(&e, &["sand.bodies[0].box", "outside the domain", "axis 0"]);
}

#[test]
fn missing_file() {
    let e = Scene::load(Path::new("config/no_such_scene.yaml"), &[]).unwrap_err();
    assert!(matches!(
        e,
        SceneError::Config(sandstep::config_error::ConfigError::Read { .. })
    ));
    assert_names(
        &e.to_string(),
        &["config/no_such_scene.yaml", "cannot read"],
    );
}

#[test]
fn malformed_yaml_and_bad_override() {
    assert_names(&error_of("name: [unclosed\n", &[]), &["scenes/test.yaml"]);
    assert_names(
        &error_of(SCENE, &["sand.dx_m"]),
        &["--set sand.dx_m", "key.path=value"],
    );
}

#[test]
fn terrain_values_out_of_range() {
    let robot_scene = include_str!("../config/robot_on_sand.yaml");
    for (text, set, field) in [
        (
            robot_scene,
            "terrain.rft.zeta_n_m3=0",
            "terrain.rft.zeta_n_m3",
        ),
        (
            robot_scene,
            "terrain.rft.element_size_m=-1",
            "terrain.rft.element_size_m",
        ),
        (
            robot_scene,
            "terrain.rft.max_dt_s=.nan",
            "terrain.rft.max_dt_s",
        ),
        (
            robot_scene,
            "terrain.rft.max_dt_s=0.05",
            "terrain.rft.max_dt_s",
        ),
        (
            robot_scene,
            "terrain.rft.max_dt_s=soon",
            "terrain.rft.max_dt_s",
        ),
        (
            robot_scene,
            "terrain.rft.surface_height_m=-0.1",
            "terrain.rft.surface_height_m",
        ),
        (
            robot_scene,
            "terrain.rft.calibration.plate_thickness_m=0.01",
            "terrain.rft.calibration.plate_thickness_m",
        ),
        (
            robot_scene,
            "terrain.rft.calibration.material=gravel",
            "terrain.rft.calibration.material",
        ),
        (robot_scene, "terrain.model=dem", "terrain.model"),
        // RFT acts on a robot's bodies: a sand-only scene cannot use it.
        (SCENE, "terrain.model=rft", "terrain.model"),
    ] {
        assert_names(&error_of(text, &[set]), &["scenes/test.yaml", field]);
    }
}

/// A robot started beyond the sand is rejected at load time, naming the coordinate (issue 22:
/// it used to panic at t = 0 where the sand window's walls met). On RFT ground there is no
/// sand domain to start over.
#[test]
fn a_robot_starting_off_the_sand() {
    let robot_scene = include_str!("../config/robot_on_sand.yaml");
    for (set, field, value) in [
        (
            "robot.initial_pose.position_m=[1.9, 0.0]",
            "position_m[0]",
            "1.9",
        ),
        (
            "robot.initial_pose.position_m=[-0.5, 0.0]",
            "position_m[0]",
            "-0.5",
        ),
        (
            "robot.initial_pose.position_m=[0.0, 0.2]",
            "position_m[1]",
            "0.2",
        ),
    ] {
        assert_names(
            &error_of(robot_scene, &[set]),
            &[
                "scenes/test.yaml",
                "robot.initial_pose.",
                field,
                value,
                "sand domain",
            ],
        );
        for window in ["sand.window=null", "terrain.model=rft"] {
            let overrides: Vec<String> = [set, window].iter().map(|s| s.to_string()).collect();
            let loaded = Scene::from_yaml(robot_scene, Path::new("scenes/test.yaml"), &overrides);
            assert_eq!(
                loaded.is_ok(),
                window == "terrain.model=rft",
                "{set} {window}"
            );
        }
    }
}

/// The load prediction needs the yielding inertia the link's dynamics present: with another
/// leg yield it is refused, naming both fields.
#[test]
fn the_load_prediction_needs_the_articulated_leg() {
    for yield_with in ["leg", "robot"] {
        let leg_yield = format!("coupling.legs_yield_with={yield_with}");
        let e = error_of(
            SCENE,
            &[leg_yield.as_str(), "coupling.load_prediction=last_substep"],
        );
        assert_names(
            &e,
            &[
                "scenes/test.yaml",
                "coupling.load_prediction",
                "coupling.legs_yield_with",
            ],
        );
    }
}

/// The motor's impedance joins the inertia the multibody presents at a leg: with another leg
/// yield it is refused, naming the field.
#[test]
fn motor_impedance_needs_the_articulated_leg() {
    let e = error_of(
        SCENE,
        &[
            "coupling.legs_yield_with=leg",
            "coupling.load_prediction=none",
            "coupling.motor_impedance=true",
        ],
    );
    assert_names(
        &e,
        &[
            "scenes/test.yaml",
            "coupling.motor_impedance",
            "articulated",
        ],
    );
}

/// The motor's impedance is the articulated leg's default; left unset, another leg yield
/// runs without it instead of being refused.
#[test]
fn the_motors_impedance_is_the_articulated_legs_default() {
    let coupling = |overrides: &[&str]| {
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &overrides).unwrap();
        scene.validate().unwrap();
        scene.config.coupling
    };
    assert!(coupling(&[]).motor_impedance());
    let leg = coupling(&["coupling.legs_yield_with=leg"]);
    assert!(!leg.motor_impedance());
    assert!(!coupling(&["coupling.motor_impedance=false"]).motor_impedance());
    assert!(coupling(&["coupling.motor_impedance=null"]).motor_impedance());
}

/// Every lattice `particles_per_cell` allows fills a body with its mass (density times volume)
/// about its centre, at the count asked for; others are refused with the allowed ones named.
#[test]
fn every_particle_lattice_gives_the_body_its_mass() {
    let sand_box = "sand.bodies.0.box={min_m: [0, 0, -0.02], max_m: [0.02, 0.03, 0]}";
    let cells = 2 * 3 * 2;
    let density_kg_m3 = 2000.0;
    let expected_mass_kg = density_kg_m3 * 0.02 * 0.03 * 0.02;
    for per_cell in [1_usize, 2, 4, 8, 16, 27, 32, 64] {
        let overrides = [
            sand_box.to_string(),
            format!("sand.bodies.0.particles_per_cell={per_cell}"),
            format!("sand.materials.sand.density_kg_m3={density_kg_m3}"),
        ];
        let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &overrides).unwrap();
        let particles = scene.build_solver().unwrap().particles;
        assert_eq!(particles.len(), cells * per_cell, "{per_cell} per cell");
        let mass: f64 = particles.mass.iter().map(|&m| m as f64).sum();
        assert!(
            (mass / expected_mass_kg - 1.0).abs() < 1e-5,
            "{per_cell} per cell: {mass} kg against {expected_mass_kg}"
        );
        let centroid =
            particles.position.iter().sum::<nalgebra::Vector3<f32>>() / particles.len() as f32;
        let centre = nalgebra::Vector3::new(0.01, 0.015, -0.01);
        assert!(
            (centroid - centre).norm() < 1e-6,
            "{per_cell} per cell: {centroid:?}"
        );
    }
    let e = error_of(
        include_str!("../config/robot_on_sand.yaml"),
        &["sand.bodies.0.particles_per_cell=6"],
    );
    assert_names(
        &e,
        &[
            "sand.bodies[0].particles_per_cell",
            "face-centred",
            "4 or 32",
        ],
    );
}
