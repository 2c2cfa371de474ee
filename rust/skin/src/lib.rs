//! Streaming parser and encoder for the wire protocol of the multi-modal skin
//! (hexagonal cells of the CellulARSkin / HEX-o-SKIN family, packet definitions "Version 2").
//!
//! Every packet is 20 bytes: a header byte with its top bit set, 18 payload bytes with their
//! top bit clear and the end-of-frame marker `0xAA`. Because a byte ≥ `0x80` can only be a
//! header (or the end marker), the parser re-synchronises on the first such byte after any
//! damage, which is why it never loses a valid packet that follows garbage.
//!
//! * [`StreamParser`] accepts the byte stream in arbitrary chunks and hands each packet to a
//!   [`PacketSink`]; [`PhysicalColumns`] and [`RawColumns`] are the column-oriented sinks the
//!   Python binding uses.
//! * [`SensorRaw`] holds the raw fields of a sensor packet; [`encode_sensor`] and
//!   [`decode_sensor`] convert between it and the 20 wire bytes; [`quantize`] maps physical
//!   values onto the representable raw values.
//! * [`SENSOR_FIELDS`] is the one table of the fields' names, ranges and scales, and its
//!   [`ColumnSpec`]s hold the one raw ↔ physical conversion ([`ColumnSpec::to_physical`],
//!   [`ColumnSpec::nearest_raw`]) that the sinks, the binding and the simulator call.
//!
//! No function of this crate panics on any input.

mod columns;
mod error;
mod packet;
mod parser;
mod sensor;

#[doc(hidden)]
pub mod testing;

pub use columns::{
    encode_sensor_columns, ColumnsError, PhysicalColumns, RawColumns, RawColumnsRef,
};
pub use error::{EncodeError, QuantizeError};
pub use packet::{encode_packet, is_valid_packet, PacketType, END_MARKER, PACKET_LEN, PAYLOAD_LEN};
pub use parser::{PacketSink, RejectReason, Stats, StreamParser, MAX_CARRY};
pub use sensor::{
    column, decode_sensor, encode_sensor, encode_sensor_into, quantize, scale, sensor_field,
    ColumnSpec, FieldSpec, SensorPhysical, SensorRaw, RANGE_ACC, RANGE_CELL_ID, RANGE_FORCE,
    RANGE_PROXIMITY, RANGE_TEMP_ACC, RANGE_TEMP_LM71, SENSOR_FIELDS,
};
