//! The MLS-MPM solver: particles, sparse grid, and the explicit substep.

use std::time::{Duration, Instant};

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::boundary::{WallNodes, Walls};
use super::cpic::{
    conflict_normal, conflicts, ghost_velocity, stencil_nodes, update_tags, wall_distance,
    ColliderImpulse, ColliderMotion, ColourBlock, NodeColour, PENALTY_MAX_CELLS, PENALTY_MIN_CELLS,
};
use super::grid::{
    arena_slots, node_in_arena, ArenaSlot, Block, ParticleBlock, SparseGrid, ARENA_NODES,
    BLOCK_EDGE,
};
use super::kernel::{Kernel, Stencil};
use super::material::Constitutive;
use super::particles::{MaterialId, NewParticle, Particles, ReorderScratch};
use super::simd::F4;
use super::sleep::{Sleep, SleepChanges, SleepSettings, WakeZone};
use super::svd::{Frame, COLD_START};

/// Particles whose constitutive updates run together (the SVD's SIMD width).
const LANES: usize = 8;

/// A material the particles can be made of.
#[derive(Clone, Debug)]
pub struct SolverMaterial {
    /// Name from the scene file, for messages.
    pub name: String,
    /// Mass density rho (kg/m^3) of the undeformed material.
    pub density_kg_m3: f32,
    /// Elasticity and plasticity.
    pub model: Constitutive,
}

impl SolverMaterial {
    /// Dilatational wave speed `sqrt((lambda + 2 mu) / rho)` (m/s), which bounds the time step.
    pub fn wave_speed_m_s(&self) -> f32 {
        let lame = self.model.lame();
        ((lame.lambda + 2.0 * lame.mu) / self.density_kg_m3).sqrt()
    }
}

/// How the time step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimeStep {
    /// `dt = cfl * dx / (c + max |v_p|)`, at most `max_dt_s`.
    Adaptive { cfl: f32, max_dt_s: f32 },
    /// A fixed step (s), whatever the CFL condition says.
    Fixed { dt_s: f32 },
}

/// How particle velocities reach the grid (physics.md section 1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Transfer {
    /// Affine particle-in-cell (Jiang et al. 2015), MLS-MPM's: each particle carries its local
    /// velocity field `v + C (x - x_p)`, which keeps angular momentum.
    #[default]
    Apic,
    /// Plain particle-in-cell: only `v` is transferred (C is still the velocity gradient that
    /// updates F), which damps every rotation and shear of the velocity field. For comparison.
    Pic,
}

/// Everything the solver needs besides particles and materials.
#[derive(Clone, Debug)]
pub struct SolverSettings {
    /// Grid node spacing (m).
    pub dx: f32,
    /// Min corner of the domain box (m); also the grid origin.
    pub domain_min: Vector3<f32>,
    /// Max corner of the domain box (m).
    pub domain_max: Vector3<f32>,
    /// How each wall of the box acts on the sand.
    pub walls: Walls,
    /// Gravitational acceleration (m/s^2).
    pub gravity: Vector3<f32>,
    pub time_step: TimeStep,
    /// A particle faster than this (m/s) means the simulation has blown up.
    pub blowup_speed_m_s: f32,
    pub transfer: Transfer,
    pub kernel: Kernel,
    /// Sleeping sand (blocks at rest left out of the substep), or none: every particle is
    /// stepped every substep.
    pub sleep: Option<SleepSettings>,
}

/// Wall time spent in each stage of the substep, by name.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimes {
    /// Sorting particles by grid block.
    pub sort: Duration,
    /// Finding active blocks and clearing their nodes.
    pub grid_alloc: Duration,
    /// Particle to grid transfer (fused APIC momentum and stress).
    pub p2g: Duration,
    /// Grid velocities, gravity, walls.
    pub grid_update: Duration,
    /// Grid to particle transfer, advection, constitutive update, blow-up check.
    pub g2p: Duration,
    /// CPIC: colouring the grid near colliders and updating particle tags.
    pub cpic: Duration,
    /// Sleeping sand: waking and putting blocks to sleep.
    pub sleep: Duration,
}

impl StageTimes {
    /// `(name, time)` of every stage, in substep order.
    pub fn named(&self) -> [(&'static str, Duration); 7] {
        [
            ("sort", self.sort),
            ("sleep", self.sleep),
            ("grid_alloc", self.grid_alloc),
            ("cpic", self.cpic),
            ("p2g", self.p2g),
            ("grid_update", self.grid_update),
            ("g2p", self.g2p),
        ]
    }

    pub fn total(&self) -> Duration {
        self.named().iter().map(|(_, t)| *t).sum()
    }
}

/// A simulation that cannot go on.
#[derive(thiserror::Error, Debug, Clone)]
pub enum SimError {
    #[error(
        "simulation blew up at step {step} (t = {time_s:.6} s, dt = {dt_s:.3e} s): particle {particle} {what} \
         (position {position:?} m, velocity {velocity:?} m/s); reduce the time step (solver.cfl, \
         solver.max_dt_s, solver.fixed_dt_s) or check the material parameters"
    )]
    BlowUp {
        step: u64,
        time_s: f64,
        dt_s: f32,
        /// Persistent id of the worst particle.
        particle: u32,
        what: String,
        position: [f32; 3],
        velocity: [f32; 3],
    },
}

/// The first bad particle found by G2P, by sorted index.
#[derive(Clone, Debug)]
struct BadParticle {
    index: usize,
    what: String,
}

/// Result of G2P over one block.
#[derive(Clone, Debug, Default)]
struct G2pSummary {
    max_speed_sq: f32,
    bad: Option<BadParticle>,
    /// Penalty impulses per collider (empty where no particle is near one).
    impulses: Vec<ColliderImpulse>,
}

impl G2pSummary {
    fn merge(self, other: Self) -> Self {
        let bad = match (self.bad, other.bad) {
            (Some(a), Some(b)) => Some(if a.index <= b.index { a } else { b }),
            (a, b) => a.or(b),
        };
        G2pSummary {
            max_speed_sq: self.max_speed_sq.max(other.max_speed_sq),
            bad,
            impulses: add_impulses(self.impulses, &other.impulses),
        }
    }
}

