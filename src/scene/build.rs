//! From a checked scene to a solver filled with particles.

use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::Vector3;

use super::config::{BodyConfig, BoxShape, MaterialConfig, SandConfig};
use super::{Scene, SceneError};
use crate::mpm::lattice::Lattice;
use crate::mpm::material::{Constitutive, DruckerPrager, FixedCorotated, Lame};
use crate::mpm::{
    NewParticle, SleepSettings, Solver, SolverMaterial, SolverSettings, TimeStep, Walls,
};
use crate::terrain::TerrainModel;

/// Checks ranges and references; errors name the file and the field.
// Negated comparisons (`!(a < b)`) on purpose: they reject NaN too.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn validate(scene: &Scene) -> Result<(), SceneError> {
    let c = &scene.config;
    let positive = |field: &str, v: f64| {
        if v > 0.0 && v.is_finite() {
            Ok(())
        } else {
            Err(scene.invalid(field, format!("{v} must be a finite number > 0")))
        }
    };
    positive("duration_s", c.duration_s)?;
    positive("output.frame_interval_s", c.output.frame_interval_s)?;
    if c.gravity_m_s2.iter().any(|g| !g.is_finite()) {
        return Err(scene.invalid("gravity_m_s2", "must be finite"));
    }
    if let Some(robot) = &c.robot {
        robot.validate(&scene.file)?;
    }
    validate_node(scene)?;
    let materials: Option<Vec<&str>> = scene
        .sand()
        .map(|s| s.materials.keys().map(String::as_str).collect());
    c.terrain
        .validate(
            c.robot.as_ref().map(|r| r.ground.height_m),
            materials.as_deref(),
        )
        .map_err(|e| SceneError::from(e.in_file(&scene.file)))?;
    validate_stress_maps_sand(scene)?;
    if !(c.coupling.friction >= 0.0 && c.coupling.friction.is_finite()) {
        return Err(scene.invalid(
            "coupling.friction",
            format!("{} must be a finite number >= 0", c.coupling.friction),
        ));
    }
    if c.coupling.load_prediction == crate::coupling::LoadPrediction::LastSubstep
        && c.coupling.legs_yield_with != crate::coupling::LegYield::Articulated
    {
        return Err(scene.invalid(
            "coupling.load_prediction",
            "last_substep needs coupling.legs_yield_with: articulated (the default); with \
             legs_yield_with: leg or robot set load_prediction: none (the default; a leg that \
             yields with any other inertia than its multibody's turns the prediction into a \
             stiff spring: docs/physics.md, CPIC step 7)",
        ));
    }
    if c.coupling.motor_impedance == Some(true)
        && c.coupling.legs_yield_with != crate::coupling::LegYield::Articulated
    {
        return Err(scene.invalid(
            "coupling.motor_impedance",
            "true needs coupling.legs_yield_with: articulated (the motor's impedance joins the \
             inertia the multibody presents at the leg); with leg or robot leave it unset or \
             set it false",
        ));
    }
    let Some(sand) = scene.sand() else {
        return if c.column_collapse.is_some() {
            Err(scene.invalid(
                "column_collapse",
                "needs a `sand` section (domain, materials)",
            ))
        } else {
            Ok(())
        };
    };
    positive("sand.dx_m", sand.dx_m as f64)?;
    if let Some(window) = &sand.window {
        super::sand_window::validate(scene, window, sand.dx_m)?;
    }
    if let Some(robot) = c
        .robot
        .as_ref()
        .filter(|_| c.terrain.model == TerrainModel::Mpm)
    {
        let start = robot.initial_pose.position_m;
        for axis in 0..2 {
            let (lo, hi) = (sand.domain.min_m[axis], sand.domain.max_m[axis]);
            if !((lo as f64)..=(hi as f64)).contains(&start[axis]) {
                return Err(scene.invalid(
                    format!("robot.initial_pose.position_m[{axis}]"),
                    format!(
                        "{} m lies outside the sand domain, {lo} to {hi} m along {} \
                         (sand.domain): the robot must start over the sand",
                        start[axis],
                        ["x", "y"][axis]
                    ),
                ));
            }
        }
    }
    for axis in 0..3 {
        let (lo, hi) = (sand.domain.min_m[axis], sand.domain.max_m[axis]);
        if !(hi - lo >= 2.0 * sand.dx_m) {
            return Err(scene.invalid(
                "sand.domain.max_m",
                format!("axis {axis}: max {hi} must exceed min {lo} by at least 2 dx"),
            ));
        }
    }
    for (name, wall) in sand.domain.walls.named() {
        if let crate::mpm::Wall::Friction(mu) = wall {
            if !(mu >= 0.0 && mu.is_finite()) {
                return Err(scene.invalid(
                    format!("sand.domain.walls.{name}.friction"),
                    format!("{mu} must be a finite coefficient >= 0"),
                ));
            }
        }
    }
    let s = &sand.solver;
    if !(s.cfl > 0.0 && s.cfl <= 1.0) {
        return Err(scene.invalid("sand.solver.cfl", format!("{} must be in (0, 1]", s.cfl)));
    }
    for (name, tau) in [
        ("flip_relaxation_s", s.flip_relaxation_s),
        ("cpic_band_relaxation_s", s.cpic_band_relaxation_s),
    ] {
        if !(tau >= 0.0 && tau.is_finite()) {
            return Err(scene.invalid(
                format!("sand.solver.{name}"),
                format!("{tau} must be a finite time >= 0 (s)"),
            ));
        }
    }
    positive("sand.solver.max_dt_s", s.max_dt_s as f64)?;
    positive("sand.solver.blowup_speed_m_s", s.blowup_speed_m_s as f64)?;
    if let Some(dt) = s.fixed_dt_s {
        positive("sand.solver.fixed_dt_s", dt as f64)?;
    }
    if let Some(sleep) = &s.sleep {
        positive("sand.solver.sleep.speed_m_s", sleep.speed_m_s as f64)?;
        positive("sand.solver.sleep.after_s", sleep.after_s as f64)?;
        if !(sleep.wake_margin_m >= 0.0 && sleep.wake_margin_m.is_finite()) {
            return Err(scene.invalid(
                "sand.solver.sleep.wake_margin_m",
                format!("{} must be a finite distance >= 0 (m)", sleep.wake_margin_m),
            ));
        }
    }
    for (name, m) in &sand.materials {
        let field = |f: &str| format!("sand.materials.{name}.{f}");
        let (density, e, nu) = match m {
            MaterialConfig::DruckerPrager {
                density_kg_m3,
                youngs_modulus_pa,
                poisson_ratio,
                friction_angle_deg,
                elastic_viscosity_pa_s,
                elastic_relaxation_s,
                ..
            } => {
                if !(*friction_angle_deg > 0.0 && *friction_angle_deg < 90.0) {
                    return Err(scene.invalid(
                        field("friction_angle_deg"),
                        format!("{friction_angle_deg} must be in (0, 90) degrees"),
                    ));
                }
                if let Some(eta) = elastic_viscosity_pa_s {
                    if !(*eta >= 0.0 && eta.is_finite()) {
                        return Err(scene.invalid(
                            field("elastic_viscosity_pa_s"),
                            format!("{eta} must be a finite viscosity >= 0 (Pa s)"),
                        ));
                    }
                }
                if let Some(tau) = elastic_relaxation_s {
                    if !(*tau >= 0.0 && tau.is_finite()) {
                        return Err(scene.invalid(
                            field("elastic_relaxation_s"),
                            format!("{tau} must be a finite time >= 0 (s)"),
                        ));
                    }
                    if let Some(eta) = elastic_viscosity_pa_s {
                        return Err(scene.invalid(
                            field("elastic_relaxation_s"),
                            format!(
                                "set the in-cone viscosity one way, elastic_relaxation_s \
                                 ({tau} s) or elastic_viscosity_pa_s ({eta} Pa s), not both \
                                 (`elastic_relaxation_s=null` clears the one a scene sets)"
                            ),
                        ));
                    }
                }
                (density_kg_m3, youngs_modulus_pa, poisson_ratio)
            }
            MaterialConfig::FixedCorotated {
                density_kg_m3,
                youngs_modulus_pa,
                poisson_ratio,
            } => (density_kg_m3, youngs_modulus_pa, poisson_ratio),
        };
        positive(&field("density_kg_m3"), *density as f64)?;
        positive(&field("youngs_modulus_pa"), *e as f64)?;
        if !(*nu > -1.0 && *nu < 0.5) {
            return Err(scene.invalid(field("poisson_ratio"), format!("{nu} must be in (-1, 0.5)")));
        }
    }
    for (i, body) in scene.bodies().iter().enumerate() {
        let field = |f: &str| {
            if i < sand.bodies.len() {
                format!("sand.bodies[{i}].{f}")
            } else {
                format!("column_collapse.{f}")
            }
        };
        validate_body(scene, sand, body, &field)?;
    }
    if let Some(cc) = &c.column_collapse {
        positive(
            "column_collapse.initial_length_m",
            cc.initial_length_m as f64,
        )?;
        positive("column_collapse.aspect_ratio", cc.aspect_ratio as f64)?;
    }
    Ok(())
}

