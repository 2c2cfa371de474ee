//! The sensor data packet (header 0xFF): raw fields, their bit layout and physical units.

use std::ops::RangeInclusive;

use crate::packet::{END_MARKER, PACKET_LEN};
use crate::{EncodeError, PacketType, QuantizeError};

/// Representable raw values of each field (the bit widths of the protocol table).
pub const RANGE_CELL_ID: RangeInclusive<i64> = 0..=0x3FFF; // 14 bit unsigned
pub const RANGE_PROXIMITY: RangeInclusive<i64> = 0..=0xFFFF; // 16 bit unsigned
pub const RANGE_ACC: RangeInclusive<i64> = -512..=511; // 10 bit two's complement
pub const RANGE_TEMP_ACC: RangeInclusive<i64> = -128..=127; // 8 bit two's complement
pub const RANGE_TEMP_LM71: RangeInclusive<i64> = -8192..=8191; // 14 bit two's complement
pub const RANGE_FORCE: RangeInclusive<i64> = 0..=0x0FFF; // 12 bit unsigned

/// Raw → physical scale factors: `physical = raw * SCALE + OFFSET`. All scales are powers of
/// two, so the conversion is exact in both `f32` and `f64` and invertible.
pub mod scale {
    /// proximity: raw / 65536, dimensionless 0..1
    pub const PROXIMITY: f64 = 1.0 / 65536.0;
    /// acceleration: raw / 256 g
    pub const ACC: f64 = 1.0 / 256.0;
    /// accelerometer die temperature: raw * 0.5 + 24 °C
    pub const TEMP_ACC: f64 = 0.5;
    pub const TEMP_ACC_OFFSET: f64 = 24.0;
    /// LM71 temperature: raw * 0.03125 °C
    pub const TEMP_LM71: f64 = 0.03125;
    /// force: raw / 1024, normalised (per-cell calibration to newtons is outside the protocol)
    pub const FORCE: f64 = 1.0 / 1024.0;
}

/// One column of a raw sensor field: its representable range and its conversion to physical
/// units (`physical = raw * scale + offset`; `cell_id` is an identity, scale 1, offset 0).
///
/// [`ColumnSpec::to_physical`] and [`ColumnSpec::nearest_raw`] are the crate's only raw ↔
/// physical arithmetic: the decoder's sinks, [`quantize`], the Python binding and the
/// simulator's force loop all call them, so that a recording converts the same way wherever
/// it is converted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnSpec {
    pub min: i64,
    pub max: i64,
    pub scale: f64,
    pub offset: f64,
}

impl ColumnSpec {
    /// Raw value → physical units. Total over any raw value (in range or not): data stored
    /// before the range was checked must still read as it did.
    #[inline(always)]
    pub fn to_physical(&self, raw: impl Into<f64>) -> f64 {
        raw.into() * self.scale + self.offset
    }

    /// Physical value → the nearest representable raw value, as a float: rounded half to even
    /// (like numpy) and clipped to the range. NaN stays NaN, so that a caller that cannot
    /// report an error (the simulator's force loop) carries it instead of inventing a value.
    #[inline(always)]
    pub fn nearest_raw(&self, physical: f64) -> f64 {
        // Clip in floating point: ±inf and huge values then land on the range's ends instead
        // of relying on the saturating float → int cast.
        ((physical - self.offset) / self.scale)
            .round_ties_even()
            .clamp(self.min as f64, self.max as f64)
    }

    /// [`Self::nearest_raw`] as an integer; NaN is an error naming `field`.
    #[inline]
    pub fn quantize(&self, field: &'static str, physical: f64) -> Result<i64, QuantizeError> {
        if physical.is_nan() {
            return Err(QuantizeError::NaN { field });
        }
        Ok(self.nearest_raw(physical) as i64)
    }
}

/// One raw field of a sensor packet: its name, whether it is signed (all fields are 16-bit
/// integers in memory), and one [`ColumnSpec`] per column (1 for a scalar field).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldSpec {
    pub name: &'static str,
    pub signed: bool,
    /// `false` for a scalar field (shape `(n,)`), `true` for a row of columns (`(n, k)`).
    pub vector: bool,
    pub columns: &'static [ColumnSpec],
}

