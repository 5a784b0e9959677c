//! The committed hexapod URDFs: up to date with the generator, parseable, 85 g, legs of the
//! published chord with the curvature sign of their name.
//!
//! Published robot (Hu et al. 2018 supplement, section 4): legs of chord 2R = 4.1 cm, width
//! 1.0 cm, thickness 0.3 cm, ABS (1050 kg/m^3), curvature +1/R (C-legs) or -1/R (reversed);
//! total mass 85 g.
//!
//! Regenerate the files with `sandstep urdf` and `sandstep urdf --reversed`, or with
//! `SANDSTEP_UPDATE_URDF=1 cargo test --release --test robot_urdf`.

use std::path::{Path, PathBuf};

use rapier3d_urdf::urdf_rs::{self, Geometry};
use sandstep::robot::mesh::TriMesh;
use sandstep::robot::urdf_gen::leg_mesh_path;
use sandstep::robot::{write_hexapod_urdf, HexapodParams, RobotConfig, RobotSim, LEGS};

/// Published total mass (kg) and the tolerance the issue allows.
const TOTAL_MASS_KG: f64 = 0.085;
const MASS_TOLERANCE: f64 = 0.02;
/// Published chord 2R (m).
const CHORD_M: f64 = 0.041;
/// Published leg thickness (m).
const THICKNESS_M: f64 = 0.003;

/// (URDF path, curvature sign).
fn committed() -> [(PathBuf, f64); 2] {
    [
        (PathBuf::from("urdf/hexapod.urdf"), 1.0),
        (PathBuf::from("urdf/hexapod_reversed.urdf"), -1.0),
    ]
}

fn params_for(sign: f64) -> HexapodParams {
    if sign > 0.0 {
        HexapodParams::default()
    } else {
        HexapodParams::reversed()
    }
}

#[test]
fn committed_urdfs_match_the_generator() {
    let update = std::env::var_os("SANDSTEP_UPDATE_URDF").is_some();
    let tmp = tempfile::tempdir().unwrap();
    for (path, sign) in committed() {
        let params = params_for(sign);
        if update {
            write_hexapod_urdf(&params, &path).unwrap();
            continue;
        }
        let fresh = tmp.path().join(path.file_name().unwrap());
        write_hexapod_urdf(&params, &fresh).unwrap();
        for (committed, generated) in [
            (path.clone(), fresh.clone()),
            (leg_mesh_path(&path), leg_mesh_path(&fresh)),
        ] {
            let a = std::fs::read(&committed).unwrap_or_else(|e| {
                panic!(
                    "{}: {e} (regenerate: see this file's header)",
                    committed.display()
                )
            });
            let b = std::fs::read(&generated).unwrap();
            assert!(
                a == b,
                "{} is stale: regenerate it (see this file's header)",
                committed.display()
            );
        }
    }
}

#[test]
fn both_urdfs_parse_with_geometry_on_every_link_and_weigh_85_g() {
    for (path, _) in committed() {
        let robot = urdf_rs::read_file(&path).unwrap();
        assert_eq!(robot.links.len(), 7, "{}", path.display());
        let mut mass = 0.0;
        for link in &robot.links {
            assert!(
                !link.visual.is_empty(),
                "{}: link {} has no visual",
                path.display(),
                link.name
            );
            assert!(
                !link.collision.is_empty(),
                "{}: link {} has no collision",
                path.display(),
                link.name
            );
            let i = &link.inertial.inertia;
            assert!(link.inertial.mass.value > 0.0 && i.ixx > 0.0 && i.iyy > 0.0 && i.izz > 0.0);
            mass += link.inertial.mass.value;
        }
        assert!(
            (mass / TOTAL_MASS_KG - 1.0).abs() < MASS_TOLERANCE,
            "{}: {mass} kg",
            path.display()
        );

        // Loaded into rapier, the bodies carry the same mass.
        let cfg = RobotConfig {
            urdf: path.clone(),
            ..Default::default()
        };
        let sim = RobotSim::new(&cfg, [0.0, 0.0, -9.81]).unwrap();
        let loaded = sim.total_mass_kg();
        assert!(
            (loaded / TOTAL_MASS_KG - 1.0).abs() < MASS_TOLERANCE,
            "{}: loaded {loaded} kg",
            path.display()
        );
    }
}

/// Signed curvature of the circle through three points of the x-z plane, positive when the
/// middle point lies at -x of a downward chord (the C-leg bulges backwards), and the circle's
/// centre.
fn circle_xz(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> (f64, [f64; 2]) {
    let d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]));
    let n = |p: [f64; 2]| p[0] * p[0] + p[1] * p[1];
    let ux = (n(a) * (b[1] - c[1]) + n(b) * (c[1] - a[1]) + n(c) * (a[1] - b[1])) / d;
    let uz = (n(a) * (c[0] - b[0]) + n(b) * (a[0] - c[0]) + n(c) * (b[0] - a[0])) / d;
    let r = ((a[0] - ux).powi(2) + (a[1] - uz).powi(2)).sqrt();
    let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    (cross.signum() / r, [ux, uz])
}

