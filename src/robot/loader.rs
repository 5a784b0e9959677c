//! Reading and checking a URDF before rapier sees it, so bad input fails with a message that
//! names the file and the element rather than a panic deep in the loader.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use rapier3d_urdf::urdf_rs::{self, Geometry, JointType, Robot};

use super::error::RobotError;
use super::geometry::LEGS;
use super::mesh::TriMesh;

/// Tolerance on the leg joints' axis (unit vector components).
const AXIS_TOLERANCE: f64 = 1e-6;

/// A URDF that passed every check of [`load_urdf`].
#[derive(Debug, Clone)]
pub struct CheckedUrdf {
    /// The URDF file.
    pub path: PathBuf,
    /// Its contents.
    pub robot: Robot,
    /// The root link's name (the body).
    pub root_link: String,
}

/// Where the text stops being well-formed XML ("line L, column C" and what is wrong there), or
/// `None` if it is well-formed (then urdf-rs refused its content, not its syntax).
fn xml_error_position(text: &str) -> Option<String> {
    for event in xml::reader::EventReader::from_str(text) {
        if let Err(e) = event {
            let at = xml::common::Position::position(&e);
            // xml-rs counts from 0; editors from 1.
            return Some(format!(
                "line {}, column {} ({})",
                at.row + 1,
                at.column + 1,
                e.msg()
            ));
        }
    }
    None
}

/// Reads `path` and checks that it is a tree of links with positive masses, that every mesh
/// it names exists and reads as STL, that collision shapes are primitives, and that the six
/// leg joints of the tripod gait exist as continuous joints about +y on the root link.
pub fn load_urdf(path: &Path) -> Result<CheckedUrdf, RobotError> {
    let text = std::fs::read_to_string(path).map_err(|e| RobotError::io(path, e))?;
    let robot = urdf_rs::read_from_string(&text).map_err(|e| RobotError::UrdfParse {
        path: path.to_path_buf(),
        message: match xml_error_position(&text) {
            Some(at) => format!("{at}: {e}"),
            None => e.to_string(),
        },
    })?;
    let root_link = check_tree(path, &robot)?;
    check_geometry(path, &robot)?;
    check_gait_joints(path, &robot, &root_link)?;
    Ok(CheckedUrdf {
        path: path.to_path_buf(),
        robot,
        root_link,
    })
}

fn invalid(path: &Path, element: String, message: impl Into<String>) -> RobotError {
    RobotError::UrdfInvalid {
        path: path.to_path_buf(),
        element,
        message: message.into(),
    }
}

/// Unique names, joints between existing links, one parent per link, one root; returns the
/// root link's name.
fn check_tree(path: &Path, robot: &Robot) -> Result<String, RobotError> {
    let mut links = HashSet::new();
    for link in &robot.links {
        if !links.insert(link.name.as_str()) {
            return Err(invalid(
                path,
                format!("link '{}'", link.name),
                "defined twice",
            ));
        }
        let m = link.inertial.mass.value;
        if !(m.is_finite() && m > 0.0) {
            return Err(invalid(
                path,
                format!("link '{}'", link.name),
                format!(
                    "<inertial> mass must be positive (got {m} kg); every link is a dynamic body"
                ),
            ));
        }
    }
    let mut joints = HashSet::new();
    let mut parent_of: HashMap<&str, &str> = HashMap::new();
    for joint in &robot.joints {
        let element = format!("joint '{}'", joint.name);
        if !joints.insert(joint.name.as_str()) {
            return Err(invalid(path, element, "defined twice"));
        }
        for (role, link) in [("parent", &joint.parent.link), ("child", &joint.child.link)] {
            if !links.contains(link.as_str()) {
                return Err(invalid(
                    path,
                    element,
                    format!("{role} link '{link}' does not exist"),
                ));
            }
        }
        if parent_of
            .insert(&joint.child.link, &joint.parent.link)
            .is_some()
        {
            return Err(invalid(
                path,
                element,
                format!("link '{}' already has a parent joint", joint.child.link),
            ));
        }
    }
    let roots: Vec<&str> = robot
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|n| !parent_of.contains_key(n))
        .collect();
    match roots.as_slice() {
        [root] => Ok(root.to_string()),
        [] if robot.links.is_empty() => Err(invalid(
            path,
            "<robot>".into(),
            "has no <link>: a robot needs at least its body",
        )),
        [] => Err(invalid(
            path,
            "<robot>".into(),
            "the joints form a loop: no root link",
        )),
        many => Err(invalid(
            path,
            "<robot>".into(),
            format!(
                "expected one root link, found {}: {}",
                many.len(),
                many.join(", ")
            ),
        )),
    }
}