impl FieldSpec {
    /// Row-major raw values of this field (`columns.len()` per row) → physical units, in the
    /// same layout. A trailing partial row is converted column by column as far as it goes.
    pub fn to_physical<T: Copy + Into<f64>>(&self, raw: &[T]) -> Vec<f64> {
        match self.columns {
            // One conversion for every value (scalar fields, acc, force): a flat loop the
            // compiler vectorises.
            [first, rest @ ..] if rest.iter().all(|c| c == first) => {
                raw.iter().map(|&v| first.to_physical(v)).collect()
            }
            columns => {
                let mut out = Vec::with_capacity(raw.len());
                for row in raw.chunks(columns.len()) {
                    out.extend(row.iter().zip(columns).map(|(&v, c)| c.to_physical(v)));
                }
                out
            }
        }
    }
}

/// The field of [`SENSOR_FIELDS`] named `name`.
pub fn sensor_field(name: &str) -> Option<&'static FieldSpec> {
    SENSOR_FIELDS.iter().find(|f| f.name == name)
}

const fn col(range: RangeInclusive<i64>, scale: f64, offset: f64) -> ColumnSpec {
    ColumnSpec {
        min: *range.start(),
        max: *range.end(),
        scale,
        offset,
    }
}

/// Each column's [`ColumnSpec`], by name, for code that handles one field (the decoder, the
/// simulator's force loop); [`SENSOR_FIELDS`] is made of these.
pub mod column {
    use super::{col, scale, ColumnSpec};
    use super::{RANGE_ACC, RANGE_CELL_ID, RANGE_FORCE, RANGE_PROXIMITY};
    use super::{RANGE_TEMP_ACC, RANGE_TEMP_LM71};

    pub const CELL_ID: ColumnSpec = col(RANGE_CELL_ID, 1.0, 0.0);
    pub const PROXIMITY: ColumnSpec = col(RANGE_PROXIMITY, scale::PROXIMITY, 0.0);
    pub const ACC: ColumnSpec = col(RANGE_ACC, scale::ACC, 0.0);
    pub const TEMP_ACC: ColumnSpec = col(RANGE_TEMP_ACC, scale::TEMP_ACC, scale::TEMP_ACC_OFFSET);
    pub const TEMP_LM71: ColumnSpec = col(RANGE_TEMP_LM71, scale::TEMP_LM71, 0.0);
    pub const FORCE: ColumnSpec = col(RANGE_FORCE, scale::FORCE, 0.0);
}

/// The sensor packet's fields in the order of [`SensorRaw`]: the one table of names, ranges
/// and scales that the Python package reads (through the binding) instead of keeping copies.
pub const SENSOR_FIELDS: [FieldSpec; 5] = [
    FieldSpec {
        name: "cell_id",
        signed: false,
        vector: false,
        columns: &[column::CELL_ID],
    },
    FieldSpec {
        name: "proximity",
        signed: false,
        vector: false,
        columns: &[column::PROXIMITY],
    },
    FieldSpec {
        name: "acc",
        signed: true,
        vector: true,
        columns: &[column::ACC, column::ACC, column::ACC],
    },
    FieldSpec {
        name: "temp",
        signed: true,
        vector: true,
        columns: &[column::TEMP_ACC, column::TEMP_LM71],
    },
    FieldSpec {
        name: "force",
        signed: false,
        vector: true,
        columns: &[column::FORCE, column::FORCE, column::FORCE],
    },
];

/// Raw fields of one sensor packet. `temp` is `[accelerometer die, LM71]`.
///
/// Not every value of these Rust types is representable on the wire (see the `RANGE_*`
/// constants); [`encode_sensor`] rejects the others.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SensorRaw {
    pub cell_id: u16,
    pub proximity: u16,
    pub acc: [i16; 3],
    pub temp: [i16; 2],
    pub force: [u16; 3],
}

