//! Geometry of the hexapod: arc-shaped legs (chord, width, thickness, signed curvature), the
//! body box, hip positions, and the mass properties that follow from them.
//!
//! Leg frame (joint angle 0): origin on the hip axis, x forward, y along the hip axis (left),
//! z up. The leg's centreline is a circular arc from the hip (0, 0, 0) to the tip (0, 0, -chord).
//! A positive curvature bulges the arc towards -x: when the leg turns forward (positive angle
//! about +y, the foot sweeping backwards under the hip) the convex side leads, as on a C-leg.
//! A negative curvature ("reversed" leg) leads with the concave side, so its tip strikes first.

use super::mesh::{inertia_from_moments, MassProperties, TriMesh};

/// Published leg chord 2R (m): Hu et al. 2018 supplement, section 4.
pub const PUBLISHED_CHORD_M: f64 = 0.041;
/// Published leg width along the hip axis (m).
pub const PUBLISHED_WIDTH_M: f64 = 0.010;
/// Published leg thickness (m).
pub const PUBLISHED_THICKNESS_M: f64 = 0.003;
/// Density of 3D-printed ABS (kg/m^3).
pub const ABS_DENSITY_KG_M3: f64 = 1050.0;
/// Published total robot mass, legs included (kg).
pub const PUBLISHED_TOTAL_MASS_KG: f64 = 0.085;
/// Published belly length along x (m).
pub const PUBLISHED_BODY_LENGTH_M: f64 = 0.13;
/// Published belly width along y (m).
pub const PUBLISHED_BODY_WIDTH_M: f64 = 0.02;
/// Body height (m). Not published; a toy gearbox-and-battery box.
pub const ASSUMED_BODY_HEIGHT_M: f64 = 0.025;
/// Hip x positions, front, middle, rear (m). Not published; spread as far as the 13 cm belly
/// allows. On rigid ground a tripod whose feet land ahead of the hips (tip-first legs) keeps
/// the centre of mass inside its support triangle only while the foot offset is below half
/// the hip spacing, so wider is steadier (docs/robot.md, "Rigid-ground stability").
pub const ASSUMED_HIP_X_M: [f64; 3] = [0.06, 0.0, -0.06];
/// Distance of each leg's mid-plane from the body's mid-plane, front, middle, rear (m). Not
/// published: half the belly width, a 10 mm hub, and half the leg width.
pub const ASSUMED_HIP_Y_M: [f64; 3] = [0.025; 3];
/// Height of the hip axes above the body's centre (m). Not published; 2.25 cm above the
/// belly, so that the belly just skims the ground when both tripods' C-legs lie flat (hips
/// R + t/2 = 2.2 cm up) and carries the body through the hand-over between tripods.
pub const ASSUMED_HIP_Z_M: f64 = 0.01;

/// Gauss-Legendre nodes on [-1, 1], 4 points (exact for polynomials of degree 7).
const GAUSS4_NODES: [f64; 4] = [
    -0.861_136_311_594_052_6,
    -0.339_981_043_584_856_3,
    0.339_981_043_584_856_3,
    0.861_136_311_594_052_6,
];
/// Gauss-Legendre weights matching [`GAUSS4_NODES`].
const GAUSS4_WEIGHTS: [f64; 4] = [
    0.347_854_845_137_453_9,
    0.652_145_154_862_546_1,
    0.652_145_154_862_546_1,
    0.347_854_845_137_453_9,
];
/// Panels along the arc for the mass-property quadrature (4 Gauss points each); the integrand
/// is smooth, so this is exact to about 1e-12.
const MASS_QUADRATURE_PANELS: usize = 64;
/// Below this |x|, sin(x)/x and asin(x)/x use their Taylor series.
const SERIES_CUTOFF: f64 = 1e-4;

/// One arc-shaped leg.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegParams {
    /// Straight-line distance from hip to tip, 2R (m). Default 0.041.
    pub chord_m: f64,
    /// Extent along the hip axis (m). Default 0.010.
    pub width_m: f64,
    /// Extent across the arc, in the plane of rotation (m). Default 0.003.
    pub thickness_m: f64,
    /// Signed curvature 1/r of the centreline (1/m), in [-2/chord, +2/chord]; +2/chord = +1/R
    /// is the published C-leg (a half circle), -1/R the reversed leg, 0 a straight leg.
    /// Default +1/R = 48.78 1/m.
    pub curvature_per_m: f64,
    /// Material density (kg/m^3). Default 1050 (ABS).
    pub density_kg_m3: f64,
}

