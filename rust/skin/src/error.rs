use thiserror::Error;

/// A raw field value that does not fit its bit width on the wire.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{field} = {value} is outside the representable range {min}..={max}")]
pub struct EncodeError {
    /// Field name as in the Python API (`cell_id`, `proximity`, `acc`, `temp`, `force`).
    pub field: &'static str,
    /// The offending value.
    pub value: i64,
    pub min: i64,
    pub max: i64,
}

/// A physical value that cannot be quantised (NaN, or a cell id outside 14 bits).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum QuantizeError {
    #[error("{field} is NaN")]
    NaN { field: &'static str },
    #[error("cell_id = {0} is outside 0..=16383 (14-bit cell ids)")]
    CellId(i64),
}
