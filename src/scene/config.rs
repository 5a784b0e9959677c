//! The scene file format: YAML mapped onto these structs. Every field documents its unit and
//! default; unknown keys are errors. `docs/scenes.md` describes the format for users.

use std::collections::BTreeMap;

use serde::{Deserialize, Deserializer};

use crate::mpm::kernel::Kernel;
use crate::mpm::material::YieldCone;
use crate::mpm::{CpicBand, Transfer, Wall};
use crate::mpm::{DEFAULT_CPIC_BAND_RELAXATION_S, DEFAULT_FLIP_RELAXATION_S};

/// A whole scene file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneConfig {
    /// Scene name, used to name outputs.
    pub name: String,
    /// Simulated time to run (s).
    pub duration_s: f64,
    /// Gravitational acceleration (m/s^2). Default `[0, 0, -9.81]` (REP-103: z up).
    #[serde(default = "default_gravity")]
    pub gravity_m_s2: [f32; 3],
    /// The MPM sand simulation, if the scene has sand.
    pub sand: Option<SandConfig>,
    /// A granular column collapse: adds the column body to `sand` and measures the runout.
    pub column_collapse: Option<ColumnCollapseConfig>,
    /// The hexapod (rigid bodies in rapier); on rigid ground when the scene has no sand.
    pub robot: Option<crate::robot::RobotConfig>,
    /// How the robot and the sand act on each other (scenes with both). Default: CPIC, two-way.
    #[serde(default)]
    pub coupling: CouplingConfig,
    /// What the run writes besides its summary.
    #[serde(default)]
    pub output: OutputConfig,
    /// The ROS 2 node and its recording (`sandstep node`, and the bag of `sandstep run`).
    #[serde(default)]
    pub node: NodeConfig,
    /// What the robot walks on: the MPM `sand` (default) or resistive force theory
    /// (`docs/scenes.md`, `docs/physics.md`).
    #[serde(default)]
    pub terrain: crate::terrain::TerrainConfig,
}

fn default_gravity() -> [f32; 3] {
    [0.0, 0.0, -9.81]
}

/// The sand: domain, grid, solver settings, materials and bodies.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SandConfig {
    pub domain: DomainConfig,
    /// Grid node spacing (m). Required; must be > 0.
    pub dx_m: f32,
    #[serde(default)]
    pub solver: SolverConfig,
    /// Materials by name.
    pub materials: BTreeMap<String, MaterialConfig>,
    /// Sand bodies filled with particles at the start. Default: none.
    #[serde(default)]
    pub bodies: Vec<BodyConfig>,
    /// Keep only the sand near the robot, the window following it (`docs/scenes.md`).
    /// Default: none (all the sand, all the time).
    #[serde(default)]
    pub window: Option<super::sand_window::SandWindowConfig>,
}

/// The axis-aligned box particles never leave.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DomainConfig {
    /// Min corner (m).
    pub min_m: [f32; 3],
    /// Max corner (m); each component greater than `min_m`'s.
    pub max_m: [f32; 3],
    /// Wall behaviour. Default: all six slip.
    #[serde(default = "default_walls")]
    pub walls: WallsConfig,
}

fn default_walls() -> WallsConfig {
    WallsConfig::all(WallConfig(Wall::Slip))
}

/// The six walls; each `sticky`, `slip` or `{friction: <coefficient>}`. Default: slip.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallsConfig {
    #[serde(default = "slip")]
    pub x_min: WallConfig,
    #[serde(default = "slip")]
    pub x_max: WallConfig,
    #[serde(default = "slip")]
    pub y_min: WallConfig,
    #[serde(default = "slip")]
    pub y_max: WallConfig,
    #[serde(default = "slip")]
    pub z_min: WallConfig,
    #[serde(default = "slip")]
    pub z_max: WallConfig,
}

impl WallsConfig {
    /// The same wall on all six sides.
    pub fn all(wall: WallConfig) -> Self {
        WallsConfig {
            x_min: wall,
            x_max: wall,
            y_min: wall,
            y_max: wall,
            z_min: wall,
            z_max: wall,
        }
    }
}

fn slip() -> WallConfig {
    WallConfig(Wall::Slip)
}

