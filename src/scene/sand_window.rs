//! A sand window that follows the robot (`sand.window`): only the sand from `behind_m` behind
//! the robot's body to `ahead_m` ahead of it is simulated. As the robot walks along +x, the
//! window moves in steps of `step_m`: the scene's bed is filled ahead (the same lattice as at
//! the start, at rest) and the sand behind is dropped; the solver's x walls move with it and
//! keep their rules. A long track then costs what the window's patch costs.

use serde::Deserialize;

use super::{Scene, SceneError};
use crate::mpm::Solver;

/// `sand.window`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SandWindowConfig {
    /// Sand kept behind the robot's body origin (m), > 0: beyond its hind legs' reach.
    pub behind_m: f32,
    /// Sand kept ahead of it (m), > 0: beyond its front legs' reach, with room for the new
    /// sand to settle before the legs arrive.
    pub ahead_m: f32,
    /// The window moves in steps of this length (m): a whole number of grid cells, at least
    /// one and at most `behind_m`.
    pub step_m: f32,
}

/// How far a ratio of lengths (the step in cells, the window in steps) may be from a whole
/// number and still count as one: float rounding (0.35 m / 0.05 m = 7.0000005).
const WHOLE_NUMBER_TOLERANCE: f32 = 1e-3;

/// Checks `sand.window` of a scene with sand (`dx_m` its grid spacing).
pub fn validate(scene: &Scene, window: &SandWindowConfig, dx_m: f32) -> Result<(), SceneError> {
    let field = |name: &str| format!("sand.window.{name}");
    for (name, v) in [
        ("behind_m", window.behind_m),
        ("ahead_m", window.ahead_m),
        ("step_m", window.step_m),
    ] {
        if !(v > 0.0 && v.is_finite()) {
            return Err(scene.invalid(field(name), format!("{v} must be a finite number > 0 (m)")));
        }
    }
    let cells = window.step_m / dx_m;
    if cells < 1.0 - WHOLE_NUMBER_TOLERANCE
        || (cells - cells.round()).abs() > WHOLE_NUMBER_TOLERANCE
    {
        return Err(scene.invalid(
            field("step_m"),
            format!(
                "{} m must be a whole number of cells (sand.dx_m = {dx_m} m), at least one",
                window.step_m
            ),
        ));
    }
    if window.step_m > window.behind_m {
        return Err(scene.invalid(
            field("step_m"),
            format!(
                "{} m must not exceed behind_m = {} m",
                window.step_m, window.behind_m
            ),
        ));
    }
    if scene.config.robot.is_none() {
        return Err(scene.invalid(
            "sand.window",
            "follows the robot: the scene needs a `robot`",
        ));
    }
    Ok(())
}

/// The window's state: where its ends are, and what it has added and dropped.
#[derive(Clone, Debug)]
pub struct SandWindow {
    config: SandWindowConfig,
    scene: Scene,
    /// Grid origin along x (m): window ends lie on `origin + k step_m`.
    origin_x_m: f32,
    /// The domain's x extent (m): the window never leaves it.
    domain_x_m: [f32; 2],
    /// Current back and front (m).
    pub x_m: [f32; 2],
    /// Particles added ahead and dropped behind so far.
    pub added: usize,
    pub dropped: usize,
}

impl SandWindow {
    /// The window around a robot at `robot_x_m`, applied to a solver filled with the whole bed:
    /// the sand outside is removed and the x walls set.
    pub fn new(
        scene: &Scene,
        config: SandWindowConfig,
        solver: &mut Solver,
        robot_x_m: f32,
    ) -> Self {
        let domain = &scene.sand().expect("a window implies sand").domain;
        let mut window = SandWindow {
            config,
            scene: scene.clone(),
            origin_x_m: domain.min_m[0],
            domain_x_m: [domain.min_m[0], domain.max_m[0]],
            x_m: [domain.min_m[0], domain.max_m[0]],
            added: 0,
            dropped: 0,
        };
        let [back, front] = window.target(robot_x_m);
        solver.remove_particles(|x| (back..front).contains(&x.x));
        window.x_m = [back, front];
        solver.set_x_walls(back, front);
        window
    }

