//! The URDF generator behind `sandstep urdf`: writes the hexapod's URDF and its leg mesh.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::error::RobotError;
use super::geometry::{HexapodParams, LegParams, BODY_LINK, LEGS, LEG_COUNT};
use super::mesh::MassProperties;

/// Folder, beside the URDF, that receives the meshes.
pub const MESH_DIR: &str = "meshes";

/// Arguments of `sandstep urdf`. Defaults reproduce the published robot
/// (`urdf/hexapod.urdf`; with `--reversed`, `urdf/hexapod_reversed.urdf`).
#[derive(clap::Args, Debug, Clone)]
pub struct UrdfArgs {
    /// Output URDF path; the leg mesh goes to `meshes/` beside it.
    /// Default: urdf/hexapod.urdf, or urdf/hexapod_reversed.urdf with --reversed.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
    /// Leg curvature in units of 1/R (R = chord/2): 1 = C-leg (half circle, convex side
    /// leading), -1 = reversed, 0 = straight; anything in [-1, 1].
    #[arg(
        long,
        default_value_t = 1.0,
        allow_negative_numbers = true,
        conflicts_with = "reversed"
    )]
    pub curvature: f64,
    /// Reversed legs: the same as --curvature -1.
    #[arg(long)]
    pub reversed: bool,
    /// Leg chord 2R (m).
    #[arg(long, default_value_t = LegParams::default().chord_m)]
    pub chord_m: f64,
    /// Leg width along the hip axis (m).
    #[arg(long, default_value_t = LegParams::default().width_m)]
    pub width_m: f64,
    /// Leg thickness (m).
    #[arg(long, default_value_t = LegParams::default().thickness_m)]
    pub thickness_m: f64,
    /// Leg material density (kg/m^3); 1050 is ABS.
    #[arg(long, default_value_t = LegParams::default().density_kg_m3)]
    pub density_kg_m3: f64,
    /// Total robot mass, legs included (kg); the body gets the rest.
    #[arg(long, default_value_t = HexapodParams::default().total_mass_kg)]
    pub total_mass_kg: f64,
}

impl UrdfArgs {
    /// The robot these arguments describe.
    pub fn params(&self) -> HexapodParams {
        let mut p = HexapodParams::default();
        p.legs.chord_m = self.chord_m;
        p.legs.width_m = self.width_m;
        p.legs.thickness_m = self.thickness_m;
        p.legs.density_kg_m3 = self.density_kg_m3;
        let units_of_inv_r = if self.reversed { -1.0 } else { self.curvature };
        p.legs.curvature_per_m = units_of_inv_r * p.legs.max_curvature_per_m();
        p.total_mass_kg = self.total_mass_kg;
        p
    }

    /// The URDF path to write.
    pub fn output_path(&self) -> PathBuf {
        self.output.clone().unwrap_or_else(|| {
            PathBuf::from(if self.reversed {
                "urdf/hexapod_reversed.urdf"
            } else {
                "urdf/hexapod.urdf"
            })
        })
    }
}

/// Runs `sandstep urdf`: writes the URDF and mesh, prints what was written.
pub fn run_urdf_command(args: &UrdfArgs) -> anyhow::Result<()> {
    let params = args.params();
    let path = args.output_path();
    write_hexapod_urdf(&params, &path)?;
    let mesh = leg_mesh_path(&path);
    println!(
        "wrote {} and {}: leg {:.3} g (curvature {:+.3} 1/m), body {:.3} g, total {:.3} g",
        path.display(),
        mesh.display(),
        1e3 * params.legs.mass_kg(),
        params.legs.curvature_per_m,
        1e3 * params.body_mass_kg(),
        1e3 * params.total_mass_kg
    );
    Ok(())
}

/// The leg mesh that [`write_hexapod_urdf`] writes beside `urdf_path`, relative to the
/// URDF's folder: `meshes/<urdf stem>_leg.stl`.
pub fn leg_mesh_file_name(urdf_path: &Path) -> String {
    let stem = urdf_path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("robot");
    format!("{MESH_DIR}/{stem}_leg.stl")
}

/// Where [`write_hexapod_urdf`] puts the leg mesh of `urdf_path`.
pub fn leg_mesh_path(urdf_path: &Path) -> PathBuf {
    urdf_path
        .parent()
        .unwrap_or(Path::new(""))
        .join(leg_mesh_file_name(urdf_path))
}