impl WallsConfig {
    /// `(field name, wall)` of the six walls.
    pub fn named(&self) -> [(&'static str, Wall); 6] {
        [
            ("x_min", self.x_min.0),
            ("x_max", self.x_max.0),
            ("y_min", self.y_min.0),
            ("y_max", self.y_max.0),
            ("z_min", self.z_min.0),
            ("z_max", self.z_max.0),
        ]
    }
}

/// One wall as written in YAML: `sticky`, `slip`, or `{friction: 0.5}`.
#[derive(Clone, Copy, Debug)]
pub struct WallConfig(pub Wall);

impl<'de> Deserialize<'de> for WallConfig {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Friction {
            friction: f32,
        }
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            Name(String),
            Friction(Friction),
        }
        let expected = "expected `sticky`, `slip` or `{friction: <coefficient>}`";
        match Repr::deserialize(d).map_err(|_| serde::de::Error::custom(expected))? {
            Repr::Name(name) if name == "sticky" => Ok(WallConfig(Wall::Sticky)),
            Repr::Name(name) if name == "slip" => Ok(WallConfig(Wall::Slip)),
            Repr::Name(name) => Err(serde::de::Error::custom(format!("`{name}`: {expected}"))),
            Repr::Friction(f) => Ok(WallConfig(Wall::Friction(f.friction))),
        }
    }
}

/// Time stepping and blow-up detection.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverConfig {
    /// CFL number of the adaptive step `dt = cfl dx / (c + max |v|)` (dimensionless, (0, 1]).
    /// Default 0.4.
    #[serde(default = "default_cfl")]
    pub cfl: f32,
    /// Upper bound of the adaptive step (s). Default 1e-3.
    #[serde(default = "default_max_dt")]
    pub max_dt_s: f32,
    /// A fixed step (s) instead of the adaptive one; it is not checked against the CFL
    /// condition. Default: none (adaptive).
    #[serde(default)]
    pub fixed_dt_s: Option<f32>,
    /// A particle faster than this (m/s) stops the run as a blow-up. Default 100.
    #[serde(default = "default_blowup_speed")]
    pub blowup_speed_m_s: f32,
    /// Particle-grid transfer: `aflip` (the default: APIC to the grid, the particle's own
    /// deviation from the grid kept back, Fei et al. 2021; the collapse's runout follows
    /// neither the substep count nor the stiffness), `apic` (MLS-MPM's affine transfer, which
    /// loses flow energy at every substep) or `pic` (velocity only, dissipative; for
    /// comparison: `docs/stability.md`).
    #[serde(default)]
    pub transfer: Transfer,
    /// With `transfer: aflip`, the relaxation time (s, >= 0) of a particle's deviation from the
    /// grid: each substep of dt keeps exp(-dt / tau) of its velocity's and its affine field's
    /// rotation's, exp(-2 dt / tau) of its strain rate's (0 is APIC's update away from
    /// colliders; near one, `cpic_band_relaxation_s` applies).
    /// Default 2e-3 (`DEFAULT_FLIP_RELAXATION_S`).
    #[serde(default = "default_flip_relaxation")]
    pub flip_relaxation_s: f32,
    /// Transfer of the particles near a collider (CPIC's band): `bulk` (the default: as
    /// `transfer`; with `aflip` a plough's drag does not follow the substep count) or `pic`
    /// (plain PIC, whose loss grows with the substep count; for comparison).
    /// `docs/speed-vs-accuracy.md`, "The CPIC band".
    #[serde(default)]
    pub cpic_band: CpicBand,
    /// With `cpic_band: bulk` and `transfer: aflip`, the relaxation time (s, >= 0) of the
    /// velocity deviation of a particle near a collider: each substep of dt keeps
    /// exp(-dt / tau) of it. Default 5e-4 (`DEFAULT_CPIC_BAND_RELAXATION_S`).
    #[serde(default = "default_cpic_band_relaxation")]
    pub cpic_band_relaxation_s: f32,
    /// Interpolation kernel: `quadratic_bspline` (the default) or `linear` (the tent, whose
    /// gradient jumps at cell boundaries; for comparison: `docs/stability.md`).
    #[serde(default)]
    pub kernel: Kernel,
    /// Sleeping sand: blocks at rest with no collider near are left out of the substep
    /// (`docs/physics.md`, "Sleeping sand"). Default: none (every particle, every substep).
    #[serde(default)]
    pub sleep: Option<SleepConfig>,
}

