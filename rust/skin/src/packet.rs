//! Packet framing: lengths, markers and the header byte of every packet type.

/// Every packet on the wire is this long.
pub const PACKET_LEN: usize = 20;
/// Payload bytes between header and end marker; each carries 7 data bits.
pub const PAYLOAD_LEN: usize = 18;
/// End-of-frame marker, the last byte of every packet.
pub const END_MARKER: u8 = 0xAA;

/// The packet types of protocol version 2, identified by their header byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum PacketType {
    Sensor = 0xFF,
    Events = 0xE2,
    LedColour = 0xC3,
    LedPwm = 0xCA,
    NeighbourList = 0xC6,
    MemoryId = 0xC4,
    MemoryOffsets = 0xC5,
    UpdateRate = 0xC8,
    ColourFeedback = 0xCC,
    Ping = 0xCB,
    MasterPort = 0xC7,
    Clock = 0xF1,
    BootLoader = 0xD0,
    PortCalibration = 0xC0,
    IdDistribution = 0xC1,
    NeighbourExploration = 0xC2,
}

impl PacketType {
    /// All types; the index of a type in this array is [`PacketType::index`].
    pub const ALL: [PacketType; 16] = [
        PacketType::Sensor,
        PacketType::Events,
        PacketType::LedColour,
        PacketType::LedPwm,
        PacketType::NeighbourList,
        PacketType::MemoryId,
        PacketType::MemoryOffsets,
        PacketType::UpdateRate,
        PacketType::ColourFeedback,
        PacketType::Ping,
        PacketType::MasterPort,
        PacketType::Clock,
        PacketType::BootLoader,
        PacketType::PortCalibration,
        PacketType::IdDistribution,
        PacketType::NeighbourExploration,
    ];

    /// The header byte.
    #[inline]
    pub const fn header(self) -> u8 {
        self as u8
    }

    /// Position in [`PacketType::ALL`].
    #[inline]
    pub fn index(self) -> usize {
        HEADER_KIND[self as usize] as usize
    }

    /// The type a header byte announces, if it is a known header.
    #[inline]
    pub fn from_header(byte: u8) -> Option<PacketType> {
        PacketType::ALL
            .get(HEADER_KIND[byte as usize] as usize)
            .copied()
    }

    /// Stable snake_case name, used as the key in statistics.
    pub const fn name(self) -> &'static str {
        match self {
            PacketType::Sensor => "sensor",
            PacketType::Events => "events",
            PacketType::LedColour => "led_colour",
            PacketType::LedPwm => "led_pwm",
            PacketType::NeighbourList => "neighbour_list",
            PacketType::MemoryId => "memory_id",
            PacketType::MemoryOffsets => "memory_offsets",
            PacketType::UpdateRate => "update_rate",
            PacketType::ColourFeedback => "colour_feedback",
            PacketType::Ping => "ping",
            PacketType::MasterPort => "master_port",
            PacketType::Clock => "clock",
            PacketType::BootLoader => "boot_loader",
            PacketType::PortCalibration => "port_calibration",
            PacketType::IdDistribution => "id_distribution",
            PacketType::NeighbourExploration => "neighbour_exploration",
        }
    }
}

/// Marks bytes that are not a known header in [`HEADER_KIND`].
pub(crate) const NOT_A_HEADER: u8 = 0xFF;

/// Header byte → index into [`PacketType::ALL`], or [`NOT_A_HEADER`]. A table lookup keeps the
/// parser's hot loop free of a 16-way match.
pub(crate) static HEADER_KIND: [u8; 256] = {
    let mut table = [NOT_A_HEADER; 256];
    let mut i = 0;
    while i < PacketType::ALL.len() {
        table[PacketType::ALL[i] as usize] = i as u8;
        i += 1;
    }
    table
};

/// Why a candidate packet (a known header at a packet start) was not accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Invalid {
    PayloadHighBit,
    BadEndMarker,
}

// Top bits of bytes 1..=7 (byte 0 is the header), 8..=15 and 16..=18 of a packet.
const HIGH_1_7: u64 = 0x8080_8080_8080_8000;
const HIGH_8_15: u64 = 0x8080_8080_8080_8080;
const HIGH_16_18: u32 = 0x0080_8080;

/// Checks framing of a packet whose header is already known: payload bytes below 0x80 and
/// the end marker in place. Word-wide tests because this runs once per packet.
#[inline(always)]
pub(crate) fn check_frame(p: &[u8; PACKET_LEN]) -> Result<(), Invalid> {
    let lo = u64::from_le_bytes([p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]]);
    let mid = u64::from_le_bytes([p[8], p[9], p[10], p[11], p[12], p[13], p[14], p[15]]);
    let hi = u32::from_le_bytes([p[16], p[17], p[18], p[19]]);
    if (lo & HIGH_1_7) | (mid & HIGH_8_15) | u64::from(hi & HIGH_16_18) != 0 {
        Err(Invalid::PayloadHighBit)
    } else if p[19] != END_MARKER {
        Err(Invalid::BadEndMarker)
    } else {
        Ok(())
    }
}

/// True when `p` is a complete valid packet of a known type.
pub fn is_valid_packet(p: &[u8; PACKET_LEN]) -> bool {
    PacketType::from_header(p[0]).is_some() && check_frame(p).is_ok()
}

/// Frames a packet of any type from its 18 payload bytes. Payload bytes must be below 0x80.
pub fn encode_packet(
    kind: PacketType,
    payload: &[u8; PAYLOAD_LEN],
) -> Result<[u8; PACKET_LEN], crate::EncodeError> {
    let mut out = [0u8; PACKET_LEN];
    out[0] = kind.header();
    for (i, &b) in payload.iter().enumerate() {
        if b >= 0x80 {
            return Err(crate::EncodeError {
                field: "payload",
                value: i64::from(b),
                min: 0,
                max: 0x7F,
            });
        }
        out[1 + i] = b;
    }
    out[PACKET_LEN - 1] = END_MARKER;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_type_round_trips_through_its_header() {
        for (i, t) in PacketType::ALL.iter().enumerate() {
            assert_eq!(PacketType::from_header(t.header()), Some(*t));
            assert_eq!(t.index(), i);
        }
        let known: Vec<u8> = PacketType::ALL.iter().map(|t| t.header()).collect();
        for b in 0..=255u8 {
            assert_eq!(
                PacketType::from_header(b).is_some(),
                known.contains(&b),
                "byte {b:#x}"
            );
        }
        assert!(PacketType::from_header(END_MARKER).is_none());
    }

    #[test]
    fn names_are_unique() {
        let mut names: Vec<&str> = PacketType::ALL.iter().map(|t| t.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), PacketType::ALL.len());
    }

    #[test]
    fn frame_check_finds_each_high_payload_byte_and_the_end_marker() {
        let ok = encode_packet(PacketType::Ping, &[0x55; PAYLOAD_LEN]).unwrap();
        assert_eq!(check_frame(&ok), Ok(()));
        for i in 1..=PAYLOAD_LEN {
            let mut p = ok;
            p[i] |= 0x80;
            assert_eq!(check_frame(&p), Err(Invalid::PayloadHighBit), "byte {i}");
        }
        for end in [0x00u8, 0x2A, 0xAB, 0xFF] {
            let mut p = ok;
            p[19] = end;
            assert_eq!(check_frame(&p), Err(Invalid::BadEndMarker));
        }
        let mut payload = [0u8; PAYLOAD_LEN];
        payload[3] = 0x80;
        assert!(encode_packet(PacketType::Ping, &payload).is_err());
    }
}
