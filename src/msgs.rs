//! ROS 2 message types as plain serde data, their `.msg` definitions and CDR encoding.
//!
//! Shared by the DDS node ([`crate::ros`]), the bag writer and reader ([`crate::bag`]) and the
//! offline analysis. No DDS here. Field order follows each `.msg` file of ROS 2 Jazzy, because
//! CDR encodes fields in declaration order with no names.

use std::fmt::Debug;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// A ROS 2 message type: package, name, `.msg` text and the types its fields use.
#[derive(Debug)]
pub struct MessageType {
    /// Package, e.g. `sensor_msgs`.
    pub package: &'static str,
    /// Type name, e.g. `JointState`.
    pub name: &'static str,
    /// The `.msg` definition (fields only, comments and constants left out).
    pub definition: &'static str,
    /// Message types the fields refer to directly.
    pub dependencies: &'static [&'static MessageType],
}

impl MessageType {
    /// Full name as rosbag2 and `ros2 topic` write it, e.g. `sensor_msgs/msg/JointState`.
    pub fn type_name(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }

    /// The `ros2msg` schema of an MCAP channel: this definition, then every dependency once,
    /// depth-first, each after a line of 80 `=` and a `MSG: package/Name` line.
    pub fn schema_text(&self) -> String {
        let mut seen: Vec<(&'static str, &'static str)> = Vec::new();
        let mut text = self.definition.to_string();
        fn visit(t: &MessageType, seen: &mut Vec<(&'static str, &'static str)>, text: &mut String) {
            for dep in t.dependencies {
                let key = (dep.package, dep.name);
                if seen.contains(&key) {
                    continue;
                }
                seen.push(key);
                text.push_str(&"=".repeat(80));
                text.push_str(&format!("\nMSG: {}/{}\n", dep.package, dep.name));
                text.push_str(dep.definition);
                visit(dep, seen, text);
            }
        }
        visit(self, &mut seen, &mut text);
        text
    }
}

/// A message that can be published, recorded and read back.
pub trait RosMessage: Serialize + DeserializeOwned + Clone + Debug + Send + 'static {
    /// Its ROS type.
    const TYPE: &'static MessageType;
}

/// The 4-byte encapsulation header of plain CDR, little-endian (RTPS `CDR_LE`).
const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The encapsulation identifier of plain CDR, big-endian (RTPS `CDR_BE`).
const CDR_BE_ID: [u8; 2] = [0x00, 0x00];

/// Why bytes did not decode as a message.
#[derive(thiserror::Error, Debug)]
pub enum CdrError {
    #[error("message shorter than the 4-byte CDR encapsulation header")]
    Truncated,
    #[error("unsupported CDR encapsulation {0:02x}{1:02x} (only plain CDR is read)")]
    Encapsulation(u8, u8),
    #[error("cannot decode {type_name}: {message}")]
    Decode { type_name: String, message: String },
}

/// Serialises `msg` as a CDR message: encapsulation header, then the little-endian body.
pub fn to_cdr<M: RosMessage>(msg: &M) -> Vec<u8> {
    let body = cdr_encoding::to_vec::<M, byteorder::LittleEndian>(msg)
        .expect("plain message structs always serialise");
    let mut out = Vec::with_capacity(4 + body.len());
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    out
}

/// Decodes a CDR message (either byte order) with its encapsulation header.
pub fn from_cdr<M: RosMessage>(bytes: &[u8]) -> Result<M, CdrError> {
    if bytes.len() < 4 {
        return Err(CdrError::Truncated);
    }
    let body = &bytes[4..];
    let decoded = if bytes[..2] == CDR_LE_HEADER[..2] {
        cdr_encoding::from_bytes::<M, byteorder::LittleEndian>(body)
    } else if bytes[..2] == CDR_BE_ID {
        cdr_encoding::from_bytes::<M, byteorder::BigEndian>(body)
    } else {
        return Err(CdrError::Encapsulation(bytes[0], bytes[1]));
    };
    decoded.map(|(m, _)| m).map_err(|e| CdrError::Decode {
        type_name: M::TYPE.type_name(),
        message: e.to_string(),
    })
}

macro_rules! message {
    ($ty:ident, $const:ident, $package:literal, $name:literal, $definition:literal, [$($dep:ident),*]) => {
        #[doc = concat!("`", $package, "/msg/", $name, "`.")]
        pub static $const: MessageType = MessageType {
            package: $package,
            name: $name,
            definition: $definition,
            dependencies: &[$(&$dep),*],
        };
        impl RosMessage for $ty {
            const TYPE: &'static MessageType = &$const;
        }
    };
}

