//! Poses over time and a small transform tree (`/tf`, `/tf_static`) to look frames up in.

use std::collections::HashMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::msgs;

/// A pose sampled at a time: (time in s since the analysis origin, pose).
pub type TimedPose = (f64, Isometry3<f64>);

/// Below this norm a quaternion is treated as unset (all zeros) and read as the identity.
const MIN_QUATERNION_NORM: f64 = 1e-9;

/// Time slack (s) when deciding whether a time lies inside a sampled range.
pub const TIME_EPSILON_S: f64 = 1e-9;

/// The rotation of a ROS quaternion, normalised; the identity if it is all zeros.
pub fn rotation_of(q: &msgs::Quaternion) -> UnitQuaternion<f64> {
    let q = Quaternion::new(q.w, q.x, q.y, q.z);
    if q.norm() < MIN_QUATERNION_NORM {
        UnitQuaternion::identity()
    } else {
        UnitQuaternion::from_quaternion(q)
    }
}

/// A `geometry_msgs/Pose` as an isometry.
pub fn pose_to_isometry(p: &msgs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.position.x, p.position.y, p.position.z),
        rotation_of(&p.orientation),
    )
}

/// A `geometry_msgs/Transform` as an isometry.
pub fn transform_to_isometry(t: &msgs::Transform) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(t.translation.x, t.translation.y, t.translation.z),
        rotation_of(&t.rotation),
    )
}

/// Interpolates between two isometries: position linearly, rotation by normalised linear
/// interpolation along the shorter arc (never fails, unlike slerp at 180 degrees).
fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let translation = a.translation.vector.lerp(&b.translation.vector, s);
    let (qa, mut qb) = (*a.rotation.quaternion(), *b.rotation.quaternion());
    if qa.dot(&qb) < 0.0 {
        qb = -qb;
    }
    let q = qa * (1.0 - s) + qb * s;
    let rotation = if q.norm() < MIN_QUATERNION_NORM {
        a.rotation
    } else {
        UnitQuaternion::from_quaternion(q)
    };
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// The pose at `t` from samples sorted by time: interpolated between neighbours, clamped to
/// the first or last sample outside their range; `None` without samples.
pub fn pose_at_clamped(samples: &[TimedPose], t: f64) -> Option<Isometry3<f64>> {
    let (first, last) = (samples.first()?, samples.last()?);
    if t <= first.0 {
        return Some(first.1);
    }
    if t >= last.0 {
        return Some(last.1);
    }
    // First sample later than t; 1..len because t > first.0 and t < last.0.
    let i = samples.partition_point(|(ts, _)| *ts <= t);
    let (t0, p0) = &samples[i - 1];
    let (t1, p1) = &samples[i];
    let span = t1 - t0;
    let s = if span > 0.0 { (t - t0) / span } else { 0.0 };
    Some(interpolate(p0, p1, s))
}

/// The pose at `t`, interpolated; `None` outside the sampled time range.
pub fn pose_at(samples: &[TimedPose], t: f64) -> Option<Isometry3<f64>> {
    let (first, last) = (samples.first()?, samples.last()?);
    if t < first.0 - TIME_EPSILON_S || t > last.0 + TIME_EPSILON_S {
        return None;
    }
    pose_at_clamped(samples, t)
}

/// Sorts samples by time and keeps one sample per time (the last given).
pub fn sort_samples(samples: &mut Vec<TimedPose>) {
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    samples.dedup_by(|later, earlier| {
        if later.0 == earlier.0 {
            *earlier = *later;
            true
        } else {
            false
        }
    });
}

/// Strips the leading `/` that ROS 1 style frame names carry.
pub fn frame_name(name: &str) -> &str {
    name.trim_start_matches('/')
}

/// How one frame hangs from its parent over time.
#[derive(Debug, Default)]
struct Edge {
    parent: String,
    /// Transform from the child frame into the parent frame, by time.
    samples: Vec<TimedPose>,
    /// From `/tf_static`: valid at every time.
    is_static: bool,
}

/// The transform tree of a bag: each child frame with its parent and its samples.
#[derive(Debug, Default)]
pub struct TfTree {
    edges: HashMap<String, Edge>,
}

/// Frames deeper than this are taken as a loop in a malformed tree.
const MAX_TREE_DEPTH: usize = 64;