impl Default for LegParams {
    fn default() -> Self {
        Self {
            chord_m: PUBLISHED_CHORD_M,
            width_m: PUBLISHED_WIDTH_M,
            thickness_m: PUBLISHED_THICKNESS_M,
            curvature_per_m: 2.0 / PUBLISHED_CHORD_M,
            density_kg_m3: ABS_DENSITY_KG_M3,
        }
    }
}

/// A point of the leg's centreline with its unit tangent (towards the tip) and its unit
/// in-plane normal (towards the convex side for positive curvature), in the leg frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcPoint {
    /// Position (m).
    pub position_m: [f64; 3],
    /// Unit tangent, pointing from hip to tip.
    pub tangent: [f64; 3],
    /// Unit normal in the x-z plane, `y x tangent`.
    pub normal: [f64; 3],
}

impl LegParams {
    /// Half the chord, R (m): the radius of the published half-circle legs.
    pub fn half_chord_m(&self) -> f64 {
        0.5 * self.chord_m
    }

    /// Largest |curvature| a chord allows, 1/R (1/m): a half circle.
    pub fn max_curvature_per_m(&self) -> f64 {
        1.0 / self.half_chord_m()
    }

    /// Checks the dimensions; the error names the field.
    pub fn validate(&self) -> Result<(), (&'static str, f64, String)> {
        for (name, value) in [
            ("chord_m", self.chord_m),
            ("width_m", self.width_m),
            ("thickness_m", self.thickness_m),
            ("density_kg_m3", self.density_kg_m3),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err((name, value, "must be a positive number".into()));
            }
        }
        let k_max = self.max_curvature_per_m();
        if !(self.curvature_per_m.is_finite() && self.curvature_per_m.abs() <= k_max * (1.0 + 1e-9))
        {
            return Err((
                "curvature_per_m",
                self.curvature_per_m,
                format!(
                    "must lie in [-1/R, +1/R] = [{:.4}, {:.4}] 1/m for chord {} m",
                    -k_max, k_max, self.chord_m
                ),
            ));
        }
        if self.thickness_m * self.curvature_per_m.abs() >= 2.0 {
            return Err((
                "thickness_m",
                self.thickness_m,
                "must be less than the arc's diameter".into(),
            ));
        }
        Ok(())
    }

    /// Curvature clamped to the admissible range (guards rounding at exactly +-1/R).
    fn k(&self) -> f64 {
        let k_max = self.max_curvature_per_m();
        self.curvature_per_m.clamp(-k_max, k_max)
    }

    /// Length of the centreline (m): `2 asin(k R) / k`, the chord when straight, pi R for a
    /// half circle.
    pub fn arc_length_m(&self) -> f64 {
        self.chord_m * asin_over(self.k() * self.half_chord_m())
    }

    /// Volume (m^3): centreline length x width x thickness, exact for a constant-thickness
    /// curved slab (the inner side is as much shorter as the outer side is longer).
    pub fn volume_m3(&self) -> f64 {
        self.arc_length_m() * self.width_m * self.thickness_m
    }

    /// Mass (kg).
    pub fn mass_kg(&self) -> f64 {
        self.density_kg_m3 * self.volume_m3()
    }

    /// Centreline point at fraction `u` of the arc length from the hip (0) to the tip (1).
    pub fn centreline(&self, u: f64) -> ArcPoint {
        let k = self.k();
        let half_len = 0.5 * self.arc_length_m();
        let s = (u - 0.5) * 2.0 * half_len; // arc length from the arc's middle
                                            // Along the chord: sin(k s)/k. Towards the bulge: (cos(k s) - cos(k L/2))/k, written
                                            // as a product of sines so it stays accurate as k -> 0.
        let along = s * sinc(k * s);
        let (a, b) = (0.5 * (half_len + s), 0.5 * (half_len - s));
        let bulge = 2.0 * k * a * b * sinc(k * a) * sinc(k * b);
        let position_m = [-bulge, 0.0, -self.half_chord_m() - along];
        let tangent = [libm::sin(k * s), 0.0, -libm::cos(k * s)];
        let normal = [tangent[2], 0.0, -tangent[0]];
        ArcPoint {
            position_m,
            tangent,
            normal,
        }
    }

    /// Signed curvature measured back from the geometry: the circle through the hip, the
    /// middle and the tip of the centreline (1/m; positive when the middle lies at -x).
    pub fn measured_curvature_per_m(&self) -> f64 {
        let p = [0.0, 0.5, 1.0].map(|u| self.centreline(u).position_m);
        signed_curvature_xz(p[0], p[1], p[2])
    }

    /// The leg as a closed triangle mesh in the leg frame: the rectangular cross-section
    /// (thickness x width) swept along the arc in `segments` straight pieces.
    pub fn mesh(&self, segments: usize) -> TriMesh {
        let segments = segments.max(1);
        let (ht, hw) = (0.5 * self.thickness_m, 0.5 * self.width_m);
        // Cross-section corners as (normal offset, y offset), counter-clockwise seen from
        // the tip side (tangent x normal = +y, so (normal, y) is right-handed about tangent).
        let corners = [(-ht, -hw), (ht, -hw), (ht, hw), (-ht, hw)];
        let mut mesh = TriMesh::default();
        for j in 0..=segments {
            let p = self.centreline(j as f64 / segments as f64);
            for &(n, y) in &corners {
                mesh.vertices.push([
                    p.position_m[0] + n * p.normal[0],
                    y,
                    p.position_m[2] + n * p.normal[2],
                ]);
            }
        }
        let v = |station: usize, corner: usize| (4 * station + corner % 4) as u32;
        for j in 0..segments {
            for c in 0..4 {
                let (a, b, cc, d) = (v(j, c), v(j, c + 1), v(j + 1, c + 1), v(j + 1, c));
                mesh.triangles.push([a, b, cc]);
                mesh.triangles.push([a, cc, d]);
            }
        }
        let last = segments;
        mesh.triangles.push([v(0, 0), v(0, 2), v(0, 1)]);
        mesh.triangles.push([v(0, 0), v(0, 3), v(0, 2)]);
        mesh.triangles.push([v(last, 0), v(last, 1), v(last, 2)]);
        mesh.triangles.push([v(last, 0), v(last, 2), v(last, 3)]);
        mesh
    }

    /// The leg's mid-surface in the leg frame, for CPIC coupling (an open sheet with no
    /// thickness): the centreline swept across the width (y in [-w/2, +w/2]), as a strip of
    /// `segments` straight pieces along the arc, two triangles each. Station j (of
    /// `segments + 1`) is centreline point u = j / segments; its vertices are 2j at y = -w/2
    /// and 2j + 1 at y = +w/2 (m). Triangles are wound so that their right-hand-rule normal is
    /// `y x tangent`, the centreline's [`ArcPoint::normal`]: the side [`LegParams::mesh`]
    /// offsets by +thickness/2. That positive side is the convex (outer) side of a C-leg
    /// (positive curvature; +z at the hip), the concave side of a reversed leg, and -x for a
    /// straight leg.
    pub fn mid_surface(&self, segments: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let segments = segments.max(1);
        let hw = 0.5 * self.width_m;
        let mut vertices = Vec::with_capacity(2 * (segments + 1));
        for j in 0..=segments {
            let p = self.centreline(j as f64 / segments as f64).position_m;
            for y in [-hw, hw] {
                vertices.push([p[0] as f32, y as f32, p[2] as f32]);
            }
        }
        let mut triangles = Vec::with_capacity(2 * segments);
        for j in 0..segments {
            // Station j at -y and +y, then station j + 1 at +y and -y: a -> b runs along +y
            // and a -> d along the piece's chord, which is parallel to the tangent at the
            // piece's middle, so both triangles' normals are y x tangent there.
            let [a, b, c, d] = [2 * j, 2 * j + 1, 2 * j + 3, 2 * j + 2].map(|i| i as u32);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
        (vertices, triangles)
    }

    /// Mass, centre of mass and inertia about the centre of mass in the leg frame, integrated
    /// over the exact curved slab (volume element `(1 + k n) ds dn dy`).
    pub fn mass_properties(&self) -> MassProperties {
        let k = self.k();
        let len = self.arc_length_m();
        let rho = self.density_kg_m3;
        let (ht, hw) = (0.5 * self.thickness_m, 0.5 * self.width_m);
        // Two Gauss points across thickness and width are exact: the integrand is cubic in n
        // and quadratic in y.
        let g2 = 1.0 / 3f64.sqrt();
        let mut mass = 0.0;
        let mut first = [0.0; 3];
        let mut second = [[0.0; 3]; 3];
        let panel = 1.0 / MASS_QUADRATURE_PANELS as f64;
        for p in 0..MASS_QUADRATURE_PANELS {
            for (xi, wi) in GAUSS4_NODES.iter().zip(GAUSS4_WEIGHTS) {
                let u = (p as f64 + 0.5 * (xi + 1.0)) * panel;
                let c = self.centreline(u);
                let w_s = wi * 0.5 * panel * len;
                for n in [-g2 * ht, g2 * ht] {
                    for y in [-g2 * hw, g2 * hw] {
                        // Each (n, y) Gauss point has weight ht * hw (2 x 2 points on a
                        // 2ht x 2hw rectangle).
                        let dm = rho * w_s * ht * hw * (1.0 + k * n);
                        let x = [
                            c.position_m[0] + n * c.normal[0],
                            y,
                            c.position_m[2] + n * c.normal[2],
                        ];
                        mass += dm;
                        for i in 0..3 {
                            first[i] += dm * x[i];
                            for j in 0..3 {
                                second[i][j] += dm * x[i] * x[j];
                            }
                        }
                    }
                }
            }
        }
        inertia_from_moments(mass, first.map(|f| f / mass), second)
    }

    /// Boxes approximating the leg for collision: `segments` pieces along the arc, each
    /// centred on the centreline, aligned with its tangent, and lengthened by the factor
    /// `1 + |k| t/2` so the outer (convex) surface has no gaps between pieces.
    pub fn collision_boxes(&self, segments: usize) -> Vec<LegBox> {
        let segments = segments.max(1);
        let piece = self.arc_length_m() / segments as f64;
        let length = piece * (1.0 + self.k().abs() * 0.5 * self.thickness_m);
        (0..segments)
            .map(|i| {
                let c = self.centreline((i as f64 + 0.5) / segments as f64);
                LegBox {
                    centre_m: c.position_m,
                    // Rotation about +y that takes the box's x axis onto the tangent.
                    pitch_rad: libm::atan2(-c.tangent[2], c.tangent[0]),
                    size_m: [length, self.width_m, self.thickness_m],
                }
            })
            .collect()
    }
}

