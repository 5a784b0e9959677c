//! How deep the legs reach below the sand surface: the lowest point of each leg's collision
//! geometry (from the URDF) placed by the leg link's pose.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// A collision primitive in its own frame (URDF conventions: cylinders and capsules along z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// Box with these half extents (m).
    Cuboid { half_extents: Vector3<f64> },
    /// Cylinder along z: radius and half length (m).
    Cylinder { radius: f64, half_length: f64 },
    /// Capsule along z: radius and half length of its straight part (m).
    Capsule { radius: f64, half_length: f64 },
    /// Sphere of this radius (m).
    Sphere { radius: f64 },
}

/// The collision geometry of one movable link.
#[derive(Clone, Debug)]
pub struct LinkGeometry {
    /// Link name (also its tf frame).
    pub link: String,
    /// Each primitive with its pose in the link frame.
    pub shapes: Vec<(Isometry3<f64>, Shape)>,
}

/// The collision geometry of the links moved by non-fixed joints (the legs), in the order of
/// their joints, and notes on what was left out (mesh geometry cannot be measured here).
pub fn moving_link_geometry(
    urdf_text: &str,
) -> Result<(Vec<LinkGeometry>, Vec<String>), urdf_rs::UrdfError> {
    let robot = urdf_rs::read_from_string(urdf_text)?;
    let mut notes = Vec::new();
    let mut links = Vec::new();
    for joint in &robot.joints {
        if matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
            continue;
        }
        let Some(link) = robot.links.iter().find(|l| l.name == joint.child.link) else {
            continue;
        };
        let mut shapes = Vec::new();
        for collision in &link.collision {
            let pose = urdf_pose(&collision.origin);
            let shape = match &collision.geometry {
                urdf_rs::Geometry::Box { size } => Shape::Cuboid {
                    half_extents: Vector3::new(size[0], size[1], size[2]) * 0.5,
                },
                urdf_rs::Geometry::Cylinder { radius, length } => Shape::Cylinder {
                    radius: *radius,
                    half_length: 0.5 * length,
                },
                urdf_rs::Geometry::Capsule { radius, length } => Shape::Capsule {
                    radius: *radius,
                    half_length: 0.5 * length,
                },
                urdf_rs::Geometry::Sphere { radius } => Shape::Sphere { radius: *radius },
                urdf_rs::Geometry::Mesh { filename, .. } => {
                    notes.push(format!(
                        "sinkage: mesh collision {filename} of {} left out",
                        link.name
                    ));
                    continue;
                }
            };
            shapes.push((pose, shape));
        }
        if !shapes.is_empty() {
            links.push(LinkGeometry {
                link: link.name.clone(),
                shapes,
            });
        }
    }
    Ok((links, notes))
}