/// Writes the hexapod's URDF to `urdf_path` and its leg mesh (binary STL) to
/// [`leg_mesh_path`] beside it, creating folders as needed.
pub fn write_hexapod_urdf(params: &HexapodParams, urdf_path: &Path) -> Result<(), RobotError> {
    params
        .validate()
        .map_err(|(field, value, reason)| RobotError::Params {
            field: field.into(),
            value,
            reason,
        })?;
    let stem = urdf_path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("robot")
        .to_string();
    let mesh_rel = leg_mesh_file_name(urdf_path);
    let mesh_path = leg_mesh_path(urdf_path);
    let mesh_dir = mesh_path.parent().unwrap_or(Path::new("")).to_path_buf();
    std::fs::create_dir_all(&mesh_dir).map_err(|e| RobotError::io(&mesh_dir, e))?;
    let header = format!(
        "sandstep leg, curvature {:+.6} 1/m",
        params.legs.curvature_per_m
    );
    params
        .legs
        .mesh(params.mesh_segments)
        .write_stl(&mesh_path, &header)
        .map_err(|e| RobotError::io(&mesh_path, e))?;
    let text = hexapod_urdf_text(params, &stem, &mesh_rel);
    std::fs::write(urdf_path, text).map_err(|e| RobotError::io(urdf_path, e))
}

