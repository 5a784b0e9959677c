//! The explicit MLS-MPM solver (Hu et al. 2018) on a sparse block grid: particles, grid, and
//! the substep, one file per stage, each timed by name ([`Stage`]):
//!
//! | stage | file | what it does |
//! |---|---|---|
//! | sort | `sort.rs` | particles in grid-block order |
//! | sleep, grid_alloc | `active_blocks.rs` | sleeping sand; the grid over the awake blocks |
//! | cpic | `cpic_grid.rs` | colours near colliders, particle tags |
//! | p2g | `p2g.rs` | mass and momentum (with stress and APIC terms) to the grid |
//! | grid_update | `grid_update.rs` | velocities, gravity, walls |
//! | g2p | `g2p.rs` | velocity and its gradient back, advection, CPIC push-back |
//! | particle_update | `particle_update.rs` | F, the constitutive update, the blow-up check |
//!
//! `docs/physics.md`, section 1, has the equations; `tests.rs` holds the dense reference
//! substep the sparse one is checked against.

mod active_blocks;
mod cpic_grid;
mod error;
mod g2p;
mod grid_update;
mod p2g;
mod particle_update;
mod settings;
mod sort;
mod stages;
#[cfg(test)]
pub(crate) mod tests;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};

use super::boundary::WallNodes;
use super::cpic::{ColliderImpulse, ColliderMotion, ColourBlock};
use super::grid::{
    arena_slots, ArenaSlot, Block, ParticleBlock, SparseGrid, ARENA_NODES, BLOCK_EDGE,
};
use super::kernel::Stencil;
use super::particles::{NewParticle, Particles, ReorderScratch};
use super::simd::InstructionSet;
use super::sleep::{Sleep, SleepChanges, WakeZone};
use cpic_grid::{add_impulses, GridColours};
pub use error::SimError;
pub use settings::{
    CpicBand, SolverMaterial, SolverSettings, TimeStep, Transfer, DEFAULT_CPIC_BAND_RELAXATION_S,
    DEFAULT_FLIP_RELAXATION_S,
};
pub use stages::{Stage, StageTimes};

/// The explicit MLS-MPM solver.
pub struct Solver {
    pub settings: SolverSettings,
    pub materials: Vec<SolverMaterial>,
    /// Read it freely; add and remove particles through [`Solver::add_particles`] and
    /// [`Solver::remove_particles`] only, and leave positions and order to the substep: the
    /// sort keeps the block keys of sleeping particles from one substep to the next.
    pub particles: Particles,
    grid: SparseGrid,
    /// Grid node index of the min and the max walls, per axis: the domain's, or an x window
    /// inside it ([`Solver::set_x_walls`]).
    wall_nodes: WallNodes,
    /// The box particles are clamped into (m): the domain, or the x window inside it.
    bounds: [Vector3<f32>; 2],
    arena_slots: [ArenaSlot; ARENA_NODES],
    /// Block key of each particle, in particle order.
    keys: Vec<u32>,
    /// Scratch permutation for sorting.
    order: Vec<u32>,
    /// Spare particle arrays for sorting.
    reorder_scratch: ReorderScratch,
    /// Spare key array for sorting.
    sorted_keys: Vec<u32>,
    /// CPIC colours of the grid blocks near colliders, for the current substep.
    colours: GridColours,
    /// Whether some particle carries CPIC tags (so they must be updated or cleared).
    tagged: bool,
    /// Velocity gradient `C` of each particle (1/s), from G2P to the particle update of the same
    /// substep (the affine matrix kept for P2G is `C` under APIC and zero under PIC).
    velocity_gradient: Vec<Matrix3<f32>>,
    /// AFLIP: the velocity (m/s; momentum in P2G) each grid node gets from the transfer alone
    /// of the particles that keep a deviation (away from colliders; with `CpicBand::Bulk` also
    /// those near one, on their compatible nodes), `sum w m (v + C (x_i - x_p)) / m_i`, without the
    /// stress impulse, gravity and walls; zero where no mass; in the order of the grid's blocks.
    transferred_velocity: Vec<Block>,
    /// Which blocks sleep (`settings.sleep`).
    sleep: Option<Sleep>,
    /// Block wakes and sleeps so far.
    pub sleep_changes: SleepChanges,
    /// Awake particles summed over the substeps taken (each particle stepped once a substep).
    pub awake_particle_steps: u64,
    /// Largest particle speed after the last substep (m/s).
    max_speed_m_s: f32,
    /// The instruction set of the wide loops (the particle update): `SANDSTEP_SIMD`, or the best
    /// this CPU has. Changes speed only: every path gives the same bits.
    instruction_set: InstructionSet,
    /// Simulated time (s).
    pub time_s: f64,
    /// Substeps taken.
    pub steps: u64,
    pub stage_times: StageTimes,
    /// A stop request (Ctrl-C), looked at when a substep starts, before G2P, and between the
    /// particle blocks of P2G and G2P ([`Solver::stop_on`]).
    stop: Arc<AtomicBool>,
    /// The stop that tore a substep inside G2P, once one has: the sand is then stepped no more.
    torn: Option<SimError>,
}