/// `sand.solver.sleep`: when blocks of sand sleep and wake.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SleepConfig {
    /// A block is quiet while all its particles are slower than this (m/s), and a neighbour
    /// at or above it wakes a sleeping block. Default 0.01.
    #[serde(default = "default_sleep_speed")]
    pub speed_m_s: f32,
    /// Quiet time after which a block falls asleep (s). Default 0.05.
    #[serde(default = "default_sleep_after")]
    pub after_s: f32,
    /// Sand within this distance (m) of a collider's bounding box stays or comes awake.
    /// Default 0.02.
    #[serde(default = "default_wake_margin")]
    pub wake_margin_m: f32,
}

fn default_sleep_speed() -> f32 {
    0.01
}
fn default_sleep_after() -> f32 {
    0.05
}
fn default_wake_margin() -> f32 {
    0.02
}

fn default_flip_relaxation() -> f32 {
    DEFAULT_FLIP_RELAXATION_S
}
fn default_cpic_band_relaxation() -> f32 {
    DEFAULT_CPIC_BAND_RELAXATION_S
}
fn default_cfl() -> f32 {
    0.4
}
fn default_max_dt() -> f32 {
    1e-3
}
fn default_blowup_speed() -> f32 {
    100.0
}

impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            cfl: default_cfl(),
            max_dt_s: default_max_dt(),
            fixed_dt_s: None,
            blowup_speed_m_s: default_blowup_speed(),
            transfer: Transfer::default(),
            flip_relaxation_s: default_flip_relaxation(),
            cpic_band: CpicBand::default(),
            cpic_band_relaxation_s: default_cpic_band_relaxation(),
            kernel: Kernel::default(),
            sleep: None,
        }
    }
}

/// A material, chosen by `model`. Serialized into the stress maps measured on it
/// (`sandstep calibrate-rft --maps --write`), which name the sand they belong to.
#[derive(Clone, Debug, PartialEq, Deserialize, serde::Serialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum MaterialConfig {
    /// Dry sand: Hencky St. Venant-Kirchhoff elasticity with Drucker-Prager plasticity (Klar et
    /// al. 2016) and volume correction (Tampubolon et al. 2017).
    DruckerPrager {
        /// Density of the bulk material (kg/m^3), > 0.
        density_kg_m3: f32,
        /// Young's modulus (Pa), > 0.
        youngs_modulus_pa: f32,
        /// Poisson's ratio, in (-1, 0.5).
        poisson_ratio: f32,
        /// Internal friction angle (deg), in (0, 90).
        friction_angle_deg: f32,
        /// Where the cone meets Mohr-Coulomb's strength: `triaxial_compression` (Klar et al.
        /// 2016, the MLS-MPM paper; the default) or `plane_strain` (bodies ploughing the sand
        /// near its surface meet a resistance bounded by the friction angle). docs/physics.md,
        /// "The yield cone's fit".
        #[serde(default)]
        yield_cone: YieldCone,
        /// Give back volume gained by expansion on later compression. Default true.
        #[serde(default = "yes")]
        volume_correction: bool,
        /// Viscosity of the sand inside its yield cone (Pa s), >= 0: damps elastic vibration,
        /// not flow. Default none (0).
        #[serde(default)]
        elastic_viscosity_pa_s: Option<f32>,
        /// The in-cone viscosity as a relaxation time (s), >= 0, instead of
        /// `elastic_viscosity_pa_s`: the viscosity is the shear modulus times it, so it damps
        /// the same share of the elastic response whatever `youngs_modulus_pa`. Default none.
        #[serde(default)]
        elastic_relaxation_s: Option<f32>,
    },
    /// Fixed-corotated elasticity (Stomakhin et al. 2012), for elastic test bodies.
    FixedCorotated {
        /// Density (kg/m^3), > 0.
        density_kg_m3: f32,
        /// Young's modulus (Pa), > 0.
        youngs_modulus_pa: f32,
        /// Poisson's ratio, in (-1, 0.5).
        poisson_ratio: f32,
    },
}

fn yes() -> bool {
    true
}

impl MaterialConfig {
    pub fn density_kg_m3(&self) -> f32 {
        match self {
            MaterialConfig::DruckerPrager { density_kg_m3, .. }
            | MaterialConfig::FixedCorotated { density_kg_m3, .. } => *density_kg_m3,
        }
    }
}