/// A box of a leg's collision compound, in the leg frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegBox {
    /// Centre (m).
    pub centre_m: [f64; 3],
    /// Rotation about the y axis (rad); the box's x axis lies along the leg's tangent.
    pub pitch_rad: f64,
    /// Full extents along the box's x (along the arc), y (width), z (thickness) (m).
    pub size_m: [f64; 3],
}

/// Where a leg sits on the body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// +y.
    Left,
    /// -y.
    Right,
}

/// Which of the two alternating tripods a leg belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tripod {
    /// {front-left, middle-right, rear-left}; gait phase offset 0.
    A,
    /// {front-right, middle-left, rear-right}; half a cycle behind tripod A.
    B,
}

/// One of the six legs: its name stem, side, hip row (0 front, 1 middle, 2 rear) and tripod.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Leg {
    /// Name stem, e.g. `front_left`; the link is `leg_<stem>`, the joint `leg_<stem>_joint`.
    pub stem: &'static str,
    /// Side of the body.
    pub side: Side,
    /// Hip row along the body: 0 front, 1 middle, 2 rear.
    pub row: usize,
    /// Tripod the leg belongs to.
    pub tripod: Tripod,
}

impl Leg {
    /// URDF link name, e.g. `leg_front_left`.
    pub fn link_name(&self) -> String {
        format!("leg_{}", self.stem)
    }

