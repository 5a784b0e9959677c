//! CPIC surface sampling: what the sand solver needs to know about a rigid collider's surface
//! at a grid node near it (compatible particle-in-cell; Hu et al. 2018, "A moving least squares
//! material point method with displacement discontinuity and two-way rigid body coupling").
//!
//! For a point within a narrow band of the surface, [`CpicSurface::sample`] gives the distance
//! to the surface, the unit normal at the closest point, the *side* of the surface the point is
//! on, and whether the point has *affinity* with the surface. Closed solids (ball, box, the
//! ground half-space) are [`CpicSurface::Solid`]s: their sides are outside and inside. Thin
//! parts (a plate, a 3 mm C-leg) are [`CpicSurface::Sheet`]s: open triangle meshes with no
//! thickness (the part's mid-surface), so that the two faces of a plate are the two sides.
//!
//! The side of a sheet is the sign of the offset from the closest point along the normal there.
//! Where the closest point lies on an edge or a vertex the face normals disagree; the
//! pseudo-normal there gives the right side (Bærentzen and Aanæs 2005, "Signed distance
//! computation using the angle weighted pseudonormal"): the sum of the two faces' unit normals
//! on an edge, the sum of the incident faces' unit normals weighted by their angles at a vertex.

use std::cmp::Ordering;
use std::collections::BTreeMap;

use rapier3d::glamx::Vec3;
use rapier3d::parry::query::PointQueryWithLocation;
use rapier3d::parry::shape::{Shape, TriMesh, TrianglePointLocation};
use rapier3d::prelude::{Pose, SharedShape};

/// A point whose offset from a free edge (or free vertex) leans outwards, away from the sheet,
/// by at most this much still projects orthogonally onto the sheet (m): it absorbs the f32
/// rounding of world coordinates up to about 10 m, so that grid nodes exactly above a plate's
/// edge keep their affinity.
pub const FREE_EDGE_TOLERANCE_M: f32 = 1e-6;

/// Below this distance from a solid's surface (m), the normal comes from the surface feature
/// rather than from the offset to the closest point, whose direction is then mostly rounding.
const OFFSET_NORMAL_MIN_DISTANCE_M: f32 = 1e-5;

/// Step of the central differences that give a solid's normal when the shape has no feature
/// normals and the point is (nearly) on its surface (m).
const GRADIENT_STEP_M: f32 = 1e-5;

/// Smallest admissible ratio of a triangle's doubled area to its longest edge squared (sqrt(3)/2
/// for an equilateral triangle): below it the triangle's normal would be rounding noise.
const MIN_TRIANGLE_AREA_RATIO: f32 = 1e-5;

/// Smallest admissible length of a pseudo-normal relative to the sum of its weights (1 where the
/// sheet is flat, 0 where it folds back onto itself).
const MIN_PSEUDO_NORMAL_COHERENCE: f32 = 1e-3;

/// Vertex pairs of a triangle's edges, in the order of parry's
/// [`TrianglePointLocation::OnEdge`]: AB, BC, AC.
const TRIANGLE_EDGES: [[usize; 2]; 3] = [[0, 1], [1, 2], [0, 2]];

/// How CPIC sees a collider's surface, in the collider's local frame.
#[derive(Clone, Debug)]
pub enum CpicSurface {
    /// A closed solid: the positive side is outside; affinity everywhere within the band. The
    /// shape's point projection must report insideness (convex primitives, the half-space,
    /// compounds of those; a [`TriMesh`] only with its `ORIENTED` flag).
    Solid(SharedShape),
    /// An open mid-surface: the positive side is the side of the closest point's
    /// (pseudo-)normal; affinity only where the point projects orthogonally onto the sheet, not
    /// beyond one of its free edges.
    Sheet(Box<Sheet>),
}

/// What a collider's surface looks like from one point near it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceSample {
    /// Unsigned distance from the point to the surface (m).
    pub distance_m: f32,
    /// Distance signed by side: positive on the positive side (outside for solids) (m).
    pub signed_distance_m: f32,
    /// Unit normal at the closest point, world frame, pointing to the positive side: the face
    /// normal, or the pseudo-normal on a sheet's edge or vertex.
    pub normal: [f32; 3],
    /// Side bit: true on the positive side (outside for solids). A point exactly on the surface
    /// is on the positive side. Beside a sheet's free edge, in the sheet's plane, the side is
    /// a tie broken by rounding; such points have no affinity.
    pub positive_side: bool,
    /// Affinity bit: the point is within the band and, for a sheet, its closest point lies on
    /// the sheet proper (the point is over the sheet, not beyond a free edge).
    pub affinity: bool,
}

