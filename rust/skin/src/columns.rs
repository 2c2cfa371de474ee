//! Column-oriented sinks: one vector per field, rows in stream order. This is the layout the
//! Python binding hands to numpy without copying (each `Vec` becomes an array's buffer).

use crate::packet::PACKET_LEN;
use crate::parser::PacketSink;
use std::ops::RangeInclusive;

use crate::sensor::{
    decode_sensor, SensorRaw, RANGE_ACC, RANGE_CELL_ID, RANGE_FORCE, RANGE_PROXIMITY,
    RANGE_TEMP_ACC, RANGE_TEMP_LM71,
};
use crate::{EncodeError, PacketType};

/// Sensor packets in physical units: `acc`, `temp`, `force` are row-major `(n, 3)`, `(n, 2)`,
/// `(n, 3)`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PhysicalColumns {
    pub cell_id: Vec<u16>,
    pub proximity: Vec<f64>,
    pub acc: Vec<f64>,
    pub temp: Vec<f64>,
    pub force: Vec<f64>,
}

impl PhysicalColumns {
    pub fn len(&self) -> usize {
        self.cell_id.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cell_id.is_empty()
    }
}

/// Packets per step of a block decode: the step's output (74 bytes per packet) is zero-filled
/// and then overwritten while it is still in L1/L2, so the zero-fill costs no memory traffic.
const STEP: usize = 512;

impl PacketSink for PhysicalColumns {
    fn sensor_block(&mut self, block: &[u8]) {
        for step in block.chunks(STEP * PACKET_LEN) {
            self.decode_step(step);
        }
    }

    #[inline(always)]
    fn sensor(&mut self, p: &SensorRaw) {
        let p = p.to_physical();
        self.cell_id.push(p.cell_id);
        self.proximity.push(p.proximity);
        self.acc.extend_from_slice(&p.acc);
        self.temp.extend_from_slice(&p.temp);
        self.force.extend_from_slice(&p.force);
    }

    fn reserve(&mut self, n: usize) {
        self.cell_id.reserve(n);
        self.proximity.reserve(n);
        self.acc.reserve(3 * n);
        self.temp.reserve(2 * n);
        self.force.reserve(3 * n);
    }
}

impl PhysicalColumns {
    #[inline(always)]
    fn decode_step(&mut self, block: &[u8]) {
        let n = block.len() / PACKET_LEN;
        let start = self.cell_id.len();
        // Zero-filling then overwriting is cheaper than per-element pushes: the zip below then
        // compiles to straight-line stores without capacity or bounds checks.
        self.cell_id.resize(start + n, 0);
        self.proximity.resize(start + n, 0.0);
        self.acc.resize(3 * (start + n), 0.0);
        self.temp.resize(2 * (start + n), 0.0);
        self.force.resize(3 * (start + n), 0.0);
        let rows = block
            .chunks_exact(PACKET_LEN)
            .zip(&mut self.cell_id[start..])
            .zip(&mut self.proximity[start..])
            .zip(self.acc[3 * start..].chunks_exact_mut(3))
            .zip(self.temp[2 * start..].chunks_exact_mut(2))
            .zip(self.force[3 * start..].chunks_exact_mut(3));
        for (((((p, cell), prox), acc), temp), force) in rows {
            let Some(p) = p.first_chunk::<PACKET_LEN>() else {
                continue;
            };
            let r = decode_sensor(p).to_physical();
            *cell = r.cell_id;
            *prox = r.proximity;
            acc.copy_from_slice(&r.acc);
            temp.copy_from_slice(&r.temp);
            force.copy_from_slice(&r.force);
        }
    }
}

/// Sensor packets as raw integers, same layout as [`PhysicalColumns`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RawColumns {
    pub cell_id: Vec<u16>,
    pub proximity: Vec<u16>,
    pub acc: Vec<i16>,
    pub temp: Vec<i16>,
    pub force: Vec<u16>,
}

impl RawColumns {
    pub fn len(&self) -> usize {
        self.cell_id.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cell_id.is_empty()
    }

    /// Row `i`, if it exists.
    pub fn row(&self, i: usize) -> Option<SensorRaw> {
        Some(SensorRaw {
            cell_id: *self.cell_id.get(i)?,
            proximity: *self.proximity.get(i)?,
            acc: *self.acc.get(3 * i..3 * i + 3)?.first_chunk()?,
            temp: *self.temp.get(2 * i..2 * i + 2)?.first_chunk()?,
            force: *self.force.get(3 * i..3 * i + 3)?.first_chunk()?,
        })
    }