/// A URDF origin (`xyz`, fixed-axis `rpy`) as an isometry.
fn urdf_pose(origin: &urdf_rs::Pose) -> Isometry3<f64> {
    let (xyz, rpy) = (&origin.xyz, &origin.rpy);
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        // URDF rpy: roll about x, then pitch about y, then yaw about z, all fixed axes,
        // which is nalgebra's Euler convention.
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// The lowest z (m) of a primitive placed at `pose` (exact for each kind).
pub fn lowest_z(pose: &Isometry3<f64>, shape: &Shape) -> f64 {
    let centre_z = pose.translation.z;
    let rotation = pose.rotation.to_rotation_matrix();
    // Row z of the rotation: how much each local axis points up.
    let up = rotation.matrix().row(2).transpose();
    match shape {
        Shape::Cuboid { half_extents } => centre_z - up.abs().dot(half_extents),
        Shape::Cylinder {
            radius,
            half_length,
        } => {
            let axis_up = up.z.abs().min(1.0);
            centre_z - axis_up * half_length - radius * (1.0 - axis_up * axis_up).sqrt()
        }
        Shape::Capsule {
            radius,
            half_length,
        } => centre_z - up.z.abs() * half_length - radius,
        Shape::Sphere { radius } => centre_z - radius,
    }
}

/// The lowest z (m) of a link's geometry with the link frame at `link_pose`.
pub fn link_lowest_z(link_pose: &Isometry3<f64>, geometry: &LinkGeometry) -> Option<f64> {
    geometry
        .shapes
        .iter()
        .map(|(pose, shape)| lowest_z(&(link_pose * pose), shape))
        .min_by(f64::total_cmp)
}

/// The sand surface level (m): the median z of a surface cloud's points; `None` if empty.
pub fn surface_level(points: &[[f32; 3]]) -> Option<f64> {
    let mut z: Vec<f64> = points
        .iter()
        .map(|p| f64::from(p[2]))
        .filter(|z| z.is_finite())
        .collect();
    if z.is_empty() {
        return None;
    }
    z.sort_by(f64::total_cmp);
    let mid = z.len() / 2;
    Some(if z.len() % 2 == 1 {
        z[mid]
    } else {
        0.5 * (z[mid - 1] + z[mid])
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use std::f64::consts::FRAC_PI_2;

    /// The lowest corner of a box by brute force.
    fn lowest_corner(pose: &Isometry3<f64>, h: Vector3<f64>) -> f64 {
        (0..8)
            .map(|i| {
                let sign = |bit: i32| if i & (1 << bit) == 0 { -1.0 } else { 1.0 };
                let corner = Point3::new(sign(0) * h.x, sign(1) * h.y, sign(2) * h.z);
                (pose * corner).z
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn box_lowest_point_matches_its_corners() {
        let h = Vector3::new(0.01, 0.02, 0.03);
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (0.3, -1.1, 2.0), (FRAC_PI_2, 0.2, -0.4)] {
            let pose = Isometry3::from_parts(
                Translation3::new(0.1, -0.2, 0.5),
                UnitQuaternion::from_euler_angles(roll, pitch, yaw),
            );
            let exact = lowest_z(&pose, &Shape::Cuboid { half_extents: h });
            assert!((exact - lowest_corner(&pose, h)).abs() < 1e-12);
        }
    }

    #[test]
    fn round_shapes() {
        let lying = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.0),
            UnitQuaternion::from_euler_angles(FRAC_PI_2, 0.0, 0.0),
        );
        let cylinder = Shape::Cylinder {
            radius: 0.1,
            half_length: 0.5,
        };
        assert!((lowest_z(&lying, &cylinder) - 0.9).abs() < 1e-12);
        let standing = Isometry3::translation(0.0, 0.0, 1.0);
        assert!((lowest_z(&standing, &cylinder) - 0.5).abs() < 1e-12);
        let capsule = Shape::Capsule {
            radius: 0.1,
            half_length: 0.5,
        };
        assert!((lowest_z(&standing, &capsule) - 0.4).abs() < 1e-12);
        assert_eq!(lowest_z(&standing, &Shape::Sphere { radius: 0.25 }), 0.75);
    }

    #[test]
    fn urdf_legs_and_median_level() {
        let urdf = r#"<robot name="r">
          <link name="base_link"><collision><geometry><box size="1 1 1"/></geometry></collision></link>
          <link name="leg"><collision><origin xyz="0 0 -0.02" rpy="0 0 0"/>
            <geometry><box size="0.004 0.01 0.04"/></geometry></collision>
            <collision><geometry><mesh filename="leg.stl"/></geometry></collision></link>
          <link name="camera"/>
          <joint name="leg_joint" type="continuous"><parent link="base_link"/><child link="leg"/>
            <axis xyz="0 1 0"/></joint>
          <joint name="camera_joint" type="fixed"><parent link="base_link"/><child link="camera"/></joint>
        </robot>"#;
        let (links, notes) = moving_link_geometry(urdf).unwrap();
        assert_eq!(links.len(), 1);
        assert_eq!(links[0].link, "leg");
        assert_eq!(notes.len(), 1, "{notes:?}");
        let lowest = link_lowest_z(&Isometry3::translation(0.0, 0.0, 0.1), &links[0]).unwrap();
        assert!((lowest - 0.06).abs() < 1e-12);
        assert_eq!(
            surface_level(&[[0.0, 0.0, 3.0], [0.0, 0.0, 1.0], [0.0, 0.0, 2.0]]),
            Some(2.0)
        );
        assert_eq!(surface_level(&[]), None);
        assert!(moving_link_geometry("<robot").is_err());
    }
}
