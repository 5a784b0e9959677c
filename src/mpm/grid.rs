//! Sparse block grid: only 4x4x4-node blocks touched by some particle's stencil exist.
//!
//! Blocks are found through a dense table over the domain's block lattice (4 bytes per possible
//! block; a 1.8 m x 0.4 m x 0.1 m domain at dx = 2.5 mm needs 72 k entries) that maps a block
//! coordinate to its slot in the active-block list; node storage exists only for active blocks.
//! Particles are bucketed by the block of their stencil base node ("particle blocks"). The
//! stencil of a particle in block `b` stays inside nodes `[4b, 4b + 6)` on each axis, so a
//! particle block reads and writes a padded 6x6x6 arena spanning blocks `b + {0,1}^3`.

use nalgebra::Vector3;

/// Nodes per block edge.
pub const BLOCK_EDGE: i32 = 4;
/// `BLOCK_EDGE = 2^BLOCK_EDGE_SHIFT`: block coordinates are node indices shifted right.
const BLOCK_EDGE_SHIFT: u32 = BLOCK_EDGE.trailing_zeros();
const _: () = assert!(BLOCK_EDGE == 1 << BLOCK_EDGE_SHIFT);
/// Nodes per block.
pub const BLOCK_NODES: usize = (BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE) as usize;
/// Nodes per arena edge: a block plus the two extra nodes a quadratic stencil reaches.
pub const ARENA_EDGE: usize = BLOCK_EDGE as usize + 2;
/// Nodes per arena.
pub const ARENA_NODES: usize = ARENA_EDGE * ARENA_EDGE * ARENA_EDGE;
/// Marks an empty slot in the block table.
const NO_BLOCK: u32 = u32::MAX;

/// One grid node: `[p_x, p_y, p_z, m]`, momentum (kg m/s) and mass (kg) after P2G; the grid
/// update overwrites the momentum by the velocity (m/s).
pub type Node = [f32; 4];
/// The nodes of one block, index `(x * 4 + y) * 4 + z`.
pub type Block = [Node; BLOCK_NODES];

/// Index of node `(x, y, z)` inside a block.
#[inline(always)]
pub fn node_in_block(x: usize, y: usize, z: usize) -> usize {
    (x * BLOCK_EDGE as usize + y) * BLOCK_EDGE as usize + z
}

/// Index of node `(x, y, z)` inside an arena.
#[inline(always)]
pub fn node_in_arena(x: usize, y: usize, z: usize) -> usize {
    (x * ARENA_EDGE + y) * ARENA_EDGE + z
}

/// Where arena node `a` lives: which of the 8 arena blocks (`dx * 4 + dy * 2 + dz`) and which
/// node inside it.
#[derive(Clone, Copy)]
pub struct ArenaSlot {
    pub block: u8,
    pub node: u8,
}

/// The 216 arena slots, in arena order.
pub fn arena_slots() -> [ArenaSlot; ARENA_NODES] {
    let edge = BLOCK_EDGE as usize;
    let mut slots = [ArenaSlot { block: 0, node: 0 }; ARENA_NODES];
    for x in 0..ARENA_EDGE {
        for y in 0..ARENA_EDGE {
            for z in 0..ARENA_EDGE {
                slots[node_in_arena(x, y, z)] = ArenaSlot {
                    block: ((x / edge) * 4 + (y / edge) * 2 + z / edge) as u8,
                    node: node_in_block(x % edge, y % edge, z % edge) as u8,
                };
            }
        }
    }
    slots
}

/// A run of particles sharing one block, with the 8 active blocks its arena spans.
#[derive(Clone, Copy, Debug)]
pub struct ParticleBlock {
    /// Block coordinate (node index / 4).
    pub coord: [i32; 3],
    /// Particle index range `start..end` in the sorted particle arrays.
    pub start: usize,
    pub end: usize,
    /// Slots of blocks `coord + (dx, dy, dz)` in `SparseGrid::blocks`, index `dx*4 + dy*2 + dz`.
    pub arena_blocks: [u32; 8],
}

