//! Properties of the encoder and the streaming parser (proptest).

use aptkt_skin::testing::{chunk_sizes, fuzz_check, reference_decode, reference_scan, Collect};
use aptkt_skin::{
    decode_sensor, encode_packet, encode_sensor, is_valid_packet, quantize, PacketType, SensorRaw,
    StreamParser, END_MARKER, PACKET_LEN, PAYLOAD_LEN,
};
use proptest::prelude::*;

fn sensor_raw() -> impl Strategy<Value = SensorRaw> {
    (
        0u16..=0x3FFF,
        any::<u16>(),
        [-512i16..=511, -512i16..=511, -512i16..=511],
        (-128i16..=127, -8192i16..=8191),
        [0u16..=4095, 0u16..=4095, 0u16..=4095],
    )
        .prop_map(|(cell_id, proximity, acc, (t0, t1), force)| SensorRaw {
            cell_id,
            proximity,
            acc,
            temp: [t0, t1],
            force,
        })
}

fn other_type() -> impl Strategy<Value = PacketType> {
    proptest::sample::select(PacketType::ALL[1..].to_vec())
}

fn parse_chunked(stream: &[u8], sizes: &[usize]) -> (Collect, StreamParser) {
    let mut parser = StreamParser::new();
    let mut sink = Collect::default();
    let mut at = 0;
    for &n in sizes {
        parser.feed(&stream[at..at + n], &mut sink);
        at += n;
    }
    parser.feed(&stream[at..], &mut sink);
    (sink, parser)
}

/// One element of a damaged stream.
#[derive(Debug, Clone)]
enum Piece {
    Intact(SensorRaw),
    Other(PacketType, [u8; PAYLOAD_LEN]),
    /// The top bit of payload byte `at` (1..=18) set.
    Flipped(SensorRaw, usize),
    /// Bytes `from..to` lost, 1 <= from < to <= 20 (the header survives).
    Dropped(SensorRaw, usize, usize),
    /// Only the first `keep` (1..=19) bytes arrive.
    Truncated(SensorRaw, usize),
    /// Line noise.
    Garbage(Vec<u8>),
}

impl Piece {
    fn bytes(&self) -> Vec<u8> {
        let enc = |r: &SensorRaw| encode_sensor(r).unwrap().to_vec();
        match self {
            Piece::Intact(r) => enc(r),
            Piece::Other(t, payload) => encode_packet(*t, payload).unwrap().to_vec(),
            Piece::Flipped(r, at) => {
                let mut b = enc(r);
                b[*at] |= 0x80;
                b
            }
            Piece::Dropped(r, from, to) => {
                let mut b = enc(r);
                b.drain(*from..*to);
                b
            }
            Piece::Truncated(r, keep) => enc(r)[..*keep].to_vec(),
            Piece::Garbage(g) => g.clone(),
        }
    }
}

/// Damage that cannot, by construction, form a valid packet out of pieces of others: garbage
/// has no 0xAA and every damaged packet keeps its header. Then the parser's output must be
/// exactly the intact packets.
fn piece(garbage: BoxedStrategy<u8>) -> impl Strategy<Value = Piece> {
    prop_oneof![
        4 => sensor_raw().prop_map(Piece::Intact),
        1 => (other_type(), proptest::array::uniform18(0u8..0x80)).prop_map(|(t, p)| Piece::Other(t, p)),
        1 => (sensor_raw(), 1usize..=18).prop_map(|(r, at)| Piece::Flipped(r, at)),
        1 => (sensor_raw(), 1usize..20, 1usize..=19)
            .prop_map(|(r, from, len)| Piece::Dropped(r, from, (from + len).min(20))),
        1 => (sensor_raw(), 1usize..=19).prop_map(|(r, keep)| Piece::Truncated(r, keep)),
        1 => proptest::collection::vec(garbage, 0..45).prop_map(Piece::Garbage),
    ]
}

fn no_end_marker() -> BoxedStrategy<u8> {
    any::<u8>()
        .prop_filter("no 0xAA", |&b| b != END_MARKER)
        .boxed()
}

fn intact_sensors(pieces: &[Piece]) -> Vec<SensorRaw> {
    pieces
        .iter()
        .filter_map(|p| {
            if let Piece::Intact(r) = p {
                Some(*r)
            } else {
                None
            }
        })
        .collect()
}

