//! What a trial's physics carries from call to call and hands back: its state
//! (`PhysicsState`), the mechanics' samples (`MechChunk`), the trajectory's segments
//! (`Segments`), and the frames and force trace of a step (returned as dicts of arrays).

use aptkt_sim::mechanics::{Chunk, Segment};
use aptkt_sim::readout::{Frames, Trace, TrialState};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::{col, mat, rows, vec1};
use crate::errors::{invalid_input, Result};

/// The whole state of one trial's physics: what the mechanics, the heat, the stick-slip and
/// the readings carry from one step to the next. Made by `SimContact.rest_state`, advanced in
/// place by `SimContact`'s steps; the arrays read from it are copies.
#[pyclass(module = "aptkt._core")]
#[derive(Clone)]
pub struct PhysicsState(pub TrialState);

impl PhysicsState {
    fn cells(&self) -> usize {
        self.0.thermal_t.len()
    }
}

#[pymethods]
impl PhysicsState {
    fn copy(&self) -> Self {
        self.clone()
    }

    /// Everything with sample time <= t_ns has been produced.
    #[getter]
    fn t_ns(&self) -> i64 {
        self.0.mech.t_ns
    }

    /// (C,) next sample index of each cell
    #[getter]
    fn next_k<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.mech.next_k.clone())
    }

    /// (terms, C, 3) relaxing parts of the stress
    #[getter]
    fn relax_h<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        let c = self.cells();
        let terms = self.0.mech.relax_h.len().checked_div(3 * c).unwrap_or(0);
        Ok(PyArray1::from_slice(py, &self.0.mech.relax_h)
            .reshape([terms, c, 3])?
            .into_any())
    }

    /// (C, 3) elastic stress at each cell's previous sample
    #[getter]
    fn relax_last<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        matrix(py, &self.0.mech.relax_last, 3)
    }

    /// (C,) N, true force on each cell at its last sample
    #[getter]
    fn latest_force<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.mech.latest_force.clone())
    }

    /// (C, N) temperatures of each cell's thermal network
    #[getter]
    fn thermal<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        let nodes = self.0.thermal.len().checked_div(self.cells()).unwrap_or(0);
        matrix(py, &self.0.thermal, nodes)
    }

    /// (C,) s, time of each cell's thermal state (its last sample)
    #[getter]
    fn thermal_t<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.thermal_t.clone())
    }

    /// (C, 2) cell centre at its last sample (for sliding distances)
    #[getter]
    fn last_xy<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.last_xy.clone())
    }

    /// (C,) N, tangential spring force of each cell's stick-slip
    #[getter]
    fn slip_load<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.slip.iter().map(|c| c.load).collect())
    }

    /// (C,) N, static friction to overcome for each cell's next slip (inf: none pending)
    #[getter]
    fn slip_threshold<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.slip.iter().map(|c| c.threshold).collect())
    }

    /// (C,) slips so far of each cell
    #[getter]
    fn slip_events<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.slip.iter().map(|c| c.events).collect())
    }

    /// Per cell, the slips still ringing: (time s, peak m/s²)
    #[getter]
    fn slip_ringing(&self) -> Vec<Vec<(f64, f64)>> {
        self.0.slip.iter().map(|c| c.ring.clone()).collect()
    }
}

/// A (len / width, width) copy of a flat row-major array.
fn matrix<'py>(py: Python<'py>, v: &[f64], width: usize) -> Result<Bound<'py, PyAny>> {
    let rows = v.len().checked_div(width).unwrap_or(0);
    Ok(PyArray1::from_slice(py, v)
        .reshape([rows, width])?
        .into_any())
}

/// Samples of a stretch of time with the TCP motion and the contact stress at their times,
/// cell-major (every sample of a cell together, in sample order): the mechanics' output, which
/// `SimContact.finish` turns into readings.
#[pyclass(module = "aptkt._core", frozen)]
pub struct MechChunk(pub Chunk);

#[pymethods]
impl MechChunk {
    /// Chunks of consecutive stretches of time as one cell-major chunk.
    #[staticmethod]
    fn concat(chunks: Vec<PyRef<'_, MechChunk>>) -> Self {
        let parts: Vec<&Chunk> = chunks.iter().map(|c| &c.0).collect();
        Self(Chunk::concat(&parts))
    }

    fn __len__(&self) -> usize {
        self.0.len()
    }

