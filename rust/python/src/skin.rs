//! Bindings of the skin protocol crate: `StreamParser`, the vectorised quantiser and encoder.
//!
//! Parsing and encoding run with the GIL released. Output columns are Rust `Vec`s whose buffers
//! become the numpy arrays' memory (no copy); 2-D fields are row-major `(n, 3)` / `(n, 2)`.

use aptkt_skin::{
    encode_packet, encode_sensor_columns, quantize as quantize_one, sensor_field, FieldSpec,
    PacketType, PhysicalColumns, RawColumns, RawColumnsRef, RejectReason, Stats, StreamParser,
    PACKET_LEN, PAYLOAD_LEN, SENSOR_FIELDS,
};
use numpy::ndarray::{Array1, Array2, ArrayD, IxDyn};
use numpy::{
    Element, IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyMemoryView};

use crate::errors::{internal, invalid_input, invalid_type, Result};

/// Rows of a 2-D field as a `(n, width)` array, taking ownership of the buffer.
fn rows_array<'py, T: Element>(
    py: Python<'py>,
    v: Vec<T>,
    width: usize,
) -> Result<Bound<'py, PyAny>> {
    let n = v.len() / width;
    let a = Array2::from_shape_vec((n, width), v).map_err(|e| internal(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

fn column<'py, T: Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyAny> {
    Array1::from_vec(v).into_pyarray(py).into_any()
}

fn physical_dict<'py>(py: Python<'py>, c: PhysicalColumns) -> Result<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("cell_id", column(py, c.cell_id))?;
    d.set_item("proximity", column(py, c.proximity))?;
    d.set_item("acc", rows_array(py, c.acc, 3)?)?;
    d.set_item("temp", rows_array(py, c.temp, 2)?)?;
    d.set_item("force", rows_array(py, c.force, 3)?)?;
    Ok(d)
}

fn raw_dict<'py>(py: Python<'py>, c: RawColumns) -> Result<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("cell_id", column(py, c.cell_id))?;
    d.set_item("proximity", column(py, c.proximity))?;
    d.set_item("acc", rows_array(py, c.acc, 3)?)?;
    d.set_item("temp", rows_array(py, c.temp, 2)?)?;
    d.set_item("force", rows_array(py, c.force, 3)?)?;
    Ok(d)
}

fn stats_dict<'py>(py: Python<'py>, s: &Stats, pending: usize) -> Result<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("packets", s.sensor_packets)?;
    d.set_item("bytes", s.bytes_in)?;
    d.set_item("bytes_skipped", s.bytes_skipped)?;
    d.set_item("pending_bytes", pending)?;
    let rejected = PyDict::new(py);
    for r in RejectReason::ALL {
        rejected.set_item(r.name(), s.rejected(r))?;
    }
    d.set_item("rejected", rejected)?;
    d.set_item("rejected_total", s.rejected.iter().sum::<u64>())?;
    let other = PyDict::new(py);
    for t in &PacketType::ALL[1..] {
        other.set_item(t.name(), s.other(*t))?;
    }
    d.set_item("other_packets", other)?;
    Ok(d)
}

/// Streaming parser of the skin's byte stream.
///
/// ``feed(data)`` accepts any chunk of the stream (a packet may be split across calls) and
/// returns the sensor packets it completed, one row each, in stream order:
/// ``cell_id`` (n,) uint16, ``proximity`` (n,) 0..1, ``acc`` (n, 3) g, ``temp`` (n, 2) °C
/// (accelerometer die, LM71), ``force`` (n, 3) normalised (raw / 1024). With ``raw=True`` the
/// same keys hold the raw integers (uint16 / int16). Other packet types, rejected candidates
/// and skipped bytes are counted in :attr:`stats`. At most 19 bytes are held between calls.
#[pyclass(module = "aptkt._core", name = "StreamParser")]
pub struct PyStreamParser {
    inner: StreamParser,
}

#[pymethods]
impl PyStreamParser {
    #[new]
    fn new() -> Self {
        PyStreamParser {
            inner: StreamParser::new(),
        }
    }