/// A sample in the collider's frame, before the band test's result is dressed for the caller.
struct LocalSample {
    /// Unsigned distance (m).
    distance_m: f32,
    /// Side bit.
    positive_side: bool,
    /// Unit normal to the positive side, local frame.
    normal: Vec3,
    /// Affinity bit.
    affinity: bool,
}

impl CpicSurface {
    /// Mid-plane rectangle of a box with these half extents (m), across its thinnest axis (the
    /// first one on ties), as a two-triangle sheet whose positive side is that axis' +direction.
    ///
    /// # Panics
    /// When a half extent is negative or not finite, or the two larger ones are not positive.
    pub fn thin_box(half_extents: [f32; 3]) -> Self {
        assert!(
            half_extents.iter().all(|h| h.is_finite() && *h >= 0.0),
            "thin_box: half extents {half_extents:?} must be finite and non-negative"
        );
        let mut thin = 0;
        for axis in 1..3 {
            if half_extents[axis] < half_extents[thin] {
                thin = axis;
            }
        }
        // e_i x e_j = e_thin, so the counter-clockwise rectangle in (i, j) faces +e_thin.
        let (i, j) = ((thin + 1) % 3, (thin + 2) % 3);
        let corner = |si: f32, sj: f32| {
            let mut v = [0.0; 3];
            v[i] = si * half_extents[i];
            v[j] = sj * half_extents[j];
            v
        };
        let vertices = vec![
            corner(-1.0, -1.0),
            corner(1.0, -1.0),
            corner(1.0, 1.0),
            corner(-1.0, 1.0),
        ];
        match Sheet::new(vertices, vec![[0, 1, 2], [0, 2, 3]]) {
            Ok(sheet) => Self::Sheet(Box::new(sheet)),
            Err(e) => panic!("thin_box({half_extents:?}): {e}"),
        }
    }