/// A body of sand filled with particles at the start; exactly one of `box` and `cylinder`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyConfig {
    /// Name of a material in `materials`.
    pub material: String,
    /// An axis-aligned box.
    #[serde(rename = "box")]
    pub box_shape: Option<BoxShape>,
    /// A cylinder.
    pub cylinder: Option<CylinderShape>,
    /// Particles per grid cell, on a lattice from the body's min corner
    /// ([`crate::mpm::lattice::Lattice`]):
    /// 1, 8, 27 or 64 (simple cubic), 2 or 16 (body-centred), 4 or 32 (face-centred).
    /// Default 8.
    #[serde(default = "default_ppc")]
    pub particles_per_cell: u32,
    /// Initial velocity (m/s). Default `[0, 0, 0]`.
    #[serde(default)]
    pub velocity_m_s: [f32; 3],
}

fn default_ppc() -> u32 {
    8
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxShape {
    /// Min corner (m).
    pub min_m: [f32; 3],
    /// Max corner (m).
    pub max_m: [f32; 3],
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CylinderShape {
    /// Centre of the base disc (m).
    pub base_centre_m: [f32; 3],
    /// Axis: `x`, `y` or `z`. Default `z`.
    #[serde(default = "default_axis")]
    pub axis: Axis,
    /// Radius (m), > 0.
    pub radius_m: f32,
    /// Length along the axis (m), > 0.
    pub height_m: f32,
}

#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn index(self) -> usize {
        self as usize
    }
}

fn default_axis() -> Axis {
    Axis::Z
}

/// A quasi-2D granular column collapse: a box of sand against the `x_min` wall, spanning the
/// domain's width along y, released at t = 0 (Lube et al. 2005).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnCollapseConfig {
    /// Name of a material in `sand.materials`.
    pub material: String,
    /// Initial length L_i along x (m), > 0.
    pub initial_length_m: f32,
    /// Aspect ratio a = H_i / L_i (dimensionless), > 0.
    pub aspect_ratio: f32,
    /// Particles per cell, as for bodies. Default 8.
    #[serde(default = "default_ppc")]
    pub particles_per_cell: u32,
}

/// Sand-robot coupling (`docs/physics.md`, section 4).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingConfig {
    /// `cpic`, or `grid_boundary` (the plain method, which leaks through thin legs; for
    /// comparison only). Default `cpic`.
    #[serde(default = "default_method")]
    pub method: crate::coupling::CouplingMethod,
    /// How the legs take part: `none`, `one_way` or `two_way`. Default `two_way`.
    #[serde(default = "default_mode")]
    pub legs: crate::coupling::CouplingMode,
    /// How the body (belly) takes part. Default `two_way`.
    #[serde(default = "default_mode")]
    pub body: crate::coupling::CouplingMode,
    /// Coulomb friction coefficient sand-robot (-), legs and body. Default 0.4.
    #[serde(default = "default_sand_friction")]
    pub friction: f32,
    /// What a leg yields to the sand with within a substep: `articulated` (the inertia the
    /// robot's multibody presents at the leg), `leg` (its own mass) or `robot` (the whole robot
    /// as one rigid body). Default `articulated`.
    #[serde(default = "default_legs_yield_with")]
    pub legs_yield_with: crate::coupling::LegYield,
    /// The velocity the yield takes for a robot link: `none` (its velocity at the start of the
    /// substep) or `last_substep` (plus the change every other load gives it over the substep,
    /// measured over the last one; needs `legs_yield_with: articulated`; the walking robot's
    /// speed then follows the step below CFL 0.4: `docs/speed-vs-accuracy.md`). Default
    /// `none`.
    #[serde(default = "default_load_prediction")]
    pub load_prediction: crate::coupling::LoadPrediction,
    /// With `legs_yield_with: articulated`, a leg also yields with the impedance its motor
    /// presents over the step (rapier answers the sand with the motor within the step).
    /// Default true with `articulated`, not used (and refused if set true) with the other leg
    /// yields; see [`Self::motor_impedance`].
    #[serde(default)]
    pub motor_impedance: Option<bool>,
}