/// The URDF document for `params`, naming the robot `name` and the leg mesh `mesh_file`
/// (relative to the URDF's folder).
pub fn hexapod_urdf_text(params: &HexapodParams, name: &str, mesh_file: &str) -> String {
    let legs = &params.legs;
    let body = params.body_mass_properties();
    let leg_mp = legs.mass_properties();
    let mut s = String::new();
    let _ = writeln!(s, r#"<?xml version="1.0"?>"#);
    let _ = writeln!(
        s,
        "<!-- Generated by `sandstep urdf` (src/robot/urdf_gen.rs); regenerate rather than edit.\n     \
         Hexapod of Hu et al. 2018 (supplement, section 4), after Li, Zhang and Goldman 2013.\n     \
         Frame: x forward, y left, z up (REP-103); SI units.\n     \
         Legs: chord {} m, width {} m, thickness {} m, curvature {} 1/m ({:+.3}/R),\n     \
         density {} kg/m^3, arc length {} m, mass {} kg each.\n     \
         Body: box {} x {} x {} m, mass {} kg; total {} kg.\n     \
         Masses and inertias are integrated from this geometry. Leg collision: {} boxes along the arc. -->",
        num(legs.chord_m),
        num(legs.width_m),
        num(legs.thickness_m),
        num(legs.curvature_per_m),
        legs.curvature_per_m / legs.max_curvature_per_m(),
        num(legs.density_kg_m3),
        num(legs.arc_length_m()),
        num(legs.mass_kg()),
        num(params.body_length_m),
        num(params.body_width_m),
        num(params.body_height_m),
        num(body.mass_kg),
        num(body.mass_kg + LEG_COUNT as f64 * leg_mp.mass_kg),
        params.collision_segments,
    );
    let _ = writeln!(s, r#"<robot name="{name}">"#);
    let _ = writeln!(
        s,
        r#"  <material name="body_grey"><color rgba="0.35 0.35 0.38 1"/></material>"#
    );
    let _ = writeln!(
        s,
        r#"  <material name="abs_orange"><color rgba="0.95 0.55 0.15 1"/></material>"#
    );

    let body_box = format!(
        r#"<box size="{} {} {}"/>"#,
        num(params.body_length_m),
        num(params.body_width_m),
        num(params.body_height_m)
    );
    let _ = writeln!(s, r#"  <link name="{BODY_LINK}">"#);
    write_inertial(&mut s, &body);
    let _ = writeln!(
        s,
        r#"    <visual><geometry>{body_box}</geometry><material name="body_grey"/></visual>"#
    );
    let _ = writeln!(
        s,
        r#"    <collision><geometry>{body_box}</geometry></collision>"#
    );
    let _ = writeln!(s, "  </link>");

    let boxes = legs.collision_boxes(params.collision_segments);
    for leg in &LEGS {
        let _ = writeln!(s, r#"  <link name="{}">"#, leg.link_name());
        write_inertial(&mut s, &leg_mp);
        let _ = writeln!(
            s,
            r#"    <visual><geometry><mesh filename="{mesh_file}"/></geometry><material name="abs_orange"/></visual>"#
        );
        for b in &boxes {
            let _ = writeln!(
                s,
                r#"    <collision><origin xyz="{} {} {}" rpy="0 {} 0"/><geometry><box size="{} {} {}"/></geometry></collision>"#,
                num(b.centre_m[0]),
                num(b.centre_m[1]),
                num(b.centre_m[2]),
                num(b.pitch_rad),
                num(b.size_m[0]),
                num(b.size_m[1]),
                num(b.size_m[2]),
            );
        }
        let _ = writeln!(s, "  </link>");
        let hip = params.hip_position_m(leg);
        let _ = writeln!(
            s,
            r#"  <joint name="{}" type="continuous">"#,
            leg.joint_name()
        );
        let _ = writeln!(s, r#"    <parent link="{BODY_LINK}"/>"#);
        let _ = writeln!(s, r#"    <child link="{}"/>"#, leg.link_name());
        let _ = writeln!(
            s,
            r#"    <origin xyz="{} {} {}" rpy="0 0 0"/>"#,
            num(hip[0]),
            num(hip[1]),
            num(hip[2])
        );
        let _ = writeln!(s, r#"    <axis xyz="0 1 0"/>"#);
        let _ = writeln!(s, "  </joint>");
    }
    let _ = writeln!(s, "</robot>");
    s
}

fn write_inertial(s: &mut String, mp: &MassProperties) {
    let i = &mp.inertia_kg_m2;
    let _ = writeln!(s, "    <inertial>");
    let _ = writeln!(
        s,
        r#"      <origin xyz="{} {} {}" rpy="0 0 0"/>"#,
        num(mp.com_m[0]),
        num(mp.com_m[1]),
        num(mp.com_m[2])
    );
    let _ = writeln!(s, r#"      <mass value="{}"/>"#, num(mp.mass_kg));
    let _ = writeln!(
        s,
        r#"      <inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/>"#,
        num(i[0][0]),
        num(i[0][1]),
        num(i[0][2]),
        num(i[1][1]),
        num(i[1][2]),
        num(i[2][2])
    );
    let _ = writeln!(s, "    </inertial>");
}

/// A number for the URDF: 9 significant digits, exponent form only for tiny values; noise
/// below 1e-15 (e.g. an off-diagonal inertia that is zero by symmetry) prints as 0.
fn num(x: f64) -> String {
    if x.abs() < 1e-15 {
        "0".into()
    } else if x.abs() >= 1e-3 {
        let s = format!("{x:.9}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{x:.8e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_compact_and_exact_enough() {
        assert_eq!(num(0.0), "0");
        assert_eq!(num(1e-17), "0");
        assert_eq!(num(0.05), "0.05");
        assert_eq!(num(-0.0205), "-0.0205");
        assert_eq!(num(1050.0), "1050");
        let tiny = 1.234_567_891e-7;
        assert!((num(tiny).parse::<f64>().unwrap() / tiny - 1.0).abs() < 1e-8);
    }

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: UrdfArgs,
    }

    fn parse(argv: &[&str]) -> Result<UrdfArgs, clap::Error> {
        use clap::Parser;
        Cli::try_parse_from(std::iter::once("urdf").chain(argv.iter().copied())).map(|c| c.args)
    }

    #[test]
    fn command_line_selects_curvature_and_output() {
        let k_max = LegParams::default().max_curvature_per_m();
        let c = parse(&[]).unwrap();
        assert_eq!(c.params(), HexapodParams::default());
        assert_eq!(c.output_path(), PathBuf::from("urdf/hexapod.urdf"));
        let r = parse(&["--reversed"]).unwrap();
        assert_eq!(r.params(), HexapodParams::reversed());
        assert_eq!(r.output_path(), PathBuf::from("urdf/hexapod_reversed.urdf"));
        let half = parse(&["--curvature", "-0.5", "-o", "x/y.urdf"]).unwrap();
        assert!((half.params().legs.curvature_per_m + 0.5 * k_max).abs() < 1e-12);
        assert_eq!(half.output_path(), PathBuf::from("x/y.urdf"));
        assert!(parse(&["--reversed", "--curvature", "0.5"]).is_err());
    }

    #[test]
    fn the_command_writes_urdf_and_mesh_or_names_the_bad_parameter() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("k.urdf");
        let out_str = out.to_str().unwrap();
        run_urdf_command(&parse(&["--curvature", "0.25", "-o", out_str]).unwrap()).unwrap();
        assert!(out.is_file() && leg_mesh_path(&out).is_file());
        let err = run_urdf_command(&parse(&["--curvature", "1.5", "-o", out_str]).unwrap());
        assert!(err.unwrap_err().to_string().contains("curvature_per_m"));
    }

    #[test]
    fn the_urdf_names_every_leg_joint_and_parses() {
        let text = hexapod_urdf_text(
            &HexapodParams::default(),
            "hexapod",
            "meshes/hexapod_leg.stl",
        );
        let robot = rapier3d_urdf::urdf_rs::read_from_string(&text).expect("valid URDF");
        assert_eq!(robot.links.len(), 7);
        for leg in &LEGS {
            assert!(robot.joints.iter().any(|j| j.name == leg.joint_name()));
        }
    }
}