impl Solver {
    pub fn new(settings: SolverSettings, materials: Vec<SolverMaterial>) -> Self {
        let grid = SparseGrid::new(settings.dx, settings.domain_min, settings.domain_max);
        let extent = settings.domain_max - settings.domain_min;
        // Tolerate round-off when the extent is a whole number of cells.
        let wall_max_node = [0, 1, 2].map(|a| (extent[a] / settings.dx - 1e-3).ceil() as i32);
        let bounds = [settings.domain_min, settings.domain_max];
        let sleep = settings.sleep.map(|s| Sleep::new(s, grid.lattice().len()));
        Solver {
            settings,
            materials,
            particles: Particles::default(),
            grid,
            wall_nodes: [[0; 3], wall_max_node],
            bounds,
            arena_slots: arena_slots(),
            sleep,
            sleep_changes: SleepChanges::default(),
            awake_particle_steps: 0,
            keys: Vec::new(),
            order: Vec::new(),
            reorder_scratch: ReorderScratch::default(),
            sorted_keys: Vec::new(),
            colours: GridColours::default(),
            tagged: false,
            velocity_gradient: Vec::new(),
            transferred_velocity: Vec::new(),
            max_speed_m_s: 0.0,
            instruction_set: InstructionSet::from_env().unwrap_or_else(|_| InstructionSet::best()),
            time_s: 0.0,
            steps: 0,
            stage_times: StageTimes::default(),
            stop: Arc::new(AtomicBool::new(false)),
            torn: None,
        }
    }

    /// Looks at `stop` inside every substep from now on: once it is set, the substep under way
    /// ends with [`SimError::Stopped`] (seen before G2P: nothing moved) or
    /// [`SimError::StoppedMidTransfer`] (seen during G2P: the blocks done moved on by the
    /// substep, each particle whole, and the solver steps no further), and
    /// [`Solver::advance_to`] returns early. It is looked at when a substep starts, before G2P,
    /// and between the particle blocks of P2G and G2P: a stop waits for the sort and grid
    /// allocation at most (0.04 s at 6.8 M particles on 2 cores, `docs/ros.md`).
    pub fn stop_on(&mut self, stop: Arc<AtomicBool>) {
        self.stop = stop;
    }

