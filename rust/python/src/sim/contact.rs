//! `SimContact`: the physics of one object in one trial (mechanics, the force loop, a whole
//! step's readings), and the thermal solution operators an object's trials share.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

use aptkt_sim::control::{run_ticks, TickRun};
use aptkt_sim::mechanics::{Chunk, MechState, Mechanics};
use aptkt_sim::readout::{ObjectSystem, Physics, ThermalSystems, TrialState};
use aptkt_sim::sensors::NORMALS;
use aptkt_sim::slip::SlipCell;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::control::{ForcePhase, LeanQueue, TickOutcome};
use super::settings::{
    ContactLaw, ForceControl, ForceSensors, PatchCells, Readout, Surface, SurfaceShape,
};
use super::state::{FramesOut, MechChunk, PhysicsState, Segments, TraceOut};
use super::{col, mat, vec1};
use crate::errors::{internal, invalid_input, Result};

/// The thermal solution operators of one object (`ThermalNetwork`), by (contact step, speed
/// step), shared by the object's trials in this process: each is made once (on the Python
/// side, an eigen-decomposition) and converted once.
#[pyclass(module = "aptkt._core", frozen)]
pub struct SimThermal {
    nodes: usize,
    systems: Mutex<HashMap<(i64, i64), Arc<ObjectSystem>>>,
}

#[pymethods]
impl SimThermal {
    #[new]
    fn new(nodes: usize) -> Result<Self> {
        if nodes < 2 {
            return Err(invalid_input("a thermal network has >= 2 nodes"));
        }
        Ok(Self {
            nodes,
            systems: Mutex::new(HashMap::new()),
        })
    }

    fn __len__(&self) -> Result<usize> {
        Ok(lock(&self.systems)?.len())
    }
}

fn lock<T>(m: &Mutex<T>) -> Result<MutexGuard<'_, T>> {
    m.lock()
        .map_err(|_| internal("thermal systems: poisoned lock"))
}

/// One (contact, speed) configuration's operator of an object's thermal network: eigenvectors
/// `u` (N, N), eigenvalues `mu` (N) and the steady state per watt of heater power, per kelvin
/// of room and per kelvin of object temperature.
#[pyclass(module = "aptkt._core", frozen)]
pub struct ThermalSystem(ObjectSystem);

#[pymethods]
impl ThermalSystem {
    #[new]
    fn new(
        u: PyReadonlyArray2<'_, f64>,
        mu: PyReadonlyArray1<'_, f64>,
        ss_heater: PyReadonlyArray1<'_, f64>,
        ss_ambient: PyReadonlyArray1<'_, f64>,
        ss_object: PyReadonlyArray1<'_, f64>,
    ) -> Self {
        Self(ObjectSystem {
            u: u.as_array().iter().copied().collect(),
            mu: vec1(&mu),
            ss_heater: vec1(&ss_heater),
            ss_ambient: vec1(&ss_ambient),
            ss_object: vec1(&ss_object),
        })
    }
}

/// The heat exchange of one object in one trial: the object's network (`SimThermal`), what
/// makes a configuration's operator the first time it is met (`make(phi_bin, v_bin) ->
/// ThermalSystem`), C^1/2 of the network's nodes, and the trial's heater power (W), room and
/// object temperatures (°C).
#[pyclass(module = "aptkt._core", frozen)]
pub struct ThermalContact {
    network: Py<SimThermal>,
    make: Py<PyAny>,
    sqrt_c: Vec<f64>,
    sources: [f64; 3],
}

#[pymethods]
impl ThermalContact {
    #[new]
    fn new(
        network: Py<SimThermal>,
        make: Py<PyAny>,
        sqrt_c: Vec<f64>,
        heater_power: f64,
        ambient: f64,
        object_temperature: f64,
    ) -> Self {
        Self {
            network,
            make,
            sqrt_c,
            sources: [heater_power, ambient, object_temperature],
        }
    }
}

/// The physics of one object in one trial: mechanics, force loop, heat, stick-slip, texture,
/// noise and readings. The thermal solution operators come from the object's `SimThermal`,
/// those it lacks from the trial's `ThermalContact.make` the first time a configuration is met
/// in this process.
#[pyclass(module = "aptkt._core", frozen)]
pub struct SimContact {
    physics: Physics,
    thermal: Mutex<ThermalSystems>,
    shared: Py<SimThermal>,
    make: Py<PyAny>,
    /// heater power (W), room and object temperature (°C)
    sources: [f64; 3],
}

impl SimContact {
    fn mech(&self) -> &Mechanics {
        &self.physics.mech
    }

