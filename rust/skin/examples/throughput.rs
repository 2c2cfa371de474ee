//! Parser throughput without Python: `cargo run --release -p aptkt-skin --example throughput [MB]`.
//! The Python benchmark (benches/bench_skin_parser.py) measures the full path through numpy.

use std::time::Instant;

use aptkt_skin::{encode_sensor, PhysicalColumns, RawColumns, SensorRaw, StreamParser};

fn main() {
    let mb: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(64);
    let n = mb * 1_000_000 / 20;
    let mut stream = Vec::with_capacity(n * 20);
    for i in 0..n {
        let raw = SensorRaw {
            cell_id: (i % 7) as u16 + 1,
            proximity: (i * 31) as u16,
            acc: [(i % 1024) as i16 - 512, 3, -200],
            temp: [(i % 256) as i16 - 128, -1000],
            force: [(i % 4096) as u16, 100, 4000],
        };
        stream.extend_from_slice(&encode_sensor(&raw).unwrap_or([0; 20]));
    }
    for chunk in chunks_from_env() {
        for label in ["physical", "raw", "phys-reuse"] {
            let mut reuse = PhysicalColumns::default();
            let mut best = f64::INFINITY;
            let mut rows = 0;
            for _ in 0..5 {
                let mut parser = StreamParser::new();
                let t = Instant::now();
                for c in stream.chunks(chunk) {
                    if label == "phys-reuse" {
                        reuse.cell_id.clear();
                        reuse.proximity.clear();
                        reuse.acc.clear();
                        reuse.temp.clear();
                        reuse.force.clear();
                        parser.feed(c, &mut reuse);
                        rows += reuse.len();
                    } else if label == "physical" {
                        let mut out = PhysicalColumns::default();
                        parser.feed(c, &mut out);
                        rows += out.len();
                    } else {
                        let mut out = RawColumns::default();
                        parser.feed(c, &mut out);
                        rows += out.len();
                    }
                }
                best = best.min(t.elapsed().as_secs_f64());
            }
            assert_eq!(rows, 5 * n);
            println!(
                "{label:8} chunk {:>9} B: {:7.0} MB/s, {:6.1} M packets/s",
                chunk,
                stream.len() as f64 / best / 1e6,
                n as f64 / best / 1e6
            );
        }
    }
}

fn chunks_from_env() -> Vec<usize> {
    match std::env::args().nth(2).and_then(|s| s.parse().ok()) {
        Some(c) => vec![c],
        None => vec![1 << 16, 1 << 20, 16 << 20],
    }
}