    /// Parse the next chunk; returns a dict of numpy arrays (see the class docstring).
    #[pyo3(signature = (data, *, raw = false))]
    fn feed<'py>(
        &mut self,
        py: Python<'py>,
        data: &Bound<'py, PyAny>,
        raw: bool,
    ) -> Result<Bound<'py, PyDict>> {
        let converted;
        let bytes: &[u8] = if let Ok(b) = data.cast::<PyBytes>() {
            b.as_bytes()
        } else {
            // bytearray / memoryview / numpy: copy into bytes, since a mutable buffer could
            // change while the GIL is released.
            // Through a memoryview, so that only buffer-protocol objects are accepted (`bytes(5)`
            // would quietly make five zero bytes), and only buffers of single bytes: an int64 or
            // float array would otherwise be parsed as its raw memory.
            let type_name = data
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default();
            let view = PyMemoryView::from(data).map_err(|_| {
                invalid_type(format!(
                    "StreamParser.feed expects bytes-like data, got {type_name}"
                ))
            })?;
            let itemsize: usize = view.getattr("itemsize")?.extract()?;
            let format: String = view.getattr("format")?.extract()?;
            let code = format.trim_start_matches(['@', '=', '<', '>', '!']);
            if itemsize != 1 || !matches!(code, "B" | "b" | "c") {
                return Err(invalid_type(format!(
                    "StreamParser.feed expects single bytes (bytes, bytearray, or a buffer of \
                     uint8/int8), got {type_name} of item format {format:?} \
                     ({itemsize} bytes per item)"
                )));
            }
            converted = py.get_type::<PyBytes>().call1((view,))?;
            converted.cast::<PyBytes>()?.as_bytes()
        };
        let parser = &mut self.inner;
        if raw {
            let cols = py.detach(|| {
                let mut cols = RawColumns::default();
                parser.feed(bytes, &mut cols);
                cols
            });
            raw_dict(py, cols)
        } else {
            let cols = py.detach(|| {
                let mut cols = PhysicalColumns::default();
                parser.feed(bytes, &mut cols);
                cols
            });
            physical_dict(py, cols)
        }
    }

    /// Link health: ``packets`` (sensor packets decoded), ``bytes``, ``bytes_skipped``,
    /// ``pending_bytes``, ``rejected`` (by reason), ``rejected_total``, ``other_packets``
    /// (valid non-sensor packets by type).
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyDict>> {
        stats_dict(py, self.inner.stats(), self.inner.pending())
    }

    /// Bytes of an unfinished packet held until the next ``feed``.
    #[getter]
    fn pending(&self) -> usize {
        self.inner.pending()
    }

    /// Drop the unfinished packet (e.g. after the link restarted); it is counted as skipped.
    fn discard_pending(&mut self) {
        self.inner.discard_pending();
    }

    /// Forget everything, statistics included.
    fn reset(&mut self) {
        self.inner.reset();
    }

    fn __repr__(&self) -> String {
        let s = self.inner.stats();
        format!(
            "StreamParser(packets={}, bytes={}, bytes_skipped={}, pending={})",
            s.sensor_packets,
            s.bytes_in,
            s.bytes_skipped,
            self.inner.pending()
        )
    }
}

fn same_rows(name: &str, got: usize, n: usize) -> Result<()> {
    if got != n {
        return Err(invalid_input(format!(
            "{name} has {got} rows, cell_id has {n}"
        )));
    }
    Ok(())
}

fn contiguous<'a, T: Element, D: numpy::ndarray::Dimension>(
    name: &str,
    a: &'a numpy::PyReadonlyArray<'_, T, D>,
) -> Result<&'a [T]> {
    a.as_slice()
        .map_err(|_| invalid_input(format!("{name} must be C-contiguous")))
}

/// Physical values → raw integers (round half to even, clip to each field's range).
/// Inputs are float64 arrays ``proximity`` (n,), ``acc_g`` (n, 3), ``temp_c`` (n, 2),
/// ``force_norm`` (n, 3) and int64 ``cell_id`` (n,); returns the dict ``feed(raw=True)`` would.
#[pyfunction]
#[pyo3(name = "_quantize")]
fn quantize<'py>(
    py: Python<'py>,
    cell_id: PyReadonlyArray1<'py, i64>,
    proximity: PyReadonlyArray1<'py, f64>,
    acc_g: PyReadonlyArray2<'py, f64>,
    temp_c: PyReadonlyArray2<'py, f64>,
    force_norm: PyReadonlyArray2<'py, f64>,
) -> Result<Bound<'py, PyDict>> {
    let n = cell_id.len();
    same_rows("proximity", proximity.len(), n)?;
    for (name, a, width) in [
        ("acc_g", &acc_g, 3),
        ("temp_c", &temp_c, 2),
        ("force_norm", &force_norm, 3),
    ] {
        let shape = a.shape();
        if shape[0] != n || shape[1] != width {
            return Err(invalid_input(format!(
                "{name} must have shape ({n}, {width}), got {shape:?}"
            )));
        }
    }
    let (c, p) = (
        contiguous("cell_id", &cell_id)?,
        contiguous("proximity", &proximity)?,
    );
    let (a, t, f) = (
        contiguous("acc_g", &acc_g)?,
        contiguous("temp_c", &temp_c)?,
        contiguous("force_norm", &force_norm)?,
    );
    let result = py.detach(|| -> Result<RawColumns, String> {
        let mut out = RawColumns::default();
        let rows = c
            .iter()
            .zip(p)
            .zip(a.chunks_exact(3))
            .zip(t.chunks_exact(2))
            .zip(f.chunks_exact(3));
        for (i, ((((&cell, &prox), acc), temp), force)) in rows.enumerate() {
            let raw = quantize_one(
                cell,
                prox,
                [acc[0], acc[1], acc[2]],
                [temp[0], temp[1]],
                [force[0], force[1], force[2]],
            )
            .map_err(|e| format!("row {i}: {e}"))?;
            out.push(&raw);
        }
        Ok(out)
    });
    raw_dict(py, result.map_err(invalid_input)?)
}