#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn validate_body(
    scene: &Scene,
    sand: &SandConfig,
    body: &BodyConfig,
    field: &dyn Fn(&str) -> String,
) -> Result<(), SceneError> {
    if !sand.materials.contains_key(&body.material) {
        let known: Vec<&String> = sand.materials.keys().collect();
        return Err(scene.invalid(
            field("material"),
            format!(
                "unknown material `{}` (materials: {known:?})",
                body.material
            ),
        ));
    }
    if Lattice::of(body.particles_per_cell).is_none() {
        return Err(scene.invalid(
            field("particles_per_cell"),
            format!(
                "{} must be one of {}",
                body.particles_per_cell,
                Lattice::ALLOWED
            ),
        ));
    }
    let (lo, hi) = match (&body.box_shape, &body.cylinder) {
        (Some(b), None) => (Vector3::from(b.min_m), Vector3::from(b.max_m)),
        (None, Some(c)) => {
            if !(c.radius_m > 0.0 && c.height_m > 0.0) {
                return Err(scene.invalid(field("cylinder"), "radius_m and height_m must be > 0"));
            }
            let a = c.axis.index();
            let mut lo = Vector3::from(c.base_centre_m).add_scalar(-c.radius_m);
            let mut hi = Vector3::from(c.base_centre_m).add_scalar(c.radius_m);
            lo[a] = c.base_centre_m[a];
            hi[a] = c.base_centre_m[a] + c.height_m;
            (lo, hi)
        }
        _ => return Err(scene.invalid(field("box"), "give exactly one of `box` and `cylinder`")),
    };
    let (dmin, dmax) = (
        Vector3::from(sand.domain.min_m),
        Vector3::from(sand.domain.max_m),
    );
    for axis in 0..3 {
        if !(lo[axis] < hi[axis]) {
            return Err(scene.invalid(field("box"), format!("empty along axis {axis}")));
        }
        if lo[axis] < dmin[axis] - 1e-6 || hi[axis] > dmax[axis] + 1e-6 {
            return Err(scene.invalid(
                field(if body.box_shape.is_some() {
                    "box"
                } else {
                    "cylinder"
                }),
                format!(
                    "extends outside the domain along axis {axis}: [{}, {}] not within [{}, {}] m",
                    lo[axis], hi[axis], dmin[axis], dmax[axis]
                ),
            ));
        }
    }
    Ok(())
}

