//! The heat, texture and stick-slip loops on their own, as `SimContact` runs them inside a step:
//! the tests compare each with its numpy formulation (tests/sim/numpy_reference.py). And the
//! switch that flushes subnormal numbers around LAPACK's eigen-decompositions.

use aptkt_sim::philox::CounterStream;
use aptkt_sim::slip::{run as slip_run, SlipCell};
use aptkt_sim::texture::acceleration;
use aptkt_sim::thermal::{heat, HeatSamples, System};
use numpy::ndarray::Axis;
use numpy::{
    PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadwriteArray1, PyReadwriteArray2,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::settings::{SlipParams, TextureField, TextureResponse};
use super::{col, mat, rows, vec1};
use crate::errors::{invalid_input, Result};

/// The exact solution of the cells' thermal networks (`aptkt_sim::thermal::heat`) with the
/// configurations' operators `u` (k, N, N), `mu` and `t_ss` (k, N), and C^1/2 (N).
#[pyclass(module = "aptkt._core", frozen)]
pub struct HeatKernel {
    systems: Vec<System>,
    sqrt_c: Vec<f64>,
}

#[pymethods]
impl HeatKernel {
    #[new]
    fn new(
        u: PyReadonlyArray3<'_, f64>,
        mu: PyReadonlyArray2<'_, f64>,
        t_ss: PyReadonlyArray2<'_, f64>,
        sqrt_c: PyReadonlyArray1<'_, f64>,
    ) -> Result<Self> {
        let (u, mu, t_ss) = (u.as_array(), mu.as_array(), t_ss.as_array());
        let k = u.shape()[0];
        let n = sqrt_c.len();
        if u.shape() != [k, n, n] || mu.shape() != [k, n] || t_ss.shape() != [k, n] {
            return Err(invalid_input(
                "systems must be u (k, N, N), mu and t_ss (k, N)",
            ));
        }
        let systems = (0..k)
            .map(|i| System {
                u: u.index_axis(Axis(0), i).iter().copied().collect(),
                mu: mu.row(i).to_vec(),
                t_ss: t_ss.row(i).to_vec(),
            })
            .collect();
        Ok(Self {
            systems,
            sqrt_c: vec1(&sqrt_c),
        })
    }

    /// [node 0, node 1] temperatures (m, 2) of a cell-major chunk's samples (`cells`, times
    /// `t_s`, configuration indices `config`); `state` (C, N) and `state_t` (C,) are advanced
    /// in place.
    fn heat<'py>(
        &self,
        cells: PyReadonlyArray1<'py, i64>,
        t_s: PyReadonlyArray1<'py, f64>,
        config: PyReadonlyArray1<'py, i64>,
        mut state: PyReadwriteArray2<'py, f64>,
        mut state_t: PyReadwriteArray1<'py, f64>,
    ) -> Result<Bound<'py, PyAny>> {
        let py = cells.py();
        let config: Vec<usize> = config
            .as_array()
            .iter()
            .map(|&c| usize::try_from(c).map_err(|_| invalid_input("negative configuration")))
            .collect::<Result<_>>()?;
        if state.as_array().ncols() != self.sqrt_c.len() {
            return Err(invalid_input("state must be (cells, N)"));
        }
        let (cells, t_s) = (vec1(&cells), vec1(&t_s));
        let mut st: Vec<f64> = state.as_array().iter().copied().collect();
        let mut stt: Vec<f64> = state_t.as_array().iter().copied().collect();
        let samples = HeatSamples {
            cells: &cells,
            t_s: &t_s,
            config: &config,
        };
        let out = py.detach(|| heat(&self.systems, &self.sqrt_c, &samples, &mut st, &mut stt))?;
        state
            .as_array_mut()
            .iter_mut()
            .zip(&st)
            .for_each(|(d, s)| *d = *s);
        state_t
            .as_array_mut()
            .iter_mut()
            .zip(&stt)
            .for_each(|(d, s)| *d = *s);
        mat(py, out)
    }
}