    /// A sheet from vertices (local frame, m) and triangles whose winding is consistent: the
    /// positive side is the side the right-hand-rule normal points to. Errors on an empty or
    /// degenerate mesh, an index out of range, an edge shared by more than two triangles, or
    /// two neighbours wound in opposite senses; see [`Sheet::new`].
    pub fn sheet(vertices: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Result<Self, SurfaceError> {
        Sheet::new(vertices, triangles).map(|sheet| Self::Sheet(Box::new(sheet)))
    }

    /// The sample at world point `point` (m) for the collider at `pose`, or None when the point
    /// is farther than `band_m` (m) from the surface (or is not finite).
    pub fn sample(&self, pose: &Pose, point: [f32; 3], band_m: f32) -> Option<SurfaceSample> {
        let local = pose.inverse_transform_point(Vec3::from(point));
        let s = match self {
            Self::Solid(shape) => sample_solid(&**shape, local, band_m),
            Self::Sheet(sheet) => sheet.sample_local(local, band_m),
        }?;
        Some(SurfaceSample {
            distance_m: s.distance_m,
            signed_distance_m: if s.positive_side {
                s.distance_m
            } else {
                -s.distance_m
            },
            normal: pose.transform_vector(s.normal).to_array(),
            positive_side: s.positive_side,
            affinity: s.affinity,
        })
    }

    /// Local-frame axis-aligned bounding box (min, max) of the surface (m), for finding the grid
    /// nodes near it. Unbounded solids (the half-space) give huge boxes: clip them to the grid.
    pub fn local_aabb(&self) -> ([f32; 3], [f32; 3]) {
        match self {
            Self::Solid(shape) => {
                let aabb = shape.compute_local_aabb();
                (aabb.mins.to_array(), aabb.maxs.to_array())
            }
            Self::Sheet(sheet) => sheet.aabb,
        }
    }
}

/// `value <= limit`; false when either is NaN.
fn at_most(value: f32, limit: f32) -> bool {
    matches!(
        value.partial_cmp(&limit),
        Some(Ordering::Less | Ordering::Equal)
    )
}

/// Samples a closed solid at a local point.
fn sample_solid(shape: &dyn Shape, local: Vec3, band_m: f32) -> Option<LocalSample> {
    if let Some(halfspace) = shape.as_halfspace() {
        // Exact, and no closest-point rounding: the ground is the commonest collider.
        let height = halfspace.normal.dot(local);
        let distance_m = height.abs();
        return (distance_m <= band_m).then_some(LocalSample {
            distance_m,
            positive_side: height >= 0.0,
            normal: halfspace.normal,
            affinity: true,
        });
    }
    let (proj, feature) = shape.project_local_point_and_get_feature(local);
    let offset = local - proj.point;
    let distance_m = offset.length();
    if !at_most(distance_m, band_m) {
        return None;
    }
    let positive_side = !proj.is_inside || distance_m == 0.0;
    let normal = if distance_m >= OFFSET_NORMAL_MIN_DISTANCE_M {
        if proj.is_inside {
            -offset / distance_m
        } else {
            offset / distance_m
        }
    } else {
        shape
            .feature_normal_at_point(proj.subshape, feature, proj.point)
            .and_then(Vec3::try_normalize)
            .unwrap_or_else(|| signed_distance_gradient(shape, local))
    };
    Some(LocalSample {
        distance_m,
        positive_side,
        normal,
        affinity: true,
    })
}

/// Outward unit normal of a solid at a local point from central differences of its signed
/// distance; zero only if the shape's distance is flat there.
fn signed_distance_gradient(shape: &dyn Shape, local: Vec3) -> Vec3 {
    let signed = |p: Vec3| {
        let proj = shape.project_local_point(p, false);
        let d = (p - proj.point).length();
        if proj.is_inside {
            -d
        } else {
            d
        }
    };
    let diff = |axis: Vec3| {
        signed(local + GRADIENT_STEP_M * axis) - signed(local - GRADIENT_STEP_M * axis)
    };
    Vec3::new(diff(Vec3::X), diff(Vec3::Y), diff(Vec3::Z)).normalize_or_zero()
}

/// An open, consistently wound triangle mesh (local frame, m) with precomputed pseudo-normals
/// and free edges, for [`CpicSurface::Sheet`].
#[derive(Clone, Debug)]
pub struct Sheet {
    /// The triangles, with parry's bounding-volume hierarchy for the closest-point search.
    mesh: TriMesh,
    /// Unit normal of each triangle.
    face_normals: Vec<Vec3>,
    /// Unit pseudo-normal of each triangle's edges, in [`TRIANGLE_EDGES`] order.
    edge_normals: Vec<[Vec3; 3]>,
    /// For each triangle's free edges (bordering no other triangle), the unit direction in the
    /// triangle's plane pointing away from it; None for shared edges. [`TRIANGLE_EDGES`] order.
    free_edge_outwards: Vec<[Option<Vec3>; 3]>,
    /// Unit angle-weighted pseudo-normal of each vertex (zero for unused vertices).
    vertex_normals: Vec<Vec3>,
    /// The outward directions of the free edges at each vertex; empty inside the sheet.
    vertex_free_outwards: Vec<Vec<Vec3>>,
    /// Bounding box (min, max) of the triangles (m).
    aabb: ([f32; 3], [f32; 3]),
}

/// Why a body's colliders do not make a sand surface: the vertices and triangles do not make a
/// sheet, the thin boxes no chain, or the body is missing.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum SurfaceError {
    #[error("a sheet needs at least one triangle")]
    NoTriangles,
    #[error("vertex {vertex} is not finite: {position:?}")]
    NonFiniteVertex { vertex: usize, position: [f32; 3] },
    #[error("triangle {triangle} refers to vertex {vertex}, but there are {vertices}")]
    NoSuchVertex {
        triangle: usize,
        vertex: u32,
        vertices: usize,
    },
    #[error("triangle {triangle} {vertices:?} is degenerate")]
    Degenerate { triangle: usize, vertices: [u32; 3] },
    #[error("triangles {} and {} are wound in opposite senses along their shared edge {edge:?}", triangles[0], triangles[1])]
    OppositeWinding {
        triangles: [usize; 2],
        edge: [u32; 2],
    },
    #[error("the sheet folds back onto itself at edge {edge:?}")]
    FoldsAtEdge { edge: [u32; 2] },
    #[error("the sheet folds back onto itself at vertex {vertex}")]
    FoldsAtVertex { vertex: usize },
    #[error("edge {edge:?} borders {triangles} triangles; a sheet's edges border one or two")]
    EdgeBordersMany { edge: [u32; 2], triangles: usize },
    /// parry's message (its builder error is not `Clone`).
    #[error("{0}")]
    Mesh(String),
    #[error("no boxes")]
    NoBoxes,
    #[error("body not in the world")]
    MissingBody,
    #[error("thin boxes do not form a chain: a box ends at {end_m:?} m, the next starts at {start_m:?} m")]
    NotAChain { end_m: [f32; 3], start_m: [f32; 3] },
}