// ---- builtin_interfaces, std_msgs, rosgraph_msgs ----

/// Time since the epoch (here: simulated time since the start).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}
message!(
    Time,
    TIME,
    "builtin_interfaces",
    "Time",
    "int32 sec\nuint32 nanosec\n",
    []
);

impl Time {
    /// `t` seconds (rounded to the nanosecond).
    pub fn from_secs(t: f64) -> Self {
        Self::from_nanos((t * 1e9).round().max(0.0) as u64)
    }
    pub fn from_nanos(ns: u64) -> Self {
        Self {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
    pub fn as_nanos(&self) -> u64 {
        self.sec.max(0) as u64 * 1_000_000_000 + self.nanosec as u64
    }
    pub fn as_secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}
message!(
    Header,
    HEADER,
    "std_msgs",
    "Header",
    "builtin_interfaces/Time stamp\nstring frame_id\n",
    [TIME]
);

impl Header {
    pub fn new(stamp: Time, frame_id: &str) -> Self {
        Self {
            stamp,
            frame_id: frame_id.to_string(),
        }
    }
}

/// `std_msgs/msg/String`.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct StringMsg {
    pub data: String,
}
message!(StringMsg, STRING, "std_msgs", "String", "string data\n", []);

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Float64 {
    pub data: f64,
}
message!(
    Float64,
    FLOAT64,
    "std_msgs",
    "Float64",
    "float64 data\n",
    []
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct MultiArrayDimension {
    pub label: String,
    pub size: u32,
    pub stride: u32,
}
message!(
    MultiArrayDimension,
    MULTI_ARRAY_DIMENSION,
    "std_msgs",
    "MultiArrayDimension",
    "string label\nuint32 size\nuint32 stride\n",
    []
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct MultiArrayLayout {
    pub dim: Vec<MultiArrayDimension>,
    pub data_offset: u32,
}
message!(
    MultiArrayLayout,
    MULTI_ARRAY_LAYOUT,
    "std_msgs",
    "MultiArrayLayout",
    "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
    [MULTI_ARRAY_DIMENSION]
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Float64MultiArray {
    pub layout: MultiArrayLayout,
    pub data: Vec<f64>,
}
message!(
    Float64MultiArray,
    FLOAT64_MULTI_ARRAY,
    "std_msgs",
    "Float64MultiArray",
    "std_msgs/MultiArrayLayout layout\nfloat64[] data\n",
    [MULTI_ARRAY_LAYOUT]
);

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Clock {
    pub clock: Time,
}
message!(
    Clock,
    CLOCK,
    "rosgraph_msgs",
    "Clock",
    "builtin_interfaces/Time clock\n",
    [TIME]
);

// ---- geometry_msgs ----

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
message!(
    Vector3,
    VECTOR3,
    "geometry_msgs",
    "Vector3",
    "float64 x\nfloat64 y\nfloat64 z\n",
    []
);

impl From<[f64; 3]> for Vector3 {
    fn from(v: [f64; 3]) -> Self {
        Self {
            x: v[0],
            y: v[1],
            z: v[2],
        }
    }
}

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
message!(
    Point,
    POINT,
    "geometry_msgs",
    "Point",
    "float64 x\nfloat64 y\nfloat64 z\n",
    []
);

impl From<[f64; 3]> for Point {
    fn from(v: [f64; 3]) -> Self {
        Self {
            x: v[0],
            y: v[1],
            z: v[2],
        }
    }
}

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}
message!(
    Quaternion,
    QUATERNION,
    "geometry_msgs",
    "Quaternion",
    "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
    []
);

impl Default for Quaternion {
    /// The identity rotation (as in ROS: w = 1).
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

impl From<[f64; 4]> for Quaternion {
    /// From `[x, y, z, w]`.
    fn from(q: [f64; 4]) -> Self {
        Self {
            x: q[0],
            y: q[1],
            z: q[2],
            w: q[3],
        }
    }
}

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}
message!(
    Pose,
    POSE,
    "geometry_msgs",
    "Pose",
    "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    [POINT, QUATERNION]
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}
message!(
    PoseStamped,
    POSE_STAMPED,
    "geometry_msgs",
    "PoseStamped",
    "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
    [HEADER, POSE]
);

/// Row-major 6x6 covariance (x, y, z, rotation about x, y, z).
pub type Covariance = [f64; 36];

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    #[serde(with = "serde_big_array::BigArray")]
    pub covariance: Covariance,
}
message!(
    PoseWithCovariance,
    POSE_WITH_COVARIANCE,
    "geometry_msgs",
    "PoseWithCovariance",
    "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    [POSE]
);

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}
message!(
    Twist,
    TWIST,
    "geometry_msgs",
    "Twist",
    "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    [VECTOR3]
);

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    #[serde(with = "serde_big_array::BigArray")]
    pub covariance: Covariance,
}
message!(
    TwistWithCovariance,
    TWIST_WITH_COVARIANCE,
    "geometry_msgs",
    "TwistWithCovariance",
    "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    [TWIST]
);

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}
message!(
    Transform,
    TRANSFORM,
    "geometry_msgs",
    "Transform",
    "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    [VECTOR3, QUATERNION]
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}
message!(
    TransformStamped,
    TRANSFORM_STAMPED,
    "geometry_msgs",
    "TransformStamped",
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    [HEADER, TRANSFORM]
);

