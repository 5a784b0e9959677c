//! The inertia a multibody presents at one of its links (its operational-space inertia,
//! Khatib 1987): what yields with a robot's leg within a substep when its joints move as the
//! multibody's dynamics let them.

use nalgebra::{DMatrix, Matrix6};
use rapier3d::glamx::Vec3;
use rapier3d::prelude::{MotorModel, Multibody, MultibodyJointSet, RigidBodyHandle};

use crate::mpm::cpic::YieldInertia;

/// `(J M^-1 J^T)^-1` for the link `body`, with `J` its body Jacobian (the velocity of its
/// centre of mass and its angular velocity, world axes, from the generalized velocities; as
/// of the end of the last step) and `M` the multibody's augmented mass matrix as rapier
/// factorised it for the last of its solver substeps (the mass matrix plus joint damping x dt,
/// armature and joint springs x dt^2, all zero on the robot). An impulse (N s,
/// N m s about the centre of mass) on the link alone changes the link's motion by `J M^-1 J^T`
/// times it, so this is the spatial inertia the link presents to the sand. None if the body is
/// not a multibody link or the factorisation does not match its degrees of freedom.
///
/// With `motors` (the rapier step's length in s and its solver substeps), each motorised joint
/// axis also yields with the impedance its motor presents over the step
/// ([`motor_impedances`]): the motor answers within the step, so a leg whose motor holds it
/// turns less about its hinge than its own inertia would.
pub fn operational_space_inertia(
    joints: &MultibodyJointSet,
    body: RigidBodyHandle,
    motors: Option<(f32, usize)>,
) -> Option<YieldInertia> {
    let link = joints.rigid_body_link(body)?;
    let multibody = joints.get_multibody(link.multibody)?;
    let jacobian = multibody.body_jacobian(link.id);
    let mass = multibody.inv_augmented_mass();
    let ndofs = multibody.ndofs();
    if jacobian.ncols() != ndofs || mass.l().nrows() != ndofs {
        return None;
    }
    let response = mass.solve(&jacobian.transpose())?;
    // J (M^-1 J^T), summed here in f64: nalgebra hands a product of dynamic matrices to
    // `matrixmultiply`, which picks its kernel (FMA or not) by the CPU at run time, and the
    // answers would differ between machines.
    let product = |r: usize, c: usize| -> f64 {
        (0..jacobian.ncols())
            .map(|k| jacobian[(r, k)] as f64 * response[(k, c)] as f64)
            .sum()
    };
    let mut mobility = Matrix6::<f64>::from_fn(|r, c| 0.5 * (product(r, c) + product(c, r)));
    let impedances = motors.map_or_else(Vec::new, |(dt_s, substeps)| {
        motor_impedances(multibody, dt_s, substeps)
    });
    if !impedances.is_empty() {
        // Woodbury: (M + E D E^T)^-1 = M^-1 - M^-1 E (D^-1 + E^T M^-1 E)^-1 E^T M^-1, with E
        // selecting the motorised coordinates and D their impedances.
        let mut selection = DMatrix::<f32>::zeros(ndofs, impedances.len());
        for (column, &(dof, _)) in impedances.iter().enumerate() {
            selection[(dof, column)] = 1.0;
        }
        let spread = mass.solve(&selection)?;
        let inner = DMatrix::<f64>::from_fn(impedances.len(), impedances.len(), |r, c| {
            let symmetric = 0.5 * (spread[(impedances[r].0, c)] + spread[(impedances[c].0, r)]);
            symmetric as f64 + if r == c { 1.0 / impedances[r].1 } else { 0.0 }
        });
        let inner = inner.try_inverse()?;
        // J M^-1 E (6 x motors), summed in f64 as above.
        let reach = DMatrix::<f64>::from_fn(6, impedances.len(), |r, c| {
            (0..ndofs)
                .map(|k| jacobian[(r, k)] as f64 * spread[(k, c)] as f64)
                .sum()
        });
        // reach inner reach^T, summed here too.
        let motors = impedances.len();
        let held = |r: usize, c: usize| -> f64 {
            (0..motors)
                .flat_map(|i| (0..motors).map(move |j| (i, j)))
                .map(|(i, j)| reach[(r, i)] * inner[(i, j)] * reach[(c, j)])
                .sum()
        };
        mobility -= Matrix6::from_fn(|r, c| 0.5 * (held(r, c) + held(c, r)));
    }
    let inertia = mobility.cholesky()?.inverse();
    let inertia = Matrix6::from_fn(|r, c| 0.5 * (inertia[(r, c)] + inertia[(c, r)]));
    Some(YieldInertia::from_spatial(inertia))
}