impl Sheet {
    /// Builds a sheet from vertices (m) and triangles wound consistently (the positive side is
    /// the side of the right-hand-rule normal). Unused vertices are allowed. Errors on no
    /// triangles, a non-finite vertex, an index out of range, a triangle with collinear
    /// vertices, an edge bordering more than two triangles, two neighbours wound in opposite
    /// senses, or a sheet folding back onto itself (a pseudo-normal of nearly zero length).
    pub fn new(vertices: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Result<Self, SurfaceError> {
        if triangles.is_empty() {
            return Err(SurfaceError::NoTriangles);
        }
        if let Some(i) = vertices
            .iter()
            .position(|v| !v.iter().all(|x| x.is_finite()))
        {
            return Err(SurfaceError::NonFiniteVertex {
                vertex: i,
                position: vertices[i],
            });
        }
        let points: Vec<Vec3> = vertices.iter().map(|&v| Vec3::from(v)).collect();

        let mut face_normals = Vec::with_capacity(triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(i) = tri.iter().find(|&&i| i as usize >= points.len()) {
                return Err(SurfaceError::NoSuchVertex {
                    triangle: t,
                    vertex: *i,
                    vertices: points.len(),
                });
            }
            let [a, b, c] = tri.map(|i| points[i as usize]);
            let doubled_area = (b - a).cross(c - a);
            let longest_sq = (b - a)
                .length_squared()
                .max((c - a).length_squared())
                .max((c - b).length_squared());
            if at_most(doubled_area.length(), MIN_TRIANGLE_AREA_RATIO * longest_sq) {
                return Err(SurfaceError::Degenerate {
                    triangle: t,
                    vertices: *tri,
                });
            }
            face_normals.push(doubled_area.normalize());
        }

        // Each undirected edge, with the triangles (and their local edge numbers) it borders.
        let mut edges: BTreeMap<(u32, u32), Vec<(usize, usize)>> = BTreeMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            for (e, [i, j]) in TRIANGLE_EDGES.iter().enumerate() {
                let (a, b) = (tri[*i], tri[*j]);
                edges.entry((a.min(b), a.max(b))).or_default().push((t, e));
            }
        }
        // The sense in which a triangle's winding runs along its edge e: A->B, B->C, C->A.
        let directed = |t: usize, e: usize| {
            let [i, j] = TRIANGLE_EDGES[e];
            let (a, b) = (triangles[t][i], triangles[t][j]);
            if e == 2 {
                (b, a)
            } else {
                (a, b)
            }
        };
        let mut edge_normals = vec![[Vec3::ZERO; 3]; triangles.len()];
        let mut free_edge_outwards = vec![[None; 3]; triangles.len()];
        let mut vertex_free_outwards = vec![Vec::new(); points.len()];
        for ((a, b), sides) in &edges {
            match sides[..] {
                [(t, e)] => {
                    let n = face_normals[t];
                    let [i, j] = TRIANGLE_EDGES[e];
                    let tri = triangles[t];
                    let (p, q, opposite) = (
                        points[tri[i] as usize],
                        points[tri[j] as usize],
                        points[tri[3 - i - j] as usize],
                    );
                    let mut outward = (q - p).cross(n).normalize();
                    if outward.dot(opposite - p) > 0.0 {
                        outward = -outward;
                    }
                    edge_normals[t][e] = n;
                    free_edge_outwards[t][e] = Some(outward);
                    vertex_free_outwards[*a as usize].push(outward);
                    vertex_free_outwards[*b as usize].push(outward);
                }
                [(t1, e1), (t2, e2)] => {
                    let (d1, d2) = (directed(t1, e1), directed(t2, e2));
                    if d1 != (d2.1, d2.0) {
                        return Err(SurfaceError::OppositeWinding {
                            triangles: [t1, t2],
                            edge: [*a, *b],
                        });
                    }
                    let sum = face_normals[t1] + face_normals[t2];
                    if at_most(sum.length(), 2.0 * MIN_PSEUDO_NORMAL_COHERENCE) {
                        return Err(SurfaceError::FoldsAtEdge { edge: [*a, *b] });
                    }
                    edge_normals[t1][e1] = sum.normalize();
                    edge_normals[t2][e2] = sum.normalize();
                }
                _ => {
                    return Err(SurfaceError::EdgeBordersMany {
                        edge: [*a, *b],
                        triangles: sides.len(),
                    })
                }
            }
        }

        let mut vertex_normals = vec![Vec3::ZERO; points.len()];
        let mut vertex_angles = vec![0.0f32; points.len()];
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let p = points[tri[k] as usize];
                let u = points[tri[(k + 1) % 3] as usize] - p;
                let v = points[tri[(k + 2) % 3] as usize] - p;
                let angle = libm::atan2f(u.cross(v).length(), u.dot(v));
                vertex_normals[tri[k] as usize] += angle * face_normals[t];
                vertex_angles[tri[k] as usize] += angle;
            }
        }
        for (i, (n, angle)) in vertex_normals.iter_mut().zip(&vertex_angles).enumerate() {
            if *angle == 0.0 {
                continue; // unused vertex
            }
            if at_most(n.length(), MIN_PSEUDO_NORMAL_COHERENCE * angle) {
                return Err(SurfaceError::FoldsAtVertex { vertex: i });
            }
            *n = n.normalize();
        }

        let used = triangles.iter().flatten().map(|&i| points[i as usize]);
        let (min, max) = used.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        });
        let mesh =
            TriMesh::new(points, triangles).map_err(|e| SurfaceError::Mesh(e.to_string()))?;
        Ok(Self {
            mesh,
            face_normals,
            edge_normals,
            free_edge_outwards,
            vertex_normals,
            vertex_free_outwards,
            aabb: (min.to_array(), max.to_array()),
        })
    }

    /// The triangle mesh (local frame, m).
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// Samples the sheet at a local point.
    fn sample_local(&self, local: Vec3, band_m: f32) -> Option<LocalSample> {
        let (proj, (t, location)) = self
            .mesh
            .project_local_point_and_get_location_with_max_dist(local, false, band_m)?;
        let offset = local - proj.point;
        let distance_m = offset.length();
        if !at_most(distance_m, band_m) {
            return None;
        }
        let t = t as usize;
        let (normal, free_outwards): (Vec3, &[Vec3]) = match location {
            TrianglePointLocation::OnFace(..) | TrianglePointLocation::OnSolid => {
                (self.face_normals[t], &[])
            }
            TrianglePointLocation::OnEdge(e, _) => (
                self.edge_normals[t][e as usize],
                self.free_edge_outwards[t][e as usize].as_slice(),
            ),
            TrianglePointLocation::OnVertex(k) => {
                let v = self.mesh.indices()[t][k as usize] as usize;
                (self.vertex_normals[v], &self.vertex_free_outwards[v])
            }
        };
        Some(LocalSample {
            distance_m,
            positive_side: offset.dot(normal) >= 0.0,
            normal,
            affinity: free_outwards
                .iter()
                .all(|m| offset.dot(*m) <= FREE_EDGE_TOLERANCE_M),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::geometry::LegParams;
    use rapier3d::glamx::Quat;

    /// Grid spacing of the tests' imagined sand grid (m).
    const DX_M: f32 = 0.005;
    /// CPIC band: 1.5 grid spacings (m).
    const BAND_M: f32 = 1.5 * DX_M;
    /// Distance tolerance (m).
    const TOL_M: f32 = 1e-6;

    fn at(surface: &CpicSurface, p: [f32; 3]) -> SurfaceSample {
        surface
            .sample(&Pose::IDENTITY, p, BAND_M)
            .unwrap_or_else(|| panic!("{p:?} should be within the band"))
    }

    fn assert_near(got: f32, want: f32, what: &str) {
        assert!((got - want).abs() < TOL_M, "{what}: {got} vs {want}");
    }

    fn assert_normal(got: [f32; 3], want: Vec3, what: &str) {
        let err = (Vec3::from(got) - want.normalize()).length();
        assert!(err < 1e-5, "{what}: normal {got:?} vs {want:?}");
    }

    /// A 4 cm x 2 cm plate, 1 mm (0.2 grid spacings) thick.
    const PLATE_HALF_EXTENTS_M: [f32; 3] = [0.02, 0.01, 0.0005];

    #[test]
    fn thin_box_sheet_splits_the_plate_faces_and_ends_at_its_edges() {
        let plate = CpicSurface::thin_box(PLATE_HALF_EXTENTS_M);
        let [hx, hy, _] = PLATE_HALF_EXTENTS_M;
        assert_eq!(plate.local_aabb(), ([-hx, -hy, 0.0], [hx, hy, 0.0]));
        // (point, distance, positive side): just above and below the mid-plane, 0.05 mm away,
        // farther out, and over the interior diagonal shared by the two triangles.
        for (p, d, positive) in [
            ([0.005, -0.003, 5e-5], 5e-5, true),
            ([0.005, -0.003, -5e-5], 5e-5, false),
            ([-0.013, 0.008, 0.004], 0.004, true),
            ([-0.013, 0.008, -0.004], 0.004, false),
            ([0.0, 0.0, 0.001], 0.001, true),
            ([0.0, 0.0, -0.001], 0.001, false),
            // Exactly over a free edge and a corner: still over the sheet.
            ([hx, 0.003, 0.002], 0.002, true),
            ([-hx, -hy, -0.002], 0.002, false),
        ] {
            let s = at(&plate, p);
            assert_near(s.distance_m, d, &format!("{p:?} distance"));
            assert_near(s.signed_distance_m, if positive { d } else { -d }, "signed");
            assert_eq!(s.positive_side, positive, "{p:?}");
            assert!(s.affinity, "{p:?} is over the plate");
            assert_normal(s.normal, Vec3::Z, &format!("{p:?}"));
        }
        // Beside the plate, in its plane extended and just off it: no affinity.
        let beyond = 0.001;
        for (p, d) in [
            ([hx + beyond, 0.0, 0.0], beyond),
            ([0.01, -hy - 2.0 * beyond, 0.0], 2.0 * beyond),
            ([-hx - beyond, hy + beyond, 0.0], beyond * 2f32.sqrt()),
            (
                [hx + beyond, 0.0, 0.002],
                (beyond * beyond + 0.002 * 0.002).sqrt(),
            ),
            (
                [0.0, hy + 1e-4, -5e-5],
                (1e-4f32 * 1e-4 + 5e-5 * 5e-5).sqrt(),
            ),
        ] {
            let s = at(&plate, p);
            assert_near(s.distance_m, d, &format!("{p:?} distance"));
            assert!(!s.affinity, "{p:?} is beyond a free edge");
        }
        // The thinnest axis picks the plane and the positive side: here x.
        let wall = CpicSurface::thin_box([0.0005, 0.02, 0.01]);
        let s = at(&wall, [1e-4, 0.01, -0.005]);
        assert!(s.positive_side && s.affinity);
        assert_near(s.distance_m, 1e-4, "wall distance");
        assert_normal(s.normal, Vec3::X, "wall");
        assert!(!at(&wall, [-1e-4, 0.01, -0.005]).positive_side);
    }

    /// Two 2 cm x 2 cm quads (two triangles each) meeting at the ridge x = 0, z = 0 along y: A
    /// in the plane z = 0 over x < 0 with normal +z, B rising from the ridge at `fold_rad` from
    /// +x about -y. At +-150 degrees B folds back over (or under) A, leaving a 30-degree wedge.
    fn folded_sheet(fold_rad: f32) -> CpicSurface {
        let (l, hy) = (0.02f32, 0.01f32);
        let far = [libm::cosf(fold_rad) * l, libm::sinf(fold_rad) * l];
        let vertices = vec![
            [-l, -hy, 0.0],
            [0.0, -hy, 0.0],
            [0.0, hy, 0.0],
            [-l, hy, 0.0],
            [far[0], -hy, far[1]],
            [far[0], hy, far[1]],
        ];
        // A: the +z-facing rectangle; B continues across the ridge edge (1, 2), wound so that
        // it runs along (2, 1), consistently with A.
        let triangles = vec![[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]];
        CpicSurface::sheet(vertices, triangles).unwrap()
    }

    #[test]
    fn pseudo_normals_keep_the_side_consistent_around_a_ridge() {
        let r = 0.002; // distance of the test points from the ridge (m)
        for sign in [1.0f32, -1.0] {
            let fold = sign * 150f32.to_radians();
            let sheet = folded_sheet(fold);
            let n_a = Vec3::Z;
            let n_b = Vec3::new(-libm::sinf(fold), 0.0, libm::cosf(fold));
            // Sanity: B's normal as built is what the fold implies.
            let on_b = Vec3::new(0.014 * libm::cosf(fold), 0.0, 0.014 * libm::sinf(fold));
            let s = at(&sheet, (on_b + 1e-3 * n_b).to_array());
            assert!(s.positive_side && s.affinity);
            assert_normal(s.normal, n_b, "face B");
            // Points around the ridge at angle phi in the x-z plane (from +x towards +z). For
            // fold +150 degrees the acute wedge between A (180 deg) and B (150 deg) is the
            // positive side; at 20 and 300 degrees the closest point is on the ridge, and the
            // face normal of A (at 20) or of B (at 300) alone would give the wrong side.
            for (phi_deg, on_ridge, positive_for_plus_fold) in [
                (20.0f32, true, false),
                (300.0, true, false),
                (0.0, true, false),
                (90.0, false, false),
                (-80.0, true, false),
                (170.0, false, true),
                (160.0, false, true),
            ] {
                let phi = sign * phi_deg.to_radians();
                let p = [r * libm::cosf(phi), 0.003, r * libm::sinf(phi)];
                let s = at(&sheet, p);
                let want = positive_for_plus_fold == (sign > 0.0);
                assert_eq!(s.positive_side, want, "fold {sign:+} phi {phi_deg}");
                assert_eq!(s.signed_distance_m > 0.0, want);
                assert!(
                    s.affinity,
                    "fold {sign:+} phi {phi_deg}: the ridge is not a free edge"
                );
                if on_ridge {
                    assert_near(s.distance_m, r, "ridge distance");
                    assert_normal(s.normal, n_a + n_b, "ridge pseudo-normal");
                }
            }
        }
    }

    #[test]
    fn solid_ball_and_ground_have_inside_and_outside() {
        let radius = 0.01;
        let ball = CpicSurface::Solid(SharedShape::ball(radius));
        let dir = Vec3::new(1.0, 2.0, -2.0) / 3.0;
        for (rho, positive) in [(0.012, true), (0.0085, false), (radius + 4e-6, true)] {
            let s = at(&ball, (rho * dir).to_array());
            assert_eq!(s.positive_side, positive, "rho {rho}");
            assert!(s.affinity);
            assert_near(s.signed_distance_m, rho - radius, "ball signed distance");
            assert_near(s.distance_m, (rho - radius).abs(), "ball distance");
            assert_normal(s.normal, dir, "ball");
        }
        assert!(
            ball.sample(&Pose::IDENTITY, [0.0; 3], BAND_M).is_none(),
            "centre"
        );
        let (min, max) = ball.local_aabb();
        assert_eq!((min, max), ([-radius; 3], [radius; 3]));

        let ground = CpicSurface::Solid(SharedShape::halfspace(Vec3::Z));
        for (z, positive) in [(0.004, true), (-0.002, false), (0.0, true), (-5e-5, false)] {
            let s = at(&ground, [0.3, -0.2, z]);
            assert_eq!(s.positive_side, positive, "z {z}");
            assert!(s.affinity);
            assert_near(s.signed_distance_m, z, "ground signed distance");
            assert_normal(s.normal, Vec3::Z, "ground");
        }
        assert!(ground
            .sample(&Pose::IDENTITY, [0.0, 0.0, BAND_M + 1e-4], BAND_M)
            .is_none());
        assert!(ground
            .sample(&Pose::IDENTITY, [0.0, 0.0, -BAND_M - 1e-4], BAND_M)
            .is_none());

        // A box: inside near a face, and the normal on the surface itself.
        let cube = CpicSurface::Solid(SharedShape::cuboid(0.01, 0.02, 0.03));
        let s = at(&cube, [0.002, 0.019, 0.0]);
        assert!(!s.positive_side);
        assert_near(s.signed_distance_m, -0.001, "box");
        assert_normal(s.normal, Vec3::Y, "box inside");
        let s = at(&cube, [0.01, 0.005, 0.007]);
        assert!(s.positive_side && s.distance_m == 0.0);
        assert_normal(s.normal, Vec3::X, "box surface");
        // A cylinder has no feature normals: on its surface the normal comes from differences.
        let can = CpicSurface::Solid(SharedShape::cylinder(0.02, 0.01));
        let s = at(&can, [0.0, 0.005, 0.01]);
        assert!(s.distance_m < TOL_M);
        assert_normal(s.normal, Vec3::Z, "cylinder surface");
    }

    #[test]
    fn points_beyond_the_band_have_no_sample() {
        let plate = CpicSurface::thin_box(PLATE_HALF_EXTENTS_M);
        let id = Pose::IDENTITY;
        assert!(plate.sample(&id, [0.005, 0.0, 0.008], 0.0075).is_none());
        assert!(plate.sample(&id, [0.005, 0.0, -0.008], 0.0075).is_none());
        assert!(plate.sample(&id, [0.005, 0.0, 0.008], 0.0085).is_some());
        assert!(plate.sample(&id, [0.03, 0.0, 0.0], 0.0075).is_none());
        assert!(plate.sample(&id, [0.03, 0.0, 0.0], 0.0105).is_some());
        assert!(plate.sample(&id, [f32::NAN, 0.0, 0.0], 1.0).is_none());
        let ball = CpicSurface::Solid(SharedShape::ball(0.01));
        assert!(ball.sample(&id, [0.0, 0.0, 0.02], 0.0075).is_none());
        assert!(ball.sample(&id, [0.0, 0.0, 0.001], 0.0075).is_none());
    }

    #[test]
    fn a_posed_collider_samples_like_its_local_frame() {
        let pose = Pose::from_parts(
            Vec3::new(0.3, -0.1, 0.2),
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
        );
        let surfaces = [
            CpicSurface::thin_box(PLATE_HALF_EXTENTS_M),
            folded_sheet(150f32.to_radians()),
            CpicSurface::Solid(SharedShape::ball(0.01)),
            CpicSurface::Solid(SharedShape::cuboid(0.01, 0.02, 0.005)),
            CpicSurface::Solid(SharedShape::halfspace(Vec3::Z)),
        ];
        // A lattice of local points at spacings that avoid the surfaces' symmetry planes.
        let axis = |i: i32| -0.0231 + 0.0037 * i as f32;
        let mut compared = 0;
        for surface in &surfaces {
            for (i, j, k) in
                (0..13).flat_map(|i| (0..7).flat_map(move |j| (0..13).map(move |k| (i, j, k))))
            {
                let local = Vec3::new(axis(i), axis(j + 3), axis(k));
                let world = pose.transform_point(local);
                let want = surface.sample(&Pose::IDENTITY, local.to_array(), BAND_M);
                let got = surface.sample(&pose, world.to_array(), BAND_M);
                let (Some(want), Some(got)) = (want, got) else {
                    let d = want.or(got).map_or(BAND_M, |s| s.distance_m);
                    assert!(want.is_none() && got.is_none() || (d - BAND_M).abs() < 1e-5);
                    continue;
                };
                compared += 1;
                assert_near(got.distance_m, want.distance_m, "posed distance");
                assert_near(
                    got.signed_distance_m,
                    want.signed_distance_m,
                    "posed signed",
                );
                if want.distance_m > 1e-5 {
                    assert_eq!(got.positive_side, want.positive_side, "{local:?}");
                    assert_eq!(got.affinity, want.affinity, "{local:?}");
                }
                let rotated = pose.transform_vector(Vec3::from(want.normal));
                assert_normal(got.normal, rotated, "posed normal");
            }
        }
        assert!(compared > 500, "{compared} points within the band");
    }

    #[test]
    fn leg_mid_surface_faces_its_convex_side() {
        let leg = LegParams::default(); // the published C-leg
        let (vertices, triangles) = leg.mid_surface(32);
        let sheet = CpicSurface::sheet(vertices, triangles).unwrap();
        let r = leg.half_chord_m() as f32;
        let gap = 0.001;
        // Around the arc's middle (at (-R, 0, -R)), 1 mm outside and inside the circle.
        let dir = Vec3::new(-1.0, 0.0, -0.3).normalize();
        let centre = Vec3::new(0.0, 0.0, -r);
        let outside = at(&sheet, (centre + (r + gap) * dir).to_array());
        let inside = at(&sheet, (centre + (r - gap) * dir).to_array());
        assert!(outside.positive_side && outside.affinity);
        assert!(!inside.positive_side && inside.affinity);
        // The polygon's chord sags inside the circle by at most R (1 - cos(pi / 64)).
        let sag = r * (1.0 - (std::f32::consts::PI / 64.0).cos());
        assert!((outside.distance_m - gap).abs() <= sag + TOL_M);
        // The normal is the nearest piece's, within half a piece (pi / 64) of the radial one.
        let cos = Vec3::from(outside.normal).dot(dir);
        assert!(
            cos > (std::f32::consts::PI / 64.0).cos() - TOL_M,
            "cos {cos}"
        );
        let beside = centre + r * dir + Vec3::new(0.0, 0.5 * leg.width_m as f32 + gap, 0.0);
        assert!(!at(&sheet, beside.to_array()).affinity);
    }

    #[test]
    fn bad_sheets_are_rejected() {
        let square = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        assert!(CpicSurface::sheet(square.clone(), vec![]).is_err());
        assert!(CpicSurface::sheet(square.clone(), vec![[0, 1, 4]]).is_err());
        assert!(CpicSurface::sheet(square.clone(), vec![[0, 1, 1]]).is_err());
        let line = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert!(CpicSurface::sheet(line, vec![[0, 1, 2]]).is_err());
        // The second triangle is wound the other way round.
        assert!(CpicSurface::sheet(square.clone(), vec![[0, 1, 2], [0, 3, 2]]).is_err());
        assert!(CpicSurface::sheet(square, vec![[0, 1, 2], [0, 2, 3]]).is_ok());
    }
}