/// The explicit MLS-MPM solver.
pub struct Solver {
    pub settings: SolverSettings,
    pub materials: Vec<SolverMaterial>,
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
    /// Which blocks sleep (`settings.sleep`).
    sleep: Option<Sleep>,
    /// Block wakes and sleeps so far.
    pub sleep_changes: SleepChanges,
    /// Awake particles summed over the substeps taken (each particle stepped once a substep).
    pub awake_particle_steps: u64,
    /// Largest particle speed after the last substep (m/s).
    max_speed_m_s: f32,
    /// Simulated time (s).
    pub time_s: f64,
    /// Substeps taken.
    pub steps: u64,
    pub stage_times: StageTimes,
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
            max_speed_m_s: 0.0,
            time_s: 0.0,
            steps: 0,
            stage_times: StageTimes::default(),
        }
    }

    /// Adds particles (undeformed, stress free).
    pub fn add_particles(&mut self, new: impl IntoIterator<Item = NewParticle>) {
        for p in new {
            self.max_speed_m_s = self.max_speed_m_s.max(p.velocity.norm());
            self.particles.push(p);
        }
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

    /// The sparse grid (valid after a substep).
    pub fn grid(&self) -> &SparseGrid {
        &self.grid
    }

    /// Time step the next substep will take (s).
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
        let t = Instant::now();
        self.sort_particles_by_block();
        self.stage_times.sort += t.elapsed();

        let t = Instant::now();
        if let Some(sleep) = &mut self.sleep {
            let (velocity, affine) = (&mut self.particles.velocity, &mut self.particles.affine);
            let changes = sleep.update(&self.grid, &self.keys, wake_zones, |run| {
                velocity[run.clone()].fill(Vector3::zeros());
                affine[run].fill(Matrix3::zeros());
            });
            self.sleep_changes.woken += changes.woken;
            self.sleep_changes.fell_asleep += changes.fell_asleep;
        }
        self.stage_times.sleep += t.elapsed();

        let t = Instant::now();
        let sleep = &self.sleep;
        self.grid.rebuild(&self.keys, |key| {
            sleep.as_ref().is_some_and(|s| s.is_asleep(key))
        });
        self.colours.clear(self.grid.blocks.len());
        self.stage_times.grid_alloc += t.elapsed();
    }

    /// Gives the CPIC colours of the active blocks: `colour(block)` returns the colours of the
    /// block at block coordinate `block` (its node `n` is grid node `4 block + local(n)`, see
    /// [`SparseGrid::node_position`]), or None if no collider is near. Runs in parallel.
    pub fn colour_nodes(&mut self, colour: impl Fn([i32; 3]) -> Option<ColourBlock> + Sync) {
        let t = Instant::now();
        let coloured: Vec<Option<ColourBlock>> =
            self.grid.coords.par_iter().map(|&c| colour(c)).collect();
        for (slot, c) in coloured.into_iter().enumerate() {
            if let Some(c) = c {
                self.colours.of_block[slot] = self.colours.blocks.len() as u32;
                self.colours.blocks.push(c);
            }
        }
        self.stage_times.cpic += t.elapsed();
    }

    /// Second half of a substep: P2G, grid update and G2P of `dt` seconds, with CPIC against
    /// `colliders` (indexed like the colour bits) wherever the grid was coloured. Returns the
    /// momentum the sand handed to each collider during the substep.
    pub fn finish_substep(
        &mut self,
        dt: f32,
        colliders: &[ColliderMotion],
    ) -> Result<Vec<ColliderImpulse>, SimError> {
        let t = Instant::now();
        self.update_particle_tags();
        self.stage_times.cpic += t.elapsed();

        let t = Instant::now();
        let p2g_impulses = self.particle_to_grid(dt, colliders);
        self.stage_times.p2g += t.elapsed();

        let t = Instant::now();
        self.update_grid(dt, colliders);
        self.stage_times.grid_update += t.elapsed();

        // Light bodies yield to the sand they meet within the substep (see `yielded`).
        let colliders: Vec<ColliderMotion> = colliders
            .iter()
            .enumerate()
            .map(|(r, c)| c.yielded(p2g_impulses.get(r)))
            .collect();
        let colliders = &colliders[..];

        let t = Instant::now();
        let result = self.grid_to_particle(dt, colliders);
        self.stage_times.g2p += t.elapsed();

        self.time_s += dt as f64;
        self.steps += 1;
        self.awake_particle_steps += self.awake_particles() as u64;
        let mut impulses = add_impulses(result?, &p2g_impulses);
        impulses.resize(colliders.len(), ColliderImpulse::default());
        Ok(impulses)
    }

    /// Keeps each particle's CPIC tags (see [`super::cpic::update_tags`]); clears them away from
    /// colliders. Free when no collider is near and no particle is tagged.
    fn update_particle_tags(&mut self) {
        if self.colours.blocks.is_empty() && !self.tagged {
            return;
        }
        let grid = &self.grid;
        let colours = &self.colours;
        let slots = &self.arena_slots;
        let positions = &self.particles.position;
        let blocks = &grid.particle_blocks;
        let runs = split_runs(&mut self.particles.cpic_tags, blocks);
        self.tagged = runs
            .into_par_iter()
            .zip(blocks.par_iter())
            .map(|(tags, pb)| {
                let Some(arena) = colours.arena(pb, slots) else {
                    tags.fill(0);
                    return false;
                };
                for (tag, x) in tags.iter_mut().zip(&positions[pb.start..pb.end]) {
                    let s = Stencil::new(grid.to_grid(x));
                    *tag = update_tags(*tag, &arena[..], &s, local_base(&s, pb));
                }
                tags.iter().any(|&t| t != 0)
            })
            .reduce(|| false, |a, b| a || b);
    }
    /// Substeps until the simulated time reaches `time_s`; the last step is shortened to land on
    /// it. Returns the number of substeps taken.
    pub fn advance_to(&mut self, time_s: f64) -> Result<u64, SimError> {
        let mut n = 0;
        while self.time_s < time_s - 1e-12 {
            let remaining = (time_s - self.time_s) as f32;
            self.substep_by(self.next_dt().min(remaining))?;
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
    }

    /// Keeps particles sorted by the block of their stencil base node (stable, so the order is
    /// a pure function of the state: runs are deterministic for any thread count).
    fn sort_particles_by_block(&mut self) {
        let grid = &self.grid;
        self.keys.clear();
        self.keys.par_extend(
            self.particles
                .position
                .par_iter()
                .map(|x| grid.block_key(x)),
        );
        if self.keys.par_windows(2).all(|w| w[0] <= w[1]) {
            return;
        }
        self.order.clear();
        self.order.extend(0..self.particles.len() as u32);
        let keys = &self.keys;
        self.order.par_sort_by_key(|&i| keys[i as usize]);
        self.particles
            .reorder(&self.order, &mut self.reorder_scratch);
        self.sorted_keys.clear();
        self.sorted_keys
            .par_extend(self.order.par_iter().map(|&i| keys[i as usize]));
        std::mem::swap(&mut self.keys, &mut self.sorted_keys);
    }

    /// P2G: each particle block scatters into a private 6x6x6 arena, and arenas are added to the
    /// grid in 8 phases by block parity, so no two writers ever share a node (no atomics, no
    /// locks).
    fn particle_to_grid(&mut self, dt: f32, colliders: &[ColliderMotion]) -> Vec<ColliderImpulse> {
        let dx = self.settings.dx;
        // Q_p = -dt V_p tau_p D^-1 + m_p C_p, applied to offsets measured in cells (D^-1 =
        // 4/dx^2 for the quadratic B-spline).
        let stress_scale = -dt / (dx * dx) * dx;
        let kernel = self.settings.kernel;
        let particles = &self.particles;
        let colours = &self.colours;
        let grid_blocks = SharedBlocks::new(&mut self.grid.blocks);
        let slots = &self.arena_slots;
        let mut impulses = Vec::new();
        for phase in 0..8 {
            let phase_impulses: Vec<Vec<ColliderImpulse>> = self
                .grid
                .particle_blocks
                .par_iter()
                .filter(|pb| pb.phase() == phase)
                .map(|pb| {
                    let mut arena = [F4::splat(0.0); ARENA_NODES];
                    let colour_arena = colours.arena(pb, slots);
                    let mut block_impulses = Vec::new();
                    for p in pb.start..pb.end {
                        let x = particles.position[p];
                        let s = Stencil::of(kernel, self.grid.to_grid(&x));
                        let m = particles.mass[p];
                        let momentum = particles.velocity[p] * m;
                        let q_cells = scale_columns(
                            &particles.stress[p],
                            &(s.inverse_moment * stress_scale * particles.volume[p]),
                        ) + particles.affine[p] * (m * dx);
                        let base = local_base(&s, pb);
                        let tags = particles.cpic_tags[p];
                        match &colour_arena {
                            Some(colour) if tags != 0 => {
                                block_impulses.resize(colliders.len(), ColliderImpulse::default());
                                let particle = CpicParticle {
                                    x,
                                    v: particles.velocity[p],
                                    mass: m,
                                    tags,
                                };
                                let cx = CpicTransfer {
                                    colours: &colour[..],
                                    colliders,
                                    dx,
                                };
                                scatter_cpic(
                                    &mut arena,
                                    &cx,
                                    &s,
                                    base,
                                    &particle,
                                    &q_cells,
                                    &mut block_impulses,
                                );
                            }
                            _ => scatter(&mut arena, &s, base, m, momentum, &q_cells),
                        }
                    }
                    for (a, slot) in slots.iter().enumerate() {
                        // SAFETY: blocks of one phase have disjoint arenas (see
                        // `ParticleBlock::phase`), so this block is written by no other task.
                        let block =
                            unsafe { grid_blocks.get_mut(pb.arena_blocks[slot.block as usize]) };
                        let node = &mut block[slot.node as usize];
                        *node = (F4::from_array(*node) + arena[a]).to_array();
                    }
                    block_impulses
                })
                .filter(|i| !i.is_empty())
                .collect();
            for block in &phase_impulses {
                impulses = add_impulses(impulses, block);
            }
        }
        impulses
    }

    /// Grid update: velocity from momentum, gravity, then the walls (and, for nodes coloured
    /// for the plain grid-boundary method, the imposed collider velocity).
    fn update_grid(&mut self, dt: f32, colliders: &[ColliderMotion]) {
        let gravity = self.settings.gravity * dt;
        let walls = self.settings.walls;
        let wall_nodes = self.wall_nodes;
        let coords = &self.grid.coords;
        let colours = &self.colours;
        let (origin, dx) = (self.grid.origin, self.grid.dx);
        let (sleep, lattice) = (self.sleep.as_ref(), self.grid.lattice());
        self.grid
            .blocks
            .par_iter_mut()
            .zip(coords.par_iter())
            .enumerate()
            .for_each(|(slot, (block, coord))| {
                let first = coord.map(|c| c * BLOCK_EDGE);
                let near_wall = (0..3).any(|a| {
                    first[a] <= wall_nodes[0][a] || first[a] + BLOCK_EDGE > wall_nodes[1][a]
                });
                let colour = colours.block(slot);
                let near_sleep = sleep.filter(|s| s.near_grid_block(&lattice, *coord));
                for (n, node) in block.iter_mut().enumerate() {
                    let mass = node[3];
                    if mass <= 0.0 {
                        continue;
                    }
                    let mut v = Vector3::new(node[0], node[1], node[2]) / mass + gravity;
                    let index = || {
                        let local = [n / 16, (n / 4) % 4, n % 4];
                        [0, 1, 2].map(|a| first[a] + local[a] as i32)
                    };
                    if near_wall {
                        v = walls.apply_at_node(v, index(), &wall_nodes);
                    }
                    if let Some(imposed) = colour.map(|c| c[n].imposed).filter(|&i| i != 0) {
                        let x = origin + Vector3::from(index().map(|i| i as f32)) * dx;
                        v = colliders[imposed as usize - 1].velocity_at(&x);
                    }
                    // Sleeping sand holds the nodes it reaches at rest.
                    if near_sleep.is_some_and(|s| s.holds_node(&lattice, index())) {
                        v = Vector3::zeros();
                    }
                    node[0] = v.x;
                    node[1] = v.y;
                    node[2] = v.z;
                }
            });
    }

    /// G2P: gathers velocity and the affine matrix, updates F, advects, keeps particles in the
    /// domain, applies the constitutive update and checks every particle for blow-up.
    fn grid_to_particle(
        &mut self,
        dt: f32,
        colliders: &[ColliderMotion],
    ) -> Result<Vec<ColliderImpulse>, SimError> {
        let context = G2pContext {
            grid: &self.grid,
            colours: &self.colours,
            colliders,
            slots: &self.arena_slots,
            materials: &self.materials,
            dt,
            dx: self.settings.dx,
            lo: self.bounds[0],
            hi: self.bounds[1],
            blowup_speed_sq: self.settings.blowup_speed_m_s * self.settings.blowup_speed_m_s,
            affine_transfer: self.settings.transfer == Transfer::Apic,
            kernel: self.settings.kernel,
        };
        let blocks = &self.grid.particle_blocks;
        let views = G2pView::split(&mut self.particles, blocks);
        let summaries = views
            .into_par_iter()
            .zip(blocks.par_iter())
            .map(|(view, pb)| grid_to_particle_block(&context, view, pb))
            .collect::<Vec<_>>();
        if let Some(sleep) = &mut self.sleep {
            let speeds: Vec<f32> = summaries.iter().map(|s| s.max_speed_sq.sqrt()).collect();
            sleep.record_speeds(blocks, &self.keys, &speeds, dt);
        }
        let summary = summaries
            .into_iter()
            .fold(G2pSummary::default(), G2pSummary::merge);
        self.max_speed_m_s = summary.max_speed_sq.sqrt();
        match summary.bad {
            None => Ok(summary.impulses),
            Some(bad) => Err(SimError::BlowUp {
                step: self.steps,
                time_s: self.time_s,
                dt_s: dt,
                particle: self.particles.id[bad.index],
                what: bad.what,
                position: self.particles.position[bad.index].into(),
                velocity: self.particles.velocity[bad.index].into(),
            }),
        }
    }
}

