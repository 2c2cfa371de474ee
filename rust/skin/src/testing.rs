//! Test support shared by the unit tests, the proptest suites and the fuzz target: a sink that
//! keeps everything, and a deliberately naive reference parser written straight from the
//! protocol text (no word tricks, no carry, no shared decoder) to compare the real one against.
//! Not part of the supported API.

use crate::columns::{PhysicalColumns, RawColumns};
use crate::packet::{PacketType, END_MARKER, PACKET_LEN};
use crate::parser::{PacketSink, RejectReason, Stats, StreamParser, MAX_CARRY};
use crate::sensor::SensorRaw;

/// Keeps every packet the parser reports, in order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Collect {
    pub sensors: Vec<SensorRaw>,
    pub others: Vec<(PacketType, [u8; PACKET_LEN])>,
}

impl PacketSink for Collect {
    fn sensor(&mut self, p: &SensorRaw) {
        self.sensors.push(*p);
    }

    fn other(&mut self, kind: PacketType, packet: &[u8; PACKET_LEN]) {
        self.others.push((kind, *packet));
    }
}

fn signed(value: u32, bits: u32) -> i16 {
    let v = value as i32;
    (if v >= 1 << (bits - 1) {
        v - (1 << bits)
    } else {
        v
    }) as i16
}

/// The decoding table of the protocol, formula by formula.
pub fn reference_decode(b: &[u8]) -> SensorRaw {
    let b = |i: usize| u32::from(b[i]);
    SensorRaw {
        cell_id: (((b(1) & 0x7F) << 7) | (b(2) & 0x7F)) as u16,
        proximity: (((b(3) & 0x7F) << 9) | ((b(4) & 0x7F) << 2) | ((b(10) >> 3) & 0x3)) as u16,
        acc: [
            signed(((b(5) & 0x7F) << 3) | (b(8) & 0x7), 10),
            signed(((b(6) & 0x7F) << 3) | (b(9) & 0x7), 10),
            signed(((b(7) & 0x7F) << 3) | (b(10) & 0x7), 10),
        ],
        temp: [
            signed(((b(8) << 1) & 0xF0) | ((b(9) >> 3) & 0xF), 8),
            signed(((b(17) & 0x7F) << 7) | (b(18) & 0x7F), 14),
        ],
        force: [
            (((b(11) & 0x7F) << 5) | (b(12) & 0x1F)) as u16,
            (((b(13) & 0x7F) << 5) | (b(14) & 0x1F)) as u16,
            (((b(15) & 0x7F) << 5) | (b(16) & 0x1F)) as u16,
        ],
    }
}

/// Parses a whole stream byte by byte. Returns what was found and the statistics; the last
/// unfinished candidate (if any) is left out of `bytes_skipped`, as the streaming parser
/// carries it.
pub fn reference_scan(s: &[u8]) -> (Collect, Stats) {
    let mut out = Collect::default();
    let mut st = Stats {
        bytes_in: s.len() as u64,
        ..Stats::default()
    };
    let mut pos = 0;
    while pos < s.len() {
        let b = s[pos];
        let kind = if b >= 0x80 {
            PacketType::from_header(b)
        } else {
            None
        };
        let Some(kind) = kind else {
            if b >= 0x80 && b != END_MARKER {
                st.rejected[RejectReason::UnknownHeader as usize] += 1;
            }
            st.bytes_skipped += 1;
            pos += 1;
            continue;
        };
        let end = (pos + PACKET_LEN).min(s.len());
        let window = &s[pos..end];
        let high_payload = window
            .iter()
            .take(PACKET_LEN - 1)
            .skip(1)
            .any(|&x| x >= 0x80);
        if high_payload {
            st.rejected[RejectReason::PayloadHighBit as usize] += 1;
        } else if window.len() < PACKET_LEN {
            break; // unfinished: pending
        } else if window[PACKET_LEN - 1] != END_MARKER {
            st.rejected[RejectReason::BadEndMarker as usize] += 1;
        } else {
            if kind == PacketType::Sensor {
                st.sensor_packets += 1;
                out.sensors.push(reference_decode(window));
            } else {
                st.other_packets[kind.index()] += 1;
                let mut p = [0u8; PACKET_LEN];
                p.copy_from_slice(window);
                out.others.push((kind, p));
            }
            pos += PACKET_LEN;
            continue;
        }
        st.bytes_skipped += 1;
        pos += 1;
    }
    (out, st)
}

/// Splits `data` into chunks whose sizes come from a small generator seeded by `seed`
/// (sizes 0..=max, zero-length chunks included on purpose).
pub fn chunk_sizes(len: usize, seed: u64, max: usize) -> Vec<usize> {
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let mut sizes = Vec::new();
    let mut total = 0;
    while total < len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let n = ((state >> 33) as usize % (max + 1)).min(len - total);
        sizes.push(n);
        total += n;
    }
    sizes
}

/// The fuzz body: any bytes, any chunking → the streaming parser agrees with the reference,
/// keeps its accounting invariant and bounded carry, and never panics. The first byte picks
/// the chunking. Panics (which is what a fuzzer looks for) on any disagreement.
pub fn fuzz_check(data: &[u8]) {
    let (seed, stream) = match data.split_first() {
        Some((&s, rest)) => (u64::from(s), rest),
        None => (0, data),
    };
    let (expected, expected_stats) = reference_scan(stream);
    let max_chunk = [1usize, 3, 19, 20, 21, 64][seed as usize % 6];
    let mut parser = StreamParser::new();
    let mut got = Collect::default();
    // The column sinks decode clean runs with their own block decoders; run them on the same
    // chunks through parsers of their own.
    let (mut raw_parser, mut raw) = (StreamParser::new(), RawColumns::default());
    let (mut phys_parser, mut phys) = (StreamParser::new(), PhysicalColumns::default());
    let mut offset = 0;
    for n in chunk_sizes(stream.len(), seed, max_chunk) {
        let chunk = &stream[offset..offset + n];
        parser.feed(chunk, &mut got);
        raw_parser.feed(chunk, &mut raw);
        phys_parser.feed(chunk, &mut phys);
        offset += n;
        assert!(parser.pending() <= MAX_CARRY);
        let st = parser.stats();
        assert_eq!(
            st.bytes_in,
            PACKET_LEN as u64 * st.packets_total() + st.bytes_skipped + parser.pending() as u64,
            "accounting invariant"
        );
    }
    assert_eq!(got, expected, "packets differ from the reference");
    let rows: Vec<SensorRaw> = (0..raw.len()).filter_map(|i| raw.row(i)).collect();
    assert_eq!(
        rows, expected.sensors,
        "RawColumns differ from the reference"
    );
    let mut want = PhysicalColumns::default();
    for r in &expected.sensors {
        let p = r.to_physical();
        want.cell_id.push(p.cell_id);
        want.proximity.push(p.proximity);
        want.acc.extend_from_slice(&p.acc);
        want.temp.extend_from_slice(&p.temp);
        want.force.extend_from_slice(&p.force);
    }
    assert_eq!(phys, want, "PhysicalColumns differ from the reference");
    assert_eq!(
        parser.stats(),
        &expected_stats,
        "statistics differ from the reference"
    );
}