/// The impedance (kg m^2 for a hinge, kg for a slider) each force-based motor of `multibody`
/// presents over one rapier step of `dt_s` with `substeps` solver substeps, as
/// `(generalized coordinate, impedance)`. Rapier solves a motor with stiffness `k` and damping
/// `c` in each substep `h = dt_s / substeps` as an implicit spring-damper, adding `c h + k h^2`
/// to the coordinate's inertia; a force spread evenly over the `n` substeps then meets about
/// `(n + 1) / (2 n) (c dt + k dt h)` in all (the first-order term of the `n` implicit
/// substeps). A motor whose spring-damper law, at the start of the step, already asks its
/// force limit (`max_force`) or more is saturated: it cannot answer, and adds nothing.
pub fn motor_impedances(multibody: &Multibody, dt_s: f32, substeps: usize) -> Vec<(usize, f64)> {
    let n = substeps.max(1) as f64;
    let (dt, h) = (dt_s as f64, dt_s as f64 / n);
    let velocities = multibody.generalized_velocity();
    let mut impedances = Vec::new();
    for link in multibody.links() {
        let data = &link.joint.data;
        let (locked, motorised) = (data.locked_axes.bits(), data.motor_axes.bits());
        let coords = link.joint.coords();
        let mut dof = link.assembly_id();
        for (axis, motor) in data.motors.iter().enumerate() {
            if (locked >> axis) & 1 == 1 {
                continue;
            }
            let asked = motor.stiffness * (motor.target_pos - coords[axis])
                + motor.damping * (motor.target_vel - velocities[dof]);
            if (motorised >> axis) & 1 == 1
                && motor.model == MotorModel::ForceBased
                && asked.abs() < motor.max_force
            {
                let impedance = (n + 1.0) / (2.0 * n)
                    * (motor.damping as f64 * dt + motor.stiffness as f64 * dt * h);
                if impedance > 0.0 {
                    impedances.push((dof, impedance));
                }
            }
            dof += 1;
        }
    }
    impedances
}