impl TfTree {
    /// Adds one transform of `child` in `parent` at time `t` (s). A child keeps the parent it
    /// was first given; later samples naming another parent are ignored.
    pub fn insert(
        &mut self,
        parent: &str,
        child: &str,
        t: f64,
        pose: Isometry3<f64>,
        is_static: bool,
    ) {
        let (parent, child) = (frame_name(parent), frame_name(child));
        if parent.is_empty() || child.is_empty() || parent == child {
            return;
        }
        let edge = self.edges.entry(child.to_string()).or_insert_with(|| Edge {
            parent: parent.to_string(),
            samples: Vec::new(),
            is_static,
        });
        if edge.parent != parent {
            return;
        }
        if is_static {
            // A static transform holds at every time: keep the latest one given.
            edge.is_static = true;
            edge.samples.clear();
        } else if edge.is_static {
            return;
        }
        edge.samples.push((t, pose));
    }

    /// Sorts every frame's samples by time; call once after the last [`TfTree::insert`].
    pub fn finish(&mut self) {
        for edge in self.edges.values_mut() {
            sort_samples(&mut edge.samples);
        }
    }

    /// The parent of `frame`, if the tree has it.
    pub fn parent(&self, frame: &str) -> Option<&str> {
        self.edges.get(frame_name(frame)).map(|e| e.parent.as_str())
    }

    /// The samples of `frame` in its parent (sorted by time).
    pub fn samples(&self, frame: &str) -> Option<&[TimedPose]> {
        self.edges
            .get(frame_name(frame))
            .map(|e| e.samples.as_slice())
    }

    /// The transform taking coordinates in `frame` into its ancestor `ancestor` at time `t`
    /// (each link interpolated, clamped to its sampled range); `None` if `ancestor` is not
    /// above `frame` in the tree. The identity when they are the same frame.
    pub fn lookup(&self, frame: &str, ancestor: &str, t: f64) -> Option<Isometry3<f64>> {
        let ancestor = frame_name(ancestor);
        let mut current = frame_name(frame);
        let mut pose = Isometry3::identity();
        for _ in 0..MAX_TREE_DEPTH {
            if current == ancestor {
                return Some(pose);
            }
            let edge = self.edges.get(current)?;
            pose = pose_at_clamped(&edge.samples, t)? * pose;
            current = &edge.parent;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn interpolation_clamps_and_blends() {
        let a = Isometry3::translation(0.0, 0.0, 0.0);
        let b = Isometry3::new(
            Vector3::new(2.0, 0.0, 0.0),
            Vector3::new(0.0, 0.0, FRAC_PI_2),
        );
        let samples = vec![(1.0, a), (2.0, b)];
        let mid = pose_at(&samples, 1.5).unwrap();
        assert!((mid.translation.x - 1.0).abs() < 1e-12);
        assert!((mid.rotation.angle() - FRAC_PI_2 / 2.0).abs() < 1e-9);
        assert!(pose_at(&samples, 0.5).is_none());
        assert_eq!(pose_at_clamped(&samples, 3.0).unwrap(), b);
    }

    #[test]
    fn lookup_composes_the_chain_up_to_the_ancestor() {
        let mut tree = TfTree::default();
        tree.insert(
            "odom",
            "base_link",
            0.0,
            Isometry3::translation(1.0, 0.0, 0.0),
            false,
        );
        tree.insert(
            "odom",
            "base_link",
            1.0,
            Isometry3::translation(2.0, 0.0, 0.0),
            false,
        );
        let hip = Isometry3::new(
            Vector3::new(0.0, 0.1, 0.0),
            Vector3::new(0.0, FRAC_PI_2, 0.0),
        );
        tree.insert("/base_link", "/leg", 0.0, hip, false);
        tree.insert(
            "base_link",
            "camera",
            5.0,
            Isometry3::translation(0.0, 0.0, 0.3),
            true,
        );
        tree.finish();
        let leg_in_odom = tree.lookup("leg", "odom", 0.5).unwrap();
        // The leg's +x axis (rotated 90 degrees about y) points down in odom.
        let tip = leg_in_odom * Point3::new(1.0, 0.0, 0.0);
        assert!((tip - Point3::new(1.5, 0.1, -1.0)).norm() < 1e-12, "{tip}");
        assert_eq!(
            tree.lookup("camera", "odom", 0.0).unwrap().translation.z,
            0.3
        );
        assert!(tree.lookup("leg", "map", 0.0).is_none());
        assert_eq!(tree.parent("leg"), Some("base_link"));
    }
}
