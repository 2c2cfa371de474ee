//! The cargo-fuzz target's body (`aptkt_skin::testing::fuzz_check`) run on stable Rust over many
//! pseudo-random byte streams, so `cargo test` exercises it even where no fuzzer is installed.
//! The streams are biased towards the bytes that matter (headers, 0xAA, low bytes) and towards
//! real packets, because uniform bytes almost never contain a valid packet.

use aptkt_skin::testing::fuzz_check;
use aptkt_skin::{encode_sensor, SensorRaw};

/// SplitMix64: tiny, deterministic, good enough to drive test inputs.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn stream(rng: &mut Rng) -> Vec<u8> {
    let len = rng.below(600) as usize;
    let mut out = Vec::with_capacity(len + 20);
    while out.len() < len {
        match rng.below(10) {
            0..=4 => {
                let raw = SensorRaw {
                    cell_id: rng.below(0x4000) as u16,
                    proximity: rng.next() as u16,
                    acc: [0, 1, 2].map(|_| rng.below(1024) as i16 - 512),
                    temp: [rng.below(256) as i16 - 128, rng.below(16384) as i16 - 8192],
                    force: [0, 1, 2].map(|_| rng.below(4096) as u16),
                };
                let Ok(mut p) = encode_sensor(&raw) else {
                    continue;
                };
                if rng.below(4) == 0 {
                    let at = rng.below(20) as usize;
                    p[at] ^= 1 << rng.below(8); // any single bit error
                }
                let keep = if rng.below(5) == 0 {
                    rng.below(21) as usize
                } else {
                    20
                };
                out.extend_from_slice(&p[..keep]);
            }
            5 => out.push([0xFF, 0xAA, 0xC8, 0xE2, 0x80][rng.below(5) as usize]),
            6 => out.push(rng.below(0x80) as u8),
            _ => out.push(rng.next() as u8),
        }
    }
    out
}

#[test]
fn fuzz_body_on_random_streams() {
    let mut rng = Rng(0x5EED_0001);
    for _ in 0..20_000 {
        let mut data = vec![rng.next() as u8];
        data.extend(stream(&mut rng));
        fuzz_check(&data);
    }
}

#[test]
fn fuzz_body_on_uniform_bytes_and_edge_cases() {
    fuzz_check(&[]);
    fuzz_check(&[0]);
    fuzz_check(&[7; 1000]);
    fuzz_check(&[0xFF; 1000]);
    fuzz_check(&[0xAA; 1000]);
    let mut rng = Rng(42);
    for _ in 0..5_000 {
        let len = rng.below(300) as usize;
        let data: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
        fuzz_check(&data);
    }
}