    fn lock(&self) -> Result<MutexGuard<'_, ThermalSystems>> {
        lock(&self.thermal)
    }

    /// The thermal configurations of `chunk`, fetching the systems not met yet.
    fn thermal_keys(&self, py: Python<'_>, chunk: &Chunk) -> Result<Vec<(i64, i64)>> {
        let keys = self.physics.thermal_keys(chunk);
        let missing = self.lock()?.missing(&keys);
        let shared = self.shared.get();
        for key in missing {
            let known = lock(&shared.systems)?.get(&key).cloned();
            let object = match known {
                Some(o) => o,
                None => {
                    let made = self.make.bind(py).call1(key)?;
                    let o = made.cast::<ThermalSystem>()?.get().0.clone();
                    o.check(shared.nodes)?;
                    let o = Arc::new(o);
                    lock(&shared.systems)?.insert(key, o.clone());
                    o
                }
            };
            let [heater, ambient, object_temperature] = self.sources;
            self.lock()?
                .insert(key, object.for_trial(heater, ambient, object_temperature))?;
        }
        Ok(keys)
    }

    /// Heat, stick-slip, texture, noise and readings of `chunk`'s samples, `st` advanced.
    fn readings<'py>(
        &self,
        py: Python<'py>,
        st: &mut TrialState,
        chunk: &Chunk,
        detail: bool,
    ) -> Result<(FramesOut<'py>, TraceOut<'py>)> {
        let keys = self.thermal_keys(py, chunk)?;
        let thermal = self.lock()?;
        let (frames, trace) =
            py.detach(|| self.physics.finish(&thermal, st, chunk, &keys, detail))?;
        drop(thermal);
        Ok((FramesOut::new(py, frames)?, TraceOut::new(py, trace)))
    }
}

#[pymethods]
impl SimContact {
    #[new]
    fn new(
        cells: PyRef<'_, PatchCells>,
        shape: PyRef<'_, SurfaceShape>,
        law: PyRef<'_, ContactLaw>,
        sensors: PyRef<'_, ForceSensors>,
        surface: PyRef<'_, Surface>,
        readout: PyRef<'_, Readout>,
        thermal: PyRef<'_, ThermalContact>,
    ) -> Result<Self> {
        let mech = Mechanics::new(
            cells.0.clone(),
            shape.0.clone(),
            law.law.clone(),
            law.relaxation.clone(),
            law.sensor_area,
        )?;
        let physics = Physics::new(
            mech,
            sensors.0.clone(),
            surface.texture.clone(),
            surface.response,
            surface.slip,
            surface.slip_keys.clone(),
            readout.0.clone(),
        )?;
        let own = ThermalSystems::new(thermal.sqrt_c.clone())?;
        if own.nodes() != thermal.network.get().nodes {
            return Err(invalid_input(
                "sqrt_c must have one entry per node of the thermal network",
            ));
        }
        Ok(Self {
            physics,
            thermal: Mutex::new(own),
            shared: thermal.network.clone_ref(cells.py()),
            make: thermal.make.clone_ref(cells.py()),
            sources: thermal.sources,
        })
    }

    /// The state at rest at `t_ns`: each cell's next sample `next_k`, every cell's thermal
    /// network at `thermal` (N), cell centres at `last_xy` (C, 2); no stress, no slip.
    fn rest_state(
        &self,
        t_ns: i64,
        next_k: Vec<i64>,
        thermal: Vec<f64>,
        last_xy: Vec<[f64; 2]>,
    ) -> Result<PhysicsState> {
        let n = self.mech().cells.len();
        let terms = self.mech().relaxation.weights.len();
        let st = TrialState {
            mech: MechState {
                t_ns,
                next_k,
                relax_h: vec![0.0; terms * n * 3],
                relax_last: vec![0.0; n * 3],
                latest_force: vec![0.0; n],
            },
            thermal: thermal.repeat(n),
            thermal_t: vec![t_ns as f64 * 1e-9; n],
            last_xy,
            slip: vec![
                SlipCell {
                    load: 0.0,
                    threshold: f64::INFINITY,
                    events: 0,
                    ring: Vec::new(),
                };
                n
            ],
        };
        self.physics.check_state(&st, thermal.len())?;
        Ok(PhysicsState(st))
    }

    /// Advance the mechanics of `state` (in place) to `t_end_ns` on the trajectory's
    /// `segments`: the samples due, with the TCP motion and the contact stress at their times.
    fn mechanics(
        &self,
        state: &Bound<'_, PhysicsState>,
        segments: PyRef<'_, Segments>,
        t_end_ns: i64,
    ) -> Result<MechChunk> {
        let mut st = state.borrow_mut();
        let mech = &mut st.0.mech;
        self.mech().check_state(mech)?;
        let segs = &segments.0;
        let chunk = state.py().detach(|| {
            let mut c = Chunk::default();
            self.mech().step(mech, segs, t_end_ns, &mut c);
            c
        });
        Ok(MechChunk(chunk))
    }