#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Wrench {
    pub force: Vector3,
    pub torque: Vector3,
}
message!(
    Wrench,
    WRENCH,
    "geometry_msgs",
    "Wrench",
    "geometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
    [VECTOR3]
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct WrenchStamped {
    pub header: Header,
    pub wrench: Wrench,
}
message!(
    WrenchStamped,
    WRENCH_STAMPED,
    "geometry_msgs",
    "WrenchStamped",
    "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
    [HEADER, WRENCH]
);

// ---- tf2_msgs, nav_msgs, sensor_msgs ----

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}
message!(
    TFMessage,
    TF_MESSAGE,
    "tf2_msgs",
    "TFMessage",
    "geometry_msgs/TransformStamped[] transforms\n",
    [TRANSFORM_STAMPED]
);

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}
message!(
    Odometry,
    ODOMETRY,
    "nav_msgs",
    "Odometry",
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    [HEADER, POSE_WITH_COVARIANCE, TWIST_WITH_COVARIANCE]
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}
message!(
    JointState,
    JOINT_STATE,
    "sensor_msgs",
    "JointState",
    "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    [HEADER]
);

/// `sensor_msgs/msg/PointField` datatype of a 32-bit float.
pub const POINT_FIELD_FLOAT32: u8 = 7;

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}
message!(
    PointField,
    POINT_FIELD,
    "sensor_msgs",
    "PointField",
    "string name\nuint32 offset\nuint8 datatype\nuint32 count\n",
    []
);

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Vec<u8>,
    pub is_dense: bool,
}
message!(
    PointCloud2,
    POINT_CLOUD2,
    "sensor_msgs",
    "PointCloud2",
    "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
    [HEADER, POINT_FIELD]
);

impl PointCloud2 {
    /// An unordered cloud of `xyz` points as three little-endian `float32` fields.
    pub fn from_points(header: Header, points: &[[f32; 3]]) -> Self {
        let fields = ["x", "y", "z"]
            .iter()
            .enumerate()
            .map(|(i, name)| PointField {
                name: name.to_string(),
                offset: 4 * i as u32,
                datatype: POINT_FIELD_FLOAT32,
                count: 1,
            })
            .collect();
        let point_step = 12u32;
        let data = points
            .iter()
            .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
            .collect();
        Self {
            header,
            height: 1,
            width: points.len() as u32,
            fields,
            is_bigendian: false,
            point_step,
            row_step: point_step * points.len() as u32,
            data,
            is_dense: true,
        }
    }

