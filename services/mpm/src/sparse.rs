//! Sparse grid storage: nodes live in blocks of 4 × 4 (× 4); only blocks that material points
//! touch are stored, so memory follows the material, not the domain.
//!
//! A dense page table maps every block of the domain to its slot in the node arrays (4 bytes per
//! block, 1/64 of a 3D block's node data); node `(i, j, k)` of an active block is at
//! `slot · B^d + (i mod 4) + 4 (j mod 4) + 16 (k mod 4)`.

use grains_grid::Grid;
use grains_grid::shape::wrap_index;

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
    /// Nodes per period on periodic axes (0 on open ones; see [`Grid::period`]).
    period: [i64; 3],
    periodic: bool,
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
            period: grid.period.map(|n| n as i64),
            periodic: grid.period.iter().any(|&p| p > 0),
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

    /// Node (i, j, k) with its periodic components brought into [0, period).
    #[inline(always)]
    pub fn wrap(&self, ijk: [i64; 3]) -> [i64; 3] {
        if !self.periodic {
            return ijk;
        }
        [0, 1, 2].map(|k| wrap_index(ijk[k], self.period[k]))
    }

    /// Rebuilds the active set: `stencil_starts` yields the first node (i, j, k) of every point's
    /// 3-node stencil; the blocks of all 3^d nodes (wrapped on periodic axes) become active.
    /// Fails with the position in the sequence of the first stencil that does not lie inside
    /// the grid.
    pub fn rebuild(&mut self, stencil_starts: impl Iterator<Item = [i64; 3]>) -> Result<(), usize> {
        self.page.fill(INACTIVE);
        self.active.clear();
        // Per axis the blocks of the stencil's three nodes (on a periodic axis they may be
        // three different blocks: the last, partly used block and the first).
        let period = self.period;
        let blocks = |k: usize, s: i64| [0, 1, 2].map(|a| wrap_index(s + a, period[k]) >> SHIFT);
        // Points come sorted by block: most stencils start in the same block as the last one.
        let mut last = [[i64::MIN; 3]; 3];
        for (p, start) in stencil_starts.enumerate() {
            if (0..self.dim).any(|k| self.period[k] == 0 && (start[k] < 0 || start[k] + 2 >= self.nodes[k])) {
                self.page.fill(INACTIVE);
                return Err(p);
            }
            let key = [blocks(0, start[0]), blocks(1, start[1]), blocks(2, start[2])];
            if key == last {
                continue;
            }
            last = key;
            let nz = if self.dim == 3 { 3 } else { 1 };
            for c in &key[2][..nz] {
                for b in &key[1] {
                    for a in &key[0] {
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
        let ijk = self.wrap(ijk);
        (ijk[0] >> SHIFT) as usize + self.blocks[0] * ((ijk[1] >> SHIFT) as usize + self.blocks[1] * (ijk[2] >> SHIFT) as usize)
    }

    /// Storage index of node (i, j, k); the node's block must be active.
    #[inline(always)]
    pub fn slot(&self, ijk: [i64; 3]) -> usize {
        let ijk = self.wrap(ijk);
        let blk = self.block_index(ijk);
        let local = (ijk[0] & (BLOCK - 1)) + BLOCK * ((ijk[1] & (BLOCK - 1)) + BLOCK * (ijk[2] & (BLOCK - 1)));
        let page = self.page[blk];
        debug_assert!(page != INACTIVE, "node {ijk:?} of an inactive block");
        ((page as usize) << (SHIFT as usize * self.dim)) + local as usize
    }

    /// Storage indices of the 3^d nodes of the stencil starting at `start`, x fastest (index
    /// a + 3 b + 9 c for node start + (a, b, c); the unused layers of 2D are 0); its blocks must
    /// be active. The per-node work of P2G and G2P: each axis is wrapped once, not per node.
    #[inline(always)]
    pub fn stencil_nodes(&self, start: [i64; 3]) -> [usize; 27] {
        let mut block = [[0usize; 3]; 3];
        let mut local = [[0i64; 3]; 3];
        for k in 0..self.dim {
            let p = self.period[k];
            let s = wrap_index(start[k], p);
            for a in 0..3 {
                let mut i = s + a as i64;
                if p > 0 && i >= p {
                    i -= p;
                }
                block[k][a] = (i >> SHIFT) as usize;
                local[k][a] = i & (BLOCK - 1);
            }
        }
        let shift = SHIFT as usize * self.dim;
        let mut out = [0usize; 27];
        let nz = if self.dim == 3 { 3 } else { 1 };
        for c in 0..nz {
            for b in 0..3 {
                let row = self.blocks[0] * (block[1][b] + self.blocks[1] * block[2][c]);
                let lrow = BLOCK * (local[1][b] + BLOCK * local[2][c]);
                for a in 0..3 {
                    let page = self.page[block[0][a] + row];
                    debug_assert!(page != INACTIVE, "a stencil node of an inactive block");
                    out[a + 3 * b + 9 * c] = ((page as usize) << shift) + (local[0][a] + lrow) as usize;
                }
            }
        }
        out
    }

    /// The lowest and the highest storage index of the 3^d nodes of the stencil starting at
    /// `start` (slots follow block order, x fastest, so they are those of the corners of
    /// per-axis lowest and highest wrapped nodes); its blocks must be active.
    pub fn stencil_slots(&self, start: [i64; 3]) -> (usize, usize) {
        let (mut lo, mut hi) = (start, start);
        for k in 0..self.dim {
            let n = [0, 1, 2].map(|a| wrap_index(start[k] + a, self.period[k]));
            lo[k] = n[0].min(n[1]).min(n[2]);
            hi[k] = n[0].max(n[1]).max(n[2]);
        }
        (self.slot(lo), self.slot(hi))
    }

    /// Storage index of node (i, j, k), or `None` when it is outside the grid or its block is
    /// not stored.
    pub fn try_slot(&self, ijk: [i64; 3]) -> Option<usize> {
        let ijk = self.wrap(ijk);
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
        let slots = map.stencil_nodes([5, 6, 7]);
        for (n, &slot) in slots.iter().enumerate() {
            assert_eq!(slot, map.slot([5 + n as i64 % 3, 6 + (n as i64 / 3) % 3, 7 + n as i64 / 9]));
        }
        for ijk in [[5, 6, 7], [7, 8, 9], [6, 7, 8], [30, 31, 32], [32, 32, 32]] {
            let s = map.slot(ijk);
            assert!(s < map.len());
            assert_eq!(map.ijk(s), ijk);
        }
        assert!(map.len() < map.domain_blocks() * map.block_nodes() / 10);
    }

    /// On a periodic axis node i and node i + period are one stored node, and a stencil
    /// that crosses the end activates the blocks on both sides.
    #[test]
    fn a_periodic_axis_wraps_slots_and_stencils() {
        // 9 cells of 1 along x (period 9: nodes 0..=8; node 9 is node 0), open along y.
        let grid = Grid::covering([0.0; 3], [9.0, 8.0, 0.0], 1.0, 2).with_periodic([true, false, false]);
        let mut map = BlockMap::new(&grid, 2);
        // Starts at x = 7 (nodes 7, 8, 0), at x = −1 (nodes 8, 0, 1); y open.
        map.rebuild([[7i64, 2, 0], [-1, 2, 0]].into_iter()).unwrap();
        // x blocks 0, 1, 2 (node 8 is alone in block 2), y blocks 0 and 1.
        assert_eq!(map.active_blocks(), 6);
        assert_eq!(map.slot([9, 3, 0]), map.slot([0, 3, 0]));
        assert_eq!(map.slot([-1, 3, 0]), map.slot([8, 3, 0]));
        assert_ne!(map.slot([8, 3, 0]), map.slot([0, 3, 0]));
        assert_eq!(map.ijk(map.slot([-1, 4, 0])), [8, 4, 0]);
        // The open axis still rejects a stencil beyond the grid.
        assert_eq!(map.clone().rebuild([[3, 7, 0]].into_iter()), Err(0));
        // The stencil across the end spans every x block: lowest slot at x = 0, highest at 8.
        // The stencil's slots are the nodes' own, wrapped.
        for start in [[7i64, 2, 0], [-1, 2, 0]] {
            let slots = map.stencil_nodes(start);
            for b in 0..3 {
                for a in 0..3 {
                    assert_eq!(slots[a + 3 * b], map.slot([start[0] + a as i64, start[1] + b as i64, 0]));
                }
            }
        }
        let (lo, hi) = map.stencil_slots([7, 2, 0]);
        assert_eq!((lo, hi), (map.slot([0, 2, 0]), map.slot([8, 4, 0])));
    }
}
