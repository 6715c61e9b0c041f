//! Payload checksum of [`crate::wire::StepHeader::checksum`].
//!
//! The payload is read as little-endian `u64` words (every wire element is a multiple of 8
//! bytes). Word `i` is folded into lane `i mod 4` as `lane = (lane ^ word) * P` (wrapping), the
//! four lanes then into one value the same way, and the byte length last. Four lanes keep the
//! multiply chains independent, so the checksum runs near memory speed. `0` on the wire means
//! "not computed": a result of `0` is sent as `1`.

const P: u64 = 0x0000_0100_0000_01b3;
const LANES: [u64; 4] = [
    0xcbf2_9ce4_8422_2325,
    0x9e37_79b9_7f4a_7c15,
    0xc2b2_ae3d_27d4_eb4f,
    0x1656_67b1_9e37_79f9,
];

/// Incremental form, for a producer that folds words while it writes them.
#[derive(Clone, Debug)]
pub struct Checksum {
    lanes: [u64; 4],
    n_words: u64,
}

impl Default for Checksum {
    fn default() -> Self {
        Checksum { lanes: LANES, n_words: 0 }
    }
}

impl Checksum {
    #[inline]
    pub fn word(&mut self, w: u64) {
        let lane = &mut self.lanes[(self.n_words & 3) as usize];
        *lane = (*lane ^ w).wrapping_mul(P);
        self.n_words += 1;
    }

    #[inline]
    pub fn f64(&mut self, x: f64) {
        self.word(x.to_bits());
    }

    pub fn finish(&self) -> u64 {
        let mut h = LANES[0];
        for lane in self.lanes {
            h = (h ^ lane).wrapping_mul(P);
        }
        h = (h ^ (self.n_words * 8)).wrapping_mul(P);
        if h == 0 { 1 } else { h }
    }
}

/// Checksum of a byte payload whose length is a multiple of 8.
pub fn checksum_bytes(bytes: &[u8]) -> u64 {
    debug_assert_eq!(bytes.len() % 8, 0, "wire payloads are whole u64 words");
    let mut c = Checksum::default();
    let mut chunks = bytes.chunks_exact(32);
    for chunk in &mut chunks {
        // Four words at a time: one per lane, in lane order.
        for k in 0..4 {
            c.word(u64::from_le_bytes(chunk[8 * k..8 * k + 8].try_into().expect("8 bytes")));
        }
    }
    for w in chunks.remainder().chunks_exact(8) {
        c.word(u64::from_le_bytes(w.try_into().expect("8 bytes")));
    }
    c.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn incremental_and_bytewise_forms_agree() {
        let words: Vec<u64> = (0..37u64).map(|i| i.wrapping_mul(0x9e37_79b9) ^ 0x55).collect();
        let mut c = Checksum::default();
        words.iter().for_each(|&w| c.word(w));
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        assert_eq!(c.finish(), checksum_bytes(&bytes));
    }

    #[test]
    fn a_flipped_bit_or_a_reordering_changes_the_checksum() {
        let bytes: Vec<u8> = (0..256u32).map(|i| (i * 7) as u8).collect();
        let base = checksum_bytes(&bytes);
        let mut flipped = bytes.clone();
        flipped[100] ^= 0x10;
        assert_ne!(base, checksum_bytes(&flipped));
        let mut swapped = bytes.clone();
        swapped.swap(0, 8);
        assert_ne!(base, checksum_bytes(&swapped));
        assert_ne!(base, checksum_bytes(&bytes[..248]));
    }

    #[test]
    fn empty_payload_has_a_nonzero_checksum() {
        assert_ne!(checksum_bytes(&[]), 0);
    }
}