/// `m diag(factors)`: column `j` of `m` times `factors[j]` (the kernel's `D^-1` on the right,
/// without a matrix product per particle).
#[inline(always)]
fn scale_columns(m: &Matrix3<f32>, factors: &Vector3<f32>) -> Matrix3<f32> {
    Matrix3::from_fn(|i, j| m[(i, j)] * factors[j])
}

/// What G2P reads besides the particles.
struct G2pContext<'a> {
    grid: &'a SparseGrid,
    colours: &'a GridColours,
    colliders: &'a [ColliderMotion],
    slots: &'a [ArenaSlot; ARENA_NODES],
    materials: &'a [SolverMaterial],
    /// Substep (s).
    dt: f32,
    /// Grid spacing (m).
    dx: f32,
    /// The box particles are clamped into (m): the domain, or its x window.
    lo: Vector3<f32>,
    hi: Vector3<f32>,
    /// Squared speed (m^2/s^2) above which a particle counts as blown up.
    blowup_speed_sq: f32,
    /// Keep the affine matrix for the next P2G (APIC) or not (PIC).
    affine_transfer: bool,
    kernel: Kernel,
}

/// G2P of one particle block: loads its 6x6x6 arena of node velocities once, then per particle
/// gathers v and C, updates F, advects and clamps, applies the constitutive update (eight
/// particles per SIMD call) and checks for blow-up.
#[inline(never)]
fn grid_to_particle_block(cx: &G2pContext, view: G2pView, pb: &ParticleBlock) -> G2pSummary {
    let G2pContext {
        grid,
        colours,
        colliders,
        slots,
        materials,
        dt,
        dx,
        lo,
        hi,
        blowup_speed_sq: blowup_sq,
        affine_transfer,
        kernel,
    } = *cx;
    let mut arena = [F4::splat(0.0); ARENA_NODES];
    for (a, slot) in slots.iter().enumerate() {
        arena[a] = F4::from_array(
            grid.blocks[pb.arena_blocks[slot.block as usize] as usize][slot.node as usize],
        );
    }
    let mut summary = G2pSummary::default();
    let colour_arena = colours.arena(pb, slots);
    // Eight particles at a time: their constitutive updates share one 8-lane SVD.
    for chunk in (0..view.position.len()).step_by(LANES) {
        let lanes = (view.position.len() - chunk).min(LANES);
        // Unused lanes carry an undeformed, unmoved F: harmless for every model.
        let mut f = [Matrix3::identity(); LANES];
        let mut step = [Matrix3::zeros(); LANES];
        let mut vc = [0.0f32; LANES];
        let mut frames = [COLD_START; LANES];
        for lane in 0..lanes {
            let i = chunk + lane;
            let x = view.position[i];
            let s = Stencil::of(kernel, grid.to_grid(&x));
            let base = local_base(&s, pb);
            let tags = view.cpic_tags[i];
            let near_collider = colour_arena.as_ref().filter(|_| tags != 0);
            let particle = || CpicParticle {
                x,
                v: view.velocity[i],
                mass: view.mass[i],
                tags,
            };
            let (mut v, b) = match near_collider {
                Some(colour) => {
                    let cx = CpicTransfer {
                        colours: &colour[..],
                        colliders,
                        dx,
                    };
                    if summary.impulses.is_empty() {
                        summary.impulses = vec![ColliderImpulse::default(); colliders.len()];
                    }
                    gather_cpic(&arena, &cx, &s, base, &particle(), &mut summary.impulses)
                }
                None => gather(&arena, &s, base),
            };
            // C_p = sum w v_i (x_i - x_p)^T D^-1, with offsets in cells.
            let c = scale_columns(&b, &(s.inverse_moment / dx));
            f[lane] = view.deformation[i];
            step[lane] = c * dt;
            vc[lane] = view.volume_correction[i];
            frames[lane] = view.svd_frame[i];
            let mut x_new = x + v * dt;
            // Near a collider: plain PIC (no affine transfer) and the penalty push-back.
            view.affine[i] = if near_collider.is_some() || !affine_transfer {
                Matrix3::zeros()
            } else {
                c
            };
            if let Some(colour) = near_collider {
                let cx = CpicTransfer {
                    colours: &colour[..],
                    colliders,
                    dx,
                };
                push_back(
                    &cx,
                    &s,
                    base,
                    &particle(),
                    &mut x_new,
                    &mut v,
                    &mut summary.impulses,
                );
            }
            view.position[i] = x_new.sup(&lo).inf(&hi);
            view.velocity[i] = v;
        }
        let material = view.material[chunk];
        let tau = if view.material[chunk..chunk + lanes]
            .iter()
            .all(|&m| m == material)
        {
            materials[material as usize]
                .model
                .update_x8(&step, &mut f, &mut vc, &mut frames)
        } else {
            std::array::from_fn(|lane| {
                let m = view.material.get(chunk + lane).copied().unwrap_or(material);
                f[lane] = (Matrix3::identity() + step[lane]) * f[lane];
                materials[m as usize]
                    .model
                    .update(&mut f[lane], &mut vc[lane], &mut frames[lane])
            })
        };
        for lane in 0..lanes {
            let i = chunk + lane;
            view.deformation[i] = f[lane];
            view.volume_correction[i] = vc[lane];
            view.svd_frame[i] = frames[lane];
            view.stress[i] = tau[lane];
            let (x, v) = (view.position[i], view.velocity[i]);
            let speed_sq = v.norm_squared();
            summary.max_speed_sq = summary.max_speed_sq.max(speed_sq);
            if summary.bad.is_none() {
                let finite = (x.sum() + speed_sq + tau[lane].sum() + f[lane].sum()).is_finite();
                let what = if !finite {
                    Some("has a non-finite state".to_string())
                } else if speed_sq > blowup_sq {
                    Some(format!("moves at {:.3e} m/s", speed_sq.sqrt()))
                } else {
                    None
                };
                summary.bad = what.map(|what| BadParticle {
                    index: pb.start + i,
                    what,
                });
            }
        }
    }
    summary
}