    /// Whether a stop has been requested.
    fn stop_requested(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// [`SimError::Stopped`] if a stop has been requested, seen during `stage`.
    fn unless_stopped(&self, stage: &'static str) -> Result<(), SimError> {
        match self.stop_requested() {
            false => Ok(()),
            true => Err(SimError::Stopped {
                step: self.steps,
                time_s: self.time_s,
                stage,
            }),
        }
    }

    /// Adds particles (undeformed, stress free).
    pub fn add_particles(&mut self, new: impl IntoIterator<Item = NewParticle>) {
        // The sort takes every key afresh.
        self.keys.clear();
        for p in new {
            self.max_speed_m_s = self.max_speed_m_s.max(p.velocity.norm());
            self.particles.push(p);
        }
    }

    /// `new` in the order the substep's sort would put them (stable, by grid block): added in
    /// this order, a freshly filled bed leaves the first substep's sort nothing to do (6.8 M
    /// particles otherwise spend half a second there, where no stop request is looked at).
    pub fn in_block_order(&self, new: Vec<NewParticle>) -> Vec<NewParticle> {
        use rayon::prelude::*;
        // Key and index in one u64: all distinct, so any sort gives the stable order.
        let mut keyed: Vec<u64> = new
            .par_iter()
            .enumerate()
            .map(|(i, p)| (u64::from(self.grid.block_key(&p.position)) << 32) | i as u64)
            .collect();
        keyed.par_sort_unstable();
        keyed
            .par_iter()
            .map(|k| new[(k & u64::from(u32::MAX)) as usize])
            .collect()
    }

    /// Makes room for `additional` more particles.
    pub fn reserve_particles(&mut self, additional: usize) {
        self.particles.reserve(additional);
    }

    /// Moves the x walls to the grid planes nearest `lo_m` and `hi_m` (m), within the domain:
    /// the sand then keeps to that window of the domain (the scene's sand window follows the
    /// robot this way). The walls keep their rules (`settings.walls.x_min`, `x_max`).
    pub fn set_x_walls(&mut self, lo_m: f32, hi_m: f32) {
        let (origin, dx) = (self.settings.domain_min.x, self.settings.dx);
        let domain_max_node = ((self.settings.domain_max.x - origin) / dx - 1e-3).ceil() as i32;
        let node = |x: f32| (((x - origin) / dx).round() as i32).clamp(0, domain_max_node);
        let (lo, hi) = (node(lo_m), node(hi_m));
        assert!(lo < hi, "x walls at {lo_m} and {hi_m} m leave no room");
        self.wall_nodes[0][0] = lo;
        self.wall_nodes[1][0] = hi;
        self.bounds[0].x = origin + lo as f32 * dx;
        self.bounds[1].x = (origin + hi as f32 * dx).min(self.settings.domain_max.x);
    }

    /// Where the x walls are (m): the domain's ends or the window of [`Solver::set_x_walls`].
    pub fn x_walls_m(&self) -> [f32; 2] {
        [self.bounds[0].x, self.bounds[1].x]
    }

    /// Removes the particles for which `keep(position)` is false; returns how many.
    pub fn remove_particles(&mut self, keep: impl Fn(&Vector3<f32>) -> bool) -> usize {
        self.keys.clear();
        self.particles.retain(keep)
    }

    /// Particles stepped in the current substep: all but the sleeping ones.
    pub fn awake_particles(&self) -> usize {
        match &self.sleep {
            None => self.particles.len(),
            Some(_) => self
                .grid
                .particle_blocks
                .iter()
                .map(|pb| pb.end - pb.start)
                .sum(),
        }
    }

    /// Blocks of sand asleep now (0 without `settings.sleep`).
    pub fn asleep_blocks(&self) -> usize {
        self.sleep.as_ref().map_or(0, Sleep::asleep_blocks)
    }

    /// The instruction set the wide loops run with.
    pub fn instruction_set(&self) -> InstructionSet {
        self.instruction_set
    }

    /// Runs the wide loops with `instruction_set` from now on (the results stay the same bits).
    pub fn set_instruction_set(&mut self, instruction_set: InstructionSet) {
        self.instruction_set = instruction_set;
    }

    /// The sparse grid (valid after a substep).
    pub fn grid(&self) -> &SparseGrid {
        &self.grid
    }

    /// Time step the next substep will take (s): the CFL bound and `max_dt_s`, or the fixed step.
    /// (The sand's in-cone viscosity needs no bound of its own: its stress is cut to what keeps
    /// the total in the cone, [`crate::mpm::material::DruckerPrager::elastic_viscosity_pa_s`].)
    pub fn next_dt(&self) -> f32 {
        match self.settings.time_step {
            TimeStep::Fixed { dt_s } => dt_s,
            TimeStep::Adaptive { cfl, max_dt_s } => {
                let c = self
                    .materials
                    .iter()
                    .map(|m| m.wave_speed_m_s())
                    .fold(0.0, f32::max);
                (cfl * self.settings.dx / (c + self.max_speed_m_s)).min(max_dt_s)
            }
        }
    }

    /// One explicit MLS-MPM substep (physics.md section 1). Returns the dt taken (s).
    pub fn substep(&mut self) -> Result<f32, SimError> {
        self.substep_by(self.next_dt())
    }

    /// One substep of `dt` seconds, with no colliders.
    fn substep_by(&mut self, dt: f32) -> Result<f32, SimError> {
        self.begin_substep(&[]);
        self.finish_substep(dt, &[]).map(|_| dt)
    }

    /// First half of a substep: sorts the particles, wakes and puts to sleep blocks of sand
    /// (with `settings.sleep`; sand near `wake_zones` stays awake) and allocates the grid for
    /// the awake sand. A coupling may then colour the grid near its colliders
    /// ([`Self::colour_nodes`]) before [`Self::finish_substep`].
    pub fn begin_substep(&mut self, wake_zones: &[WakeZone]) {
        let mut times = std::mem::take(&mut self.stage_times);
        times.time(Stage::Sort, || self.sort_particles_by_block());
        times.time(Stage::Sleep, || self.update_sleep(wake_zones));
        times.time(Stage::GridAlloc, || self.allocate_grid());
        self.stage_times = times;
    }

    /// Gives the CPIC colours of the active blocks: `colour(block)` returns the colours of the
    /// block at block coordinate `block` (its node `n` is grid node `4 block + local(n)`, see
    /// [`SparseGrid::node_position`]), or None if no collider is near. Runs in parallel.
    pub fn colour_nodes(&mut self, colour: impl Fn([i32; 3]) -> Option<ColourBlock> + Sync) {
        let mut times = std::mem::take(&mut self.stage_times);
        times.time(Stage::Cpic, || self.colour_blocks(colour));
        self.stage_times = times;
    }

    /// Second half of a substep: P2G, grid update, G2P and the particle update of `dt`
    /// seconds, with CPIC against `colliders` (indexed like the colour bits) wherever the grid
    /// was coloured. Returns the momentum the sand handed to each collider during the substep.
    pub fn finish_substep(
        &mut self,
        dt: f32,
        colliders: &[ColliderMotion],
    ) -> Result<Vec<ColliderImpulse>, SimError> {
        if let Some(torn) = &self.torn {
            return Err(torn.clone());
        }
        self.unless_stopped("the start")?;
        let mut times = std::mem::take(&mut self.stage_times);
        times.time(Stage::Cpic, || self.update_particle_tags());
        let p2g_impulses = times.time(Stage::P2g, || self.particle_to_grid(dt, colliders));
        times.time(Stage::GridUpdate, || self.update_grid(dt, colliders));
        // P2G skips its blocks once a stop is requested; the grid is then abandoned here.
        if let Err(stopped) = self.unless_stopped("the transfer to the grid") {
            self.stage_times = times;
            return Err(stopped);
        }
        // Light bodies yield to the sand they meet within the substep (see `yielded`).
        let colliders: Vec<ColliderMotion> = colliders
            .iter()
            .enumerate()
            .map(|(r, c)| c.yielded(p2g_impulses.get(r)))
            .collect();
        let (g2p_impulses, moved) =
            times.time(Stage::G2p, || self.grid_to_particle(dt, &colliders));
        let checked = times.time(Stage::ParticleUpdate, || {
            self.update_particles(dt, moved.as_deref())
        });
        self.stage_times = times;
        if let Some(moved) = moved {
            let torn = SimError::StoppedMidTransfer {
                step: self.steps,
                time_s: self.time_s,
                dt_s: dt,
                moved: moved.iter().filter(|&&m| m).count(),
                blocks: moved.len(),
            };
            self.torn = Some(torn.clone());
            return Err(torn);
        }

        self.time_s += dt as f64;
        self.steps += 1;
        self.awake_particle_steps += self.awake_particles() as u64;
        checked?;
        let mut impulses = add_impulses(g2p_impulses, &p2g_impulses);
        impulses.resize(colliders.len(), ColliderImpulse::default());
        Ok(impulses)
    }

    /// Substeps until the simulated time reaches `time_s`; the last step is shortened to land on
    /// it. Returns the number of substeps taken. Returns early, inside the substep under way,
    /// once a stop is requested ([`Solver::stop_on`]).
    pub fn advance_to(&mut self, time_s: f64) -> Result<u64, SimError> {
        let mut n = 0;
        while self.time_s < time_s - 1e-12 && !self.stop_requested() {
            let remaining = (time_s - self.time_s) as f32;
            match self.substep_by(self.next_dt().min(remaining)) {
                Err(e) if e.is_stop() => break,
                result => result?,
            };
            n += 1;
        }
        Ok(n)
    }

    /// Bytes held by particles, grid and solver scratch.
    pub fn memory_bytes(&self) -> usize {
        self.particles.memory_bytes()
            + self.grid.memory_bytes()
            + self.reorder_scratch.memory_bytes()
            + (self.keys.capacity() + self.order.capacity() + self.sorted_keys.capacity())
                * std::mem::size_of::<u32>()
            + self.velocity_gradient.capacity() * std::mem::size_of::<Matrix3<f32>>()
            + self.transferred_velocity.capacity() * std::mem::size_of::<Block>()
    }
}

/// `m diag(factors)`: column `j` of `m` times `factors[j]` (the kernel's `D^-1` on the right,
/// without a matrix product per particle).
#[inline(always)]
fn scale_columns(m: &Matrix3<f32>, factors: &Vector3<f32>) -> Matrix3<f32> {
    Matrix3::from_fn(|i, j| m[(i, j)] * factors[j])
}

/// Offset of a particle's stencil base node inside its block's arena (each in `0..4`).
#[inline(always)]
fn local_base(s: &Stencil, pb: &ParticleBlock) -> [usize; 3] {
    [0, 1, 2].map(|a| (s.base[a] - pb.coord[a] * BLOCK_EDGE) as usize)
}

/// Splits `data` into the particle runs of `blocks`, in order (the runs of sleeping blocks
/// between them are left out).
fn split_runs<'a, T>(mut data: &'a mut [T], blocks: &[ParticleBlock]) -> Vec<&'a mut [T]> {
    let mut taken = 0;
    blocks
        .iter()
        .map(|pb| {
            let (_, rest) = std::mem::take(&mut data).split_at_mut(pb.start - taken);
            let (run, rest) = rest.split_at_mut(pb.end - pb.start);
            (data, taken) = (rest, pb.end);
            run
        })
        .collect()
}
