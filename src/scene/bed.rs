//! How much sand a robot needs: the bed rule (`docs/scenes.md`, "How big a bed").
//!
//! The rule is in units of the robot's leg *reach* r, the radius of the circle its farthest
//! collision point sweeps about the hip (a leg turns full circles; for the shipped hexapod
//! r = 4.3 cm, the 4.1 cm chord plus the leg's half width and thickness). Around the box the
//! legs sweep at the start (every leg's circle, and the body), the bed needs
//!
//! - depth below the surface of at least [`DEPTH_PER_REACH`] r (6 cm for the hexapod): on 3 cm
//!   the rough floor props the sand the legs load, they sink half as deep and the robot walks
//!   18 +- 10 % faster, while 6 cm walks as a 6 cm bed that is also wider and longer does
//!   (within 2 %);
//! - at least [`SIDE_MARGIN_PER_REACH`] r of sand either side of the swept box (widening the
//!   shipped bed from there changed nothing);
//! - at least [`END_MARGIN_PER_REACH`] r behind it and ahead of it (ahead, the robot's path
//!   comes on top: a bed or a sand window must reach past where the robot goes).
//!
//! The factors are the least bed the measurements support (`docs/speed-vs-accuracy.md`, "How
//! big a bed": the `bed` study of `config/sweeps/accuracy.yaml`); `tests/bed.rs` checks that
//! the shipped bed walks as a deeper and longer one does.

use rapier3d::glamx::Vec3;
use rapier3d::parry::bounding_volume::Aabb;
use rapier3d::prelude::{Collider, Pose, RigidBody};

use crate::robot::RobotSim;

/// Least depth of sand below the surface, per leg reach.
pub const DEPTH_PER_REACH: f64 = 1.4;
/// Least sand either side of the legs' swept box, per leg reach.
pub const SIDE_MARGIN_PER_REACH: f64 = 2.0;
/// Least sand behind and ahead of the legs' swept box at the start, per leg reach.
pub const END_MARGIN_PER_REACH: f64 = 0.4;

/// The bed's sides and ends by name, as the warnings and metrics give them.
pub const RIGHT_SIDE: &str = "right side (-y)";
pub const LEFT_SIDE: &str = "left side (+y)";
pub const BACK_END: &str = "back (-x)";
pub const FRONT_END: &str = "front (+x)";

/// A box `[min, max]` that [`include`] grows from nothing.
const EMPTY_BOX: [[f64; 3]; 2] = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];

/// Grows `bounds` to include the box `[lo, hi]`.
fn include(bounds: &mut [[f64; 3]; 2], lo: [f64; 3], hi: [f64; 3]) {
    for (a, (l, h)) in lo.iter().zip(hi).enumerate() {
        bounds[0][a] = bounds[0][a].min(*l);
        bounds[1][a] = bounds[1][a].max(h);
    }
}

fn to_f64(v: Vec3) -> [f64; 3] {
    [v.x as f64, v.y as f64, v.z as f64]
}

/// A collider's world pose and bounding box. World poses of colliders are synchronised only by
/// a step: they are composed here from the body's.
fn world_aabb(body: &RigidBody, collider: &Collider) -> (Pose, Aabb) {
    let pose = *body.position() * collider.position_wrt_parent().copied().unwrap_or_default();
    (pose, collider.shape().compute_aabb(&pose))
}

/// The box the robot's colliders (body and legs) occupy now (m): min and max corners.
pub fn robot_box_m(robot: &RobotSim) -> [[f64; 3]; 2] {
    let world = robot.world();
    let mut bounds = EMPTY_BOX;
    for handle in std::iter::once(robot.body_handle()).chain(robot.leg_handles()) {
        let body = &world.bodies[handle];
        for &c in body.colliders() {
            let (_, aabb) = world_aabb(body, &world.colliders[c]);
            include(&mut bounds, to_f64(aabb.mins), to_f64(aabb.maxs));
        }
    }
    bounds
}

/// The sides of the bed `bed_m` (m, min and max corners) that the robot's box `robot_m`
/// ([`robot_box_m`]) reaches or crosses, named as in [`BedRule::shortfalls`]: there the robot is
/// at or over the bed's edge, not on open sand.
pub fn sides_reached(robot_m: [[f64; 3]; 2], bed_m: [[f64; 3]; 2]) -> Vec<&'static str> {
    let ([lo, hi], [bed_lo, bed_hi]) = (robot_m, bed_m);
    [
        (RIGHT_SIDE, lo[1] <= bed_lo[1]),
        (LEFT_SIDE, hi[1] >= bed_hi[1]),
        (BACK_END, lo[0] <= bed_lo[0]),
        (FRONT_END, hi[0] >= bed_hi[0]),
    ]
    .into_iter()
    .filter_map(|(side, reached)| reached.then_some(side))
    .collect()
}