/// Offset of a particle's stencil base node inside its block's arena (each in `0..4`).
#[inline(always)]
fn local_base(s: &Stencil, pb: &ParticleBlock) -> [usize; 3] {
    [0, 1, 2].map(|a| (s.base[a] - pb.coord[a] * BLOCK_EDGE) as usize)
}

/// CPIC colours of the grid blocks near colliders, for one substep.
#[derive(Clone, Debug, Default)]
struct GridColours {
    /// Grid block slot -> index in `blocks`, or `NO_COLOUR`.
    of_block: Vec<u32>,
    blocks: Vec<ColourBlock>,
}

const NO_COLOUR: u32 = u32::MAX;

impl GridColours {
    fn clear(&mut self, grid_blocks: usize) {
        self.of_block.clear();
        self.of_block.resize(grid_blocks, NO_COLOUR);
        self.blocks.clear();
    }

    /// Colours of grid block `slot`, if coloured.
    fn block(&self, slot: usize) -> Option<&ColourBlock> {
        match self.of_block.get(slot) {
            Some(&c) if c != NO_COLOUR => Some(&self.blocks[c as usize]),
            _ => None,
        }
    }

    /// The 6x6x6 colour arena of a particle block, or None if none of its nodes is coloured.
    fn arena(
        &self,
        pb: &ParticleBlock,
        slots: &[ArenaSlot; ARENA_NODES],
    ) -> Option<Box<[NodeColour; ARENA_NODES]>> {
        if self.blocks.is_empty()
            || pb
                .arena_blocks
                .iter()
                .all(|&b| self.of_block[b as usize] == NO_COLOUR)
        {
            return None;
        }
        let mut arena = Box::new([NodeColour::default(); ARENA_NODES]);
        for (a, slot) in slots.iter().enumerate() {
            let c = self.of_block[pb.arena_blocks[slot.block as usize] as usize];
            if c != NO_COLOUR {
                arena[a] = self.blocks[c as usize][slot.node as usize];
            }
        }
        Some(arena)
    }
}

