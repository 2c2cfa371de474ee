//! The streaming parser: bytes in arbitrary chunks → packets, with re-synchronisation.
//!
//! Rule: a byte ≥ 0x80 can only start a packet. The parser examines, in stream order, every
//! such byte that is not inside an accepted packet. A known header followed by 18 bytes < 0x80
//! and the end marker is a packet; anything else is rejected *as a candidate only*, and the
//! search resumes at the next byte ≥ 0x80 after the rejected header — i.e. inside the rejected
//! candidate, where the next real packet starts when the previous one was truncated. Accepted
//! packets can never overlap another valid packet (their bytes 1..=19 are < 0x80 or 0xAA, which
//! is no header), so every valid packet in the stream is found, whatever the chunking.

use crate::packet::{
    check_frame, Invalid, PacketType, END_MARKER, HEADER_KIND, NOT_A_HEADER, PACKET_LEN,
};
use crate::sensor::{decode_sensor, SensorRaw};

/// At most this many bytes are carried from one `feed` to the next (an unfinished packet).
pub const MAX_CARRY: usize = PACKET_LEN - 1;

/// Receives what the parser finds, in stream order.
pub trait PacketSink {
    /// A valid sensor packet (header 0xFF).
    fn sensor(&mut self, packet: &SensorRaw);

    /// A run of consecutive valid sensor packets (`block.len()` is a multiple of 20, every
    /// packet already checked). The parser reports clean stretches of the stream this way so
    /// that a sink can decode them column by column in a tight loop; the default decodes one
    /// packet at a time through [`PacketSink::sensor`].
    #[inline(always)]
    fn sensor_block(&mut self, block: &[u8]) {
        for p in block.chunks_exact(PACKET_LEN) {
            if let Some(p) = p.first_chunk::<PACKET_LEN>() {
                self.sensor(&decode_sensor(p));
            }
        }
    }

    /// A valid packet of any other type. The default ignores it (the parser counts it anyway).
    #[inline(always)]
    fn other(&mut self, _kind: PacketType, _packet: &[u8; PACKET_LEN]) {}

    /// Called once per `feed` with an upper bound on the sensor packets it can deliver, so a
    /// sink can allocate once instead of growing in the hot loop.
    #[inline(always)]
    fn reserve(&mut self, _max_packets: usize) {}
}

/// Why a candidate packet was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectReason {
    /// A byte ≥ 0x80 at a packet start that is neither a known header nor the end marker.
    UnknownHeader,
    /// A known header, but one of the 18 payload bytes has its top bit set (typically the
    /// packet was truncated and the next header follows, or a bit flipped).
    PayloadHighBit,
    /// A known header and a clean payload, but byte 19 is not the end marker 0xAA.
    BadEndMarker,
}

impl RejectReason {
    pub const ALL: [RejectReason; 3] = [
        RejectReason::UnknownHeader,
        RejectReason::PayloadHighBit,
        RejectReason::BadEndMarker,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            RejectReason::UnknownHeader => "unknown_header",
            RejectReason::PayloadHighBit => "payload_high_bit",
            RejectReason::BadEndMarker => "bad_end_marker",
        }
    }
}

/// Link-health counters. Invariant after every `feed`:
/// `bytes_in == 20 * (sensor_packets + Σ other_packets) + bytes_skipped + pending`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Stats {
    /// Bytes fed so far.
    pub bytes_in: u64,
    /// Bytes that were not part of any valid packet (garbage, rejected candidates, stray 0xAA).
    pub bytes_skipped: u64,
    /// Valid sensor packets delivered.
    pub sensor_packets: u64,
    /// Valid packets of each type, indexed by [`PacketType::index`] (the sensor slot stays 0).
    pub other_packets: [u64; PacketType::ALL.len()],
    /// Rejected candidates, indexed like [`RejectReason::ALL`].
    pub rejected: [u64; 3],
}

impl Stats {
    pub fn rejected(&self, reason: RejectReason) -> u64 {
        self.rejected[reason as usize]
    }

    pub fn other(&self, kind: PacketType) -> u64 {
        self.other_packets[kind.index()]
    }

    /// All valid packets, sensor or not.
    pub fn packets_total(&self) -> u64 {
        self.sensor_packets + self.other_packets.iter().sum::<u64>()
    }
}

enum Run {
    /// Scanning reached the end of the region; continue at this position.
    Next(usize),
    /// A candidate packet starts here but the data ends before its 20th byte.
    Pending(usize),
}

/// Streaming parser with bounded state: at most [`MAX_CARRY`] bytes are kept between feeds.
#[derive(Debug, Clone)]
pub struct StreamParser {
    carry: [u8; MAX_CARRY],
    carry_len: usize,
    stats: Stats,
}