/// One sensor packet in physical units (force still normalised).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorPhysical {
    pub cell_id: u16,
    pub proximity: f64,
    /// g
    pub acc: [f64; 3],
    /// °C: accelerometer die, LM71
    pub temp: [f64; 2],
    /// normalised: raw / 1024
    pub force: [f64; 3],
}

#[inline(always)]
fn sign_extend(value: u32, bits: u32) -> i16 {
    let shift = 32 - bits;
    ((value << shift) as i32 >> shift) as i16
}

/// Decodes the fields of a sensor packet. Only the data bits named by the protocol are read,
/// so unused bits and framing are ignored here (the parser checks framing before calling).
#[inline(always)]
pub fn decode_sensor(p: &[u8; PACKET_LEN]) -> SensorRaw {
    let b = |i: usize| u32::from(p[i] & 0x7F);
    let acc = |hi: usize, lo: usize| sign_extend((b(hi) << 3) | (b(lo) & 0x7), 10);
    let force = |hi: usize, lo: usize| ((b(hi) << 5) | (b(lo) & 0x1F)) as u16;
    let temp_acc = ((b(8) << 1) & 0xF0) | ((b(9) >> 3) & 0xF);
    SensorRaw {
        cell_id: ((b(1) << 7) | b(2)) as u16,
        proximity: ((b(3) << 9) | (b(4) << 2) | ((b(10) >> 3) & 0x3)) as u16,
        acc: [acc(5, 8), acc(6, 9), acc(7, 10)],
        temp: [
            sign_extend(temp_acc, 8),
            sign_extend((b(17) << 7) | b(18), 14),
        ],
        force: [force(11, 12), force(13, 14), force(15, 16)],
    }
}

impl SensorRaw {
    /// Physical units per the protocol table.
    #[inline(always)]
    pub fn to_physical(&self) -> SensorPhysical {
        SensorPhysical {
            cell_id: self.cell_id,
            proximity: column::PROXIMITY.to_physical(self.proximity),
            acc: self.acc.map(|a| column::ACC.to_physical(a)),
            temp: [
                column::TEMP_ACC.to_physical(self.temp[0]),
                column::TEMP_LM71.to_physical(self.temp[1]),
            ],
            force: self.force.map(|f| column::FORCE.to_physical(f)),
        }
    }

    /// Checks every field against its bit width.
    pub fn validate(&self) -> Result<(), EncodeError> {
        let check = |field: &'static str, value: i64, range: RangeInclusive<i64>| {
            if range.contains(&value) {
                Ok(())
            } else {
                Err(EncodeError {
                    field,
                    value,
                    min: *range.start(),
                    max: *range.end(),
                })
            }
        };
        check("cell_id", i64::from(self.cell_id), RANGE_CELL_ID)?;
        for a in self.acc {
            check("acc", i64::from(a), RANGE_ACC)?;
        }
        check("temp", i64::from(self.temp[0]), RANGE_TEMP_ACC)?;
        check("temp", i64::from(self.temp[1]), RANGE_TEMP_LM71)?;
        for f in self.force {
            check("force", i64::from(f), RANGE_FORCE)?;
        }
        Ok(())
    }
}

/// Encodes a sensor packet into `out` (20 bytes); unused bits are sent as 0.
pub fn encode_sensor_into(raw: &SensorRaw, out: &mut [u8; PACKET_LEN]) -> Result<(), EncodeError> {
    raw.validate()?;
    let cell = u32::from(raw.cell_id);
    let prox = u32::from(raw.proximity);
    // Two's complement fields are masked to their width; validate() guarantees no information is lost.
    let acc = raw.acc.map(|a| (a as u32) & 0x3FF);
    let t_acc = (raw.temp[0] as u32) & 0xFF;
    let t_lm71 = (raw.temp[1] as u32) & 0x3FFF;
    let force = raw.force.map(u32::from);
    let bytes: [u32; PACKET_LEN] = [
        u32::from(PacketType::Sensor.header()),
        cell >> 7,
        cell & 0x7F,
        prox >> 9,
        (prox >> 2) & 0x7F,
        acc[0] >> 3,
        acc[1] >> 3,
        acc[2] >> 3,
        (acc[0] & 0x7) | ((t_acc >> 4) << 3),
        (acc[1] & 0x7) | ((t_acc & 0xF) << 3),
        (acc[2] & 0x7) | ((prox & 0x3) << 3),
        force[0] >> 5,
        force[0] & 0x1F,
        force[1] >> 5,
        force[1] & 0x1F,
        force[2] >> 5,
        force[2] & 0x1F,
        t_lm71 >> 7,
        t_lm71 & 0x7F,
        u32::from(END_MARKER),
    ];
    for (o, b) in out.iter_mut().zip(bytes) {
        *o = b as u8;
    }
    Ok(())
}