/// `a + b`, collider by collider (the shorter one padded with zeros).
fn add_impulses(mut a: Vec<ColliderImpulse>, b: &[ColliderImpulse]) -> Vec<ColliderImpulse> {
    if a.len() < b.len() {
        a.resize(b.len(), ColliderImpulse::default());
    }
    for (a, b) in a.iter_mut().zip(b) {
        a.linear_n_s += b.linear_n_s;
        a.angular_n_m_s += b.angular_n_m_s;
        a.sand_mass_kg += b.sand_mass_kg;
        a.sand_first_moment += b.sand_first_moment;
        a.sand_inertia += b.sand_inertia;
    }
    a
}

/// What the CPIC transfers of one particle block read besides the particle.
struct CpicTransfer<'a> {
    /// Colour arena of the block.
    colours: &'a [NodeColour],
    colliders: &'a [ColliderMotion],
    /// Grid spacing (m).
    dx: f32,
}

/// A particle as the CPIC transfers see it, at the start of the substep.
struct CpicParticle {
    x: Vector3<f32>,
    v: Vector3<f32>,
    mass: f32,
    tags: u64,
}

/// [`scatter`] with CPIC: a node incompatible with the particle receives nothing; the collider
/// of the conflict receives, at the node, the momentum the particle would have left there less
/// what the ghost velocity gives back in G2P.
#[inline(never)]
fn scatter_cpic(
    arena: &mut [F4; ARENA_NODES],
    cx: &CpicTransfer,
    s: &Stencil,
    base: [usize; 3],
    p: &CpicParticle,
    q_cells: &Matrix3<f32>,
    impulses: &mut [ColliderImpulse],
) {
    let momentum = p.v * p.mass;
    for (a, w, d) in stencil_nodes(s, base) {
        let contribution = (momentum + q_cells * d) * w;
        let colour = &cx.colours[a];
        let conflict = conflicts(colour.bits, p.tags);
        if conflict == 0 {
            let node = F4::from_array([contribution.x, contribution.y, contribution.z, w * p.mass]);
            arena[a] = arena[a] + node;
        } else {
            // The collider takes what the node would have received; G2P subtracts what the
            // ghost velocity gives back.
            let x_node = p.x + d * cx.dx;
            let (r, _) = conflict_normal(colour, conflict, p.tags);
            let centre = &cx.colliders[r].centre_m;
            impulses[r].add_at(contribution, &x_node, centre);
            impulses[r].sand_mass_kg += (w * p.mass) as f64;
            let (m, arm) = ((w * p.mass) as f64, (x_node - centre).cast::<f64>());
            impulses[r].sand_first_moment += arm * m;
            impulses[r].sand_inertia +=
                (Matrix3::identity() * arm.norm_squared() - arm * arm.transpose()) * m;
        }
    }
}