impl Default for StreamParser {
    fn default() -> Self {
        Self::new()
    }
}

impl StreamParser {
    pub fn new() -> Self {
        StreamParser {
            carry: [0; MAX_CARRY],
            carry_len: 0,
            stats: Stats::default(),
        }
    }

    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// Bytes of an unfinished packet held until the next `feed`.
    pub fn pending(&self) -> usize {
        self.carry_len
    }

    /// Drops the unfinished packet (counted as skipped) and keeps the statistics; used when
    /// the link restarts, so a fragment from before cannot be glued to bytes from after.
    pub fn discard_pending(&mut self) {
        self.stats.bytes_skipped += self.carry_len as u64;
        self.carry_len = 0;
    }

    /// Forgets everything, statistics included.
    pub fn reset(&mut self) {
        *self = StreamParser::new();
    }

    /// Upper bound on the packets the next `feed` of `len` bytes can complete.
    pub fn max_packets(&self, len: usize) -> usize {
        (self.carry_len + len) / PACKET_LEN
    }

    /// Parses the next chunk of the stream, handing each packet to `sink` in stream order.
    pub fn feed<S: PacketSink>(&mut self, data: &[u8], sink: &mut S) {
        self.stats.bytes_in += data.len() as u64;
        sink.reserve(self.max_packets(data.len()));
        let mut start = 0;
        if self.carry_len > 0 {
            // A packet began in an earlier chunk. Glue the carry to the first bytes of `data`
            // in a small stack buffer; every candidate starting in the carry region is complete
            // there unless `data` itself is shorter than what is missing.
            let carry_len = self.carry_len;
            let take = data.len().min(MAX_CARRY);
            let mut joined = [0u8; 2 * MAX_CARRY];
            joined[..carry_len].copy_from_slice(&self.carry[..carry_len]);
            joined[carry_len..carry_len + take].copy_from_slice(&data[..take]);
            let joined = &joined[..carry_len + take];
            self.carry_len = 0;
            match self.run(joined, 0, carry_len, sink) {
                Run::Pending(at) => {
                    self.keep(&joined[at..]);
                    return;
                }
                Run::Next(pos) => start = pos - carry_len,
            }
        }
        if let Run::Pending(at) = self.run(data, start, data.len(), sink) {
            self.keep(&data[at..]);
        }
    }

    fn keep(&mut self, tail: &[u8]) {
        // A pending candidate is always shorter than a packet; the guard only keeps the
        // bound explicit (anything longer would have been decided already).
        let n = tail.len().min(MAX_CARRY);
        self.stats.bytes_skipped += (tail.len() - n) as u64;
        self.carry[..n].copy_from_slice(&tail[tail.len() - n..]);
        self.carry_len = n;
    }

    /// Scans candidates starting in `buf[pos..stop]`; an accepted packet may extend past
    /// `stop` (up to `buf.len()`).
    #[inline(always)]
    fn run<S: PacketSink>(&mut self, buf: &[u8], mut pos: usize, stop: usize, sink: &mut S) -> Run {
        let stats = &mut self.stats;
        while pos < stop {
            let header = buf[pos];
            if header < 0x80 {
                let next = find_high(&buf[pos..stop]).map_or(stop, |k| pos + k);
                stats.bytes_skipped += (next - pos) as u64;
                pos = next;
                continue;
            }
            let kind = HEADER_KIND[header as usize];
            if kind == NOT_A_HEADER {
                // A stray end marker (left from a packet that lost its start) is not a candidate.
                if header != END_MARKER {
                    stats.rejected[RejectReason::UnknownHeader as usize] += 1;
                }
                stats.bytes_skipped += 1;
                pos += 1;
                continue;
            }
            let Some(packet) = buf[pos..].first_chunk::<PACKET_LEN>() else {
                // Unfinished at the end of the data. If a payload byte we already have is ≥ 0x80
                // the verdict is known now, so reject at once and keep the carry short.
                if buf[pos + 1..].iter().any(|&b| b >= 0x80) {
                    stats.rejected[RejectReason::PayloadHighBit as usize] += 1;
                    stats.bytes_skipped += 1;
                    pos += 1;
                    continue;
                }
                return Run::Pending(pos);
            };
            match check_frame(packet) {
                Ok(()) => {
                    if kind == 0 {
                        // Clean stream: take every following valid sensor packet in one go.
                        let end = sensor_run_end(buf, pos + PACKET_LEN);
                        stats.sensor_packets += ((end - pos) / PACKET_LEN) as u64;
                        sink.sensor_block(&buf[pos..end]);
                        pos = end;
                    } else {
                        stats.other_packets[kind as usize] += 1;
                        sink.other(PacketType::ALL[kind as usize & 0xF], packet);
                        pos += PACKET_LEN;
                    }
                }
                Err(why) => {
                    let reason = match why {
                        Invalid::PayloadHighBit => RejectReason::PayloadHighBit,
                        Invalid::BadEndMarker => RejectReason::BadEndMarker,
                    };
                    stats.rejected[reason as usize] += 1;
                    stats.bytes_skipped += 1;
                    pos += 1;
                }
            }
        }
        Run::Next(pos)
    }
}