/// The rule applied to a robot at its start pose.
#[derive(Clone, Debug, PartialEq)]
pub struct BedRule {
    /// Leg reach r (m): largest distance from a hip to a point of its leg's colliders.
    pub reach_m: f64,
    /// The box the legs sweep at the start, with the body (m): min and max corners.
    pub swept_m: [[f64; 3]; 2],
    /// The least bed (m): min and max corners, the top at the sand surface.
    pub required_m: [[f64; 3]; 2],
}

impl BedRule {
    /// The rule for `robot` standing above a sand surface at `surface_z_m` (m).
    pub fn for_robot(robot: &RobotSim, surface_z_m: f64) -> Self {
        let world = robot.world();
        let mut reach_m = 0.0f64;
        let mut swept_m = EMPTY_BOX;
        for &leg in &robot.leg_handles() {
            let rb = &world.bodies[leg];
            let hip_point = rb.translation();
            let mut leg_y = [f64::INFINITY, f64::NEG_INFINITY];
            for &c in rb.colliders() {
                let collider = &world.colliders[c];
                let (pose, aabb) = world_aabb(rb, collider);
                leg_y = [
                    leg_y[0].min(aabb.mins.y as f64),
                    leg_y[1].max(aabb.maxs.y as f64),
                ];
                let corners = match collider.shape().as_cuboid() {
                    Some(cuboid) => {
                        let h = cuboid.half_extents;
                        (0..8)
                            .map(|k| {
                                let local = Vec3::new(
                                    if k & 4 != 0 { h.x } else { -h.x },
                                    if k & 2 != 0 { h.y } else { -h.y },
                                    if k & 1 != 0 { h.z } else { -h.z },
                                );
                                pose.transform_point(local)
                            })
                            .collect::<Vec<_>>()
                    }
                    // Other shapes: the corners of their bounding box (an upper bound).
                    None => (0..8)
                        .map(|k| {
                            let pick =
                                |bit: i32, lo: f32, hi: f32| if k & bit != 0 { hi } else { lo };
                            Vec3::new(
                                pick(4, aabb.mins.x, aabb.maxs.x),
                                pick(2, aabb.mins.y, aabb.maxs.y),
                                pick(1, aabb.mins.z, aabb.maxs.z),
                            )
                        })
                        .collect(),
                };
                for p in corners {
                    reach_m = reach_m.max((p - hip_point).length() as f64);
                }
            }
            let hip = to_f64(hip_point);
            include(
                &mut swept_m,
                [hip[0], leg_y[0], hip[2]],
                [hip[0], leg_y[1], hip[2]],
            );
        }
        // Each leg's circle about its hip, then the body.
        let [lo, hi] = swept_m;
        swept_m = [
            [lo[0] - reach_m, lo[1], lo[2] - reach_m],
            [hi[0] + reach_m, hi[1], hi[2] + reach_m],
        ];
        let body = &world.bodies[robot.body_handle()];
        for &c in body.colliders() {
            let (_, aabb) = world_aabb(body, &world.colliders[c]);
            include(&mut swept_m, to_f64(aabb.mins), to_f64(aabb.maxs));
        }
        let (end, side) = (
            END_MARGIN_PER_REACH * reach_m,
            SIDE_MARGIN_PER_REACH * reach_m,
        );
        let required_m = [
            [
                swept_m[0][0] - end,
                swept_m[0][1] - side,
                surface_z_m - DEPTH_PER_REACH * reach_m,
            ],
            [swept_m[1][0] + end, swept_m[1][1] + side, surface_z_m],
        ];
        BedRule {
            reach_m,
            swept_m,
            required_m,
        }
    }

    /// Where a bed `[min, max]` (m) falls short of the rule: one line per side, empty if it
    /// meets it.
    pub fn shortfalls(&self, bed_m: [[f64; 3]; 2]) -> Vec<String> {
        let [need_lo, need_hi] = self.required_m;
        let [lo, hi] = bed_m;
        let r = self.reach_m;
        let mut lines = Vec::new();
        let mut short = |what: &str, by_m: f64, rule: String| {
            // Round-off of f32 positions is no shortfall.
            if by_m > 1e-4 {
                lines.push(format!(
                    "{what} {:.1} mm short of the bed rule ({rule})",
                    by_m * 1e3
                ));
            }
        };
        let r_cm = r * 100.0;
        short(
            "depth",
            lo[2] - need_lo[2],
            format!("{DEPTH_PER_REACH} x reach {r_cm:.2} cm"),
        );
        for (name, by_m) in [
            (RIGHT_SIDE, lo[1] - need_lo[1]),
            (LEFT_SIDE, need_hi[1] - hi[1]),
        ] {
            short(
                name,
                by_m,
                format!("{SIDE_MARGIN_PER_REACH} x reach beyond the legs"),
            );
        }
        for (name, by_m) in [
            (BACK_END, lo[0] - need_lo[0]),
            (FRONT_END, need_hi[0] - hi[0]),
        ] {
            short(
                name,
                by_m,
                format!("{END_MARGIN_PER_REACH} x reach beyond the legs"),
            );
        }
        lines
    }
}