    /// Heat, stick-slip, texture, noise and readings of a chunk's samples (the second half of a
    /// step; `state` is advanced in place). Returns the frames in arrival order and the force
    /// trace (dicts of arrays, the fields of `Frames` and `ForceTrace`).
    fn finish<'py>(
        &self,
        state: &Bound<'py, PhysicsState>,
        chunk: PyRef<'py, MechChunk>,
        detail: bool,
    ) -> Result<(FramesOut<'py>, TraceOut<'py>)> {
        let mut st = state.borrow_mut();
        self.readings(state.py(), &mut st.0, &chunk.0, detail)
    }

    /// A whole step to `t_end_ns` (mechanics, then `finish`); `state` is advanced in place.
    fn step<'py>(
        &self,
        state: &Bound<'py, PhysicsState>,
        segments: PyRef<'py, Segments>,
        t_end_ns: i64,
        detail: bool,
    ) -> Result<(FramesOut<'py>, TraceOut<'py>)> {
        let py = state.py();
        let mut st = state.borrow_mut();
        let trial = &mut st.0;
        self.mech().check_state(&trial.mech)?;
        let segs = &segments.0;
        let chunk = py.detach(|| {
            let mut c = Chunk::default();
            self.mech().step(&mut trial.mech, segs, t_end_ns, &mut c);
            c
        });
        self.readings(py, trial, &chunk, detail)
    }

    /// Normal deviates (n, 10) and arrival times of samples `ks` of `cells` sampled at `t_ns`.
    fn noise<'py>(
        &self,
        ks: PyReadonlyArray1<'py, i64>,
        cells: PyReadonlyArray1<'py, i64>,
        t_ns: PyReadonlyArray1<'py, i64>,
    ) -> Result<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let py = ks.py();
        let sensors = &self.physics.sensors;
        let (ks, cells, t_ns) = (vec1(&ks), vec1(&cells), vec1(&t_ns));
        if cells.len() != ks.len() || t_ns.len() != ks.len() {
            return Err(invalid_input(
                "ks, cells and t_ns must have the same length",
            ));
        }
        let n = sensors.n_cells as i64;
        if cells.iter().any(|&c| c < 0 || c >= n) || ks.iter().any(|&k| k < 0) {
            return Err(invalid_input("cell or sample index out of range"));
        }
        let (z, arrival): (Vec<[f64; NORMALS]>, Vec<i64>) = py.detach(|| {
            (0..ks.len())
                .map(|i| sensors.noise_and_arrival(ks[i], cells[i] as usize, t_ns[i]))
                .unzip()
        });
        Ok((mat::<NORMALS>(py, z)?, col(py, arrival)))
    }

    /// Force-control ticks of one phase (see `aptkt_sim::control::run_ticks`) on the skin's
    /// reading as `queue` computes it from the packets in flight. The phase's segments are the
    /// one in force (settle, ramp) or the planned ones from now on (guard). `state`, `queue`
    /// and `phase` (its progress) are advanced in place. The outcome says why the ticks
    /// stopped ("flush": make the packets of `queue.samples`, then call again).
    fn force_ticks(
        &self,
        state: &Bound<'_, PhysicsState>,
        segments: PyRef<'_, Segments>,
        queue: &Bound<'_, LeanQueue>,
        control: PyRef<'_, ForceControl>,
        phase: &Bound<'_, ForcePhase>,
    ) -> Result<TickOutcome> {
        let py = state.py();
        let ctl = control.0;
        if ctl.tick_ns <= 0 {
            return Err(invalid_input("tick_ns must be > 0"));
        }
        let (mut st, mut q, mut ph) = (state.borrow_mut(), queue.borrow_mut(), phase.borrow_mut());
        let mech = &mut st.0.mech;
        self.mech().check_state(mech)?;
        q.check(self.mech().cells.len())?;
        let mut run = TickRun {
            phase: ph.0,
            segs: segments.0.clone(),
            chunk: Chunk::default(),
            samples: q.samples,
        };
        let queue = &mut q.queue;
        let (status, error) = py.detach(|| {
            run_ticks(
                &self.physics.mech,
                &self.physics.sensors,
                &ctl,
                mech,
                queue,
                &mut run,
            )
        });
        ph.0 = run.phase;
        q.samples = run.samples;
        TickOutcome::new(py, status, error, run.segs[0], run.chunk)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SimThermal>()?;
    m.add_class::<ThermalSystem>()?;
    m.add_class::<ThermalContact>()?;
    m.add_class::<SimContact>()
}
