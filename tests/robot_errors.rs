//! Bad robot input fails with a message that names the file and the element: a malformed
//! URDF, a missing mesh, a leg joint the gait expects but the URDF lacks, a joint of the wrong
//! kind, a dangling link, a missing file, an out-of-range config value.

use std::path::{Path, PathBuf};

use sandstep::robot::urdf_gen::hexapod_urdf_text;
use sandstep::robot::{write_hexapod_urdf, HexapodParams, RobotConfig, RobotError, RobotSim};

fn load(urdf: &Path) -> Result<RobotSim, RobotError> {
    let cfg = RobotConfig {
        urdf: urdf.to_path_buf(),
        ..Default::default()
    };
    RobotSim::new(&cfg, [0.0, 0.0, -9.81])
}

/// A folder with a valid hexapod (URDF and mesh) whose URDF text is then `edit`ed.
fn edited_urdf(edit: impl Fn(String) -> String) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hexapod.urdf");
    write_hexapod_urdf(&HexapodParams::default(), &path).unwrap();
    let text = hexapod_urdf_text(
        &HexapodParams::default(),
        "hexapod",
        "meshes/hexapod_leg.stl",
    );
    std::fs::write(&path, edit(text)).unwrap();
    (dir, path)
}

fn message(r: Result<RobotSim, RobotError>) -> (RobotError, String) {
    let err = r.err().expect("loading should fail");
    let msg = err.to_string();
    (err, msg)
}

#[test]
fn the_unedited_copy_loads() {
    let (_dir, path) = edited_urdf(|t| t);
    load(&path).unwrap();
}

#[test]
fn malformed_urdf_names_the_file() {
    let (_dir, path) = edited_urdf(|t| t.replace("</robot>", ""));
    let (err, msg) = message(load(&path));
    assert!(matches!(err, RobotError::UrdfParse { .. }), "{err:?}");
    assert!(
        msg.starts_with(&format!("{}: malformed URDF", path.display())),
        "{msg}"
    );
}

/// A malformed URDF says where it breaks (issue 22: it gave no line): a link left open (its
/// closing tag removed) is reported at the line where a later element closes.
#[test]
fn malformed_urdf_names_the_line() {
    let (_dir, path) = edited_urdf(|t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        // The first link's `</link>` removed.
        let close = lines.iter().position(|l| l.trim() == "</link>").unwrap();
        lines.remove(close);
        lines.join("\n")
    });
    let (_, msg) = message(load(&path));
    let at = msg
        .split("line ")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .and_then(|n| n.parse::<usize>().ok())
        .unwrap_or_else(|| panic!("no line in `{msg}`"));
    let text = std::fs::read_to_string(&path).unwrap();
    let line = text.lines().nth(at - 1).unwrap_or_default();
    assert!(
        line.contains("</"),
        "line {at} `{line}` closes an element: {msg}"
    );
    assert!(msg.contains("column "), "{msg}");
}

#[test]
fn missing_mesh_names_link_and_mesh() {
    let (_dir, path) = edited_urdf(|t| t);
    std::fs::remove_file(path.parent().unwrap().join("meshes/hexapod_leg.stl")).unwrap();
    let (err, msg) = message(load(&path));
    assert!(matches!(err, RobotError::MeshNotFound { .. }), "{err:?}");
    let want = format!(
        "{}: link 'leg_front_left': mesh 'meshes/hexapod_leg.stl' not found",
        path.display()
    );
    assert!(msg.starts_with(&want), "{msg}");
}

#[test]
fn unreadable_mesh_names_link_and_mesh() {
    let (_dir, path) = edited_urdf(|t| t);
    std::fs::write(
        path.parent().unwrap().join("meshes/hexapod_leg.stl"),
        "not a mesh",
    )
    .unwrap();
    let (err, msg) = message(load(&path));
    assert!(matches!(err, RobotError::MeshInvalid { .. }), "{err:?}");
    assert!(
        msg.contains("link 'leg_front_left': mesh 'meshes/hexapod_leg.stl': not an STL file"),
        "{msg}"
    );
}