    /// URDF joint name, e.g. `leg_front_left_joint`.
    pub fn joint_name(&self) -> String {
        format!("leg_{}_joint", self.stem)
    }
}

/// Number of legs.
pub const LEG_COUNT: usize = 6;

/// The six legs, in the order used by every per-joint array of this module.
pub const LEGS: [Leg; LEG_COUNT] = [
    Leg {
        stem: "front_left",
        side: Side::Left,
        row: 0,
        tripod: Tripod::A,
    },
    Leg {
        stem: "middle_left",
        side: Side::Left,
        row: 1,
        tripod: Tripod::B,
    },
    Leg {
        stem: "rear_left",
        side: Side::Left,
        row: 2,
        tripod: Tripod::A,
    },
    Leg {
        stem: "front_right",
        side: Side::Right,
        row: 0,
        tripod: Tripod::B,
    },
    Leg {
        stem: "middle_right",
        side: Side::Right,
        row: 1,
        tripod: Tripod::A,
    },
    Leg {
        stem: "rear_right",
        side: Side::Right,
        row: 2,
        tripod: Tripod::B,
    },
];

/// Name of the body link.
pub const BODY_LINK: &str = "base_link";

/// The whole robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HexapodParams {
    /// The six (identical) legs.
    pub legs: LegParams,
    /// Body (belly) length along x (m). Default 0.13.
    pub body_length_m: f64,
    /// Body (belly) width along y (m). Default 0.02.
    pub body_width_m: f64,
    /// Body height along z (m). Default 0.025 (assumed).
    pub body_height_m: f64,
    /// Total mass, legs included (kg); the body gets what the legs leave. Default 0.085.
    pub total_mass_kg: f64,
    /// The body's centre of mass relative to the centre of its box (m), inside the box; its
    /// inertia stays the uniform box's, about that point. The body's frame (`base_link`, the
    /// pose a run reports) is at this point. Default [0, 0, 0] (assumed: a uniform body).
    pub body_com_m: [f64; 3],
    /// Hip x positions in the body frame, front, middle, rear (m). Default [0.06, 0, -0.06].
    pub hip_x_m: [f64; 3],
    /// Lateral distance of each leg's mid-plane from the body's mid-plane, front, middle, rear
    /// (m). Default [0.025; 3].
    pub hip_y_m: [f64; 3],
    /// Height of the hip axes above the body's centre (m). Default 0.01.
    pub hip_z_m: f64,
    /// Straight pieces of the visual leg mesh. Default 48.
    pub mesh_segments: usize,
    /// Boxes of the leg collision compound. Default 16.
    pub collision_segments: usize,
}