fn is_subsequence<T: PartialEq>(needle: &[T], haystack: &[T]) -> bool {
    let mut it = haystack.iter();
    needle.iter().all(|n| it.any(|h| h == n))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn decode_inverts_encode(raw in sensor_raw()) {
        let bytes = encode_sensor(&raw).unwrap();
        prop_assert!(is_valid_packet(&bytes));
        prop_assert_eq!(decode_sensor(&bytes), raw);
        prop_assert_eq!(reference_decode(&bytes), raw);
    }

    #[test]
    fn encode_inverts_decode_up_to_unused_bits(payload in proptest::array::uniform18(0u8..0x80)) {
        let packet = encode_packet(PacketType::Sensor, &payload).unwrap();
        let mut cleared = packet;
        cleared[10] &= 0x1F;
        for i in [12, 14, 16] {
            cleared[i] &= 0x1F;
        }
        prop_assert_eq!(encode_sensor(&decode_sensor(&packet)).unwrap(), cleared);
    }

    #[test]
    fn quantize_inverts_the_physical_conversion(raw in sensor_raw()) {
        let p = raw.to_physical();
        prop_assert_eq!(quantize(i64::from(p.cell_id), p.proximity, p.acc, p.temp, p.force).unwrap(), raw);
    }

    #[test]
    fn parser_equals_the_reference_on_any_bytes(
        stream in proptest::collection::vec(
            prop_oneof![any::<u8>(), Just(0xFFu8), Just(END_MARKER), 0u8..0x80], 0..400),
        seed in any::<u64>(),
        max in 0usize..45,
    ) {
        let sizes = chunk_sizes(stream.len(), seed, max.max(1));
        let (got, parser) = parse_chunked(&stream, &sizes);
        let (want, stats) = reference_scan(&stream);
        prop_assert_eq!(got, want);
        prop_assert_eq!(parser.stats(), &stats);
    }

    #[test]
    fn fuzz_body_holds_on_structured_streams(pieces in proptest::collection::vec(piece(any::<u8>().boxed()), 0..20), seed in any::<u8>()) {
        let mut data = vec![seed];
        data.extend(pieces.iter().flat_map(Piece::bytes));
        fuzz_check(&data);
    }

    #[test]
    fn every_intact_packet_and_nothing_else(
        pieces in proptest::collection::vec(piece(no_end_marker()), 0..40),
        seed in any::<u64>(),
        max in 1usize..64,
    ) {
        let stream: Vec<u8> = pieces.iter().flat_map(Piece::bytes).collect();
        let (whole, _) = parse_chunked(&stream, &[]);
        prop_assert_eq!(&whole.sensors, &intact_sensors(&pieces));
        let others: Vec<(PacketType, [u8; PACKET_LEN])> = pieces
            .iter()
            .filter_map(|p| if let Piece::Other(t, pl) = p { Some((*t, encode_packet(*t, pl).unwrap())) } else { None })
            .collect();
        prop_assert_eq!(&whole.others, &others);
        // Independent of chunking, statistics included.
        let (chunked, parser) = parse_chunked(&stream, &chunk_sizes(stream.len(), seed, max));
        let (_, one_shot) = parse_chunked(&stream, &[]);
        prop_assert_eq!(&chunked, &whole);
        prop_assert_eq!(parser.stats(), one_shot.stats());
    }

    #[test]
    fn intact_packets_survive_any_garbage(
        pieces in proptest::collection::vec(
            prop_oneof![
                3 => piece(any::<u8>().boxed()),
                // a packet that lost its header: its tail may glue onto a preceding 0xFF
                1 => (sensor_raw(), 1usize..20).prop_map(|(r, from)| Piece::Garbage(encode_sensor(&r).unwrap()[from..].to_vec())),
            ],
            0..40),
        seed in any::<u64>(),
    ) {
        let stream: Vec<u8> = pieces.iter().flat_map(Piece::bytes).collect();
        let (got, _) = parse_chunked(&stream, &chunk_sizes(stream.len(), seed, 33));
        prop_assert!(is_subsequence(&intact_sensors(&pieces), &got.sensors));
    }
}