    /// Back and front of the window for a robot at `robot_x_m`, on whole steps. Near a domain
    /// end the window stops there, keeping its whole length (`behind_m + ahead_m`) inside the
    /// domain, or all of a shorter domain: a robot that walks past the end of the bed keeps
    /// the last window's sand behind it.
    fn target(&self, robot_x_m: f32) -> [f32; 2] {
        let step = self.config.step_m;
        let [domain_min, domain_max] = self.domain_x_m;
        let on_steps = |x: f32, round: fn(f32) -> f32| {
            (self.origin_x_m + round((x - self.origin_x_m) / step) * step)
                .clamp(domain_min, domain_max)
        };
        let length = self.config.behind_m + self.config.ahead_m;
        let back = on_steps(robot_x_m - self.config.behind_m, f32::floor);
        let front = on_steps(robot_x_m + self.config.ahead_m, f32::ceil);
        // The length in whole steps, rounded to the nearer step where float rounding leaves it
        // a hair off one.
        [
            back.min(on_steps(domain_max - length, |s| {
                (s + WHOLE_NUMBER_TOLERANCE).floor()
            })),
            front.max(on_steps(domain_min + length, |s| {
                (s - WHOLE_NUMBER_TOLERANCE).ceil()
            })),
        ]
    }

    /// Moves the window forward to follow a robot at `robot_x_m` (never back): fills the bed
    /// ahead, drops the sand behind, moves the walls. Returns whether it moved.
    pub fn follow(&mut self, solver: &mut Solver, robot_x_m: f32) -> bool {
        let [back, front] = self.target(robot_x_m);
        let [old_back, old_front] = self.x_m;
        if back <= old_back && front <= old_front {
            return false;
        }
        if front > old_front {
            let slab = self.scene.sand_particles(Some(old_front..front));
            self.added += slab.len();
            solver.add_particles(slab);
        }
        let back = back.max(old_back);
        if back > old_back {
            self.dropped += solver.remove_particles(|x| x.x >= back);
        }
        self.x_m = [back, front.max(old_front)];
        solver.set_x_walls(self.x_m[0], self.x_m[1]);
        true
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    const WINDOW: &str = "sand.window={behind_m: 0.1, ahead_m: 0.2, step_m: 0.05}";

    fn scene(overrides: &[&str]) -> Result<Scene, SceneError> {
        let overrides: Vec<String> = ["sand.dx_m=0.0125"]
            .iter()
            .chain(overrides)
            .map(|s| s.to_string())
            .collect();
        Scene::load(Path::new("config/robot_on_sand.yaml"), &overrides)
    }

    /// Particle positions, sorted, as bit patterns (exact comparison).
    fn lattice(positions: &[nalgebra::Vector3<f32>]) -> Vec<[u32; 3]> {
        let mut bits: Vec<[u32; 3]> = positions
            .iter()
            .map(|x| [x.x.to_bits(), x.y.to_bits(), x.z.to_bits()])
            .collect();
        bits.sort_unstable();
        bits
    }

    #[test]
    fn window_fills_ahead_and_drops_behind_on_the_beds_own_lattice() {
        let scene = scene(&[WINDOW]).unwrap();
        let mut solver = scene.build_solver().unwrap();
        let whole_bed = solver.particles.len();
        let config = scene.sand().unwrap().window.unwrap();
        // The bed runs from x = -0.12 m: the window's ends lie on -0.12 + k 0.05 m.
        let mut window = SandWindow::new(&scene, config, &mut solver, 0.0);
        let [back, front] = window.x_m;
        assert!(
            (back + 0.12).abs() < 1e-6 && (front - 0.23).abs() < 1e-6,
            "{:?}",
            window.x_m
        );
        assert_eq!(solver.x_walls_m(), window.x_m);
        let start = solver.particles.len();
        assert!(start < whole_bed / 2, "{start} of {whole_bed}");

        // The robot walks 0.2 m: the window moves 4 steps; what it holds is exactly the bed's
        // lattice between its new ends, nothing doubled and no gap at the slabs' seams.
        assert!(window.follow(&mut solver, 0.2));
        let [back, front] = window.x_m;
        assert!(
            (back - 0.08).abs() < 1e-6 && (front - 0.43).abs() < 1e-6,
            "{:?}",
            window.x_m
        );
        assert_eq!(solver.x_walls_m(), window.x_m);
        let direct = scene.sand_particles(Some(back..front));
        let direct: Vec<_> = direct.iter().map(|p| p.position).collect();
        assert_eq!(lattice(&solver.particles.position), lattice(&direct));
        assert_eq!(
            start + window.added - window.dropped,
            solver.particles.len()
        );
        assert!(window.added > 0 && window.dropped > 0);
        // Every particle keeps a unique id.
        let mut ids = solver.particles.id.clone();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), solver.particles.len());