/// The velocity of the centre of mass (m/s) and the angular velocity (rad/s) of the link
/// `body`, from its multibody's generalized velocities. The link's rigid-body velocity lags
/// them in rapier 0.36: after a step with 4 solver substeps it shows three quarters of an
/// impulse handed to the link, the rest only after the next step (measured, unit test below;
/// it appears to be set before the last substep's velocity increment). None if the body is
/// not a multibody link.
pub fn link_velocity(joints: &MultibodyJointSet, body: RigidBodyHandle) -> Option<(Vec3, Vec3)> {
    let link = joints.rigid_body_link(body)?;
    let multibody = joints.get_multibody(link.multibody)?;
    let jacobian = multibody.body_jacobian(link.id);
    let velocities = multibody.generalized_velocity();
    if jacobian.ncols() != velocities.nrows() {
        return None;
    }
    // Summed here, in a fixed order (see `operational_space_inertia`).
    let v = |r: usize| -> f32 {
        (0..velocities.nrows())
            .map(|k| jacobian[(r, k)] * velocities[k])
            .sum()
    };
    Some((Vec3::new(v(0), v(1), v(2)), Vec3::new(v(3), v(4), v(5))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use rapier3d::prelude::{
        ColliderBuilder, JointAxis, PhysicsWorld, RevoluteJointBuilder, RigidBodyBuilder,
    };

    /// A 1 kg cube with a 10 g rod hinged about y beside its +x face, no gravity, stepped once so
    /// that rapier has factorised the mass matrix.
    fn hinged_rod() -> (PhysicsWorld, RigidBodyHandle, RigidBodyHandle) {
        let mut world = PhysicsWorld::new();
        world.gravity = Vec3::ZERO;
        world.integration_parameters.dt = 1e-4;
        // The robot's setting (`robot.physics.solver_iterations`, rapier's default too).
        world.integration_parameters.num_solver_iterations = 4;
        let (cube, _) = world.insert(
            RigidBodyBuilder::dynamic(),
            ColliderBuilder::cuboid(0.05, 0.05, 0.05).mass(1.0),
        );
        // The rod hangs down from the hinge 1 cm off the cube's +x face, clear of it: its
        // centre 4 cm below.
        let (rod, _) = world.insert(
            RigidBodyBuilder::dynamic().translation(Vec3::new(0.06, 0.0, -0.04)),
            ColliderBuilder::cuboid(0.002, 0.005, 0.04).mass(0.01),
        );
        let joint = world
            .insert_multibody_joint(
                cube,
                rod,
                RevoluteJointBuilder::new(Vec3::Y)
                    .local_anchor1(Vec3::new(0.06, 0.0, 0.0))
                    .local_anchor2(Vec3::new(0.0, 0.0, 0.04)),
            )
            .expect("a tree");
        // No joint damping, as on the robot (rapier's default is 0.1 N m s/rad).
        let (multibody, _) = world.multibody_joints.get_mut(joint).expect("the joint");
        multibody.damping_mut().fill(0.0);
        world.step();
        (world, cube, rod)
    }

    /// An impulse on the rod alone changes its motion (from the generalized velocities) by the
    /// inverse of the inertia it presents, as rapier's next step finds.
    #[test]
    fn a_hinged_link_presents_the_inertia_the_step_finds() {
        let (mut world, cube, rod) = hinged_rod();
        let inertia =
            operational_space_inertia(&world.multibody_joints, rod, None).expect("a link");
        let impulse = Vector6::new(2e-4, 1e-4, -3e-4, 1e-6, -2e-6, 5e-7);
        let predicted = inertia.spatial().cholesky().expect("SPD").solve(&impulse);
        let dt = world.integration_parameters.dt;
        let before = link_velocity(&world.multibody_joints, rod).expect("a link");
        let rb = &mut world.bodies[rod];
        rb.add_force(Vec3::new(2e-4, 1e-4, -3e-4) / dt, true);
        rb.add_torque(Vec3::new(1e-6, -2e-6, 5e-7) / dt, true);
        world.step();
        let after = link_velocity(&world.multibody_joints, rod).expect("a link");
        let (v, w) = (after.0 - before.0, after.1 - before.1);
        let stepped = Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z).cast::<f64>();
        assert!(
            (stepped - predicted).norm() < 0.02 * predicted.norm(),
            "stepped {stepped} predicted {predicted}"
        );
        // Against cube and rod locked together (about the rod's centre): pushed along the
        // hinge axis the hinge does not turn, so the rod moves with the locked pair; pushed
        // across it, it swings with a small part of the pair's mass.
        let parts = [cube, rod].map(|h| {
            let rb = &world.bodies[h];
            let com = rb.center_of_mass();
            let own = rb
                .mass_properties()
                .local_mprops
                .reconstruct_inertia_matrix();
            (
                rb.mass() as f64,
                nalgebra::Vector3::new(com.x, com.y, com.z).cast::<f64>(),
                nalgebra::Matrix3::from_fn(|r, c| own.col(c)[r] as f64),
            )
        });
        let centre = world.bodies[rod].center_of_mass();
        let locked = YieldInertia::of_parts(
            parts,
            &nalgebra::Vector3::new(centre.x, centre.y, centre.z).cast::<f64>(),
        );
        let mobility = |y: &YieldInertia| y.spatial().cholesky().unwrap().inverse();
        let (free, held) = (mobility(&inertia), mobility(&locked));
        let along = free[(1, 1)] / held[(1, 1)];
        assert!(
            (along - 1.0).abs() < 0.01,
            "along the hinge {along} x the locked pair's"
        );
        let across = held[(0, 0)] / free[(0, 0)];
        assert!(
            across < 0.1,
            "across the hinge {across} x the locked pair's mass"
        );
    }

    /// A motor that holds the rod answers a push within the step: about the hinge the rod
    /// then turns as if its inertia carried the motor's impedance (`motor_impedances`), not
    /// as its own inertia alone would; along the hinge nothing changes.
    #[test]
    fn a_held_link_presents_its_motors_impedance() {
        let (mut world, _, rod) = hinged_rod();
        let link = world
            .multibody_joints
            .rigid_body_link(rod)
            .copied()
            .expect("a link");
        let multibody = world
            .multibody_joints
            .get_multibody_mut(link.multibody)
            .expect("its multibody");
        // A motor holding the rod where it hangs: its damping over the step a few tenths of the
        // rod's 2.1e-5 kg m^2 about the hinge.
        multibody
            .link_mut(link.id)
            .expect("the rod")
            .joint
            .data
            .set_motor(JointAxis::AngX, 0.0, 0.0, 2.0, 0.05)
            .set_motor_max_force(JointAxis::AngX, 1e3)
            .set_motor_model(JointAxis::AngX, MotorModel::ForceBased);
        world.step();
        let dt = world.integration_parameters.dt;
        let motors = Some((dt, world.integration_parameters.num_solver_iterations));
        let joints = &world.multibody_joints;
        let held = operational_space_inertia(joints, rod, motors).expect("a link");
        let free = operational_space_inertia(joints, rod, None).expect("a link");
        // Pushed across the hinge at the rod's centre.
        let impulse = Vector6::new(2e-5, 0.0, 0.0, 0.0, 0.0, 0.0);
        let predicted = |y: &YieldInertia| y.spatial().cholesky().expect("SPD").solve(&impulse);
        let before = link_velocity(joints, rod).expect("a link");
        world.bodies[rod].add_force(Vec3::new(2e-5, 0.0, 0.0) / dt, true);
        world.step();
        let after = link_velocity(&world.multibody_joints, rod).expect("a link");
        let stepped = (after.0.x - before.0.x) as f64;
        let (with_motor, without) = (predicted(&held)[0], predicted(&free)[0]);
        assert!(
            (with_motor / stepped - 1.0).abs() < 0.02,
            "stepped {stepped} with the motor's impedance {with_motor}"
        );
        assert!(
            without / stepped - 1.0 > 0.1,
            "stepped {stepped} with the rod's own inertia {without}"
        );
        let along = held.spatial()[(1, 1)] / free.spatial()[(1, 1)];
        assert!((along - 1.0).abs() < 1e-3, "along the hinge {along}");
        // A motor already at its limit (the rod is off target) cannot answer.
        let multibody = world
            .multibody_joints
            .get_multibody_mut(link.multibody)
            .expect("its multibody");
        let joint = &mut multibody.link_mut(link.id).expect("the rod").joint.data;
        joint.set_motor(JointAxis::AngX, 0.5, 0.0, 2.0, 0.05);
        joint.set_motor_max_force(JointAxis::AngX, 0.1);
        let joints = &world.multibody_joints;
        let saturated = operational_space_inertia(joints, rod, motors).expect("a link");
        let free = operational_space_inertia(joints, rod, None).expect("a link");
        assert_eq!(saturated.spatial(), free.spatial());
    }

    /// A body that is no multibody link has no articulated inertia or link velocity.
    #[test]
    fn a_free_body_is_no_link() {
        let (mut world, _, _) = hinged_rod();
        let (free, _) = world.insert(RigidBodyBuilder::dynamic(), ColliderBuilder::ball(0.01));
        assert!(operational_space_inertia(&world.multibody_joints, free, None).is_none());
        assert!(link_velocity(&world.multibody_joints, free).is_none());
    }

    /// After a step with a force on the rod, its rigid-body velocity shows only the first
    /// three of rapier's four solver substeps; the generalized velocities show all of it.
    #[test]
    fn the_link_velocity_is_read_from_the_generalized_velocities() {
        let (mut world, _, rod) = hinged_rod();
        let before = link_velocity(&world.multibody_joints, rod).expect("a link");
        let dt = world.integration_parameters.dt;
        world.bodies[rod].add_force(Vec3::new(0.0, 1e-4, 0.0) / dt, true);
        world.step();
        let full = link_velocity(&world.multibody_joints, rod)
            .expect("a link")
            .0
            .y
            - before.0.y;
        let shown = world.bodies[rod].linvel().y - before.0.y;
        assert!(
            (shown / full - 0.75).abs() < 0.02,
            "shown {shown} of {full}"
        );
    }
}