impl Default for HexapodParams {
    fn default() -> Self {
        Self {
            legs: LegParams::default(),
            body_length_m: PUBLISHED_BODY_LENGTH_M,
            body_width_m: PUBLISHED_BODY_WIDTH_M,
            body_height_m: ASSUMED_BODY_HEIGHT_M,
            total_mass_kg: PUBLISHED_TOTAL_MASS_KG,
            body_com_m: [0.0; 3],
            hip_x_m: ASSUMED_HIP_X_M,
            hip_y_m: ASSUMED_HIP_Y_M,
            hip_z_m: ASSUMED_HIP_Z_M,
            mesh_segments: 48,
            collision_segments: 16,
        }
    }
}

impl HexapodParams {
    /// The published robot with reversed legs (curvature -1/R).
    pub fn reversed() -> Self {
        let mut p = Self::default();
        p.legs.curvature_per_m = -p.legs.curvature_per_m;
        p
    }

    /// These parameters with legs of curvature `curvature_per_r` in units of 1/R (R = half
    /// the chord): 1 = C-leg, -1 = reversed, 0 = straight.
    pub fn with_curvature(mut self, curvature_per_r: f64) -> Self {
        self.legs.curvature_per_m = curvature_per_r * self.legs.max_curvature_per_m();
        self
    }

    /// Body mass (kg): the total less six legs.
    pub fn body_mass_kg(&self) -> f64 {
        self.total_mass_kg - LEG_COUNT as f64 * self.legs.mass_kg()
    }

    /// Body mass properties in the body's frame, whose origin is the body's centre of mass
    /// (`body_com_m` from the box's centre; the URDF places the box and the hips around it):
    /// the inertia of a uniform box of the body's size about that point.
    pub fn body_mass_properties(&self) -> MassProperties {
        let m = self.body_mass_kg();
        let (a, b, c) = (self.body_length_m, self.body_width_m, self.body_height_m);
        let mut inertia = [[0.0; 3]; 3];
        inertia[0][0] = m * (b * b + c * c) / 12.0;
        inertia[1][1] = m * (a * a + c * c) / 12.0;
        inertia[2][2] = m * (a * a + b * b) / 12.0;
        MassProperties {
            mass_kg: m,
            com_m: [0.0; 3],
            inertia_kg_m2: inertia,
        }
    }

    /// Hip of a leg from the centre of the body's box (m); the URDF's joint origin is this
    /// less `body_com_m`.
    pub fn hip_position_m(&self, leg: &Leg) -> [f64; 3] {
        let y = match leg.side {
            Side::Left => self.hip_y_m[leg.row],
            Side::Right => -self.hip_y_m[leg.row],
        };
        [self.hip_x_m[leg.row], y, self.hip_z_m]
    }