/// The physical values of one field's raw array, in its shape.
fn field_physical<'py, T: Element + Copy + Into<f64>>(
    py: Python<'py>,
    field: &FieldSpec,
    raw: &PyReadonlyArrayDyn<'py, T>,
) -> Result<Bound<'py, PyAny>> {
    let shape = raw.shape().to_vec();
    let width = field.columns.len();
    if field.vector && shape.last() != Some(&width) {
        return Err(invalid_input(format!(
            "{} must have {width} columns, got shape {shape:?}",
            field.name
        )));
    }
    let values = contiguous(field.name, raw)?;
    let out = py.detach(|| field.to_physical(values));
    let a = ArrayD::from_shape_vec(IxDyn(&shape), out).map_err(|e| internal(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// Raw integers of the field ``name`` (its dtype: uint16, or int16 for a signed field; a
/// vector field's columns last) → float64 physical values in the same shape, with the crate's
/// conversion (the parser's, bit for bit).
#[pyfunction]
#[pyo3(name = "_to_physical")]
fn to_physical<'py>(
    py: Python<'py>,
    name: &str,
    raw: &Bound<'py, PyAny>,
) -> Result<Bound<'py, PyAny>> {
    let field = sensor_field(name)
        .ok_or_else(|| invalid_input(format!("{name:?} is not a sensor field")))?;
    let dtype = if field.signed { "int16" } else { "uint16" };
    let wrong_type = |_| invalid_type(format!("{name} must be a numpy array of {dtype}"));
    if field.signed {
        field_physical(
            py,
            field,
            &raw.extract::<PyReadonlyArrayDyn<'py, i16>>()
                .map_err(wrong_type)?,
        )
    } else {
        field_physical(
            py,
            field,
            &raw.extract::<PyReadonlyArrayDyn<'py, u16>>()
                .map_err(wrong_type)?,
        )
    }
}

/// Raw integer columns (int64; shapes as ``feed(raw=True)`` returns) → consecutive 20-byte
/// sensor packets. Values outside a field's bit width raise ``ValueError`` naming field and row.
#[pyfunction]
#[pyo3(name = "_encode_sensor_packets")]
fn encode_sensor_packets<'py>(
    py: Python<'py>,
    cell_id: PyReadonlyArray1<'py, i64>,
    proximity: PyReadonlyArray1<'py, i64>,
    acc: PyReadonlyArray2<'py, i64>,
    temp: PyReadonlyArray2<'py, i64>,
    force: PyReadonlyArray2<'py, i64>,
) -> Result<Bound<'py, PyBytes>> {
    let cols = RawColumnsRef {
        cell_id: contiguous("cell_id", &cell_id)?,
        proximity: contiguous("proximity", &proximity)?,
        acc: contiguous("acc", &acc)?,
        temp: contiguous("temp", &temp)?,
        force: contiguous("force", &force)?,
    };
    for (name, a, width) in [("acc", &acc, 3), ("temp", &temp, 2), ("force", &force, 3)] {
        if a.shape()[1] != width {
            return Err(invalid_input(format!(
                "{name} must have {width} columns, got {:?}",
                a.shape()
            )));
        }
    }
    let bytes = py.detach(|| encode_sensor_columns(&cols))?;
    Ok(PyBytes::new(py, &bytes))
}

/// One packet of any type from its header byte and 18 payload bytes (each < 0x80).
#[pyfunction]
fn encode_packet_bytes<'py>(
    py: Python<'py>,
    header: u8,
    payload: &[u8],
) -> Result<Bound<'py, PyBytes>> {
    let kind = PacketType::from_header(header)
        .ok_or_else(|| invalid_input(format!("{header:#04x} is not a known packet header")))?;
    let payload: &[u8; PAYLOAD_LEN] = payload.try_into().map_err(|_| {
        invalid_input(format!(
            "payload must be {PAYLOAD_LEN} bytes, got {}",
            payload.len()
        ))
    })?;
    let packet = encode_packet(kind, payload)?;
    Ok(PyBytes::new(py, &packet))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<PyStreamParser>()?;
    m.add_function(wrap_pyfunction!(quantize, m)?)?;
    m.add_function(wrap_pyfunction!(to_physical, m)?)?;
    m.add_function(wrap_pyfunction!(encode_sensor_packets, m)?)?;
    m.add_function(wrap_pyfunction!(encode_packet_bytes, m)?)?;
    m.add("PACKET_LEN", PACKET_LEN)?;
    // The sensor fields as (name, numpy dtype, vector, ((min, max, scale, offset), ...)): the
    // crate's table, so Python keeps no copy of the wire's ranges and scales.
    let fields = SENSOR_FIELDS
        .iter()
        .map(|f| {
            let dtype = if f.signed { "<i2" } else { "<u2" };
            let columns: Vec<(i64, i64, f64, f64)> = f
                .columns
                .iter()
                .map(|c| (c.min, c.max, c.scale, c.offset))
                .collect();
            (f.name, dtype, f.vector, columns)
        })
        .collect::<Vec<_>>();
    m.add("SENSOR_FIELDS", fields)?;
    let types = PyDict::new(py);
    for t in PacketType::ALL {
        types.set_item(t.name(), t.header())?;
    }
    m.add("PACKET_TYPES", types)?;
    Ok(())
}