impl crate::scene::Scene {
    /// The bed: the box around the scene's box-shaped sand bodies (m), if it has any.
    pub fn bed_box_m(&self) -> Option<[[f64; 3]; 2]> {
        let mut bed = EMPTY_BOX;
        for body in self.bodies() {
            let b = body.box_shape?;
            include(&mut bed, b.min_m.map(f64::from), b.max_m.map(f64::from));
        }
        bed[0][0].is_finite().then_some(bed)
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::scene::Scene;

    fn rule_of(scene: &Scene) -> BedRule {
        let robot = RobotSim::new(scene.config.robot.as_ref().unwrap(), [0.0, 0.0, -9.81]).unwrap();
        BedRule::for_robot(&robot, 0.0)
    }

    #[test]
    fn shipped_beds_meet_the_rule_and_a_shallow_one_does_not() {
        let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &[]).unwrap();
        let rule = rule_of(&scene);
        // The hexapod's legs: 4.1 cm chord, 1 cm wide, 3 mm thick (docs/robot.md).
        assert!(
            (0.041..0.045).contains(&rule.reach_m),
            "reach {} m",
            rule.reach_m
        );
        let bed = scene.bed_box_m().unwrap();
        println!("{rule:?}\nbed {bed:?}");
        assert_eq!(rule.shortfalls(bed), Vec::<String>::new());
        let track = Scene::load(Path::new("config/robot_on_track.yaml"), &[]).unwrap();
        assert!(rule_of(&track)
            .shortfalls(track.bed_box_m().unwrap())
            .is_empty());

        let shallow = [[bed[0][0], bed[0][1], -0.03], bed[1]];
        let lines = rule.shortfalls(shallow);
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(
            lines[0].starts_with("depth") && lines[0].contains("reach"),
            "{lines:?}"
        );
        let narrow = [[bed[0][0], -0.1, bed[0][2]], bed[1]];
        assert!(rule.shortfalls(narrow)[0].starts_with("right side"));
    }

    #[test]
    fn a_robot_reaches_the_sides_its_colliders_touch_or_cross() {
        let bed = [[-0.1, -0.1, -0.06], [0.8, 0.1, 0.0]];
        let inside = [[-0.05, -0.05, 0.0], [0.05, 0.05, 0.05]];
        assert!(sides_reached(inside, bed).is_empty());
        let left_front = [[0.7, 0.05, 0.0], [0.85, 0.1, 0.05]];
        assert_eq!(sides_reached(left_front, bed), [LEFT_SIDE, FRONT_END]);
        let right_back = [[-0.12, -0.11, 0.0], [0.0, 0.0, 0.05]];
        assert_eq!(sides_reached(right_back, bed), [RIGHT_SIDE, BACK_END]);
    }

    #[test]
    fn the_robots_box_holds_its_legs_and_body_where_they_stand() {
        let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &[]).unwrap();
        let robot = RobotSim::new(scene.config.robot.as_ref().unwrap(), [0.0, 0.0, -9.81]).unwrap();
        let [lo, hi] = robot_box_m(&robot);
        // The hexapod (docs/robot.md): hips at x = +-6 cm with legs of 4.1 cm chord, leg
        // mid-planes 2.5 cm either side with legs 1 cm wide, the belly 13 x 2 cm.
        assert!(lo[0] < -0.065 && hi[0] > 0.065, "x {lo:?} {hi:?}");
        assert!(
            (lo[1] + 0.03).abs() < 1e-3 && (hi[1] - 0.03).abs() < 1e-3,
            "y {lo:?} {hi:?}"
        );
        let bed = scene.bed_box_m().unwrap();
        assert!(sides_reached([lo, hi], bed).is_empty());
        // Moved 10 cm to the left, its left legs reach past the 12 cm side.
        let moved = [[lo[0], lo[1] + 0.1, lo[2]], [hi[0], hi[1] + 0.1, hi[2]]];
        assert_eq!(sides_reached(moved, bed), [LEFT_SIDE]);
    }
}
