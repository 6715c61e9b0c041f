//! Sparse grid storage: nodes live in blocks of 4 × 4 (× 4); only blocks that material points
//! touch are stored, so memory follows the material, not the domain.
//!
//! A dense page table maps every block of the domain to its slot in the node arrays (4 bytes per
//! block, 1/64 of a 3D block's node data); node `(i, j, k)` of an active block is at
//! `slot · B^d + (i mod 4) + 4 (j mod 4) + 16 (k mod 4)`.

use grains_grid::Grid;

/// Nodes per block along an axis (a power of two).
pub const BLOCK: i64 = 4;
const SHIFT: u32 = 2;
const INACTIVE: u32 = u32::MAX;

#[derive(Clone, Debug, Default)]
pub struct BlockMap {
    /// Blocks per axis (1 on unused axes).
    blocks: [usize; 3],
    /// Nodes per axis of the grid.
    nodes: [i64; 3],
    dim: usize,
    /// Block → slot (INACTIVE when not stored).
    page: Vec<u32>,
    /// Slot → block, in block order.
    active: Vec<u32>,
}

impl BlockMap {
    pub fn new(grid: &Grid, dim: usize) -> Self {
        let mut blocks = [1usize; 3];
        for (k, b) in blocks.iter_mut().enumerate().take(dim) {
            *b = (grid.nodes[k] as usize).div_ceil(BLOCK as usize);
        }
        BlockMap {
            blocks,
            nodes: grid.nodes.map(|n| n as i64),
            dim,
            page: vec![INACTIVE; blocks.iter().product()],
            active: Vec::new(),
        }
    }

    /// Nodes per block (B^d).
    #[inline(always)]
    pub fn block_nodes(&self) -> usize {
        1 << (SHIFT as usize * self.dim)
    }

    /// Stored node count.
    pub fn len(&self) -> usize {
        self.active.len() * self.block_nodes()
    }

    pub fn is_empty(&self) -> bool {
        self.active.is_empty()
    }

    /// Active block count.
    pub fn active_blocks(&self) -> usize {
        self.active.len()
    }

    /// Blocks in the domain.
    pub fn domain_blocks(&self) -> usize {
        self.page.len()
    }

    /// Rebuilds the active set: `stencil_starts` yields the first node (i, j, k) of every point's
    /// 3-node stencil; the blocks of all 3^d nodes become active. Fails with the position in the
    /// sequence of the first stencil that does not lie inside the grid.
    pub fn rebuild(&mut self, stencil_starts: impl Iterator<Item = [i64; 3]>) -> Result<(), usize> {
        self.page.fill(INACTIVE);
        self.active.clear();
        let reach = |s: i64| [s >> SHIFT, (s + 2) >> SHIFT];
        // Points come sorted by block: most stencils start in the same block as the last one.
        let mut last = [i64::MIN; 3];
        for (p, start) in stencil_starts.enumerate() {
            if (0..self.dim).any(|k| start[k] < 0 || start[k] + 2 >= self.nodes[k]) {
                self.page.fill(INACTIVE);
                return Err(p);
            }
            let (bx, by, bz) = (reach(start[0]), reach(start[1]), reach(start[2]));
            let key = [bx[0] + (bx[1] << 32), by[0] + (by[1] << 32), bz[0] + (bz[1] << 32)];
            if key == last {
                continue;
            }
            last = key;
            let nz = if self.dim == 3 { 2 } else { 1 };
            for c in &bz[..nz] {
                for b in &by {
                    for a in &bx {
                        let blk = *a as usize + self.blocks[0] * (*b as usize + self.blocks[1] * *c as usize);
                        // Mark first; slots are assigned in block order below.
                        self.page[blk] = 0;
                    }
                }
            }
        }
        for (blk, slot) in self.page.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = self.active.len() as u32;
                self.active.push(blk as u32);
            }
        }
        Ok(())
    }

    /// Index of the block holding node (i, j, k) (blocks numbered x fastest, as slots are).
    #[inline(always)]
    pub fn block_index(&self, ijk: [i64; 3]) -> usize {
        (ijk[0] >> SHIFT) as usize + self.blocks[0] * ((ijk[1] >> SHIFT) as usize + self.blocks[1] * (ijk[2] >> SHIFT) as usize)
    }

    /// Storage index of node (i, j, k); the node's block must be active.
    #[inline(always)]
    pub fn slot(&self, ijk: [i64; 3]) -> usize {
        let blk = self.block_index(ijk);
        let local = (ijk[0] & (BLOCK - 1)) + BLOCK * ((ijk[1] & (BLOCK - 1)) + BLOCK * (ijk[2] & (BLOCK - 1)));
        let page = self.page[blk];
        debug_assert!(page != INACTIVE, "node {ijk:?} of an inactive block");
        ((page as usize) << (SHIFT as usize * self.dim)) + local as usize
    }

    /// Storage index of node (i, j, k), or `None` when it is outside the grid or its block is
    /// not stored.
    pub fn try_slot(&self, ijk: [i64; 3]) -> Option<usize> {
        if (0..self.dim).any(|k| ijk[k] < 0 || ijk[k] >= self.nodes[k]) {
            return None;
        }
        (self.page[self.block_index(ijk)] != INACTIVE).then(|| self.slot(ijk))
    }

    /// Node (i, j, k) of a storage index (which may lie beyond the grid in a boundary block).
    #[inline]
    pub fn ijk(&self, slot: usize) -> [i64; 3] {
        let bn = self.block_nodes();
        let blk = self.active[slot / bn] as usize;
        let local = (slot % bn) as i64;
        let b = [
            blk % self.blocks[0],
            (blk / self.blocks[0]) % self.blocks[1],
            blk / (self.blocks[0] * self.blocks[1]),
        ];
        let l = [local & (BLOCK - 1), (local >> SHIFT) & (BLOCK - 1), local >> (2 * SHIFT)];
        [0, 1, 2].map(|k| b[k] as i64 * BLOCK + l[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_round_trip_and_only_touched_blocks_are_stored() {
        let grid = Grid::covering([0.0; 3], [10.0, 10.0, 10.0], 0.25, 3);
        let mut map = BlockMap::new(&grid, 3);
        map.rebuild([[5i64, 6, 7], [30, 30, 30]].into_iter()).unwrap();
        // 41 nodes per axis: a stencil must start at 0..=38.
        assert_eq!(map.clone().rebuild([[1, 1, 1], [38, 0, 39]].into_iter()), Err(1));
        assert_eq!(map.clone().rebuild([[-1, 1, 1]].into_iter()), Err(0));
        // Stencil x 5..7, y 6..8, z 7..9 spans blocks 1 × {1, 2} × {1, 2}; 30..32 spans blocks
        // 7..8 on every axis.
        assert_eq!(map.active_blocks(), 4 + 8);
        for ijk in [[5, 6, 7], [7, 8, 9], [6, 7, 8], [30, 31, 32], [32, 32, 32]] {
            let s = map.slot(ijk);
            assert!(s < map.len());
            assert_eq!(map.ijk(s), ijk);
        }
        assert!(map.len() < map.domain_blocks() * map.block_nodes() / 10);
    }
}