#[test]
fn missing_gait_joint_is_named() {
    let (_dir, path) = edited_urdf(|t| t.replace("leg_rear_right_joint", "leg_rr_joint"));
    let (err, msg) = message(load(&path));
    assert!(matches!(err, RobotError::MissingJoint { .. }), "{err:?}");
    let want = format!(
        "{}: joint 'leg_rear_right_joint' expected by the tripod gait is missing",
        path.display()
    );
    assert!(msg.starts_with(&want), "{msg}");
    assert!(
        msg.contains("leg_rr_joint"),
        "lists the joints found: {msg}"
    );
}

#[test]
fn gait_joint_of_the_wrong_kind_is_named() {
    let (_dir, path) = edited_urdf(|t| {
        t.replacen(
            r#"<joint name="leg_middle_left_joint" type="continuous">"#,
            r#"<joint name="leg_middle_left_joint" type="fixed">"#,
            1,
        )
    });
    let (err, msg) = message(load(&path));
    assert!(matches!(err, RobotError::UrdfInvalid { .. }), "{err:?}");
    assert!(
        msg.contains("joint 'leg_middle_left_joint': the gait needs a continuous joint"),
        "{msg}"
    );
}

#[test]
fn joint_to_a_missing_link_is_named() {
    let (_dir, path) = edited_urdf(|t| {
        t.replacen(
            r#"<child link="leg_front_right"/>"#,
            r#"<child link="nope"/>"#,
            1,
        )
    });
    let (_, msg) = message(load(&path));
    assert!(
        msg.contains("joint 'leg_front_right_joint': child link 'nope' does not exist"),
        "{msg}"
    );
}

/// A URDF without links is told so (issue 22: it was told "the joints form a loop").
#[test]
fn urdf_without_links_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.urdf");
    std::fs::write(
        &path,
        "<?xml version=\"1.0\"?>\n<robot name=\"empty\"></robot>\n",
    )
    .unwrap();
    let (_, msg) = message(load(&path));
    assert!(msg.contains("has no <link>"), "{msg}");
    assert!(!msg.contains("loop"), "{msg}");
}

#[test]
fn missing_urdf_file_names_it() {
    let (_, msg) = message(load(Path::new("urdf/no_such_robot.urdf")));
    assert!(msg.starts_with("urdf/no_such_robot.urdf: "), "{msg}");
}

#[test]
fn config_errors_name_file_and_field() {
    let yaml = "urdf: urdf/hexapod.urdf\nground: {friction: -0.2}\n";
    let cfg: RobotConfig = serde_yaml_ng::from_str(yaml).unwrap();
    let msg = cfg
        .validate(Path::new("config/bad.yaml"))
        .unwrap_err()
        .to_string();
    assert!(
        msg.starts_with("config/bad.yaml: robot.ground.friction = -0.2"),
        "{msg}"
    );
}

/// A start yaw beyond a turn is refused, naming the field (tests/fuzz.rs found 1e308 deg: the
/// f32 rotation overflowed, the pose became NaN, and the sand window's walls crossed).
#[test]
fn a_yaw_beyond_a_turn_is_refused() {
    for yaw in ["1e308", "361", "-400"] {
        let yaml = format!("urdf: urdf/hexapod.urdf\ninitial_pose: {{yaw_deg: {yaw}}}\n");
        let cfg: RobotConfig = serde_yaml_ng::from_str(&yaml).unwrap();
        let msg = cfg
            .validate(Path::new("config/bad.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("config/bad.yaml: robot.initial_pose.yaw_deg"),
            "{yaw}: {msg}"
        );
    }
    let yaml = "urdf: urdf/hexapod.urdf\ninitial_pose: {yaw_deg: -360}\n";
    let cfg: RobotConfig = serde_yaml_ng::from_str(yaml).unwrap();
    cfg.validate(Path::new("config/ok.yaml")).unwrap();
}
