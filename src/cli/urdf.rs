//! `sandstep urdf`: writes a hexapod URDF and its leg mesh from leg and body parameters.

use std::path::PathBuf;

use crate::robot::{leg_mesh_path, write_hexapod_urdf, HexapodParams, LegParams};

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
    /// Body (belly) height along z (m; assumed, not published).
    #[arg(long, default_value_t = HexapodParams::default().body_height_m)]
    pub body_height_m: f64,
    /// The body's centre of mass relative to the centre of its box, x,y,z (m; assumed), inside
    /// the box; the inertia stays the uniform box's. The body's frame (the pose a run reports)
    /// is put there. Default 0,0,0.
    #[arg(long, value_parser = three_numbers, allow_hyphen_values = true, value_name = "X,Y,Z")]
    pub body_com_m: Option<[f64; 3]>,
    /// Hip x positions in the body frame, front, middle, rear (m; assumed): three
    /// comma-separated values. Default: the assumed layout of docs/robot.md.
    #[arg(
        long,
        value_parser = three_numbers,
        allow_hyphen_values = true,
        value_name = "FRONT,MIDDLE,REAR"
    )]
    pub hip_x_m: Option<[f64; 3]>,
    /// Lateral distance of each leg's mid-plane from the body's mid-plane (m; assumed): one
    /// value for all legs, or front,middle,rear. Default: the assumed layout of docs/robot.md.
    #[arg(
        long,
        value_parser = one_or_three_numbers,
        allow_hyphen_values = true,
        value_name = "Y|FRONT,MIDDLE,REAR"
    )]
    pub hip_y_m: Option<[f64; 3]>,
    /// Height of the hip axes above the body's centre (m; assumed), negative below it.
    #[arg(long, default_value_t = HexapodParams::default().hip_z_m, allow_negative_numbers = true)]
    pub hip_z_m: f64,
}

impl UrdfArgs {
    /// The robot these arguments describe.
    pub fn params(&self) -> HexapodParams {
        let mut p = HexapodParams::default();
        p.legs.chord_m = self.chord_m;
        p.legs.width_m = self.width_m;
        p.legs.thickness_m = self.thickness_m;
        p.legs.density_kg_m3 = self.density_kg_m3;
        p.total_mass_kg = self.total_mass_kg;
        p.body_height_m = self.body_height_m;
        p.body_com_m = self.body_com_m.unwrap_or(p.body_com_m);
        p.hip_x_m = self.hip_x_m.unwrap_or(p.hip_x_m);
        p.hip_y_m = self.hip_y_m.unwrap_or(p.hip_y_m);
        p.hip_z_m = self.hip_z_m;
        p.with_curvature(if self.reversed { -1.0 } else { self.curvature })
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

/// Parses `a,b,c` into three numbers.
fn three_numbers(text: &str) -> Result<[f64; 3], String> {
    let numbers: Vec<f64> = text
        .split(',')
        .map(|n| n.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| e.to_string())?;
    numbers
        .try_into()
        .map_err(|n: Vec<f64>| format!("3 comma-separated numbers needed, got {}", n.len()))
}

/// Parses `a` (the same for all three) or `a,b,c`.
fn one_or_three_numbers(text: &str) -> Result<[f64; 3], String> {
    match text.trim().parse::<f64>() {
        Ok(one) => Ok([one; 3]),
        Err(_) if text.contains(',') => three_numbers(text)
            .map_err(|_| format!("1 or 3 comma-separated numbers needed, got {text:?}")),
        Err(e) => Err(e.to_string()),
    }
}

/// Runs `sandstep urdf`: writes the URDF and mesh, prints what was written.
pub fn urdf(args: &UrdfArgs) -> anyhow::Result<()> {
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

#[cfg(test)]
mod tests {
    use super::*;

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
        urdf(&parse(&["--curvature", "0.25", "-o", out_str]).unwrap()).unwrap();
        assert!(out.is_file() && leg_mesh_path(&out).is_file());
        let err = urdf(&parse(&["--curvature", "1.5", "-o", out_str]).unwrap());
        assert!(err.unwrap_err().to_string().contains("curvature_per_m"));
        let err = urdf(&parse(&["--hip-y-m=0.01", "-o", out_str]).unwrap());
        assert!(err.unwrap_err().to_string().contains("hip_y_m"));
    }

    #[test]
    fn hip_options_take_negative_numbers_in_either_form() {
        let p = parse(&["--hip-z-m", "-0.004", "--hip-x-m", "-0.05,0,0.05"])
            .unwrap()
            .params();
        assert_eq!((p.hip_z_m, p.hip_x_m), (-0.004, [-0.05, 0.0, 0.05]));
        let p = parse(&["--hip-x-m=0.07, 0.01 ,-0.07"]).unwrap().params();
        assert_eq!(p.hip_x_m, [0.07, 0.01, -0.07]);
        assert!(parse(&["--hip-x-m", "0.05,0"]).is_err());
        assert!(parse(&["--hip-x-m", "0.05,x,0"]).is_err());
    }

    #[test]
    fn hip_y_takes_one_or_three_numbers_and_the_centre_of_mass_three() {
        let p = parse(&["--hip-y-m", "0.03"]).unwrap().params();
        assert_eq!(p.hip_y_m, [0.03; 3]);
        let p = parse(&["--hip-y-m", "0.024,0.035,0.024"]).unwrap().params();
        assert_eq!(p.hip_y_m, [0.024, 0.035, 0.024]);
        let two = parse(&["--hip-y-m", "0.03,0.04"])
            .err()
            .unwrap()
            .to_string();
        assert!(two.contains("1 or 3"), "{two}");
        // Negative values parse (and are then refused by the check that names hip_y_m).
        assert_eq!(
            parse(&["--hip-y-m", "-0.03"]).unwrap().params().hip_y_m,
            [-0.03; 3]
        );
        let p = parse(&["--body-com-m", "-0.01,0,-0.005"]).unwrap().params();
        assert_eq!(p.body_com_m, [-0.01, 0.0, -0.005]);
        assert!(parse(&["--body-com-m", "0.01"]).is_err());
    }
}