impl ParticleBlock {
    /// P2G phase of the block: the parity of its coordinates. Two distinct blocks of one phase
    /// differ by at least 2 along some axis, so their arenas share no node.
    pub fn phase(&self) -> usize {
        let [x, y, z] = self.coord;
        ((x & 1) * 4 + (y & 1) * 2 + (z & 1)) as usize
    }
}

/// The sparse grid over an axis-aligned domain.
#[derive(Clone, Debug)]
pub struct SparseGrid {
    /// Node spacing (m).
    pub dx: f32,
    /// `1 / dx` (1/m): positions are scaled by it, never divided by dx.
    inv_dx: f32,
    /// World position of node (0, 0, 0) (m); the domain's min corner.
    pub origin: Vector3<f32>,
    /// The blocks the table covers.
    lattice: BlockLattice,
    /// Block lattice -> slot in `coords`/`blocks`, or `NO_BLOCK`.
    table: Vec<u32>,
    /// Coordinates of active blocks.
    pub coords: Vec<[i32; 3]>,
    /// Node data of active blocks.
    pub blocks: Vec<Block>,
    /// Particle blocks in particle order, rebuilt by [`SparseGrid::rebuild`].
    pub particle_blocks: Vec<ParticleBlock>,
}

impl SparseGrid {
    /// A grid with spacing `dx` covering the box `[min, max]` (m), where particles are kept.
    pub fn new(dx: f32, min: Vector3<f32>, max: Vector3<f32>) -> Self {
        let mut table_min = [0; 3];
        let mut table_dims = [0; 3];
        for axis in 0..3 {
            // A particle on the min wall has base node -1; one on the max wall has base node
            // ceil(extent/dx); the arena reaches one block further.
            let last_node = ((max[axis] - min[axis]) / dx).ceil() as i32;
            table_min[axis] = (-1i32).div_euclid(BLOCK_EDGE);
            let table_max = last_node.div_euclid(BLOCK_EDGE) + 1;
            table_dims[axis] = table_max - table_min[axis] + 1;
        }
        let cells = table_dims.iter().map(|&d| d as usize).product();
        SparseGrid {
            dx,
            inv_dx: 1.0 / dx,
            origin: min,
            lattice: BlockLattice {
                min: table_min,
                dims: table_dims,
            },
            table: vec![NO_BLOCK; cells],
            coords: Vec::new(),
            blocks: Vec::new(),
            particle_blocks: Vec::new(),
        }
    }

    /// Position of a point in grid units (cells from the origin).
    #[inline(always)]
    pub fn to_grid(&self, x: &Vector3<f32>) -> Vector3<f32> {
        (x - self.origin) * self.inv_dx
    }

    /// World position of the grid node with global index `index` (m).
    pub fn node_position(&self, index: [i32; 3]) -> Vector3<f32> {
        self.origin + Vector3::new(index[0] as f32, index[1] as f32, index[2] as f32) * self.dx
    }

    /// Linear key of the block holding the stencil base node of a particle at `x`; keys order
    /// blocks x-major, and `rebuild` expects particles sorted by it.
    #[inline]
    pub fn block_key(&self, x: &Vector3<f32>) -> u32 {
        let xg = self.to_grid(x);
        let BlockLattice { min, dims } = self.lattice;
        // Lattice coordinate along `axis`; the floor division by BLOCK_EDGE is a shift.
        let block = |axis: usize| {
            let base = super::kernel::floor_i32(xg[axis] - 0.5);
            ((base >> BLOCK_EDGE_SHIFT) - min[axis]).clamp(0, dims[axis] - 1) as u32
        };
        (block(0) * dims[1] as u32 + block(1)) * dims[2] as u32 + block(2)
    }

    /// The block lattice the table covers (keys and coordinates).
    pub fn lattice(&self) -> BlockLattice {
        self.lattice
    }

    fn table_index(&self, c: [i32; 3]) -> usize {
        self.lattice.index(c)
    }