    /// The `xyz` points of a cloud written by [`PointCloud2::from_points`] or any cloud with
    /// little-endian `float32` fields `x`, `y`, `z`; `None` if it has no such fields.
    pub fn points(&self) -> Option<Vec<[f32; 3]>> {
        if self.is_bigendian || self.point_step == 0 {
            return None;
        }
        let offset = |n: &str| {
            self.fields
                .iter()
                .find(|f| f.name == n && f.datatype == POINT_FIELD_FLOAT32)
                .map(|f| f.offset as usize)
        };
        let (ox, oy, oz) = (offset("x")?, offset("y")?, offset("z")?);
        let step = self.point_step as usize;
        let read = |p: &[u8], o: usize| {
            p.get(o..o + 4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        self.data
            .chunks_exact(step)
            .map(|p| Some([read(p, ox)?, read(p, oy)?, read(p, oz)?]))
            .collect()
    }
}

// ---- std_srvs (request and response of the node's services) ----

/// `std_srvs/srv/Trigger` request (ROS 2 gives empty messages one `uint8` member).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct TriggerRequest {
    pub structure_needs_at_least_one_member: u8,
}

/// `std_srvs/srv/Trigger` and `std_srvs/srv/SetBool` response.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct ServiceResponse {
    pub success: bool,
    pub message: String,
}

/// `std_srvs/srv/SetBool` request.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct SetBoolRequest {
    pub data: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schema_lists_each_dependency_once_depth_first() {
        let text = ODOMETRY.schema_text();
        let msgs: Vec<&str> = text
            .lines()
            .filter_map(|l| l.strip_prefix("MSG: "))
            .collect();
        assert_eq!(
            msgs,
            [
                "std_msgs/Header",
                "builtin_interfaces/Time",
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "geometry_msgs/TwistWithCovariance",
                "geometry_msgs/Twist",
                "geometry_msgs/Vector3",
            ]
        );
        assert!(text.starts_with("std_msgs/Header header\n"));
        assert_eq!(ODOMETRY.type_name(), "nav_msgs/msg/Odometry");
    }

    #[test]
    fn cdr_matches_the_wire_layout() {
        // Header { stamp: 1.5 s, frame_id: "odom" }: sec, nanosec, string length (with NUL),
        // the bytes and the NUL; then Float64 data aligned to 8 from the body's start.
        let msg = JointState {
            header: Header::new(Time::from_secs(1.5), "odom"),
            name: vec!["a".into()],
            position: vec![2.0],
            velocity: vec![],
            effort: vec![],
        };
        let bytes = to_cdr(&msg);
        assert_eq!(&bytes[..4], &CDR_LE_HEADER);
        let body = &bytes[4..];
        assert_eq!(&body[0..4], &1i32.to_le_bytes());
        assert_eq!(&body[4..8], &500_000_000u32.to_le_bytes());
        assert_eq!(&body[8..12], &5u32.to_le_bytes());
        assert_eq!(&body[12..17], b"odom\0");
        // name: length 1 at 20 (aligned to 4), string "a\0" with length 2 at 24..
        assert_eq!(&body[20..24], &1u32.to_le_bytes());
        assert_eq!(&body[24..28], &2u32.to_le_bytes());
        // position: count at 32, the f64 aligned to 8 at 40.
        assert_eq!(&body[32..36], &1u32.to_le_bytes());
        assert_eq!(&body[40..48], &2.0f64.to_le_bytes());
        assert_eq!(from_cdr::<JointState>(&bytes).unwrap(), msg);
    }

    #[test]
    fn odometry_and_cloud_round_trip() {
        let odom = Odometry {
            header: Header::new(Time::from_nanos(12_345), "odom"),
            child_frame_id: "base_link".into(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: [1.0, 2.0, 3.0].into(),
                    orientation: [0.0, 0.0, 0.6, 0.8].into(),
                },
                covariance: std::array::from_fn(|i| i as f64),
            },
            twist: TwistWithCovariance {
                twist: Twist::default(),
                covariance: [0.0; 36],
            },
        };
        assert_eq!(from_cdr::<Odometry>(&to_cdr(&odom)).unwrap(), odom);
        let points = [[0.1, 0.2, 0.3], [-1.0, 2.5, 0.0]];
        let cloud = PointCloud2::from_points(Header::default(), &points);
        let back = from_cdr::<PointCloud2>(&to_cdr(&cloud)).unwrap();
        assert_eq!(back.points().unwrap(), points);
    }

    #[test]
    fn bad_bytes_name_the_problem() {
        assert!(matches!(
            from_cdr::<Float64>(&[0, 1]),
            Err(CdrError::Truncated)
        ));
        assert!(matches!(
            from_cdr::<Float64>(&[0, 9, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8]),
            Err(CdrError::Encapsulation(0, 9))
        ));
        let err = from_cdr::<Float64>(&[0, 1, 0, 0, 1]).unwrap_err();
        assert!(err.to_string().contains("std_msgs/msg/Float64"), "{err}");
    }
}