    /// Checks every parameter; the error names the field.
    pub fn validate(&self) -> Result<(), (&'static str, f64, String)> {
        self.legs.validate()?;
        for (name, value) in [
            ("body_length_m", self.body_length_m),
            ("body_width_m", self.body_width_m),
            ("body_height_m", self.body_height_m),
            ("total_mass_kg", self.total_mass_kg),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err((name, value, "must be a positive number".into()));
            }
        }
        if let Some(x) = self.hip_x_m.iter().find(|x| !x.is_finite()) {
            return Err(("hip_x_m", *x, "hip positions must be finite".into()));
        }
        let half_box = [self.body_length_m, self.body_width_m, self.body_height_m].map(|a| a / 2.0);
        if let Some((c, _)) = self
            .body_com_m
            .iter()
            .zip(half_box)
            .find(|(c, half)| !(c.is_finite() && c.abs() <= *half))
        {
            return Err((
                "body_com_m",
                *c,
                "must lie inside the body's box (each coordinate within half its size)".into(),
            ));
        }
        if !self.hip_z_m.is_finite() {
            return Err(("hip_z_m", self.hip_z_m, "must be finite".into()));
        }
        // Closer in, a leg's inner face would lie inside the belly (the robot does not
        // collide with itself).
        let flush_m = (self.body_width_m + self.legs.width_m) / 2.0;
        if let Some(y) = self
            .hip_y_m
            .iter()
            .find(|y| !(y.is_finite() && **y >= flush_m))
        {
            return Err((
                "hip_y_m",
                *y,
                format!(
                    "must be at least {flush_m} m (half the body's and a leg's widths): a \
                     leg would cut into the belly"
                ),
            ));
        }
        if self.body_mass_kg() <= 0.0 {
            return Err((
                "total_mass_kg",
                self.total_mass_kg,
                format!(
                    "must exceed the six legs' mass {:.4} kg",
                    LEG_COUNT as f64 * self.legs.mass_kg()
                ),
            ));
        }
        if self.mesh_segments < 2 || self.collision_segments < 1 {
            return Err((
                "mesh_segments",
                self.mesh_segments as f64,
                "need >= 2 mesh and >= 1 collision pieces".into(),
            ));
        }
        Ok(())
    }
}

/// Signed curvature of the circle through three points of the x-z plane (1/m): positive when
/// the middle point lies on the -x side of the line from the first to the last point (the
/// C-leg convention of this module), 0 when collinear.
pub fn signed_curvature_xz(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (ab, bc, ca) = (dist_xz(a, b), dist_xz(b, c), dist_xz(c, a));
    // Twice the signed triangle area in (x, z); for a chord pointing down (-z) it is positive
    // when the middle point lies at -x. Curvature of the circumcircle: 4 area / (ab bc ca).
    let cross = (b[0] - a[0]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[0] - a[0]);
    2.0 * cross / (ab * bc * ca)
}

