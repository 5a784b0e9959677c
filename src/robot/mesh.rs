//! Closed triangle meshes: binary STL output, STL input (binary or ASCII), and exact
//! mass properties of the enclosed solid (divergence theorem over signed tetrahedra).

use std::path::Path;

/// Why bytes are not a usable STL mesh.
#[derive(thiserror::Error, Debug)]
pub enum StlError {
    #[error(
        "not an STL file ({bytes} bytes, neither a binary STL nor text starting with 'solid')"
    )]
    NotStl { bytes: usize },
    #[error("ASCII STL is not UTF-8: {0}")]
    NotUtf8(#[from] std::str::Utf8Error),
    #[error("line {line}: malformed vertex")]
    MalformedVertex { line: usize },
    #[error("{vertices} vertices is not a whole number of triangles")]
    PartialTriangle { vertices: usize },
    #[error("STL file has no triangles")]
    NoTriangles,
    #[error("STL file has non-finite coordinates")]
    NonFinite,
}

/// A triangle mesh, in metres. Triangles wind counter-clockwise seen from outside.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions (m).
    pub vertices: Vec<[f64; 3]>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
}

/// Mass, centre of mass and inertia tensor of a rigid solid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass in the body frame (m).
    pub com_m: [f64; 3],
    /// Inertia tensor about the centre of mass, body axes (kg m^2).
    pub inertia_kg_m2: [[f64; 3]; 3],
}

/// Bytes of a binary STL header.
const STL_HEADER_BYTES: usize = 80;
/// Bytes per triangle record of a binary STL (normal, 3 vertices, attribute word).
const STL_TRIANGLE_BYTES: usize = 50;

impl TriMesh {
    /// Enclosed volume (m^3); positive when the triangles face outward.
    pub fn volume_m3(&self) -> f64 {
        self.tetrahedra().map(|(v, _, _, _)| v).sum()
    }

    /// Mass properties of the solid the mesh encloses, at uniform `density_kg_m3`.
    pub fn mass_properties(&self, density_kg_m3: f64) -> MassProperties {
        let mut volume = 0.0;
        let mut first = [0.0; 3];
        let mut second = [[0.0; 3]; 3];
        for (v, a, b, c) in self.tetrahedra() {
            // Tetrahedron (0, a, b, c): integral of x = V (a + b + c) / 4 and integral of
            // x x^T = V/20 (a a^T + b b^T + c c^T + s s^T) with s = a + b + c.
            let s = [a[0] + b[0] + c[0], a[1] + b[1] + c[1], a[2] + b[2] + c[2]];
            volume += v;
            for i in 0..3 {
                first[i] += v * s[i] / 4.0;
                for j in 0..3 {
                    second[i][j] +=
                        v / 20.0 * (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + s[i] * s[j]);
                }
            }
        }
        let com = first.map(|f| f / volume);
        let second = second.map(|row| row.map(|x| x * density_kg_m3));
        inertia_from_moments(density_kg_m3 * volume, com, second)
    }

    /// Axis-aligned bounds `(min, max)` of the vertices (m).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.vertices {
            for i in 0..3 {
                lo[i] = lo[i].min(v[i]);
                hi[i] = hi[i].max(v[i]);
            }
        }
        (lo, hi)
    }

    /// Signed volume and corners of the tetrahedron each triangle forms with the origin.
    fn tetrahedra(&self) -> impl Iterator<Item = (f64, [f64; 3], [f64; 3], [f64; 3])> + '_ {
        self.triangles.iter().map(|t| {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            (dot(a, cross(b, c)) / 6.0, a, b, c)
        })
    }

    /// The mesh as a binary STL (f32 coordinates).
    pub fn to_binary_stl(&self, header: &str) -> Vec<u8> {
        let mut out = Vec::with_capacity(84 + STL_TRIANGLE_BYTES * self.triangles.len());
        let mut head = [b' '; STL_HEADER_BYTES];
        // A binary STL must not start with "solid", or readers take it for ASCII.
        for (dst, src) in head.iter_mut().zip(header.bytes().filter(|b| b.is_ascii())) {
            *dst = src;
        }
        out.extend_from_slice(&head);
        out.extend_from_slice(&(self.triangles.len() as u32).to_le_bytes());
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            let n = normalized(cross(sub(b, a), sub(c, a)));
            for v in [n, a, b, c] {
                for x in v {
                    out.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            out.extend_from_slice(&0u16.to_le_bytes());
        }
        out
    }

    /// Writes the mesh as a binary STL file (whole or not at all: [`crate::files`]).
    pub fn write_stl(&self, path: &Path, header: &str) -> std::io::Result<()> {
        crate::files::write_atomically(path, &self.to_binary_stl(header))
    }

    /// Parses an STL file's bytes, binary or ASCII. Vertices are not merged.
    pub fn from_stl_bytes(bytes: &[u8]) -> Result<Self, StlError> {
        let mesh = if is_binary_stl(bytes) {
            parse_binary_stl(bytes)
        } else if bytes.trim_ascii_start().starts_with(b"solid") {
            parse_ascii_stl(bytes)?
        } else {
            return Err(StlError::NotStl { bytes: bytes.len() });
        };
        if mesh.triangles.is_empty() {
            return Err(StlError::NoTriangles);
        }
        if mesh.vertices.iter().flatten().any(|x| !x.is_finite()) {
            return Err(StlError::NonFinite);
        }
        Ok(mesh)
    }
}