/// [`gather`] with CPIC: an incompatible node contributes the ghost velocity instead of its own.
#[inline(never)]
fn gather_cpic(
    arena: &[F4; ARENA_NODES],
    cx: &CpicTransfer,
    s: &Stencil,
    base: [usize; 3],
    p: &CpicParticle,
    impulses: &mut [ColliderImpulse],
) -> (Vector3<f32>, Matrix3<f32>) {
    let (mut v, mut b) = (Vector3::zeros(), Matrix3::zeros());
    for (a, w, d) in stencil_nodes(s, base) {
        let colour = &cx.colours[a];
        let conflict = conflicts(colour.bits, p.tags);
        let v_node = if conflict == 0 {
            let [x, y, z, _] = arena[a].to_array();
            Vector3::new(x, y, z)
        } else {
            let x_node = p.x + d * cx.dx;
            let (r, normal) = conflict_normal(colour, conflict, p.tags);
            let motion = &cx.colliders[r];
            let ghost = ghost_velocity(p.v, &x_node, motion, normal);
            impulses[r].add_at(-ghost * (w * p.mass), &x_node, &motion.centre_m);
            ghost
        };
        v += v_node * w;
        b += v_node * w * d.transpose();
    }
    (v, b)
}

/// CPIC penalty: a particle that ended up between [`PENALTY_MIN_CELLS`] and
/// [`PENALTY_MAX_CELLS`] on the wrong side of its closest collider is put back on the surface
/// and loses its velocity into the collider; the collider receives the reaction.
#[inline(never)]
fn push_back(
    cx: &CpicTransfer,
    s: &Stencil,
    base: [usize; 3],
    p: &CpicParticle,
    x_new: &mut Vector3<f32>,
    v: &mut Vector3<f32>,
    impulses: &mut [ColliderImpulse],
) {
    let Some((r, distance, normal)) = wall_distance(p.tags, cx.colours, s, base) else {
        return;
    };
    let distance = distance + normal.dot(&(*x_new - p.x));
    if distance >= -PENALTY_MIN_CELLS * cx.dx || distance <= -PENALTY_MAX_CELLS * cx.dx {
        return;
    }
    *x_new -= normal * distance;
    let motion = &cx.colliders[r];
    let approach = (*v - motion.velocity_at(x_new)).dot(&normal);
    if approach < 0.0 {
        let dv = -approach * normal;
        *v += dv;
        impulses[r].add_at(-dv * p.mass, x_new, &motion.centre_m);
    }
}

/// Adds one particle's mass and momentum `w_ip (m_p v_p + Q_p (x_i - x_p))` to its 27 arena
/// nodes; `q_cells` is Q_p scaled for offsets in cells. With `x_i - x_p = (i, j, k) - fx` (cells)
/// the affine term is built up one axis at a time, and a node's four components
/// `[p_x, p_y, p_z, m]` are one SIMD vector: two multiplies and two adds per node.
#[inline(always)]
fn scatter(
    arena: &mut [F4; ARENA_NODES],
    s: &Stencil,
    base: [usize; 3],
    mass: f32,
    momentum: Vector3<f32>,
    q_cells: &Matrix3<f32>,
) {
    // Columns of Q with a zero mass lane; the mass lane of `at_base` carries m_p.
    let q =
        [0, 1, 2].map(|c| F4::from_array([q_cells[(0, c)], q_cells[(1, c)], q_cells[(2, c)], 0.0]));
    let p = momentum - q_cells * s.fx;
    let at_base = F4::from_array([p.x, p.y, p.z, mass]);
    let w_k = s.weights[2].map(F4::splat);
    let mut p_i = at_base;
    for i in 0..3 {
        let mut p_ij = p_i;
        for j in 0..3 {
            let w_ij = F4::splat(s.weights[0][i] * s.weights[1][j]);
            let row = node_in_arena(base[0] + i, base[1] + j, base[2]);
            let p_ij0 = p_ij * w_ij;
            let q_k = q[2] * w_ij;
            arena[row] = arena[row] + p_ij0 * w_k[0];
            arena[row + 1] = arena[row + 1] + (p_ij0 + q_k) * w_k[1];
            arena[row + 2] = arena[row + 2] + (p_ij0 + q_k + q_k) * w_k[2];
            p_ij = p_ij + q[1];
        }
        p_i = p_i + q[0];
    }
}

/// Gathers `(sum w_i v_i, sum w_i v_i d_i^T)` over the 27 stencil nodes, `d_i` in cells. The
/// outer product is summed per axis: `sum w v (i, j, k)^T - (sum w v) fx^T`. Arena nodes are
/// SIMD vectors `[v_x, v_y, v_z, m]`; the mass lane is summed along and ignored.
#[inline(always)]
fn gather(
    arena: &[F4; ARENA_NODES],
    s: &Stencil,
    base: [usize; 3],
) -> (Vector3<f32>, Matrix3<f32>) {
    let zero = F4::splat(0.0);
    let w_k = s.weights[2].map(F4::splat);
    let (mut v, mut by_i, mut by_j, mut by_k) = (zero, zero, zero, zero);
    for i in 0..3 {
        let mut v_i = zero;
        for j in 0..3 {
            let w_ij = F4::splat(s.weights[0][i] * s.weights[1][j]);
            let row = node_in_arena(base[0] + i, base[1] + j, base[2]);
            let v0 = arena[row] * w_k[0];
            let v1 = arena[row + 1] * w_k[1];
            let v2 = arena[row + 2] * w_k[2];
            let v_ij = (v0 + v1 + v2) * w_ij;
            by_k = by_k + (v1 + v2 + v2) * w_ij;
            v_i = v_i + v_ij;
            by_j = by_j + v_ij * F4::splat(j as f32);
        }
        v = v + v_i;
        by_i = by_i + v_i * F4::splat(i as f32);
    }
    let column = |c: F4| {
        let [x, y, z, _] = c.to_array();
        Vector3::new(x, y, z)
    };
    let v = column(v);
    let b =
        Matrix3::from_columns(&[column(by_i), column(by_j), column(by_k)]) - v * s.fx.transpose();
    (v, b)
}

/// Mutable views of the particle arrays G2P writes, for one particle block.
struct G2pView<'a> {
    position: &'a mut [Vector3<f32>],
    velocity: &'a mut [Vector3<f32>],
    affine: &'a mut [Matrix3<f32>],
    deformation: &'a mut [Matrix3<f32>],
    stress: &'a mut [Matrix3<f32>],
    volume_correction: &'a mut [f32],
    svd_frame: &'a mut [Frame],
    mass: &'a [f32],
    cpic_tags: &'a [u64],
    material: &'a [MaterialId],
}