/// Meshes exist and read as STL; collision shapes are primitives.
fn check_geometry(path: &Path, robot: &Robot) -> Result<(), RobotError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    for link in &robot.links {
        for (i, c) in link.collision.iter().enumerate() {
            if let Geometry::Mesh { filename, .. } = &c.geometry {
                return Err(invalid(
                    path,
                    format!("link '{}' <collision> {i}", link.name),
                    format!(
                        "mesh '{filename}': collision meshes are not supported; use box, cylinder, \
                         capsule or sphere primitives (the generator uses boxes along each leg)"
                    ),
                ));
            }
        }
        for geometry in link.visual.iter().map(|v| &v.geometry) {
            if let Geometry::Mesh { filename, .. } = geometry {
                check_mesh(path, dir, &link.name, filename)?;
            }
        }
    }
    Ok(())
}

fn check_mesh(urdf: &Path, dir: &Path, link: &str, filename: &str) -> Result<(), RobotError> {
    let mesh_err = |message: String| RobotError::MeshInvalid {
        urdf: urdf.to_path_buf(),
        link: link.into(),
        mesh: filename.into(),
        message,
    };
    if filename.starts_with("package://") {
        return Err(mesh_err(
            "package:// URIs are not resolved; use a path relative to the URDF's folder".into(),
        ));
    }
    let resolved = match filename.strip_prefix("file://") {
        Some(abs) => PathBuf::from(abs),
        None => dir.join(filename),
    };
    if !resolved.is_file() {
        return Err(RobotError::MeshNotFound {
            urdf: urdf.to_path_buf(),
            link: link.into(),
            mesh: filename.into(),
            resolved,
        });
    }
    let is_stl = resolved
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("stl"));
    if !is_stl {
        return Err(mesh_err("only STL meshes are supported".into()));
    }
    let bytes = std::fs::read(&resolved).map_err(|e| RobotError::io(&resolved, e))?;
    TriMesh::from_stl_bytes(&bytes)
        .map(|_| ())
        .map_err(|e| mesh_err(e.to_string()))
}

/// The six leg joints exist, are continuous, turn about +y, and hang off the root link.
fn check_gait_joints(path: &Path, robot: &Robot, root: &str) -> Result<(), RobotError> {
    for leg in &LEGS {
        let name = leg.joint_name();
        let Some(joint) = robot.joints.iter().find(|j| j.name == name) else {
            let available: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
            return Err(RobotError::MissingJoint {
                path: path.to_path_buf(),
                joint: name,
                available: if available.is_empty() {
                    "none".into()
                } else {
                    available.join(", ")
                },
            });
        };
        let element = format!("joint '{name}'");
        if joint.joint_type != JointType::Continuous {
            return Err(invalid(
                path,
                element,
                format!(
                    "the gait needs a continuous joint, found type {:?}",
                    joint.joint_type
                ),
            ));
        }
        let axis = *joint.axis.xyz;
        if (axis[0].abs() + (axis[1] - 1.0).abs() + axis[2].abs()) > AXIS_TOLERANCE {
            return Err(invalid(
                path,
                element,
                format!("axis must be 0 1 0 (+y, positive = walking forward), found {axis:?}"),
            ));
        }
        if joint.parent.link != root {
            return Err(invalid(
                path,
                element,
                format!(
                    "parent must be the body (root link '{root}'), found '{}'",
                    joint.parent.link
                ),
            ));
        }
    }
    Ok(())
}