/// Inertia tensor about the centre of mass from the mass, centre of mass and the second
/// moments `S = integral of rho x x^T dV` about the origin.
pub(crate) fn inertia_from_moments(
    mass_kg: f64,
    com_m: [f64; 3],
    second: [[f64; 3]; 3],
) -> MassProperties {
    let trace = second[0][0] + second[1][1] + second[2][2];
    let c2 = dot(com_m, com_m);
    let mut inertia = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let delta = if i == j { 1.0 } else { 0.0 };
            let about_origin = trace * delta - second[i][j];
            let shift = mass_kg * (c2 * delta - com_m[i] * com_m[j]);
            inertia[i][j] = about_origin - shift;
        }
    }
    MassProperties {
        mass_kg,
        com_m,
        inertia_kg_m2: inertia,
    }
}

fn is_binary_stl(bytes: &[u8]) -> bool {
    if bytes.len() < STL_HEADER_BYTES + 4 {
        return false;
    }
    let count = u32::from_le_bytes(bytes[80..84].try_into().expect("4 bytes")) as usize;
    bytes.len() == STL_HEADER_BYTES + 4 + STL_TRIANGLE_BYTES * count
}

fn parse_binary_stl(bytes: &[u8]) -> TriMesh {
    let mut mesh = TriMesh::default();
    for record in bytes[84..].chunks_exact(STL_TRIANGLE_BYTES) {
        let f = |k: usize| {
            let o = 12 + 4 * k;
            f32::from_le_bytes(record[o..o + 4].try_into().expect("4 bytes")) as f64
        };
        let base = mesh.vertices.len() as u32;
        for v in 0..3 {
            mesh.vertices.push([f(3 * v), f(3 * v + 1), f(3 * v + 2)]);
        }
        mesh.triangles.push([base, base + 1, base + 2]);
    }
    mesh
}

fn parse_ascii_stl(bytes: &[u8]) -> Result<TriMesh, StlError> {
    let text = std::str::from_utf8(bytes)?;
    let mut mesh = TriMesh::default();
    for (line_no, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if words.next() != Some("vertex") {
            continue;
        }
        let mut v = [0.0; 3];
        for x in &mut v {
            *x = words
                .next()
                .and_then(|w| w.parse().ok())
                .ok_or(StlError::MalformedVertex { line: line_no + 1 })?;
        }
        mesh.vertices.push(v);
    }
    if mesh.vertices.len() % 3 != 0 {
        return Err(StlError::PartialTriangle {
            vertices: mesh.vertices.len(),
        });
    }
    let n = mesh.vertices.len() as u32 / 3;
    mesh.triangles = (0..n).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
    Ok(mesh)
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn normalized(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        a.map(|x| x / n)
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned box `[0, a] x [0, b] x [0, c]` with outward triangles.
    fn box_mesh(a: f64, b: f64, c: f64) -> TriMesh {
        let vertices = (0..8)
            .map(|i| {
                let bit = |k: u32| ((i >> k) & 1) as f64;
                [a * bit(0), b * bit(1), c * bit(2)]
            })
            .collect();
        // Faces as quads (outward, counter-clockwise), split into two triangles each.
        let quads = [
            [0, 2, 3, 1], // z = 0
            [4, 5, 7, 6], // z = c
            [0, 1, 5, 4], // y = 0
            [2, 6, 7, 3], // y = b
            [0, 4, 6, 2], // x = 0
            [1, 3, 7, 5], // x = a
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    #[test]
    fn box_mass_properties_match_the_closed_form() {
        let (a, b, c, rho) = (0.3, 0.2, 0.1, 1000.0);
        let p = box_mesh(a, b, c).mass_properties(rho);
        let m = rho * a * b * c;
        assert!((p.mass_kg - m).abs() < 1e-12);
        for (got, want) in p.com_m.iter().zip([a / 2.0, b / 2.0, c / 2.0]) {
            assert!((got - want).abs() < 1e-12);
        }
        let want = [
            m * (b * b + c * c) / 12.0,
            m * (a * a + c * c) / 12.0,
            m * (a * a + b * b) / 12.0,
        ];
        for (i, row) in p.inertia_kg_m2.iter().enumerate() {
            for (j, value) in row.iter().enumerate() {
                let expected = if i == j { want[i] } else { 0.0 };
                assert!((value - expected).abs() < 1e-12, "I[{i}][{j}]");
            }
        }
    }

    #[test]
    fn binary_stl_round_trips() {
        let mesh = box_mesh(0.01, 0.02, 0.03);
        let bytes = mesh.to_binary_stl("test box");
        assert_eq!(bytes.len(), 84 + 50 * 12);
        let back = TriMesh::from_stl_bytes(&bytes).unwrap();
        assert_eq!(back.triangles.len(), 12);
        assert!((back.volume_m3() - 0.01 * 0.02 * 0.03).abs() < 1e-12);
    }

    #[test]
    fn ascii_stl_is_read_and_garbage_is_rejected() {
        let text = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n\
                    vertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
        let mesh = TriMesh::from_stl_bytes(text.as_bytes()).unwrap();
        assert_eq!(mesh.triangles.len(), 1);
        assert!(TriMesh::from_stl_bytes(b"this is not a mesh").is_err());
        assert!(TriMesh::from_stl_bytes(b"solid empty\nendsolid empty\n").is_err());
    }
}