impl CouplingConfig {
    /// Whether a leg yields with its motor's impedance too: as set, else with the articulated
    /// leg yield (the default since 2026-12-06: `docs/speed-vs-accuracy.md`, "The motor's
    /// impedance becomes the default").
    pub fn motor_impedance(&self) -> bool {
        self.motor_impedance
            .unwrap_or(self.legs_yield_with == crate::coupling::LegYield::Articulated)
    }
}

fn default_method() -> crate::coupling::CouplingMethod {
    crate::coupling::CouplingMethod::Cpic
}
fn default_mode() -> crate::coupling::CouplingMode {
    crate::coupling::CouplingMode::TwoWay
}
fn default_sand_friction() -> f32 {
    0.4
}
fn default_legs_yield_with() -> crate::coupling::LegYield {
    crate::coupling::LegYield::Articulated
}
fn default_load_prediction() -> crate::coupling::LoadPrediction {
    crate::coupling::LoadPrediction::None
}

impl Default for CouplingConfig {
    fn default() -> Self {
        CouplingConfig {
            method: default_method(),
            legs: default_mode(),
            body: default_mode(),
            friction: default_sand_friction(),
            legs_yield_with: default_legs_yield_with(),
            load_prediction: default_load_prediction(),
            motor_impedance: None,
        }
    }
}

/// Outputs of `sandstep run`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Interval between frames (s of sim time): progress, metrics samples and snapshots.
    /// Default 0.01.
    #[serde(default = "default_frame_interval")]
    pub frame_interval_s: f64,
    /// Write a PLY particle snapshot every this many frames; 0 = never. Default 0.
    #[serde(default)]
    pub ply_every_frames: u32,
}

fn default_frame_interval() -> f64 {
    0.01
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            frame_interval_s: default_frame_interval(),
            ply_every_frames: 0,
        }
    }
}

/// The ROS 2 node: names, rates, command handling (`docs/ros.md`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeConfig {
    /// Node name. Default `sandstep`.
    pub name: String,
    /// Node namespace; relative topics (all but `/clock`, `/tf`, `/tf_static`) live in it.
    /// Default `/`.
    pub namespace: String,
    /// Rate of the robot state topics (`joint_states`, `odom`, `/tf`, `body_pose`,
    /// `body_wrench`, `leg_wrenches/*`) and `/clock`, and of the control tick that applies
    /// commands (Hz of simulated time). Default 100.
    pub state_rate_hz: f64,
    /// Rate of `sand/surface` (Hz of simulated time); 0 = never. Default 2.
    pub surface_rate_hz: f64,
    /// Side of the x-y columns whose top particle makes one `sand/surface` point (m).
    /// Default: the sand's `dx_m`.
    pub surface_cell_m: Option<f32>,
    /// A command older than this (s of simulated time) gives way to the scene's `robot.gait`;
    /// 0 = commands never expire. Default 1.
    pub command_timeout_s: f64,
    /// Distance the robot covers per gait cycle, turning `cmd_vel` linear.x (m/s) into a gait
    /// frequency (m). Default 0.1 (C-legs on sand at 2 Hz walk about 0.2 m/s).
    pub stride_length_m: f64,
    /// Lateral distance between the left and right legs, turning `cmd_vel` angular.z (rad/s)
    /// into a right-minus-left frequency difference (m). Default 0.05.
    pub track_width_m: f64,
    /// How service requests and replies are matched on the wire: `enhanced` (rmw_fastrtps,
    /// the ROS 2 default), `cyclone` (rmw_cyclonedds) or `basic`. Default `enhanced`.
    pub service_mapping: ServiceMappingConfig,
    /// Use only the loopback interface for DDS (peers on this machine only). Default false.
    pub loopback_only: bool,
}

/// `node.service_mapping`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ServiceMappingConfig {
    Enhanced,
    Cyclone,
    Basic,
}

impl Default for NodeConfig {
    fn default() -> Self {
        NodeConfig {
            name: "sandstep".into(),
            namespace: "/".into(),
            state_rate_hz: 100.0,
            surface_rate_hz: 2.0,
            surface_cell_m: None,
            command_timeout_s: 1.0,
            stride_length_m: 0.1,
            track_width_m: 0.05,
            service_mapping: ServiceMappingConfig::Enhanced,
            loopback_only: false,
        }
    }
}