        // Walking back, or less than a step, moves nothing.
        assert!(!window.follow(&mut solver, 0.0));
        assert!(!window.follow(&mut solver, 0.21));
        assert_eq!(window.x_m, [back, front]);
    }

    /// A robot that walks to the end of the bed, or past it, or starts behind its beginning,
    /// leaves the window at the domain's end with its whole length: the walls never meet
    /// (issue 22: the track with a short domain panicked at t = 2.96 s).
    #[test]
    fn the_window_stops_at_the_domains_ends() {
        let scene = scene(&[WINDOW]).unwrap();
        let mut solver = scene.build_solver().unwrap();
        let config = scene.sand().unwrap().window.unwrap();
        let mut window = SandWindow::new(&scene, config, &mut solver, 0.0);
        // The bed runs from -0.12 to 0.8 m; the window is 0.3 m long, on 0.05 m steps.
        for robot_x_m in [0.7, 0.8, 0.95, 5.0] {
            window.follow(&mut solver, robot_x_m);
            let [back, front] = window.x_m;
            assert!(
                (front - 0.8).abs() < 1e-6 && (back - 0.48).abs() < 1e-6,
                "robot at {robot_x_m} m: {:?}",
                window.x_m
            );
            assert_eq!(solver.x_walls_m(), window.x_m);
            assert!(solver.particles.position.iter().all(|x| x.x >= back));
        }
        let mut solver = scene.build_solver().unwrap();
        let behind = SandWindow::new(&scene, config, &mut solver, -1.0);
        let [back, front] = behind.x_m;
        let length = front - back;
        assert!(
            (back + 0.12).abs() < 1e-6 && (0.3 - 1e-6..0.35 + 1e-6).contains(&length),
            "{:?}",
            behind.x_m
        );
        assert!(!solver.particles.is_empty());
    }

    #[test]
    fn bad_windows_name_the_field() {
        let error = |set: &str| scene(&[set]).unwrap_err().to_string();
        let cells = error("sand.window={behind_m: 0.1, ahead_m: 0.2, step_m: 0.03}");
        assert!(
            cells.contains("sand.window.step_m") && cells.contains("whole number"),
            "{cells}"
        );
        let behind = error("sand.window={behind_m: 0.05, ahead_m: 0.2, step_m: 0.1}");
        assert!(
            behind.contains("sand.window.step_m") && behind.contains("behind_m"),
            "{behind}"
        );
        let negative = error("sand.window={behind_m: -0.1, ahead_m: 0.2, step_m: 0.05}");
        assert!(negative.contains("sand.window.behind_m"), "{negative}");
        let no_robot = scene(&[WINDOW, "robot=null"]).unwrap_err().to_string();
        assert!(
            no_robot.contains("sand.window") && no_robot.contains("robot"),
            "{no_robot}"
        );
    }
}