#[test]
fn each_leg_has_the_published_chord_and_the_curvature_sign_of_its_file() {
    for (path, sign) in committed() {
        let robot = urdf_rs::read_file(&path).unwrap();
        let dir = path.parent().unwrap();
        for leg in &LEGS {
            let link = robot
                .links
                .iter()
                .find(|l| l.name == leg.link_name())
                .unwrap();
            let where_ = format!("{}: {}", path.display(), link.name);
            // Collision compound: box centres lie on the leg's centreline arc.
            let centres: Vec<[f64; 2]> = link
                .collision
                .iter()
                .map(|c| [c.origin.xyz[0], c.origin.xyz[2]])
                .collect();
            let n = centres.len();
            assert!(n >= 8, "{where_}: {n} collision boxes");
            let (k, centre) = circle_xz(centres[0], centres[n / 2], centres[n - 1]);
            let r = (centre[0].powi(2) + centre[1].powi(2)).sqrt();
            let radius = 1.0 / k.abs();
            assert!((k.signum() - sign).abs() < 1e-12, "{where_}: curvature {k}");
            assert!(
                (k.abs() * CHORD_M / 2.0 - 1.0).abs() < 0.01,
                "{where_}: |k| {} vs 1/R",
                k.abs()
            );
            // The hip (link origin) is the arc's first end: it lies on the same circle.
            assert!(
                (r - radius).abs() < 1e-6,
                "{where_}: hip {r} m from the arc's centre, radius {radius}"
            );
            // The tip lies half a box spacing beyond the last centre, on the circle.
            let angle = |p: [f64; 2]| (p[1] - centre[1]).atan2(p[0] - centre[0]);
            let spacing = angle(centres[n - 1]) - angle(centres[n - 2]);
            let tip_angle = angle(centres[n - 1]) + 0.5 * spacing;
            let tip = [
                centre[0] + radius * tip_angle.cos(),
                centre[1] + radius * tip_angle.sin(),
            ];
            let chord = (tip[0].powi(2) + tip[1].powi(2)).sqrt();
            assert!(
                (chord / CHORD_M - 1.0).abs() < 0.005,
                "{where_}: chord {chord} m"
            );

            // Visual mesh: bulges to -x for C-legs, +x for reversed legs, by about R + t/2.
            let Geometry::Mesh { filename, .. } = &link.visual[0].geometry else {
                panic!("{where_}: visual is not a mesh")
            };
            let mesh =
                TriMesh::from_stl_bytes(&std::fs::read(dir.join(filename)).unwrap()).unwrap();
            let (lo, hi) = mesh.bounds();
            let bulge = if sign > 0.0 { -lo[0] } else { hi[0] };
            let want = CHORD_M / 2.0 + THICKNESS_M / 2.0;
            assert!(
                (bulge - want).abs() < 2e-4,
                "{where_}: mesh bulges {bulge} m, want {want}"
            );
            assert!(
                (-lo[2] - (CHORD_M + THICKNESS_M / 2.0)).abs() < 2e-4,
                "{where_}: mesh reaches {} m",
                -lo[2]
            );
        }
    }
}

#[test]
fn generator_writes_intermediate_curvatures_into_a_fresh_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let path: &Path = &tmp.path().join("deep/straight.urdf");
    let mut params = HexapodParams::default();
    params.legs.curvature_per_m = 0.0;
    write_hexapod_urdf(&params, path).unwrap();
    assert!(leg_mesh_path(path).is_file());
    let cfg = RobotConfig {
        urdf: path.to_path_buf(),
        ..Default::default()
    };
    let sim = RobotSim::new(&cfg, [0.0, 0.0, -9.81]).unwrap();
    // Straight legs are lighter (chord instead of pi R long); the body takes up the rest.
    assert!((sim.total_mass_kg() / TOTAL_MASS_KG - 1.0).abs() < 1e-4);

    params.legs.curvature_per_m = 100.0;
    let err = write_hexapod_urdf(&params, path).unwrap_err().to_string();
    assert!(err.contains("curvature_per_m = 100"), "{err}");
}

/// `sandstep urdf` places the hips and the body's centre of mass where its options say (the
/// assumed layout of `docs/robot.md` is one choice among those a study measures), and refuses a
/// wrong count.
#[test]
fn urdf_command_places_the_hips_it_is_given() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("low_hips.urdf");
    let urdf = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_sandstep"))
            .arg("urdf")
            .arg("-o")
            .arg(&path)
            .args(extra)
            .output()
            .unwrap()
    };
    let out = urdf(&[
        "--hip-x-m=0.05,0.001,-0.055",
        "--hip-y-m=0.03,0.035,0.03",
        "--hip-z-m=-0.004",
        "--body-height-m=0.02",
        "--body-com-m=0.01,0,-0.005",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let robot = urdf_rs::read_file(&path).unwrap();
    let origin = |name: &str| {
        let joint = robot.joints.iter().find(|j| j.name == name).unwrap();
        joint.origin.xyz.0
    };
    let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-9);
    for (joint, expected) in [
        // Hips given from the box's centre; the body's frame is its centre of mass, 1 cm ahead
        // of and 5 mm below the box's centre.
        ("leg_front_left_joint", [0.04, 0.03, 0.001]),
        ("leg_middle_right_joint", [-0.009, -0.035, 0.001]),
        ("leg_rear_left_joint", [-0.065, 0.03, 0.001]),
    ] {
        assert!(
            close(origin(joint), expected),
            "{joint}: {:?}",
            origin(joint)
        );
    }
    let body = robot.links.iter().find(|l| l.name == "base_link").unwrap();
    match &body.collision[0].geometry {
        Geometry::Box { size } => assert!((size.0[2] - 0.02).abs() < 1e-9, "{:?}", size.0),
        other => panic!("body collision is {other:?}"),
    }
    // The body's frame is at its centre of mass; the box sits around it as the option says.
    let com = body.inertial.origin.xyz.0;
    assert!(
        close(com, [0.0; 3]),
        "body centre of mass {com:?} off its frame"
    );
    let box_centre = body.collision[0].origin.xyz.0;
    assert!(
        close(box_centre, [-0.01, 0.0, 0.005]),
        "body box at {box_centre:?}"
    );
    let out = urdf(&["--hip-x-m=0.05,0.0"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--hip-x-m"));
}