/// End of the run of consecutive valid sensor packets starting at `pos`.
#[inline(always)]
fn sensor_run_end(buf: &[u8], mut pos: usize) -> usize {
    while let Some(p) = buf.get(pos..).and_then(|s| s.first_chunk::<PACKET_LEN>()) {
        if p[0] != PacketType::Sensor.header() || check_frame(p).is_err() {
            break;
        }
        pos += PACKET_LEN;
    }
    pos
}

/// Index of the first byte ≥ 0x80, eight bytes at a time (garbage and gaps are skipped fast).
#[inline]
fn find_high(s: &[u8]) -> Option<usize> {
    let mut chunks = s.chunks_exact(8);
    let mut offset = 0;
    for c in &mut chunks {
        let word = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        let high = word & 0x8080_8080_8080_8080;
        if high != 0 {
            return Some(offset + (high.trailing_zeros() / 8) as usize);
        }
        offset += 8;
    }
    chunks
        .remainder()
        .iter()
        .position(|&b| b >= 0x80)
        .map(|k| offset + k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{reference_scan, Collect};
    use crate::{encode_packet, encode_sensor, PAYLOAD_LEN};

    fn sensor(cell: u16) -> [u8; PACKET_LEN] {
        encode_sensor(&SensorRaw {
            cell_id: cell,
            proximity: cell * 3,
            acc: [1, -2, 3],
            temp: [-4, 5],
            force: [6, 7, 8],
        })
        .unwrap()
    }

    fn parse(chunks: &[&[u8]]) -> (Collect, StreamParser) {
        let mut p = StreamParser::new();
        let mut sink = Collect::default();
        for c in chunks {
            p.feed(c, &mut sink);
        }
        (sink, p)
    }

    fn cells(c: &Collect) -> Vec<u16> {
        c.sensors.iter().map(|s| s.cell_id).collect()
    }

    #[test]
    fn find_high_matches_a_byte_loop() {
        for len in 0..40 {
            for at in 0..=len {
                let mut v = vec![0x7Fu8; len];
                if at < len {
                    v[at] = 0x80;
                }
                assert_eq!(find_high(&v), v.iter().position(|&b| b >= 0x80));
            }
        }
    }

    #[test]
    fn clean_stream_in_one_chunk_and_byte_by_byte() {
        let stream: Vec<u8> = (1..=5).flat_map(sensor).collect();
        let (one, p) = parse(&[&stream]);
        assert_eq!(cells(&one), vec![1, 2, 3, 4, 5]);
        assert_eq!(p.stats().bytes_skipped, 0);
        let bytes: Vec<&[u8]> = stream.chunks(1).collect();
        let (many, p) = parse(&bytes);
        assert_eq!(one, many);
        assert_eq!(p.stats().sensor_packets, 5);
        assert_eq!(p.pending(), 0);
    }

    #[test]
    fn truncated_packet_does_not_cost_the_next_one() {
        let a = sensor(1);
        let b = sensor(2);
        let mut stream = a[..11].to_vec(); // header + 10 bytes, then the next packet
        stream.extend_from_slice(&b);
        let (c, p) = parse(&[&stream]);
        assert_eq!(cells(&c), vec![2]);
        assert_eq!(p.stats().rejected(RejectReason::PayloadHighBit), 1);
        assert_eq!(p.stats().bytes_skipped, 11);
    }

    #[test]
    fn packet_missing_its_end_marker_byte() {
        // 19 bytes: the next header lands where 0xAA belongs.
        let mut stream = sensor(1)[..19].to_vec();
        stream.extend_from_slice(&sensor(2));
        let (c, p) = parse(&[&stream]);
        assert_eq!(cells(&c), vec![2]);
        assert_eq!(p.stats().rejected(RejectReason::BadEndMarker), 1);
    }

    #[test]
    fn dropped_byte_in_the_middle_and_stray_end_marker() {
        let mut a = sensor(1).to_vec();
        a.remove(7);
        let mut stream = a;
        stream.extend_from_slice(&sensor(2));
        stream.push(END_MARKER);
        stream.extend_from_slice(&sensor(3));
        let (c, p) = parse(&[&stream]);
        assert_eq!(cells(&c), vec![2, 3]);
        // The end marker moved into the payload: the damaged packet fails the payload check.
        assert_eq!(p.stats().rejected(RejectReason::PayloadHighBit), 1);
        assert_eq!(p.stats().rejected(RejectReason::UnknownHeader), 0);
        assert_eq!(p.stats().bytes_skipped, 20);
    }

    #[test]
    fn flipped_top_bit_rejects_only_that_packet() {
        let mut a = sensor(1);
        a[5] |= 0x80; // becomes an unknown header inside the packet
        let mut stream = a.to_vec();
        stream.extend_from_slice(&sensor(2));
        let (c, p) = parse(&[&stream]);
        assert_eq!(cells(&c), vec![2]);
        assert_eq!(p.stats().rejected(RejectReason::PayloadHighBit), 1);
        assert_eq!(p.stats().rejected(RejectReason::UnknownHeader), 1);
    }

    #[test]
    fn other_packet_types_are_counted_and_reported() {
        let ping = encode_packet(PacketType::Ping, &[1; PAYLOAD_LEN]).unwrap();
        let rate = encode_packet(PacketType::UpdateRate, &[3; PAYLOAD_LEN]).unwrap();
        let stream = [&sensor(1)[..], &ping, &rate, &ping, &sensor(2)].concat();
        let (c, p) = parse(&[&stream[..7], &stream[7..]]);
        assert_eq!(cells(&c), vec![1, 2]);
        assert_eq!(
            c.others,
            vec![
                (PacketType::Ping, ping),
                (PacketType::UpdateRate, rate),
                (PacketType::Ping, ping)
            ]
        );
        assert_eq!(p.stats().other(PacketType::Ping), 2);
        assert_eq!(p.stats().other(PacketType::UpdateRate), 1);
        assert_eq!(p.stats().packets_total(), 5);
    }

    #[test]
    fn carry_never_exceeds_nineteen_bytes() {
        let mut p = StreamParser::new();
        let mut sink = Collect::default();
        let s = sensor(9);
        for _ in 0..3 {
            for b in s {
                p.feed(&[b], &mut sink);
                assert!(p.pending() <= MAX_CARRY);
            }
        }
        p.feed(&s[..19], &mut sink);
        assert_eq!(p.pending(), 19);
        p.feed(&[], &mut sink);
        assert_eq!(p.pending(), 19);
        p.feed(&s[19..], &mut sink);
        assert_eq!(p.pending(), 0);
        assert_eq!(cells(&sink), vec![9; 4]);
    }

    #[test]
    fn rejection_is_decided_early_inside_the_carry() {
        let mut p = StreamParser::new();
        let mut sink = Collect::default();
        // header, 3 payload bytes, then a new header: the first candidate is dead already.
        p.feed(&[0xFF, 1, 2, 3, 0xFF, 4], &mut sink);
        assert_eq!(p.pending(), 2);
        assert_eq!(p.stats().rejected(RejectReason::PayloadHighBit), 1);
    }

    #[test]
    fn discard_pending_counts_the_fragment() {
        let mut p = StreamParser::new();
        let mut sink = Collect::default();
        p.feed(&sensor(1)[..12], &mut sink);
        p.discard_pending();
        p.feed(&sensor(2)[12..], &mut sink);
        assert!(sink.sensors.is_empty());
        assert_eq!(p.stats().bytes_skipped, 20);
        assert_eq!(p.pending(), 0);
    }

    #[test]
    fn agrees_with_the_reference_on_a_nasty_mix() {
        let ping = encode_packet(PacketType::Ping, &[0; PAYLOAD_LEN]).unwrap();
        let mut stream = Vec::new();
        for i in 0..50u16 {
            stream.extend_from_slice(&sensor(i));
            stream.extend_from_slice(&[0xAA, 0xFF, 0x80, 0x00, 0xC8][..(i % 6) as usize]);
            stream.extend_from_slice(&ping[..(i as usize * 7) % 21]);
        }
        let expected = reference_scan(&stream);
        for chunk in [1, 2, 3, 7, 19, 20, 21, 64, 1000] {
            let parts: Vec<&[u8]> = stream.chunks(chunk).collect();
            let (c, p) = parse(&parts);
            assert_eq!(c, expected.0, "chunk {chunk}");
            assert_eq!(p.stats(), &expected.1, "chunk {chunk}");
        }
    }
}
