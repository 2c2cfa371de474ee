//! Philox4x64-10 counter-based random numbers, bit-identical to numpy's `Philox` bit generator,
//! and the per-sample noise the simulated skin draws from it.
//!
//! A sample owns `blocks` consecutive Philox blocks of 4 words; numpy increments the counter
//! before producing a block, so block `j` of sample `i` is the block at counter
//! `i * blocks + j + 1` (the same offset whatever chunking the Python side used).

const M0: u64 = 0xD2E7_470E_E14C_6C93;
const M1: u64 = 0xCA5A_8263_9512_1157;
const W0: u64 = 0x9E37_79B9_7F4A_7C15;
const W1: u64 = 0xBB67_AE85_84CA_A73B;

#[inline]
fn mulhilo(a: u64, b: u64) -> (u64, u64) {
    let p = (a as u128) * (b as u128);
    ((p >> 64) as u64, p as u64)
}

/// One Philox4x64 block (10 rounds) at `ctr` under `key`.
pub fn block(mut ctr: [u64; 4], key: [u64; 2]) -> [u64; 4] {
    let mut k = key;
    for round in 0..10 {
        if round > 0 {
            k[0] = k[0].wrapping_add(W0);
            k[1] = k[1].wrapping_add(W1);
        }
        let (hi0, lo0) = mulhilo(M0, ctr[0]);
        let (hi1, lo1) = mulhilo(M1, ctr[2]);
        ctr = [hi1 ^ ctr[1] ^ k[0], lo1, hi0 ^ ctr[3] ^ k[1], lo0];
    }
    ctr
}

/// Random words addressed by (sample index, slot), as `aptkt.sim.seeding.CounterStream.raw`.
#[derive(Clone, Copy, Debug)]
pub struct CounterStream {
    pub key: [u64; 2],
    pub slots: usize,
}

impl CounterStream {
    pub fn new(key: [u64; 2], slots: usize) -> Self {
        Self { key, slots }
    }

    fn blocks(&self) -> u64 {
        self.slots.div_ceil(4) as u64
    }

    /// The `slots` words of sample `index` into `out` (length `slots`).
    pub fn words(&self, index: u64, out: &mut [u64]) {
        let blocks = self.blocks();
        let base = index.wrapping_mul(blocks);
        for j in 0..blocks {
            // 256-bit counter: a carry beyond the first word needs 2^64 blocks, never reached.
            let b = block([base.wrapping_add(j + 1), 0, 0, 0], self.key);
            for (w, v) in b.iter().enumerate() {
                let s = (j as usize) * 4 + w;
                if s < self.slots {
                    out[s] = *v;
                }
            }
        }
    }
}

/// A uniform deviate in [0, 1) from a word (53 high bits), as numpy's `random_raw >> 11`.
#[inline]
pub fn unit(word: u64) -> f64 {
    (word >> 11) as f64 / 9_007_199_254_740_992.0
}

/// Box-Muller normals from pairs of uniforms `(u[2i], u[2i+1])`, as `CounterStream.normal`.
#[inline]
pub fn box_muller(u_even: f64, u_odd: f64) -> (f64, f64) {
    let r = (-2.0 * (1.0 - u_even).ln()).sqrt();
    let a = 2.0 * std::f64::consts::PI * u_odd;
    (r * a.cos(), r * a.sin())
}
