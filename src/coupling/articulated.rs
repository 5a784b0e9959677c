//! The inertia a multibody presents at one of its links (its operational-space inertia,
//! Khatib 1987): what yields with a robot's leg within a substep when its joints move as the
//! multibody's dynamics let them.

use nalgebra::Matrix6;
use rapier3d::glamx::Vec3;
use rapier3d::prelude::{MultibodyJointSet, RigidBodyHandle};

use crate::mpm::cpic::YieldInertia;

/// `(J M^-1 J^T)^-1` for the link `body`, with `J` its body Jacobian (the velocity of its
/// centre of mass and its angular velocity, world axes, from the generalized velocities; as
/// of the end of the last step) and `M` the multibody's augmented mass matrix as rapier
/// factorised it for the last of its solver substeps (the mass matrix plus joint damping x dt,
/// armature and joint springs x dt^2, all zero on the robot). An impulse (N s,
/// N m s about the centre of mass) on the link alone changes the link's motion by `J M^-1 J^T`
/// times it, so this is the spatial inertia the link presents to the sand. None if the body is
/// not a multibody link or the factorisation does not match its degrees of freedom.
pub fn operational_space_inertia(
    joints: &MultibodyJointSet,
    body: RigidBodyHandle,
) -> Option<YieldInertia> {
    let link = joints.rigid_body_link(body)?;
    let multibody = joints.get_multibody(link.multibody)?;
    let jacobian = multibody.body_jacobian(link.id);
    let mass = multibody.inv_augmented_mass();
    if jacobian.ncols() != multibody.ndofs() || mass.l().nrows() != multibody.ndofs() {
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
    let mobility = Matrix6::<f64>::from_fn(|r, c| 0.5 * (product(r, c) + product(c, r)));
    let inertia = mobility.cholesky()?.inverse();
    let inertia = Matrix6::from_fn(|r, c| 0.5 * (inertia[(r, c)] + inertia[(c, r)]));
    Some(YieldInertia::from_spatial(inertia))
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
        ColliderBuilder, PhysicsWorld, RevoluteJointBuilder, RigidBodyBuilder,
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
        let inertia = operational_space_inertia(&world.multibody_joints, rod).expect("a link");
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

    /// A body that is no multibody link has no articulated inertia or link velocity.
    #[test]
    fn a_free_body_is_no_link() {
        let (mut world, _, _) = hinged_rod();
        let (free, _) = world.insert(RigidBodyBuilder::dynamic(), ColliderBuilder::ball(0.01));
        assert!(operational_space_inertia(&world.multibody_joints, free).is_none());
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