/// Encodes a sensor packet (raw fields → 20 wire bytes).
pub fn encode_sensor(raw: &SensorRaw) -> Result<[u8; PACKET_LEN], EncodeError> {
    let mut out = [0u8; PACKET_LEN];
    encode_sensor_into(raw, &mut out)?;
    Ok(out)
}

/// Physical values → the nearest representable raw values (round half to even, clip to the
/// field's range). `cell_id` is an identity, not a measurement: out of range is an error.
pub fn quantize(
    cell_id: i64,
    proximity: f64,
    acc_g: [f64; 3],
    temp_c: [f64; 2],
    force_norm: [f64; 3],
) -> Result<SensorRaw, QuantizeError> {
    if !RANGE_CELL_ID.contains(&cell_id) {
        return Err(QuantizeError::CellId(cell_id));
    }
    // The casts cannot truncate: quantize() returns values within each column's range.
    let mut acc = [0i16; 3];
    for (o, a) in acc.iter_mut().zip(acc_g) {
        *o = column::ACC.quantize("acc", a)? as i16;
    }
    let mut force = [0u16; 3];
    for (o, f) in force.iter_mut().zip(force_norm) {
        *o = column::FORCE.quantize("force", f)? as u16;
    }
    Ok(SensorRaw {
        cell_id: cell_id as u16,
        proximity: column::PROXIMITY.quantize("proximity", proximity)? as u16,
        acc,
        temp: [
            column::TEMP_ACC.quantize("temp", temp_c[0])? as i16,
            column::TEMP_LM71.quantize("temp", temp_c[1])? as i16,
        ],
        force,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sets column `c` of the field named `name` in `raw` (the table's order and shapes).
    fn set(raw: &mut SensorRaw, name: &str, c: usize, v: i64) {
        match name {
            "cell_id" => raw.cell_id = v as u16,
            "proximity" => raw.proximity = v as u16,
            "acc" => raw.acc[c] = v as i16,
            "temp" => raw.temp[c] = v as i16,
            "force" => raw.force[c] = v as u16,
            other => panic!("unknown field {other}"),
        }
    }

    fn physical_of(p: &SensorPhysical, name: &str, c: usize) -> f64 {
        match name {
            "cell_id" => f64::from(p.cell_id),
            "proximity" => p.proximity,
            "acc" => p.acc[c],
            "temp" => p.temp[c],
            "force" => p.force[c],
            other => panic!("unknown field {other}"),
        }
    }

    /// The exported table is the one the decoder and the validator use: its ranges are exactly
    /// what `validate` accepts, its scales what `to_physical` applies.
    #[test]
    fn the_field_table_agrees_with_decoding_and_validation() {
        let names: Vec<&str> = SENSOR_FIELDS.iter().map(|f| f.name).collect();
        assert_eq!(names, ["cell_id", "proximity", "acc", "temp", "force"]);
        for field in SENSOR_FIELDS {
            assert_eq!(field.vector, field.columns.len() > 1);
            for (c, spec) in field.columns.iter().enumerate() {
                assert_eq!(field.signed, spec.min < 0, "{}", field.name);
                for v in [spec.min, spec.max, (spec.min + spec.max) / 2] {
                    let mut raw = SensorRaw::default();
                    set(&mut raw, field.name, c, v);
                    assert!(raw.validate().is_ok(), "{} = {v}", field.name);
                    let got = physical_of(&raw.to_physical(), field.name, c);
                    assert_eq!(
                        got,
                        v as f64 * spec.scale + spec.offset,
                        "{}[{c}]",
                        field.name
                    );
                }
                let limit = if field.signed {
                    i64::from(i16::MAX)
                } else {
                    i64::from(u16::MAX)
                };
                if spec.max < limit {
                    let mut raw = SensorRaw::default();
                    set(&mut raw, field.name, c, spec.max + 1);
                    assert!(raw.validate().is_err(), "{} = {}", field.name, spec.max + 1);
                }
            }
        }
    }

    /// Every representable raw value of every column: raw → physical → raw is the identity,
    /// and the column-wise conversion (what the binding calls) is the per-packet one.
    #[test]
    fn every_raw_value_round_trips_through_physical() {
        for field in SENSOR_FIELDS {
            for (c, spec) in field.columns.iter().enumerate() {
                for v in spec.min..=spec.max {
                    let physical = spec.to_physical(v as f64);
                    assert_eq!(spec.quantize(field.name, physical), Ok(v), "{}", field.name);
                    let mut raw = SensorRaw::default();
                    set(&mut raw, field.name, c, v);
                    assert_eq!(
                        physical,
                        physical_of(&raw.to_physical(), field.name, c),
                        "{}[{c}] = {v}",
                        field.name
                    );
                }
            }
        }
        let temp = sensor_field("temp").unwrap();
        let got = temp.to_physical(&[-128i16, -8192, 127, 8191, 5]);
        assert_eq!(got, [-40.0, -256.0, 87.5, 8191.0 * 0.03125, 26.5]);
        let acc = sensor_field("acc").unwrap();
        assert_eq!(
            acc.to_physical(&[-512i16, 256, 1]),
            [-2.0, 1.0, 1.0 / 256.0]
        );
        assert!(sensor_field("nope").is_none());
    }

    #[test]
    fn nearest_raw_carries_nan_and_clips_infinities() {
        assert!(column::FORCE.nearest_raw(f64::NAN).is_nan());
        assert_eq!(column::FORCE.nearest_raw(f64::INFINITY), 4095.0);
        assert_eq!(column::TEMP_ACC.nearest_raw(f64::NEG_INFINITY), -128.0);
        assert_eq!(column::TEMP_ACC.nearest_raw(24.25), 0.0); // half to even
        assert_eq!(column::TEMP_ACC.nearest_raw(24.75), 2.0);
    }

    /// A packet written out by hand from the protocol table, bit by bit.
    #[test]
    fn decodes_a_hand_built_packet() {
        // cell 0x1234 = 0b01_0010_0011_0100 → b1 = 0x24, b2 = 0x34
        // proximity 0xBEEF = 1011 1110 1110 1111 → b3 = 0x5F (bits 15..9), b4 = 0x3B (bits 8..2), low 2 = 0b11
        // acc x = -1 (0x3FF): b5 = 0x7F, b8 low3 = 7; acc y = 5 (0x005): b6 = 0, b9 low3 = 5
        // acc z = -512 (0x200): b7 = 0x40, b10 low3 = 0
        // temp1 = -3 (0xFD): b8 bits 3..6 = 0xF, b9 bits 3..6 = 0xD
        // forces 4095, 1, 2048; LM71 = -2 (0x3FFE): b17 = 0x7F, b18 = 0x7E
        let p: [u8; 20] = [
            0xFF,
            0x24,
            0x34,
            0x5F,
            0x3B,
            0x7F,
            0x00,
            0x40,
            (0xF << 3) | 7,
            (0xD << 3) | 5,
            (0b11 << 3),
            0x7F,
            0x1F,
            0x00,
            0x01,
            0x40,
            0x00,
            0x7F,
            0x7E,
            0xAA,
        ];
        let raw = decode_sensor(&p);
        assert_eq!(
            raw,
            SensorRaw {
                cell_id: 0x1234,
                proximity: 0xBEEF,
                acc: [-1, 5, -512],
                temp: [-3, -2],
                force: [4095, 1, 2048],
            }
        );
        assert_eq!(encode_sensor(&raw).unwrap(), p);
        let phys = raw.to_physical();
        assert_eq!(phys.proximity, 48879.0 / 65536.0);
        assert_eq!(phys.acc, [-1.0 / 256.0, 5.0 / 256.0, -2.0]);
        assert_eq!(phys.temp, [22.5, -0.0625]);
        assert_eq!(phys.force, [4095.0 / 1024.0, 1.0 / 1024.0, 2.0]);
    }

    #[test]
    fn unused_bits_are_ignored_by_the_decoder() {
        let raw = SensorRaw {
            cell_id: 7,
            proximity: 1,
            acc: [1, 2, 3],
            temp: [4, 5],
            force: [6, 7, 8],
        };
        let mut p = encode_sensor(&raw).unwrap();
        p[10] |= 0b0110_0000;
        for i in [12, 14, 16] {
            p[i] |= 0b0110_0000;
        }
        assert_eq!(decode_sensor(&p), raw);
    }

    #[test]
    fn encoder_rejects_each_out_of_range_field() {
        let ok = SensorRaw::default();
        let cases = [
            SensorRaw {
                cell_id: 0x4000,
                ..ok
            },
            SensorRaw {
                acc: [512, 0, 0],
                ..ok
            },
            SensorRaw {
                acc: [0, -513, 0],
                ..ok
            },
            SensorRaw {
                temp: [128, 0],
                ..ok
            },
            SensorRaw {
                temp: [-129, 0],
                ..ok
            },
            SensorRaw {
                temp: [0, 8192],
                ..ok
            },
            SensorRaw {
                temp: [0, -8193],
                ..ok
            },
            SensorRaw {
                force: [0, 0, 4096],
                ..ok
            },
        ];
        for c in cases {
            assert!(encode_sensor(&c).is_err(), "{c:?}");
        }
        let extremes = SensorRaw {
            cell_id: 0x3FFF,
            proximity: u16::MAX,
            acc: [511, -512, 0],
            temp: [-128, 8191],
            force: [4095, 0, 4095],
        };
        assert_eq!(decode_sensor(&encode_sensor(&extremes).unwrap()), extremes);
    }

    #[test]
    fn quantize_rounds_half_to_even_and_clips() {
        let r = quantize(
            3,
            0.5,
            [1.0, -3.0, 2.5 / 256.0],
            [24.25, 20.0],
            [0.5, 10.0, -1.0],
        )
        .unwrap();
        assert_eq!(r.cell_id, 3);
        assert_eq!(r.proximity, 32768);
        assert_eq!(r.acc, [256, -512, 2]); // -3 g clips to -512; 2.5 → 2 (half to even)
        assert_eq!(r.temp, [0, 640]); // (24.25 - 24) / 0.5 = 0.5 → 0
        assert_eq!(r.force, [512, 4095, 0]);
        let inf = quantize(
            0,
            f64::INFINITY,
            [f64::NEG_INFINITY; 3],
            [1e300, -1e300],
            [f64::INFINITY; 3],
        )
        .unwrap();
        assert_eq!(inf.proximity, 65535);
        assert_eq!(inf.acc, [-512; 3]);
        assert_eq!(inf.temp, [127, -8192]);
        assert_eq!(inf.force, [4095; 3]);
        assert!(matches!(
            quantize(0, f64::NAN, [0.0; 3], [0.0; 2], [0.0; 3]),
            Err(QuantizeError::NaN { .. })
        ));
        assert!(matches!(
            quantize(16384, 0.0, [0.0; 3], [0.0; 2], [0.0; 3]),
            Err(QuantizeError::CellId(_))
        ));
        assert!(matches!(
            quantize(-1, 0.0, [0.0; 3], [0.0; 2], [0.0; 3]),
            Err(QuantizeError::CellId(_))
        ));
    }
}