    #[getter]
    fn size(&self) -> usize {
        self.0.len()
    }

    #[getter]
    fn cells<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.cells.clone())
    }

    /// sample index of each sample within its cell
    #[getter]
    fn ks<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.ks.clone())
    }

    /// sample time (s)
    #[getter]
    fn t_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.t_s.clone())
    }

    /// sample time (ns)
    #[getter]
    fn t_ns<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.t_ns.clone())
    }

    /// (m, 3) TCP position
    #[getter]
    fn pos<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.pos.clone())
    }

    /// (m, 3) TCP velocity
    #[getter]
    fn vel<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.vel.clone())
    }

    /// (m, 3) TCP acceleration
    #[getter]
    fn acc<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.acc.clone())
    }

    /// (m, 3) Pa at the force sensors
    #[getter]
    fn sigma<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.sigma.clone())
    }
}

/// Segments of constant acceleration of the TCP's trajectory: start times (S,) ns and the
/// position, velocity and acceleration at each start (S, 3).
#[pyclass(module = "aptkt._core", frozen)]
pub struct Segments(pub Vec<Segment>);

#[pymethods]
impl Segments {
    #[new]
    fn new(
        t0: PyReadonlyArray1<'_, i64>,
        p0: PyReadonlyArray2<'_, f64>,
        v0: PyReadonlyArray2<'_, f64>,
        a: PyReadonlyArray2<'_, f64>,
    ) -> Result<Self> {
        let t = vec1(&t0);
        let (p, v, acc) = (
            rows::<3>(&p0, "p0")?,
            rows::<3>(&v0, "v0")?,
            rows::<3>(&a, "a")?,
        );
        if t.is_empty() || p.len() != t.len() || v.len() != t.len() || acc.len() != t.len() {
            return Err(invalid_input(
                "trajectory: one row per segment, at least one",
            ));
        }
        Ok(Self(
            (0..t.len())
                .map(|i| Segment {
                    t0: t[i],
                    p0: p[i],
                    v0: v[i],
                    a: acc[i],
                })
                .collect(),
        ))
    }

    fn __len__(&self) -> usize {
        self.0.len()
    }

    #[getter]
    fn t0<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        col(py, self.0.iter().map(|s| s.t0).collect())
    }

    #[getter]
    fn p0<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.iter().map(|s| s.p0).collect())
    }

    #[getter]
    fn v0<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.iter().map(|s| s.v0).collect())
    }

    #[getter]
    fn a<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.0.iter().map(|s| s.a).collect())
    }
}

/// The frames of a step in arrival order, as `aptkt.sim.physics.Frames`'s fields.
#[derive(IntoPyObject)]
pub struct FramesOut<'py> {
    cell_index: Bound<'py, PyAny>,
    cell_id: Bound<'py, PyAny>,
    t_sample_ns: Bound<'py, PyAny>,
    t_ns: Bound<'py, PyAny>,
    proximity: Bound<'py, PyAny>,
    acc: Bound<'py, PyAny>,
    temp: Bound<'py, PyAny>,
    force: Bound<'py, PyAny>,
    force_true: Bound<'py, PyAny>,
}

impl<'py> FramesOut<'py> {
    pub fn new(py: Python<'py>, f: Frames) -> Result<Self> {
        Ok(Self {
            cell_index: col(py, f.cell_index),
            cell_id: col(py, f.cell_id),
            t_sample_ns: col(py, f.t_sample_ns),
            t_ns: col(py, f.t_ns),
            proximity: col(py, f.proximity),
            acc: mat(py, f.acc)?,
            temp: mat(py, f.temp)?,
            force: mat(py, f.force)?,
            force_true: col(py, f.force_true),
        })
    }
}

/// The true force of every sample of a step, as `aptkt.sim.physics.ForceTrace`'s fields.
#[derive(IntoPyObject)]
pub struct TraceOut<'py> {
    cell_index: Bound<'py, PyAny>,
    t_sample_ns: Bound<'py, PyAny>,
    force: Bound<'py, PyAny>,
}

impl<'py> TraceOut<'py> {
    pub fn new(py: Python<'py>, t: Trace) -> Self {
        Self {
            cell_index: col(py, t.cells),
            t_sample_ns: col(py, t.t_ns),
            force: col(py, t.force),
        }
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PhysicsState>()?;
    m.add_class::<MechChunk>()?;
    m.add_class::<Segments>()
}