    pub fn push(&mut self, p: &SensorRaw) {
        self.cell_id.push(p.cell_id);
        self.proximity.push(p.proximity);
        self.acc.extend_from_slice(&p.acc);
        self.temp.extend_from_slice(&p.temp);
        self.force.extend_from_slice(&p.force);
    }
}

impl PacketSink for RawColumns {
    fn sensor_block(&mut self, block: &[u8]) {
        let n = block.len() / PACKET_LEN;
        let start = self.cell_id.len();
        self.cell_id.resize(start + n, 0);
        self.proximity.resize(start + n, 0);
        self.acc.resize(3 * (start + n), 0);
        self.temp.resize(2 * (start + n), 0);
        self.force.resize(3 * (start + n), 0);
        let rows = block
            .chunks_exact(PACKET_LEN)
            .zip(&mut self.cell_id[start..])
            .zip(&mut self.proximity[start..])
            .zip(self.acc[3 * start..].chunks_exact_mut(3))
            .zip(self.temp[2 * start..].chunks_exact_mut(2))
            .zip(self.force[3 * start..].chunks_exact_mut(3));
        for (((((p, cell), prox), acc), temp), force) in rows {
            let Some(p) = p.first_chunk::<PACKET_LEN>() else {
                continue;
            };
            let r = decode_sensor(p);
            *cell = r.cell_id;
            *prox = r.proximity;
            acc.copy_from_slice(&r.acc);
            temp.copy_from_slice(&r.temp);
            force.copy_from_slice(&r.force);
        }
    }

    #[inline(always)]
    fn sensor(&mut self, p: &SensorRaw) {
        self.push(p);
    }

    fn reserve(&mut self, n: usize) {
        self.cell_id.reserve(n);
        self.proximity.reserve(n);
        self.acc.reserve(3 * n);
        self.temp.reserve(2 * n);
        self.force.reserve(3 * n);
    }
}

/// Encodes rows given as columns (the layout of [`RawColumns`], but wide integers so that
/// out-of-range input from the caller is reported rather than wrapped). Every column must have
/// the same number of rows; the error names the field and row.
pub struct RawColumnsRef<'a> {
    pub cell_id: &'a [i64],
    pub proximity: &'a [i64],
    pub acc: &'a [i64],
    pub temp: &'a [i64],
    pub force: &'a [i64],
}

/// Error of [`encode_sensor_columns`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ColumnsError {
    #[error("column {field} has {got} values, expected {expected} ({rows} rows)")]
    Shape {
        field: &'static str,
        got: usize,
        expected: usize,
        rows: usize,
    },
    #[error("row {row}: {source}")]
    Value { row: usize, source: EncodeError },
}

impl<'a> RawColumnsRef<'a> {
    fn rows(&self) -> Result<usize, ColumnsError> {
        let n = self.cell_id.len();
        for (field, got, width) in [
            ("proximity", self.proximity.len(), 1),
            ("acc", self.acc.len(), 3),
            ("temp", self.temp.len(), 2),
            ("force", self.force.len(), 3),
        ] {
            if got != width * n {
                return Err(ColumnsError::Shape {
                    field,
                    got,
                    expected: width * n,
                    rows: n,
                });
            }
        }
        Ok(n)
    }
}

/// `v` as the field's integer type; an error naming the field's range if it does not fit
/// (whether it lies in the range is checked when the packet is encoded).
fn narrow<T: TryFrom<i64>>(
    field: &'static str,
    v: i64,
    range: &RangeInclusive<i64>,
) -> Result<T, EncodeError> {
    T::try_from(v).map_err(|_| EncodeError {
        field,
        value: v,
        min: *range.start(),
        max: *range.end(),
    })
}

/// The three columns of a vector field (see [`narrow`]).
fn narrow3<T: TryFrom<i64>>(
    field: &'static str,
    v: &[i64],
    range: &RangeInclusive<i64>,
) -> Result<[T; 3], EncodeError> {
    Ok([
        narrow(field, v[0], range)?,
        narrow(field, v[1], range)?,
        narrow(field, v[2], range)?,
    ])
}