impl<'a> G2pView<'a> {
    fn split(p: &'a mut Particles, blocks: &[ParticleBlock]) -> Vec<G2pView<'a>> {
        let mut position = split_runs(&mut p.position, blocks).into_iter();
        let mut velocity = split_runs(&mut p.velocity, blocks).into_iter();
        let mut affine = split_runs(&mut p.affine, blocks).into_iter();
        let mut deformation = split_runs(&mut p.deformation, blocks).into_iter();
        let mut stress = split_runs(&mut p.stress, blocks).into_iter();
        let mut volume_correction = split_runs(&mut p.volume_correction, blocks).into_iter();
        let mut svd_frame = split_runs(&mut p.svd_frame, blocks).into_iter();
        let material = &p.material[..];
        let (mass, cpic_tags) = (&p.mass[..], &p.cpic_tags[..]);
        (0..blocks.len())
            .map(|b| G2pView {
                position: position.next().unwrap(),
                velocity: velocity.next().unwrap(),
                affine: affine.next().unwrap(),
                deformation: deformation.next().unwrap(),
                stress: stress.next().unwrap(),
                volume_correction: volume_correction.next().unwrap(),
                svd_frame: svd_frame.next().unwrap(),
                material: &material[blocks[b].start..blocks[b].end],
                mass: &mass[blocks[b].start..blocks[b].end],
                cpic_tags: &cpic_tags[blocks[b].start..blocks[b].end],
            })
            .collect()
    }
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

/// Grid blocks written from parallel P2G tasks that are known to touch disjoint blocks.
struct SharedBlocks {
    ptr: *mut Block,
    len: usize,
}

// SAFETY: access goes through `get_mut`, whose callers guarantee disjointness.
unsafe impl Sync for SharedBlocks {}
unsafe impl Send for SharedBlocks {}

impl SharedBlocks {
    fn new(blocks: &mut [Block]) -> Self {
        SharedBlocks {
            ptr: blocks.as_mut_ptr(),
            len: blocks.len(),
        }
    }

    /// # Safety
    /// No other reference to block `i` may exist while the returned one lives.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get_mut(&self, i: u32) -> &mut Block {
        assert!((i as usize) < self.len);
        &mut *self.ptr.add(i as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpm::material::{FixedCorotated, Lame};
    use crate::mpm::Wall;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    const DX: f32 = 0.01;

    fn jelly() -> SolverMaterial {
        SolverMaterial {
            name: "jelly".into(),
            density_kg_m3: 1000.0,
            model: Constitutive::FixedCorotated(FixedCorotated {
                lame: Lame::from_young_poisson(1e5, 0.3),
            }),
        }
    }

    fn settings(gravity: Vector3<f32>, walls: Walls) -> SolverSettings {
        SolverSettings {
            dx: DX,
            domain_min: Vector3::zeros(),
            domain_max: Vector3::new(0.4, 0.3, 0.3),
            walls,
            gravity,
            time_step: TimeStep::Fixed { dt_s: 1e-4 },
            blowup_speed_m_s: 100.0,
            transfer: Transfer::Apic,
            kernel: Kernel::QuadraticBspline,
            sleep: None,
        }
    }

    /// A blob of particles with random velocities, affine matrices and symmetric stresses.
    fn random_solver(seed: u64, gravity: Vector3<f32>, walls: Walls) -> Solver {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut s = Solver::new(settings(gravity, walls), vec![jelly()]);
        let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
        let new: Vec<NewParticle> = (0..3000)
            .map(|_| NewParticle {
                position: Vector3::new(r(0.05, 0.35), r(0.05, 0.25), r(0.05, 0.25)),
                velocity: Vector3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)),
                mass: r(0.5, 1.5) * 1e-3,
                volume: 1e-6,
                material: 0,
            })
            .collect();
        s.add_particles(new);
        let mut rng = SmallRng::seed_from_u64(seed + 1);
        for p in 0..s.particles.len() {
            s.particles.affine[p] = Matrix3::from_fn(|_, _| rng.random_range(-5.0..5.0));
            let a = Matrix3::from_fn(|_, _| rng.random_range(-1e3..1e3f32));
            s.particles.stress[p] = a + a.transpose();
        }
        s
    }

    fn grid_totals(s: &Solver) -> (f64, Vector3<f64>, Vector3<f64>) {
        let (mut m, mut p, mut l) = (0.0, Vector3::zeros(), Vector3::zeros());
        for (block, coord) in s.grid.blocks.iter().zip(&s.grid.coords) {
            for (n, node) in block.iter().enumerate() {
                let idx = [n / 16, (n / 4) % 4, n % 4];
                let x = Vector3::from_fn(|a, _| ((coord[a] * BLOCK_EDGE) as usize + idx[a]) as f64)
                    * DX as f64
                    + s.grid.origin.cast::<f64>();
                let mom = Vector3::new(node[0] as f64, node[1] as f64, node[2] as f64);
                m += node[3] as f64;
                p += mom;
                l += x.cross(&mom);
            }
        }
        (m, p, l)
    }

    fn close(a: Vector3<f64>, b: Vector3<f64>, scale: f64) -> bool {
        (a - b).norm() <= 1e-5 * scale
    }

    #[test]
    fn p2g_conserves_mass_momentum_and_angular_momentum() {
        let mut s = random_solver(1, Vector3::zeros(), Walls::all(Wall::Slip));
        let (m0, p0, l0) = (
            s.particles.total_mass(),
            s.particles.total_momentum(),
            s.particles.total_angular_momentum(DX),
        );
        s.sort_particles_by_block();
        s.grid.rebuild(&s.keys, |_| false);
        // Stress enters P2G but, being symmetric and summed against zero-mean offsets, adds no
        // net force or torque.
        s.particle_to_grid(1e-4, &[]);
        let (m, p, l) = grid_totals(&s);
        let p_scale = s.particles.mass.iter().map(|&m| m as f64).sum::<f64>();
        assert!((m - m0).abs() < 1e-6 * m0, "mass {m} vs {m0}");
        assert!(close(p, p0, p_scale), "momentum {p:?} vs {p0:?}");
        assert!(
            close(l, l0, p_scale * 0.4),
            "angular momentum {l:?} vs {l0:?}"
        );
    }

    #[test]
    fn g2p_gives_back_the_grid_angular_momentum() {
        let mut s = random_solver(2, Vector3::zeros(), Walls::all(Wall::Slip));
        for p in 0..s.particles.len() {
            s.particles.stress[p] = Matrix3::zeros();
        }
        s.sort_particles_by_block();
        s.grid.rebuild(&s.keys, |_| false);
        s.particle_to_grid(0.0, &[]);
        s.update_grid(0.0, &[]);
        // After the grid update the nodes hold velocities; weight them by mass.
        let (mut p_grid, mut l_grid) = (Vector3::zeros(), Vector3::zeros());
        for (block, coord) in s.grid.blocks.iter().zip(&s.grid.coords) {
            for (n, node) in block.iter().enumerate() {
                let idx = [n / 16, (n / 4) % 4, n % 4];
                let x = Vector3::from_fn(|a, _| ((coord[a] * BLOCK_EDGE) as usize + idx[a]) as f64)
                    * DX as f64;
                let mom =
                    Vector3::new(node[0] as f64, node[1] as f64, node[2] as f64) * node[3] as f64;
                p_grid += mom;
                l_grid += x.cross(&mom);
            }
        }
        s.grid_to_particle(0.0, &[]).unwrap();
        let scale = s.particles.total_mass();
        assert!(close(s.particles.total_momentum(), p_grid, scale));
        assert!(close(
            s.particles.total_angular_momentum(DX),
            l_grid,
            scale * 0.4
        ));
    }

    /// The same substep on a plain dense grid, written as simply as possible.
    fn dense_reference_step(s: &mut Solver, dt: f32) {
        // Nodes -1 ..= extent/dx + 1 per axis, stored with an offset of 1.
        let n = [44usize, 34, 34];
        let at = |i: [i32; 3]| -> usize {
            let u = i.map(|v| (v + 1) as usize);
            (u[0] * n[1] + u[1]) * n[2] + u[2]
        };
        let mut grid = vec![[0.0f32; 4]; n[0] * n[1] * n[2]];
        let p = &s.particles;
        for q in 0..p.len() {
            let st = Stencil::new(p.position[q] / DX);
            let m = p.mass[q];
            let qm = p.stress[q] * (-dt * 4.0 / DX * p.volume[q]) + p.affine[q] * (m * DX);
            for (i, j, k) in stencil_nodes() {
                let w = st.weight(i, j, k);
                let mom = (p.velocity[q] * m + qm * st.offset_cells(i, j, k)) * w;
                let g = &mut grid[at([
                    st.base[0] + i as i32,
                    st.base[1] + j as i32,
                    st.base[2] + k as i32,
                ])];
                g[0] += mom.x;
                g[1] += mom.y;
                g[2] += mom.z;
                g[3] += w * m;
            }
        }
        let wall_nodes = s.wall_nodes;
        for x in -1..(n[0] as i32 - 1) {
            for y in -1..(n[1] as i32 - 1) {
                for z in -1..(n[2] as i32 - 1) {
                    let g = &mut grid[at([x, y, z])];
                    if g[3] <= 0.0 {
                        continue;
                    }
                    let v = Vector3::new(g[0], g[1], g[2]) / g[3] + s.settings.gravity * dt;
                    let v = s.settings.walls.apply_at_node(v, [x, y, z], &wall_nodes);
                    g[0] = v.x;
                    g[1] = v.y;
                    g[2] = v.z;
                }
            }
        }
        let (lo, hi) = (s.settings.domain_min, s.settings.domain_max);
        let p = &mut s.particles;
        for q in 0..p.len() {
            let st = Stencil::new(p.position[q] / DX);
            let (mut v, mut b) = (Vector3::zeros(), Matrix3::zeros());
            for (i, j, k) in stencil_nodes() {
                let g = grid[at([
                    st.base[0] + i as i32,
                    st.base[1] + j as i32,
                    st.base[2] + k as i32,
                ])];
                let vi = Vector3::new(g[0], g[1], g[2]) * st.weight(i, j, k);
                v += vi;
                b += vi * st.offset_cells(i, j, k).transpose();
            }
            let c = b * (4.0 / DX);
            p.deformation[q] = (Matrix3::identity() + c * dt) * p.deformation[q];
            p.position[q] = (p.position[q] + v * dt).sup(&lo).inf(&hi);
            p.velocity[q] = v;
            p.affine[q] = c;
            let mut vc = p.volume_correction[q];
            let model = &s.materials[0].model;
            p.stress[q] = model.update(&mut p.deformation[q], &mut vc, &mut p.svd_frame[q]);
            p.volume_correction[q] = vc;
        }
    }

    fn stencil_nodes() -> impl Iterator<Item = (usize, usize, usize)> {
        (0..3).flat_map(|i| (0..3).flat_map(move |j| (0..3).map(move |k| (i, j, k))))
    }

    #[test]
    fn sparse_grid_matches_a_dense_reference_grid() {
        let walls = Walls {
            z_min: Wall::Sticky,
            x_max: Wall::Friction(0.5),
            ..Walls::all(Wall::Slip)
        };
        let gravity = Vector3::new(0.0, 0.0, -9.81);
        let mut sparse = random_solver(3, gravity, walls);
        // Push some particles against the walls so the boundary code runs.
        for p in 0..300 {
            sparse.particles.position[p].z = 0.001 * (p % 7) as f32;
            sparse.particles.position[p].x = 0.4 - 0.001 * (p % 5) as f32;
        }
        let mut dense = Solver::new(sparse.settings.clone(), sparse.materials.clone());
        dense.particles = sparse.particles.clone();
        dense.wall_nodes = sparse.wall_nodes;
        for _ in 0..5 {
            sparse.substep().unwrap();
            dense_reference_step(&mut dense, 1e-4);
        }
        let mut by_id = vec![0usize; sparse.particles.len()];
        for (q, &id) in sparse.particles.id.iter().enumerate() {
            by_id[id as usize] = q;
        }
        let (mut dx_max, mut dv_max) = (0.0f32, 0.0f32);
        for q in 0..dense.particles.len() {
            let r = by_id[dense.particles.id[q] as usize];
            dx_max =
                dx_max.max((sparse.particles.position[r] - dense.particles.position[q]).norm());
            dv_max =
                dv_max.max((sparse.particles.velocity[r] - dense.particles.velocity[q]).norm());
        }
        assert!(dx_max < 1e-6, "positions differ by {dx_max} m");
        assert!(dv_max < 1e-3, "velocities differ by {dv_max} m/s");
    }
}