/// Stress maps belong to the sand they were measured on: with a `sand` section, it must hold
/// their material under the same name with the same settings.
fn validate_stress_maps_sand(scene: &Scene) -> Result<(), SceneError> {
    let (Some(choice), Some(sand)) = (&scene.config.terrain.rft.stress_maps, scene.sand()) else {
        return Ok(());
    };
    let Some(file) = &choice.read else {
        return Ok(());
    };
    let field = "terrain.rft.stress_maps.file";
    let name = &file.material_name;
    let message = match sand.materials.get(name) {
        None => format!("measured on material `{name}`, which sand.materials does not have"),
        Some(here) => match differing_settings(&file.material, here) {
            Ok(differing) if differing.is_empty() => return Ok(()),
            Ok(differing) => format!(
                "measured on material `{name}` with other settings ({}); measure the maps on \
                 this sand (`sandstep calibrate-rft <scene> --maps --write FILE`)",
                differing.join(", ")
            ),
            Err(e) => format!("its material `{name}` cannot be read: {e}"),
        },
    };
    Err(scene.invalid(field, format!("{}: {message}", choice.file.display())))
}

/// The settings of `here` that differ from the material `measured` as a stress-map file holds
/// it: `name: measured -> here` for each (the measured one read back as a material first, so
/// that a malformed one is an error and defaults compare as values).
fn differing_settings(
    measured: &serde_yaml_ng::Value,
    here: &super::config::MaterialConfig,
) -> Result<Vec<String>, serde_yaml_ng::Error> {
    let measured: super::config::MaterialConfig = serde_yaml_ng::from_value(measured.clone())?;
    if measured == *here {
        return Ok(Vec::new());
    }
    let as_map = |m: &super::config::MaterialConfig| match serde_yaml_ng::to_value(m) {
        Ok(serde_yaml_ng::Value::Mapping(map)) => map,
        _ => Default::default(),
    };
    let (measured, here) = (as_map(&measured), as_map(here));
    let text = |v: Option<&serde_yaml_ng::Value>| {
        v.and_then(|v| serde_yaml_ng::to_string(v).ok())
            .map_or("none".into(), |s| s.trim().to_string())
    };
    let mut keys: Vec<&serde_yaml_ng::Value> = Vec::new();
    for key in measured.keys().chain(here.keys()) {
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    Ok(keys
        .into_iter()
        .filter(|k| measured.get(*k) != here.get(*k))
        .map(|k| {
            let name = k.as_str().unwrap_or("?");
            format!("{name}: {} -> {}", text(measured.get(k)), text(here.get(k)))
        })
        .collect())
}

impl Scene {
    /// The `sand` section, if any.
    pub fn sand(&self) -> Option<&SandConfig> {
        self.config.sand.as_ref()
    }

    /// The scene's sand bodies: those listed under `sand.bodies`, then the column of a
    /// `column_collapse` scene.
    pub fn bodies(&self) -> Vec<BodyConfig> {
        let Some(sand) = self.sand() else {
            return Vec::new();
        };
        let mut bodies = sand.bodies.clone();
        if let Some(cc) = &self.config.column_collapse {
            let min = sand.domain.min_m;
            let max = sand.domain.max_m;
            bodies.push(BodyConfig {
                material: cc.material.clone(),
                box_shape: Some(BoxShape {
                    min_m: min,
                    max_m: [
                        min[0] + cc.initial_length_m,
                        max[1],
                        min[2] + cc.aspect_ratio * cc.initial_length_m,
                    ],
                }),
                cylinder: None,
                particles_per_cell: cc.particles_per_cell,
                velocity_m_s: [0.0; 3],
            });
        }
        bodies
    }

    /// The MPM solver of the scene's sand, filled with its bodies' particles.
    pub fn build_solver(&self) -> Option<Solver> {
        self.build_solver_unless(&AtomicBool::new(false))
            .expect("never stopped")
    }

    /// [`Scene::build_solver`], or [`FillStopped`] once `stop` is set while the sand is filled
    /// (looked at every lattice plane of particles).
    pub fn build_solver_unless(&self, stop: &AtomicBool) -> Result<Option<Solver>, FillStopped> {
        let Some(sand) = self.sand() else {
            return Ok(None);
        };
        let materials = sand
            .materials
            .iter()
            .map(|(name, m)| SolverMaterial {
                name: name.clone(),
                density_kg_m3: m.density_kg_m3(),
                model: constitutive(m),
            })
            .collect();
        let s = &sand.solver;
        let settings = SolverSettings {
            dx: sand.dx_m,
            domain_min: sand.domain.min_m.into(),
            domain_max: sand.domain.max_m.into(),
            walls: {
                let w = sand.domain.walls;
                Walls {
                    x_min: w.x_min.0,
                    x_max: w.x_max.0,
                    y_min: w.y_min.0,
                    y_max: w.y_max.0,
                    z_min: w.z_min.0,
                    z_max: w.z_max.0,
                }
            },
            gravity: self.config.gravity_m_s2.into(),
            time_step: match s.fixed_dt_s {
                Some(dt_s) => TimeStep::Fixed { dt_s },
                None => TimeStep::Adaptive {
                    cfl: s.cfl,
                    max_dt_s: s.max_dt_s,
                },
            },
            blowup_speed_m_s: s.blowup_speed_m_s,
            transfer: s.transfer,
            flip_relaxation_s: s.flip_relaxation_s,
            cpic_band: s.cpic_band,
            cpic_band_relaxation_s: s.cpic_band_relaxation_s,
            kernel: s.kernel,
            sleep: s.sleep.map(|c| SleepSettings {
                speed_m_s: c.speed_m_s,
                after_s: c.after_s,
                wake_margin_m: c.wake_margin_m,
            }),
        };
        let mut solver = Solver::new(settings, materials);
        let particles = self.sand_particles_unless(None, stop)?;
        if stop.load(Ordering::Relaxed) {
            return Err(FillStopped);
        }
        let particles = solver.in_block_order(particles);
        // Added a share at a time, looking at `stop` in between (6.8 M particles take most of
        // a second).
        solver.reserve_particles(particles.len());
        let mut particles = particles.into_iter();
        while particles.len() > 0 {
            if stop.load(Ordering::Relaxed) {
                return Err(FillStopped);
            }
            solver.add_particles(particles.by_ref().take(PARTICLES_ADDED_AT_ONCE));
        }
        Ok(Some(solver))
    }

    /// The particles of the scene's sand bodies, or of their part with `x` in `x_range` (m):
    /// the same lattice points either way, so slabs filled one after another adjoin exactly.
    pub fn sand_particles(&self, x_range: Option<std::ops::Range<f32>>) -> Vec<NewParticle> {
        self.sand_particles_unless(x_range, &AtomicBool::new(false))
            .expect("never stopped")
    }

    /// [`Scene::sand_particles`], or [`FillStopped`] once `stop` is set.
    fn sand_particles_unless(
        &self,
        x_range: Option<std::ops::Range<f32>>,
        stop: &AtomicBool,
    ) -> Result<Vec<NewParticle>, FillStopped> {
        let Some(sand) = self.sand() else {
            return Ok(Vec::new());
        };
        let names: Vec<&String> = sand.materials.keys().collect();
        let mut particles = Vec::new();
        for body in self.bodies() {
            let material = names.iter().position(|n| **n == body.material).unwrap() as u16;
            let density = sand.materials[&body.material].density_kg_m3();
            let filled = fill_body(&body, sand.dx_m, density, material, stop)?;
            match &x_range {
                None => particles.extend(filled),
                Some(r) => {
                    particles.extend(filled.into_iter().filter(|p| r.contains(&p.position.x)))
                }
            }
        }
        Ok(particles)
    }
}

/// Particles the build adds to the solver between two looks at the stop request.
const PARTICLES_ADDED_AT_ONCE: usize = 1 << 18;

/// A stop request seen while the sand was being filled: nothing was built.
#[derive(Debug)]
pub struct FillStopped;

fn constitutive(m: &MaterialConfig) -> Constitutive {
    match *m {
        MaterialConfig::DruckerPrager {
            youngs_modulus_pa,
            poisson_ratio,
            friction_angle_deg,
            yield_cone,
            volume_correction,
            elastic_viscosity_pa_s,
            elastic_relaxation_s,
            ..
        } => {
            let lame = Lame::from_young_poisson(youngs_modulus_pa, poisson_ratio);
            Constitutive::DruckerPrager(DruckerPrager {
                elastic_viscosity_pa_s: match elastic_relaxation_s {
                    Some(tau_s) => lame.mu * tau_s,
                    None => elastic_viscosity_pa_s.unwrap_or(0.0),
                },
                ..DruckerPrager::with_cone(
                    lame,
                    friction_angle_deg.to_radians(),
                    yield_cone,
                    volume_correction,
                )
            })
        }
        MaterialConfig::FixedCorotated {
            youngs_modulus_pa,
            poisson_ratio,
            ..
        } => Constitutive::FixedCorotated(FixedCorotated {
            lame: Lame::from_young_poisson(youngs_modulus_pa, poisson_ratio),
        }),
    }
}

/// Is a point (m) inside a shape?
type Inside = Box<dyn Fn(&Vector3<f32>) -> bool>;

/// Particles a body's lattice holds at most (its bounding box's lattice points; f64, so that a
/// mistyped `dx` gives a huge count, not an overflow): for the memory estimate before filling.
pub fn body_particle_bound(body: &BodyConfig, dx: f32) -> f64 {
    let lattice = Lattice::of(body.particles_per_cell).expect("validated");
    let (lo, hi, _) = body_bounds(body);
    lattice.count_in(&(hi - lo), dx)
}

/// A body's bounding box (m) and the test of whether a point is inside it.
fn body_bounds(body: &BodyConfig) -> (Vector3<f32>, Vector3<f32>, Inside) {
    match (&body.box_shape, &body.cylinder) {
        (Some(b), _) => (
            b.min_m.into(),
            b.max_m.into(),
            Box::new(|_: &Vector3<f32>| true),
        ),
        (None, Some(c)) => {
            let a = c.axis.index();
            let centre = Vector3::from(c.base_centre_m);
            let (r, h) = (c.radius_m, c.height_m);
            let mut lo = centre.add_scalar(-r);
            let mut hi = centre.add_scalar(r);
            lo[a] = centre[a];
            hi[a] = centre[a] + h;
            let inside = move |x: &Vector3<f32>| {
                let mut d = x - centre;
                d[a] = 0.0;
                d.norm_squared() <= r * r
            };
            (lo, hi, Box::new(inside))
        }
        (None, None) => unreachable!("validated"),
    }
}

/// Particles on the body's lattice ([`Lattice`], from its box's min corner), inside it; or
/// [`FillStopped`] once `stop` is set: it is looked at before every lattice plane, so a stop
/// waits for one plane of particles (the default bed at dx = 2.5 mm, 6.8 M particles, fills in
/// 0.3 s).
pub fn fill_body(
    body: &BodyConfig,
    dx: f32,
    density: f32,
    material: u16,
    stop: &AtomicBool,
) -> Result<Vec<NewParticle>, FillStopped> {
    let lattice = Lattice::of(body.particles_per_cell).expect("validated");
    let volume = lattice.particle_volume(dx);
    let (lo, hi, inside) = body_bounds(body);
    let extent = hi - lo;
    let mut out = Vec::with_capacity(lattice.count_in(&extent, dx) as usize);
    let filled = lattice.points(
        &lo,
        &extent,
        dx,
        || !stop.load(Ordering::Relaxed),
        |x| {
            if inside(&x) {
                out.push(NewParticle {
                    position: x,
                    velocity: body.velocity_m_s.into(),
                    mass: density * volume,
                    volume,
                    material,
                });
            }
        },
    );
    if filled {
        Ok(out)
    } else {
        Err(FillStopped)
    }
}

/// Checks the `node` section.
fn validate_node(scene: &Scene) -> Result<(), SceneError> {
    let n = &scene.config.node;
    let check = |field: &str, ok: bool, v: f64, rule: &str| {
        if ok {
            Ok(())
        } else {
            Err(scene.invalid(format!("node.{field}"), format!("{v} must be {rule}")))
        }
    };
    let positive = |v: f64| v > 0.0 && v.is_finite();
    let non_negative = |v: f64| v >= 0.0 && v.is_finite();
    check(
        "state_rate_hz",
        positive(n.state_rate_hz),
        n.state_rate_hz,
        "a finite number > 0",
    )?;
    check(
        "surface_rate_hz",
        non_negative(n.surface_rate_hz),
        n.surface_rate_hz,
        "a finite number >= 0",
    )?;
    if let Some(cell) = n.surface_cell_m {
        check(
            "surface_cell_m",
            positive(cell as f64),
            cell as f64,
            "a finite number > 0",
        )?;
    }
    check(
        "command_timeout_s",
        non_negative(n.command_timeout_s),
        n.command_timeout_s,
        "a finite number >= 0",
    )?;
    check(
        "stride_length_m",
        positive(n.stride_length_m),
        n.stride_length_m,
        "a finite number > 0",
    )?;
    check(
        "track_width_m",
        positive(n.track_width_m),
        n.track_width_m,
        "a finite number > 0",
    )?;
    let name_ok = !n.name.is_empty()
        && !n.name.starts_with(|c: char| c.is_ascii_digit())
        && n.name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !name_ok {
        return Err(scene.invalid(
            "node.name",
            format!(
                "`{}` must be letters, digits and _ and not start with a digit",
                n.name
            ),
        ));
    }
    let namespace_ok = n.namespace.starts_with('/')
        && (n.namespace == "/"
            || n.namespace[1..].split('/').all(|part| {
                !part.is_empty() && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            }));
    if !namespace_ok {
        return Err(scene.invalid(
            "node.namespace",
            format!(
                "`{}` must be `/` or `/a/b` with parts of letters, digits and _",
                n.namespace
            ),
        ));
    }
    Ok(())
}