fn dist_xz(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// sin(x)/x.
fn sinc(x: f64) -> f64 {
    if x.abs() < SERIES_CUTOFF {
        1.0 - x * x / 6.0
    } else {
        libm::sin(x) / x
    }
}

/// asin(x)/x.
fn asin_over(x: f64) -> f64 {
    if x.abs() < SERIES_CUTOFF {
        1.0 + x * x / 6.0
    } else {
        libm::asin(x) / x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn leg(curvature_in_units_of_inv_r: f64) -> LegParams {
        let mut p = LegParams::default();
        p.curvature_per_m = curvature_in_units_of_inv_r * p.max_curvature_per_m();
        p
    }

    #[test]
    fn centreline_runs_from_hip_to_tip_with_unit_tangents() {
        for k in [-1.0, -0.5, 0.0, 1e-7, 0.3, 1.0] {
            let p = leg(k);
            let hip = p.centreline(0.0).position_m;
            let tip = p.centreline(1.0).position_m;
            assert!(hip.iter().all(|x| x.abs() < 1e-12), "k {k}: hip {hip:?}");
            assert!(
                (tip[0]).abs() < 1e-12 && (tip[2] + p.chord_m).abs() < 1e-12,
                "k {k}: tip {tip:?}"
            );
            for u in [0.0, 0.3, 1.0] {
                let t = p.centreline(u).tangent;
                assert!(((t[0] * t[0] + t[2] * t[2]).sqrt() - 1.0).abs() < 1e-12);
            }
            // Finite-difference arc length equals the closed form.
            let n = 4000;
            let len: f64 = (0..n)
                .map(|i| {
                    let a = p.centreline(i as f64 / n as f64).position_m;
                    let b = p.centreline((i + 1) as f64 / n as f64).position_m;
                    dist_xz(a, b)
                })
                .sum();
            assert!((len - p.arc_length_m()).abs() < 1e-8, "k {k}");
        }
    }

    #[test]
    fn half_circle_leg_has_published_shape_and_bulges_backwards() {
        let c = leg(1.0);
        let r = c.half_chord_m();
        assert!((c.arc_length_m() - PI * r).abs() < 1e-12);
        let mid = c.centreline(0.5).position_m;
        assert!(
            (mid[0] + r).abs() < 1e-12 && (mid[2] + r).abs() < 1e-12,
            "{mid:?}"
        );
        assert!((c.measured_curvature_per_m() - 1.0 / r).abs() < 1e-9);
        let rev = leg(-1.0);
        assert!(rev.centreline(0.5).position_m[0] > 0.0);
        assert!((rev.measured_curvature_per_m() + 1.0 / r).abs() < 1e-9);
        assert!(leg(0.0).measured_curvature_per_m().abs() < 1e-9);
        assert!((leg(0.4).measured_curvature_per_m() - 0.4 / r).abs() < 1e-9);
    }

    #[test]
    fn published_leg_weighs_about_two_grams() {
        let m = leg(1.0).mass_kg();
        // pi * 0.0205 * 0.01 * 0.003 * 1050 = 2.029 g.
        assert!((m - 2.0287e-3).abs() < 1e-6, "{m}");
        let p = HexapodParams::default();
        assert!((p.body_mass_kg() - (0.085 - 6.0 * m)).abs() < 1e-15);
    }

    #[test]
    fn straight_leg_inertia_is_a_box() {
        let p = leg(0.0);
        let mp = p.mass_properties();
        let m = p.mass_kg();
        assert!((mp.mass_kg - m).abs() < 1e-12 * m.max(1.0));
        assert!((mp.com_m[2] + p.chord_m / 2.0).abs() < 1e-12);
        let (l, w, t) = (p.chord_m, p.width_m, p.thickness_m);
        let want = [
            m * (w * w + l * l) / 12.0,
            m * (t * t + l * l) / 12.0,
            m * (t * t + w * w) / 12.0,
        ];
        for (i, want) in want.iter().enumerate() {
            let got = mp.inertia_kg_m2[i][i];
            assert!((got - want).abs() < 1e-9 * want, "axis {i}");
        }
    }

    #[test]
    fn half_circle_inertia_matches_a_thin_semicircular_ring() {
        let p = leg(1.0);
        let mp = p.mass_properties();
        let (m, r) = (p.mass_kg(), p.half_chord_m());
        assert!((mp.mass_kg - m).abs() < 1e-9 * m);
        // Centre of mass of a half annulus of radii R -+ t/2: (2R/pi)(1 + (t/2)^2 / (3R^2))
        // from the circle's centre (0, 0, -R), towards -x.
        let h = 0.5 * p.thickness_m;
        let com_x = -2.0 * r / PI * (1.0 + h * h / (3.0 * r * r));
        assert!(
            (mp.com_m[0] - com_x).abs() < 1e-9 * r,
            "{} vs {com_x}",
            mp.com_m[0]
        );
        assert!((mp.com_m[2] + r).abs() < 1e-9);
        // About y through the centre of mass: m R^2 (1 - 4/pi^2) plus thickness corrections
        // of order (t/R)^2 / 12 = 0.2 %.
        let thin = m * r * r * (1.0 - 4.0 / (PI * PI));
        assert!(
            (mp.inertia_kg_m2[1][1] / thin - 1.0).abs() < 0.01,
            "{}",
            mp.inertia_kg_m2[1][1] / thin
        );
    }

    #[test]
    fn mesh_encloses_the_same_solid_as_the_quadrature() {
        for k in [-1.0, 0.0, 0.6, 1.0] {
            let p = leg(k);
            let mesh = p.mesh(256);
            let vol = mesh.volume_m3();
            assert!((vol / p.volume_m3() - 1.0).abs() < 1e-4, "k {k}: {vol}");
            let a = mesh.mass_properties(p.density_kg_m3);
            let b = p.mass_properties();
            for i in 0..3 {
                assert!((a.com_m[i] - b.com_m[i]).abs() < 1e-6, "k {k} com {i}");
                for j in 0..3 {
                    let scale = b.inertia_kg_m2[1][1];
                    assert!(
                        (a.inertia_kg_m2[i][j] - b.inertia_kg_m2[i][j]).abs() < 1e-3 * scale,
                        "k {k} I{i}{j}"
                    );
                }
            }
        }
    }

    #[test]
    fn collision_boxes_follow_the_arc() {
        let p = leg(1.0);
        let boxes = p.collision_boxes(16);
        assert_eq!(boxes.len(), 16);
        // Box centres lie on the circle of radius R about (0, 0, -R).
        for b in &boxes {
            let d = (b.centre_m[0].powi(2) + (b.centre_m[2] + p.half_chord_m()).powi(2)).sqrt();
            assert!((d - p.half_chord_m()).abs() < 1e-12);
        }
        // The first box starts out along -x (the tangent at the hip of a C-leg).
        assert!(boxes[0].pitch_rad.cos() < -0.9);
        assert!(boxes.iter().map(|b| b.size_m[0]).sum::<f64>() > p.arc_length_m());
    }

    #[test]
    fn mid_surface_is_the_swept_centreline_facing_the_thickness_offset() {
        let segments = 24;
        for k in [-1.0, 0.0, 0.6, 1.0] {
            let p = leg(k);
            let (vertices, triangles) = p.mid_surface(segments);
            assert_eq!(vertices.len(), 2 * (segments + 1), "k {k}");
            assert_eq!(triangles.len(), 2 * segments, "k {k}");
            let vertices: Vec<[f64; 3]> = vertices.iter().map(|v| v.map(f64::from)).collect();
            // Every vertex is a centreline point at y = -+w/2 (up to f32 rounding of ~4 cm).
            for (i, v) in vertices.iter().enumerate() {
                let c = p.centreline((i / 2) as f64 / segments as f64).position_m;
                let y = if i % 2 == 0 { -0.5 } else { 0.5 } * p.width_m;
                let err = [v[0] - c[0], v[1] - y, v[2] - c[2]];
                assert!(
                    err.iter().all(|e| e.abs() < 1e-8),
                    "k {k} vertex {i}: {v:?}"
                );
            }
            let mesh = p.mesh(segments);
            for (t, tri) in triangles.iter().enumerate() {
                let [a, b, c] = tri.map(|i| vertices[i as usize]);
                let n = cross(sub(b, a), sub(c, a));
                let piece = t / 2;
                // The normal is the centreline normal at the piece's middle...
                let want = p.centreline((piece as f64 + 0.5) / segments as f64).normal;
                let cos = dot(n, want) / dot(n, n).sqrt();
                assert!(cos > 0.999, "k {k} triangle {t}: cos {cos}");
                // ... the side where `mesh` puts its +thickness/2 corners (corner 1 of each
                // station)...
                let station = p.centreline(piece as f64 / segments as f64).position_m;
                assert!(dot(n, sub(mesh.vertices[4 * piece + 1], station)) > 0.0);
                // ... which for a C-leg is the convex side, away from the arc's centre
                // (0, 0, -R).
                if k == 1.0 {
                    assert!(dot(n, sub(a, [0.0, 0.0, -p.half_chord_m()])) > 0.0);
                }
            }
            if k == 1.0 {
                // On the C-leg all vertices lie on the circle of radius R about (0, 0, -R),
                // and the first piece, at the hip, faces +z.
                let r = p.half_chord_m();
                for v in &vertices {
                    let d = (v[0] * v[0] + (v[2] + r).powi(2)).sqrt();
                    assert!((d - r).abs() < 1e-8, "{v:?}");
                }
                let [a, b, c] = triangles[0].map(|i| vertices[i as usize]);
                assert!(cross(sub(b, a), sub(c, a))[2] > 0.0);
            }
        }
    }

    fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }

    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }

    #[test]
    fn tripods_alternate_legs_along_each_side() {
        for row in 0..3 {
            let l = LEGS
                .iter()
                .find(|l| l.row == row && l.side == Side::Left)
                .unwrap();
            let r = LEGS
                .iter()
                .find(|l| l.row == row && l.side == Side::Right)
                .unwrap();
            assert_ne!(l.tripod, r.tripod, "row {row}");
        }
        assert_eq!(LEGS.iter().filter(|l| l.tripod == Tripod::A).count(), 3);
        assert_eq!(LEGS[0].joint_name(), "leg_front_left_joint");
    }

    #[test]
    fn bad_parameters_are_named() {
        let mut p = HexapodParams::default();
        p.legs.curvature_per_m = 60.0;
        assert_eq!(p.validate().unwrap_err().0, "curvature_per_m");
        let named = |p: HexapodParams| p.validate().err().map(|e| e.0);
        let d = HexapodParams::default;
        let light = HexapodParams {
            total_mass_kg: 0.01,
            ..d()
        };
        assert_eq!(named(light), Some("total_mass_kg"));
        let hip_z_m = f64::INFINITY;
        assert_eq!(named(HexapodParams { hip_z_m, ..d() }), Some("hip_z_m"));
        // Legs 1 cm wide beside a 2 cm belly: 1.5 cm is flush, 1.4 cm cuts into it.
        let (inside, flush) = (0.014, 0.015);
        assert_eq!(
            named(HexapodParams {
                hip_y_m: [flush, inside, flush],
                ..d()
            }),
            Some("hip_y_m")
        );
        assert_eq!(
            named(HexapodParams {
                hip_y_m: [flush; 3],
                ..d()
            }),
            None
        );
        // The body's box is 2.5 cm tall: its centre of mass may sit 1.25 cm below its centre.
        let body_com_m = [0.0, 0.0, -0.0125];
        assert_eq!(named(HexapodParams { body_com_m, ..d() }), None);
        let body_com_m = [0.0, 0.0, -0.013];
        assert_eq!(
            named(HexapodParams { body_com_m, ..d() }),
            Some("body_com_m")
        );
        assert!(HexapodParams::default().validate().is_ok());
        assert!(HexapodParams::reversed().validate().is_ok());
    }
}