/// Encodes all rows into `20 * n` bytes of consecutive sensor packets.
pub fn encode_sensor_columns(cols: &RawColumnsRef<'_>) -> Result<Vec<u8>, ColumnsError> {
    let n = cols.rows()?;
    let mut out = vec![0u8; n * PACKET_LEN];
    for (row, chunk) in out.chunks_exact_mut(PACKET_LEN).enumerate() {
        let value = |source| ColumnsError::Value { row, source };
        let raw = (|| -> Result<SensorRaw, EncodeError> {
            let acc = &cols.acc[3 * row..3 * row + 3];
            let temp = &cols.temp[2 * row..2 * row + 2];
            let force = &cols.force[3 * row..3 * row + 3];
            Ok(SensorRaw {
                cell_id: narrow("cell_id", cols.cell_id[row], &RANGE_CELL_ID)?,
                proximity: narrow("proximity", cols.proximity[row], &RANGE_PROXIMITY)?,
                acc: narrow3("acc", acc, &RANGE_ACC)?,
                temp: [
                    narrow("temp", temp[0], &RANGE_TEMP_ACC)?,
                    narrow("temp", temp[1], &RANGE_TEMP_LM71)?,
                ],
                force: narrow3("force", force, &RANGE_FORCE)?,
            })
        })()
        .map_err(value)?;
        let Some(packet) = chunk.first_chunk_mut::<PACKET_LEN>() else {
            continue; // chunks_exact_mut yields exactly PACKET_LEN bytes
        };
        crate::encode_sensor_into(&raw, packet).map_err(value)?;
    }
    Ok(out)
}

/// Collects the packets of other types too (tests and tools; the hot path only counts them).
impl PacketSink for Vec<(PacketType, [u8; PACKET_LEN])> {
    fn sensor(&mut self, _p: &SensorRaw) {}

    fn other(&mut self, kind: PacketType, packet: &[u8; PACKET_LEN]) {
        self.push((kind, *packet));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{decode_sensor, StreamParser};

    #[test]
    fn encode_columns_round_trips_and_names_bad_rows() {
        let cell_id = [1i64, 2];
        let proximity = [0i64, 65535];
        let acc = [-512i64, 0, 511, 1, 2, 3];
        let temp = [-128i64, 8191, 127, -8192];
        let force = [0i64, 4095, 7, 8, 9, 10];
        let cols = RawColumnsRef {
            cell_id: &cell_id,
            proximity: &proximity,
            acc: &acc,
            temp: &temp,
            force: &force,
        };
        let bytes = encode_sensor_columns(&cols).unwrap();
        assert_eq!(bytes.len(), 40);
        let mut parsed = RawColumns::default();
        StreamParser::new().feed(&bytes, &mut parsed);
        assert_eq!(parsed.cell_id, vec![1, 2]);
        assert_eq!(parsed.acc, vec![-512, 0, 511, 1, 2, 3]);
        assert_eq!(parsed.temp, vec![-128, 8191, 127, -8192]);
        assert_eq!(parsed.force, vec![0, 4095, 7, 8, 9, 10]);
        let first: &[u8; 20] = bytes.first_chunk().unwrap();
        assert_eq!(parsed.row(0), Some(decode_sensor(first)));
        assert_eq!(parsed.row(2), None);

        let bad_temp = [-128i64, 8191, 128, 0];
        let err = encode_sensor_columns(&RawColumnsRef {
            temp: &bad_temp,
            ..cols
        })
        .unwrap_err();
        assert_eq!(
            err,
            ColumnsError::Value {
                row: 1,
                source: EncodeError {
                    field: "temp",
                    value: 128,
                    min: -128,
                    max: 127
                }
            }
        );
        let big = [1i64, 1 << 40];
        let err = encode_sensor_columns(&RawColumnsRef {
            cell_id: &big,
            ..cols
        })
        .unwrap_err();
        assert!(matches!(
            err,
            ColumnsError::Value {
                row: 1,
                source: EncodeError {
                    field: "cell_id",
                    ..
                }
            }
        ));
        let short = [1i64; 5];
        let err = encode_sensor_columns(&RawColumnsRef {
            force: &short,
            ..cols
        })
        .unwrap_err();
        assert!(matches!(
            err,
            ColumnsError::Shape {
                field: "force",
                got: 5,
                expected: 6,
                rows: 2
            }
        ));
    }
}