    /// Rebuilds the active blocks for particles sorted by `keys` (their [`Self::block_key`]),
    /// leaving out the runs whose key `skip` holds (sleeping sand), and zeroes all node data.
    pub fn rebuild(&mut self, keys: &[u32], skip: impl Fn(u32) -> bool) {
        for c in std::mem::take(&mut self.coords) {
            let i = self.table_index(c);
            self.table[i] = NO_BLOCK;
        }
        self.particle_blocks.clear();
        let mut start = 0;
        while start < keys.len() {
            let key = keys[start];
            let mut end = start + 1;
            while end < keys.len() && keys[end] == key {
                end += 1;
            }
            if skip(key) {
                start = end;
                continue;
            }
            let coord = self.lattice.coord_of_key(key);
            let mut arena_blocks = [0u32; 8];
            for (slot, offset) in arena_blocks.iter_mut().enumerate() {
                let c = [
                    coord[0] + (offset_bit(slot, 2)),
                    coord[1] + (offset_bit(slot, 1)),
                    coord[2] + (offset_bit(slot, 0)),
                ];
                *offset = self.activate(c);
            }
            self.particle_blocks.push(ParticleBlock {
                coord,
                start,
                end,
                arena_blocks,
            });
            start = end;
        }
        let zero: Block = [[0.0; 4]; BLOCK_NODES];
        self.blocks.clear();
        self.blocks.resize(self.coords.len(), zero);
    }

    fn activate(&mut self, c: [i32; 3]) -> u32 {
        let i = self.table_index(c);
        if self.table[i] == NO_BLOCK {
            self.table[i] = self.coords.len() as u32;
            self.coords.push(c);
        }
        self.table[i]
    }

    /// Node data at a global node index, if its block is active.
    pub fn node(&self, index: [i32; 3]) -> Option<&Node> {
        let c = index.map(|i| i.div_euclid(BLOCK_EDGE));
        let l = index.map(|i| i.rem_euclid(BLOCK_EDGE) as usize);
        let key = self.lattice.key_of_block(c)?;
        let slot = self.table[key as usize];
        (slot != NO_BLOCK).then(|| &self.blocks[slot as usize][node_in_block(l[0], l[1], l[2])])
    }

    /// Bytes held by the grid (table, block list, node data and particle blocks).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.table.capacity() * size_of::<u32>()
            + self.coords.capacity() * size_of::<[i32; 3]>()
            + self.blocks.capacity() * size_of::<Block>()
            + self.particle_blocks.capacity() * size_of::<ParticleBlock>()
    }
}

/// Bit `bit` of an arena-block slot index, as a block offset 0 or 1.
#[inline(always)]
fn offset_bit(slot: usize, bit: usize) -> i32 {
    ((slot >> bit) & 1) as i32
}

/// The lattice of blocks a grid's table covers: block coordinates and their keys (x-major
/// linear indices, the order particles are sorted in).
#[derive(Clone, Copy, Debug)]
pub struct BlockLattice {
    /// Smallest block coordinate covered, per axis.
    min: [i32; 3],
    /// Blocks per axis.
    dims: [i32; 3],
}

impl BlockLattice {
    /// Blocks covered: keys run from 0 to this.
    pub fn len(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn index(&self, c: [i32; 3]) -> usize {
        let [_, ny, nz] = self.dims;
        let l = [0, 1, 2].map(|a| c[a] - self.min[a]);
        ((l[0] * ny + l[1]) * nz + l[2]) as usize
    }

    /// The block coordinate of `key`.
    pub fn coord_of_key(&self, key: u32) -> [i32; 3] {
        let [_, ny, nz] = self.dims;
        let k = key as i32;
        [
            k / (ny * nz) + self.min[0],
            (k / nz) % ny + self.min[1],
            k % nz + self.min[2],
        ]
    }

    /// The key of the block at coordinate `c`, if the lattice covers it.
    #[inline]
    pub fn key_of_block(&self, c: [i32; 3]) -> Option<u32> {
        let inside = (0..3).all(|a| c[a] >= self.min[a] && c[a] < self.min[a] + self.dims[a]);
        inside.then(|| self.index(c) as u32)
    }

    /// Keys of the up to 26 blocks around block `key` that the lattice covers.
    pub fn neighbour_keys(&self, key: u32) -> impl Iterator<Item = u32> + '_ {
        let [x, y, z] = self.coord_of_key(key);
        (0..27).filter(|&o| o != 13).filter_map(move |o| {
            self.key_of_block([x + o / 9 - 1, y + o / 3 % 3 - 1, z + o % 3 - 1])
        })
    }
}
