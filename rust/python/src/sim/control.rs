//! The force loop's typed pieces: its phases (`ForcePhase`), the packets in flight and the
//! skin's reading computed from them (`LeanQueue`), and what a run of ticks returns
//! (`TickOutcome`). The settings of the admittance law are `settings::ForceControl`.

use aptkt_sim::control::{self, Phase, Status};
use aptkt_sim::mechanics::{Chunk, Segment};
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::state::{MechChunk, Segments};
use super::{mat, rows, vec1};
use crate::errors::{invalid_input, Result};

/// What a run of force-control ticks does, and how far it got (the ticks carry it on after
/// a flush): settle on the target force, a ramp along a direction, or a guarded move.
#[pyclass(module = "aptkt._core")]
pub struct ForcePhase(pub Phase);

#[pymethods]
impl ForcePhase {
    /// Hold x/y until the force error stays below 10 % for five ticks; a timeout past
    /// `t_limit_ns`.
    #[staticmethod]
    fn settle(t_limit_ns: i64) -> Self {
        Self(Phase::Settle {
            t_limit_ns,
            settled: 0,
        })
    }

    /// Move along `direction` (x, y) at `v + acc (t - t_start)` until `t_stop_ns`.
    #[staticmethod]
    fn ramp(t_start_ns: i64, t_stop_ns: i64, v: f64, acc: f64, direction: [f64; 2]) -> Self {
        Self(Phase::Ramp {
            t_start_ns,
            t_stop_ns,
            v,
            acc,
            d: direction,
        })
    }

    /// A guarded move on the planned trajectory: until the reading exceeds `threshold` (N)
    /// or `t_end_ns`, in speculation windows of `window_ns`.
    #[staticmethod]
    fn guard(t_end_ns: i64, threshold: f64, window_ns: i64) -> Self {
        Self(Phase::Guard {
            t_end_ns,
            threshold,
            window_ns,
            w_end_ns: i64::MIN,
        })
    }

    /// True for a guarded move (it follows the planned segments, not the one in force).
    #[getter]
    fn guarded(&self) -> bool {
        matches!(self.0, Phase::Guard { .. })
    }

    fn __repr__(&self) -> String {
        format!("{:?}", self.0)
    }
}

/// The skin's force reading during a lean force loop: the packets computed but not arrived
/// yet, each cell's newest calibrated reading (C, 3) N, the skin's calibration (C, 3), and
/// the samples made since the packets were last made (`samples`).
#[pyclass(module = "aptkt._core")]
pub struct LeanQueue {
    pub queue: control::LeanQueue,
    #[pyo3(get, set)]
    pub samples: usize,
}

impl LeanQueue {
    /// The calibration and readings match a patch of `cells` cells, the queue its cells.
    pub fn check(&self, cells: usize) -> Result<()> {
        let q = &self.queue;
        if q.latest.len() != cells
            || q.cal_gain.len() != cells
            || q.cal_offset.len() != cells
            || q.cell.iter().any(|&c| c < 0 || c as usize >= cells)
        {
            return Err(invalid_input(
                "force queue or calibration does not match the patch",
            ));
        }
        Ok(())
    }
}

#[pymethods]
impl LeanQueue {
    #[new]
    fn new(
        cal_gain: PyReadonlyArray2<'_, f64>,
        cal_offset: PyReadonlyArray2<'_, f64>,
        latest: PyReadonlyArray2<'_, f64>,
    ) -> Result<Self> {
        let queue = control::LeanQueue {
            cal_gain: rows::<3>(&cal_gain, "cal_gain")?,
            cal_offset: rows::<3>(&cal_offset, "cal_offset")?,
            latest: rows::<3>(&latest, "latest")?,
            ..Default::default()
        };
        let cells = queue.latest.len();
        if queue.cal_gain.len() != cells || queue.cal_offset.len() != cells {
            return Err(invalid_input(
                "calibration and readings need one row per cell",
            ));
        }
        Ok(Self { queue, samples: 0 })
    }

    /// Queue packets (arrival times, cells, normalised force readings (n, 3)) as the skin
    /// reads them: the wire's force field, calibrated, in arrival order.
    fn push(
        &mut self,
        t_ns: PyReadonlyArray1<'_, i64>,
        cells: PyReadonlyArray1<'_, i64>,
        force_norm: PyReadonlyArray2<'_, f64>,
    ) -> Result<()> {
        let (t, c, f) = (
            vec1(&t_ns),
            vec1(&cells),
            rows::<3>(&force_norm, "force_norm")?,
        );
        let n = self.queue.latest.len();
        if c.len() != t.len() || f.len() != t.len() || c.iter().any(|&x| x < 0 || x as usize >= n) {
            return Err(invalid_input(
                "packets: one time, cell of the patch and force row each",
            ));
        }
        for i in 0..t.len() {
            self.queue.push(t[i], c[i] as usize, f[i]);
        }
        Ok(())
    }

    /// Apply the packets that have arrived by `t_ns` (the newest of each cell wins).
    fn deliver(&mut self, t_ns: i64) {
        self.queue.deliver(t_ns);
    }

    /// The skin's total normal force now (N), summed as the skin source sums it.
    fn reading(&self) -> f64 {
        self.queue.reading()
    }

    /// Each cell's newest calibrated reading (C, 3) N.
    #[getter]
    fn latest<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyAny>> {
        mat(py, self.queue.latest.clone())
    }

    /// Packets in flight.
    fn __len__(&self) -> usize {
        self.queue.t.len()
    }
}

/// Why a run of force-control ticks returned ("done", "triggered", "timeout", "too_deep",
/// "wrench" or "flush"), the force error of its last tick, the segment in force at its end
/// and the samples it made.
#[pyclass(module = "aptkt._core", frozen, get_all)]
pub struct TickOutcome {
    status: String,
    error: f64,
    segment: Py<Segments>,
    chunk: Py<MechChunk>,
}

impl TickOutcome {
    pub fn new(
        py: Python<'_>,
        status: Status,
        error: f64,
        segment: Segment,
        chunk: Chunk,
    ) -> Result<Self> {
        Ok(Self {
            status: match status {
                Status::Done => "done",
                Status::Triggered => "triggered",
                Status::Timeout => "timeout",
                Status::TooDeep => "too_deep",
                Status::Wrench => "wrench",
                Status::Flush => "flush",
            }
            .to_string(),
            error,
            segment: Py::new(py, Segments(vec![segment]))?,
            chunk: Py::new(py, MechChunk(chunk))?,
        })
    }
}

#[pymethods]
impl TickOutcome {
    fn __repr__(&self) -> String {
        format!(
            "TickOutcome(status={:?}, error={:?})",
            self.status, self.error
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ForcePhase>()?;
    m.add_class::<LeanQueue>()?;
    m.add_class::<TickOutcome>()
}