/// Texture acceleration (n, 3) of cells at object-frame positions `u` (n, 2), velocities `w`
/// (n, 2) and contact pressures (see `aptkt_sim::texture::acceleration`).
#[pyfunction]
fn sim_texture<'py>(
    texture: PyRef<'py, TextureField>,
    response: PyRef<'py, TextureResponse>,
    u: PyReadonlyArray2<'py, f64>,
    w: PyReadonlyArray2<'py, f64>,
    pressure: PyReadonlyArray1<'py, f64>,
) -> Result<Bound<'py, PyAny>> {
    let py = u.py();
    let tex = &texture.0;
    if tex.amplitude.len() != tex.kvec.len() || tex.phase.len() != tex.kvec.len() {
        return Err(invalid_input(
            "kvec, amplitude and phase must have one row per wave",
        ));
    }
    let (u, w, p) = (rows::<2>(&u, "u")?, rows::<2>(&w, "w")?, vec1(&pressure));
    if w.len() != u.len() || p.len() != u.len() {
        return Err(invalid_input(
            "u, w and pressure must have one row per sample",
        ));
    }
    let k = response.0;
    let out = py.detach(|| acceleration(tex, &k, &u, &w, &p));
    mat(py, out)
}

/// One cell's stick-slip state: spring load (N), next slip threshold (N, inf: none pending),
/// slips so far, and the slips still ringing (time s, peak m/s²).
#[pyclass(module = "aptkt._core", get_all)]
pub struct SlipState {
    load: f64,
    threshold: f64,
    events: i64,
    ring: Vec<(f64, f64)>,
}

#[pymethods]
impl SlipState {
    #[new]
    fn new(load: f64, threshold: f64, events: i64, ring: Vec<(f64, f64)>) -> Self {
        Self {
            load,
            threshold,
            events,
            ring,
        }
    }
}

/// Stick-slip of one cell over a stretch of samples (see `aptkt_sim::slip::run`): the
/// tangential acceleration (n,) at times `t` (s) from the sliding distance since each previous
/// sample, the normal force and the sliding speed; `cell` is advanced in place.
#[pyfunction]
fn sim_slip<'py>(
    params: PyRef<'py, SlipParams>,
    key: [u64; 2],
    cell: &Bound<'py, SlipState>,
    t: PyReadonlyArray1<'py, f64>,
    path: PyReadonlyArray1<'py, f64>,
    force: PyReadonlyArray1<'py, f64>,
    speed: PyReadonlyArray1<'py, f64>,
) -> Result<Bound<'py, PyAny>> {
    let py = cell.py();
    let (t, path, force, speed) = (vec1(&t), vec1(&path), vec1(&force), vec1(&speed));
    if path.len() != t.len() || force.len() != t.len() || speed.len() != t.len() {
        return Err(invalid_input(
            "t, path, force and speed must have the same length",
        ));
    }
    let p = params.0;
    let stream = CounterStream::new(key, 2);
    let mut state = cell.borrow_mut();
    let mut c = SlipCell {
        load: state.load,
        threshold: state.threshold,
        events: state.events,
        ring: std::mem::take(&mut state.ring),
    };
    let out = py.detach(|| slip_run(&p, &stream, &mut c, &t, &path, &force, &speed));
    (state.load, state.threshold, state.events, state.ring) =
        (c.load, c.threshold, c.events, c.ring);
    Ok(col(py, out))
}

/// Flush subnormal numbers to zero in this thread's floating-point unit (x86-64 SSE: the FTZ
/// and DAZ bits of MXCSR) when `on`, or restore the register to `previous`. Returns the register
/// as it was. Used around LAPACK's eigen-decompositions of the thermal networks, which meet
/// subnormal intermediates and then run a hundred times slower; elsewhere a no-op returning 0.
#[pyfunction]
#[pyo3(signature = (on, previous=None))]
fn _flush_subnormals(on: bool, previous: Option<u32>) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
        let mut csr: u32 = 0;
        // SAFETY: stmxcsr/ldmxcsr read and write this thread's SSE control register; only the
        // FTZ and DAZ bits change (or the register is restored to a value it held).
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack));
            let new = match previous {
                Some(p) => p,
                None if on => csr | FTZ_DAZ,
                None => csr & !FTZ_DAZ,
            };
            std::arch::asm!("ldmxcsr [{}]", in(reg) &new, options(nostack));
        }
        csr
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (on, previous);
        0
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<HeatKernel>()?;
    m.add_class::<SlipState>()?;
    m.add_function(wrap_pyfunction!(sim_texture, m)?)?;
    m.add_function(wrap_pyfunction!(sim_slip, m)?)?;
    m.add_function(wrap_pyfunction!(_flush_subnormals, m)?)
}
