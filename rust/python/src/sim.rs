//! Bindings of the simulation core (`aptkt-sim`): `SimContact` (one object in one trial:
//! mechanics, the force loop, a whole step's readings) and the heat, texture and stick-slip
//! loops on their own (the tests compare them with numpy). Converts arrays, releases the GIL;
//! the per-trial state stays in the Python `PhysicsState`, read once per call into the core's
//! `TrialState` and written back in place.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use aptkt_sim::control::{run_ticks, ForceControl, LeanQueue, Phase, Status};
use aptkt_sim::mechanics::{Cells, Chunk, Law, MechState, Mechanics, Relaxation, Segment, Shape};
use aptkt_sim::philox::CounterStream;
use aptkt_sim::readout::{
    Frames, ObjectSystem, Physics, Readout, ThermalSystems, Trace, TrialState,
};
use aptkt_sim::sensors::{Sensors, NORMALS};
use aptkt_sim::slip::{run as slip_run, SlipCell, SlipParams};
use aptkt_sim::texture::{acceleration, Texture, TextureResponse};
use aptkt_sim::thermal::{heat, System};
use aptkt_sim::SimError;
use numpy::ndarray::{Array1, Array2};
use numpy::{
    Element, IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadwriteArray1,
    PyReadwriteArray2, PyReadwriteArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

fn sim_err(e: SimError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn rows<const W: usize>(a: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<Vec<[f64; W]>> {
    let v = a.as_array();
    if v.ncols() != W {
        return Err(PyValueError::new_err(format!(
            "{name} must have {W} columns"
        )));
    }
    Ok(v.rows()
        .into_iter()
        .map(|r| std::array::from_fn(|j| r[j]))
        .collect())
}

fn vec1<T: Element + Copy>(a: &PyReadonlyArray1<'_, T>) -> Vec<T> {
    a.as_array().iter().copied().collect()
}

fn col<'py, T: Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyAny> {
    Array1::from_vec(v).into_pyarray(py).into_any()
}

fn mat<'py, const W: usize>(py: Python<'py>, v: Vec<[f64; W]>) -> PyResult<Bound<'py, PyAny>> {
    let n = v.len();
    let flat: Vec<f64> = v.into_iter().flatten().collect();
    let a =
        Array2::from_shape_vec((n, W), flat).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

fn chunk_tuple<'py>(py: Python<'py>, c: Chunk) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(
        py,
        [
            col(py, c.cells),
            col(py, c.ks),
            col(py, c.t_s),
            col(py, c.t_ns),
            mat(py, c.pos)?,
            mat(py, c.vel)?,
            mat(py, c.acc)?,
            mat(py, c.sigma)?,
        ],
    )
}

fn segments(
    t0: &PyReadonlyArray1<'_, i64>,
    p0: &PyReadonlyArray2<'_, f64>,
    v0: &PyReadonlyArray2<'_, f64>,
    a: &PyReadonlyArray2<'_, f64>,
) -> PyResult<Vec<Segment>> {
    let (p, v, acc) = (
        rows::<3>(p0, "p0")?,
        rows::<3>(v0, "v0")?,
        rows::<3>(a, "a")?,
    );
    let t = t0.as_array();
    if t.is_empty() || p.len() != t.len() || v.len() != t.len() || acc.len() != t.len() {
        return Err(PyValueError::new_err(
            "trajectory: one row per segment, at least one",
        ));
    }
    Ok((0..t.len())
        .map(|i| Segment {
            t0: t[i],
            p0: p[i],
            v0: v[i],
            a: acc[i],
        })
        .collect())
}

/// The whole physics state held by a Python `PhysicsState` (numpy arrays and the stick-slip
/// state), converted once per call and written back in place after it.
struct StateRef<'py> {
    obj: Bound<'py, PyAny>,
    slip: Bound<'py, PyAny>,
    next_k: PyReadwriteArray1<'py, i64>,
    relax_h: PyReadwriteArray3<'py, f64>,
    relax_last: PyReadwriteArray2<'py, f64>,
    latest_force: PyReadwriteArray1<'py, f64>,
    thermal: PyReadwriteArray2<'py, f64>,
    thermal_t: PyReadwriteArray1<'py, f64>,
    last_xy: PyReadwriteArray2<'py, f64>,
    slip_load: PyReadwriteArray1<'py, f64>,
    slip_threshold: PyReadwriteArray1<'py, f64>,
    slip_events: PyReadwriteArray1<'py, i64>,
}

fn copy_into<T: Element + Copy, D: numpy::ndarray::Dimension>(
    mut dst: numpy::ndarray::ArrayViewMut<'_, T, D>,
    src: &[T],
) {
    dst.iter_mut().zip(src).for_each(|(d, s)| *d = *s);
}

fn flat<T: Element + Copy, D: numpy::ndarray::Dimension>(
    a: numpy::ndarray::ArrayView<'_, T, D>,
) -> Vec<T> {
    a.iter().copied().collect()
}

impl<'py> StateRef<'py> {
    fn new(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let slip = obj.getattr("slip")?;
        let arr = |name: &str| obj.getattr(name);
        Ok(Self {
            next_k: arr("next_k")?.extract()?,
            relax_h: arr("relax_h")?.extract()?,
            relax_last: arr("relax_last")?.extract()?,
            latest_force: arr("latest_force")?.extract()?,
            thermal: arr("thermal")?.extract()?,
            thermal_t: arr("thermal_t")?.extract()?,
            last_xy: arr("last_xy")?.extract()?,
            slip_load: slip.getattr("load")?.extract()?,
            slip_threshold: slip.getattr("threshold")?.extract()?,
            slip_events: slip.getattr("events")?.extract()?,
            slip,
            obj: obj.clone(),
        })
    }

    fn load(&self) -> PyResult<TrialState> {
        let t_ns: i64 = self.obj.getattr("t_ns")?.extract()?;
        let ringing: Vec<Vec<(f64, f64)>> = self.slip.getattr("ringing")?.extract()?;
        let (load, threshold, events) = (
            flat(self.slip_load.as_array()),
            flat(self.slip_threshold.as_array()),
            flat(self.slip_events.as_array()),
        );
        if ringing.len() != load.len()
            || threshold.len() != load.len()
            || events.len() != load.len()
        {
            return Err(PyValueError::new_err(
                "stick-slip state: one load, threshold, count and ringing list per cell",
            ));
        }
        let xy = self.last_xy.as_array();
        if xy.ncols() != 2 {
            return Err(PyValueError::new_err("last_xy must be (cells, 2)"));
        }
        Ok(TrialState {
            mech: MechState {
                t_ns,
                next_k: flat(self.next_k.as_array()),
                relax_h: flat(self.relax_h.as_array()),
                relax_last: flat(self.relax_last.as_array()),
                latest_force: flat(self.latest_force.as_array()),
            },
            thermal: flat(self.thermal.as_array()),
            thermal_t: flat(self.thermal_t.as_array()),
            last_xy: xy.rows().into_iter().map(|r| [r[0], r[1]]).collect(),
            slip: ringing
                .into_iter()
                .enumerate()
                .map(|(c, ring)| SlipCell {
                    load: load[c],
                    threshold: threshold[c],
                    events: events[c],
                    ring,
                })
                .collect(),
        })
    }

    fn store(&mut self, st: &TrialState) -> PyResult<()> {
        self.obj.setattr("t_ns", st.mech.t_ns)?;
        copy_into(self.next_k.as_array_mut(), &st.mech.next_k);
        copy_into(self.relax_h.as_array_mut(), &st.mech.relax_h);
        copy_into(self.relax_last.as_array_mut(), &st.mech.relax_last);
        copy_into(self.latest_force.as_array_mut(), &st.mech.latest_force);
        copy_into(self.thermal.as_array_mut(), &st.thermal);
        copy_into(self.thermal_t.as_array_mut(), &st.thermal_t);
        let xy: Vec<f64> = st.last_xy.iter().flatten().copied().collect();
        copy_into(self.last_xy.as_array_mut(), &xy);
        let load: Vec<f64> = st.slip.iter().map(|c| c.load).collect();
        let threshold: Vec<f64> = st.slip.iter().map(|c| c.threshold).collect();
        let events: Vec<i64> = st.slip.iter().map(|c| c.events).collect();
        copy_into(self.slip_load.as_array_mut(), &load);
        copy_into(self.slip_threshold.as_array_mut(), &threshold);
        copy_into(self.slip_events.as_array_mut(), &events);
        let ringing: Vec<Vec<(f64, f64)>> = st.slip.iter().map(|c| c.ring.clone()).collect();
        self.slip.setattr("ringing", ringing)?;
        Ok(())
    }
}

fn frames_tuple<'py>(py: Python<'py>, f: Frames) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(
        py,
        [
            col(py, f.cell_index),
            col(py, f.cell_id),
            col(py, f.t_sample_ns),
            col(py, f.t_ns),
            col(py, f.proximity),
            mat(py, f.acc)?,
            mat(py, f.temp)?,
            mat(py, f.force)?,
            col(py, f.force_true),
        ],
    )
}

fn trace_tuple<'py>(py: Python<'py>, t: Trace) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(py, [col(py, t.cells), col(py, t.t_ns), col(py, t.force)])
}

/// The per-trial constants of the readings, from a dict with these keys (see
/// `aptkt_sim::readout::Readout`).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct ReadoutArgs {
    centres: Vec<[f64; 2]>,
    axes: Vec<[[f64; 3]; 3]>,
    acc_bias: Vec<[f64; 3]>,
    cell_ids: Vec<i64>,
    gravity: f64,
    acc_noise: f64,
    die_self_heating: f64,
    die_temp_noise: f64,
    temp_noise: f64,
    prox_dark: f64,
    prox_gain: f64,
    prox_distance: f64,
    prox_noise: f64,
    reflectivity: f64,
    table_reflectivity: f64,
    contact_pressure_half: f64,
    conductance_scale: f64,
    contact_steps: f64,
    speed_step: f64,
    arm_vibration: f64,
    arm_modes: Vec<[f64; 5]>,
    texture_kvec: Vec<[f64; 2]>,
    texture_amplitude: Vec<f64>,
    texture_phase: Vec<f64>,
    /// see `sim_texture`
    texture_constants: [f64; 10],
    /// see `sim_slip`
    slip_params: [f64; 11],
    slip_keys: Vec<(u64, u64)>,
    /// C^1/2 of the thermal network's nodes
    sqrt_c: Vec<f64>,
}

fn texture_response(c: [f64; 10]) -> TextureResponse {
    TextureResponse {
        cover_contact_length: c[0],
        contact_resonance: c[1],
        contact_damping: c[2],
        acc_bandwidth: c[3],
        coupling_modulus: c[4],
        coupling_pressure: c[5],
        tangential_coupling: c[6],
        lateral_coupling: c[7],
        top_modulus: c[8],
        mu_kinetic: c[9],
    }
}

fn slip_params(c: [f64; 11]) -> SlipParams {
    SlipParams {
        mu_s: c[0],
        mu_k: c[1],
        tangential_stiffness: c[2],
        tangential_mass: c[3],
        threshold_sd: c[4],
        coupling: c[5],
        rate_hz: c[6],
        omega: c[7],
        decay: c[8],
        gain: c[9],
        lag: c[10],
    }
}

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
    fn new(nodes: usize) -> PyResult<Self> {
        if nodes < 2 {
            return Err(PyValueError::new_err("a thermal network has >= 2 nodes"));
        }
        Ok(Self {
            nodes,
            systems: Mutex::new(HashMap::new()),
        })
    }

    fn __len__(&self) -> PyResult<usize> {
        Ok(lock(&self.systems)?.len())
    }
}

fn lock<T>(m: &Mutex<T>) -> PyResult<std::sync::MutexGuard<'_, T>> {
    m.lock()
        .map_err(|_| PyValueError::new_err("thermal systems: poisoned lock"))
}

/// The physics of one object in one trial: mechanics, force loop, heat, stick-slip, texture,
/// noise and readings. The thermal solution operators come from the object's `SimThermal`;
/// those it lacks from `make(phi_bin, v_bin) -> (u, mu, ss_heater, ss_ambient, ss_object)`
/// the first time a configuration is met in this process.
#[pyclass(module = "aptkt._core", frozen)]
pub struct SimContact {
    physics: Physics,
    thermal: Mutex<ThermalSystems>,
    shared: Py<SimThermal>,
    make: Py<PyAny>,
    /// heater power (W), room and object temperature (°C)
    sources: (f64, f64, f64),
}

impl SimContact {
    fn mech(&self) -> &Mechanics {
        &self.physics.mech
    }

    /// The thermal configurations of `chunk`, fetching the systems not met yet.
    fn thermal_keys(&self, py: Python<'_>, chunk: &Chunk) -> PyResult<Vec<(i64, i64)>> {
        let keys = self.physics.thermal_keys(chunk);
        let missing = self.lock()?.missing(&keys);
        let shared = self.shared.get();
        for key in missing {
            let known = lock(&shared.systems)?.get(&key).cloned();
            let object = match known {
                Some(o) => o,
                None => {
                    let got = self.make.bind(py).call1(key)?;
                    let (u, mu, ss_h, ss_a, ss_o): (
                        PyReadonlyArray2<'_, f64>,
                        PyReadonlyArray1<'_, f64>,
                        PyReadonlyArray1<'_, f64>,
                        PyReadonlyArray1<'_, f64>,
                        PyReadonlyArray1<'_, f64>,
                    ) = got.extract()?;
                    let o = ObjectSystem {
                        u: flat(u.as_array()),
                        mu: vec1(&mu),
                        ss_heater: vec1(&ss_h),
                        ss_ambient: vec1(&ss_a),
                        ss_object: vec1(&ss_o),
                    };
                    o.check(shared.nodes).map_err(sim_err)?;
                    let o = Arc::new(o);
                    lock(&shared.systems)?.insert(key, o.clone());
                    o
                }
            };
            let (hp, amb, obj) = self.sources;
            self.lock()?
                .insert(key, object.for_trial(hp, amb, obj))
                .map_err(sim_err)?;
        }
        Ok(keys)
    }

    fn lock(&self) -> PyResult<std::sync::MutexGuard<'_, ThermalSystems>> {
        lock(&self.thermal)
    }
}

fn chunk_from(
    cells: PyReadonlyArray1<'_, i64>,
    ks: PyReadonlyArray1<'_, i64>,
    t_s: PyReadonlyArray1<'_, f64>,
    t_ns: PyReadonlyArray1<'_, i64>,
    pos: PyReadonlyArray2<'_, f64>,
    vel: PyReadonlyArray2<'_, f64>,
    acc: PyReadonlyArray2<'_, f64>,
    sigma: PyReadonlyArray2<'_, f64>,
) -> PyResult<Chunk> {
    let c = Chunk {
        cells: vec1(&cells),
        ks: vec1(&ks),
        t_s: vec1(&t_s),
        t_ns: vec1(&t_ns),
        pos: rows::<3>(&pos, "pos")?,
        vel: rows::<3>(&vel, "vel")?,
        acc: rows::<3>(&acc, "acc")?,
        sigma: rows::<3>(&sigma, "sigma")?,
    };
    let m = c.cells.len();
    if [
        c.ks.len(),
        c.t_s.len(),
        c.t_ns.len(),
        c.pos.len(),
        c.vel.len(),
        c.acc.len(),
        c.sigma.len(),
    ]
    .iter()
    .any(|&l| l != m)
    {
        return Err(PyValueError::new_err(
            "chunk: every array needs one row per sample",
        ));
    }
    Ok(c)
}

#[pymethods]
impl SimContact {
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (clock_rate, clock_phase, sensor_height, sensor_xy, centre, rotation,
        surface_z, tilt, crown_radius, waves, size, law_delta, law_sigma, skin_stiffness,
        relax_weights, relax_times, sensor_area, noise_key, force_gain, force_offset,
        force_noise, latency_ns, jitter_s, readout, thermal, make, sources))]
    fn new(
        clock_rate: PyReadonlyArray1<'_, f64>,
        clock_phase: PyReadonlyArray1<'_, f64>,
        sensor_height: PyReadonlyArray2<'_, f64>,
        sensor_xy: PyReadonlyArray3<'_, f64>,
        centre: (f64, f64),
        rotation: f64,
        surface_z: f64,
        tilt: (f64, f64),
        crown_radius: f64,
        waves: PyReadonlyArray2<'_, f64>,
        size: (f64, f64),
        law_delta: PyReadonlyArray1<'_, f64>,
        law_sigma: PyReadonlyArray1<'_, f64>,
        skin_stiffness: f64,
        relax_weights: Vec<f64>,
        relax_times: Vec<f64>,
        sensor_area: f64,
        noise_key: (u64, u64),
        force_gain: PyReadonlyArray2<'_, f64>,
        force_offset: PyReadonlyArray2<'_, f64>,
        force_noise: f64,
        latency_ns: i64,
        jitter_s: f64,
        readout: ReadoutArgs,
        thermal: Py<SimThermal>,
        make: Py<PyAny>,
        sources: (f64, f64, f64),
    ) -> PyResult<Self> {
        let xy = sensor_xy.as_array();
        if xy.shape()[1..] != [3, 2] {
            return Err(PyValueError::new_err("sensor_xy must be (cells, 3, 2)"));
        }
        let cells = Cells {
            clock_rate: vec1(&clock_rate),
            clock_phase: vec1(&clock_phase),
            sensor_height: rows::<3>(&sensor_height, "sensor_height")?,
            sensor_xy: (0..xy.shape()[0])
                .map(|c| std::array::from_fn(|s| [xy[[c, s, 0]], xy[[c, s, 1]]]))
                .collect(),
        };
        let shape = Shape {
            centre: [centre.0, centre.1],
            rotation,
            surface_z,
            tilt: [tilt.0, tilt.1],
            crown_radius,
            waves: rows::<4>(&waves, "waves")?,
            size: [size.0, size.1],
        };
        let law = Law::new(vec1(&law_delta), vec1(&law_sigma), skin_stiffness).map_err(sim_err)?;
        let relaxation = Relaxation {
            weights: relax_weights,
            times: relax_times,
        };
        let mech = Mechanics::new(cells, shape, law, relaxation, sensor_area).map_err(sim_err)?;
        let sensors = Sensors::new(
            [noise_key.0, noise_key.1],
            rows::<3>(&force_gain, "force_gain")?,
            rows::<3>(&force_offset, "force_offset")?,
            force_noise,
            latency_ns,
            jitter_s,
        )
        .map_err(sim_err)?;
        let r = readout;
        let physics = Physics::new(
            mech,
            sensors,
            Texture {
                kvec: r.texture_kvec,
                amplitude: r.texture_amplitude,
                phase: r.texture_phase,
            },
            texture_response(r.texture_constants),
            slip_params(r.slip_params),
            r.slip_keys.into_iter().map(|(a, b)| [a, b]).collect(),
            Readout {
                centres: r.centres,
                axes: r.axes,
                acc_bias: r.acc_bias,
                cell_ids: r.cell_ids,
                gravity: r.gravity,
                acc_noise: r.acc_noise,
                die_self_heating: r.die_self_heating,
                die_temp_noise: r.die_temp_noise,
                temp_noise: r.temp_noise,
                prox_dark: r.prox_dark,
                prox_gain: r.prox_gain,
                prox_distance: r.prox_distance,
                prox_noise: r.prox_noise,
                reflectivity: r.reflectivity,
                table_reflectivity: r.table_reflectivity,
                contact_pressure_half: r.contact_pressure_half,
                conductance_scale: r.conductance_scale,
                contact_steps: r.contact_steps,
                speed_step: r.speed_step,
                arm_vibration: r.arm_vibration,
                arm_modes: r.arm_modes,
            },
        )
        .map_err(sim_err)?;
        let own = ThermalSystems::new(r.sqrt_c).map_err(sim_err)?;
        if own.nodes() != thermal.get().nodes {
            return Err(PyValueError::new_err(
                "sqrt_c must have one entry per node of the thermal network",
            ));
        }
        Ok(Self {
            physics,
            thermal: Mutex::new(own),
            shared: thermal,
            make,
            sources,
        })
    }

    /// Advance the mechanics of `state` (a `PhysicsState`, updated in place) to `t_end_ns` on
    /// the trajectory's segments. Returns the chunk (cells, ks, t_s, t_ns, pos, vel, acc, sigma).
    #[allow(clippy::too_many_arguments)]
    fn mechanics<'py>(
        &self,
        py: Python<'py>,
        state: &Bound<'py, PyAny>,
        seg_t0: PyReadonlyArray1<'py, i64>,
        seg_p0: PyReadonlyArray2<'py, f64>,
        seg_v0: PyReadonlyArray2<'py, f64>,
        seg_a: PyReadonlyArray2<'py, f64>,
        t_end_ns: i64,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let segs = segments(&seg_t0, &seg_p0, &seg_v0, &seg_a)?;
        let mut sr = StateRef::new(state)?;
        let mut st = sr.load()?;
        self.mech().check_state(&st.mech).map_err(sim_err)?;
        let chunk = py.detach(|| {
            let mut c = Chunk::default();
            self.mech().step(&mut st.mech, &segs, t_end_ns, &mut c);
            c
        });
        sr.store(&st)?;
        chunk_tuple(py, chunk)
    }

    /// Heat, stick-slip, texture, noise and readings of a chunk's samples (the second half of a
    /// step; `state` is updated in place). Returns the frames (cell_index, cell_id,
    /// t_sample_ns, t_ns, proximity, acc, temp, force, force_true) in arrival order and the
    /// force trace (cells, t_ns, force).
    #[allow(clippy::too_many_arguments)]
    fn finish<'py>(
        &self,
        py: Python<'py>,
        state: &Bound<'py, PyAny>,
        cells: PyReadonlyArray1<'py, i64>,
        ks: PyReadonlyArray1<'py, i64>,
        t_s: PyReadonlyArray1<'py, f64>,
        t_ns: PyReadonlyArray1<'py, i64>,
        pos: PyReadonlyArray2<'py, f64>,
        vel: PyReadonlyArray2<'py, f64>,
        acc: PyReadonlyArray2<'py, f64>,
        sigma: PyReadonlyArray2<'py, f64>,
        detail: bool,
    ) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyTuple>)> {
        let chunk = chunk_from(cells, ks, t_s, t_ns, pos, vel, acc, sigma)?;
        let mut sr = StateRef::new(state)?;
        let mut st = sr.load()?;
        let keys = self.thermal_keys(py, &chunk)?;
        let thermal = self.lock()?;
        let (frames, trace) = py
            .detach(|| {
                self.physics
                    .finish(&thermal, &mut st, &chunk, &keys, detail)
            })
            .map_err(sim_err)?;
        drop(thermal);
        sr.store(&st)?;
        Ok((frames_tuple(py, frames)?, trace_tuple(py, trace)?))
    }

    /// A whole step to `t_end_ns` (mechanics, then `finish`); `state` is updated in place.
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        state: &Bound<'py, PyAny>,
        seg_t0: PyReadonlyArray1<'py, i64>,
        seg_p0: PyReadonlyArray2<'py, f64>,
        seg_v0: PyReadonlyArray2<'py, f64>,
        seg_a: PyReadonlyArray2<'py, f64>,
        t_end_ns: i64,
        detail: bool,
    ) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyTuple>)> {
        let segs = segments(&seg_t0, &seg_p0, &seg_v0, &seg_a)?;
        let mut sr = StateRef::new(state)?;
        let mut st = sr.load()?;
        self.mech().check_state(&st.mech).map_err(sim_err)?;
        let chunk = py.detach(|| {
            let mut c = Chunk::default();
            self.mech().step(&mut st.mech, &segs, t_end_ns, &mut c);
            c
        });
        let keys = self.thermal_keys(py, &chunk)?;
        let thermal = self.lock()?;
        let (frames, trace) = py
            .detach(|| {
                self.physics
                    .finish(&thermal, &mut st, &chunk, &keys, detail)
            })
            .map_err(sim_err)?;
        drop(thermal);
        sr.store(&st)?;
        Ok((frames_tuple(py, frames)?, trace_tuple(py, trace)?))
    }

    /// Normal deviates (n, 10) and arrival times of samples `ks` of `cells` sampled at `t_ns`.
    fn noise<'py>(
        &self,
        py: Python<'py>,
        ks: PyReadonlyArray1<'py, i64>,
        cells: PyReadonlyArray1<'py, i64>,
        t_ns: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let sensors = &self.physics.sensors;
        let (ks, cells, t_ns) = (vec1(&ks), vec1(&cells), vec1(&t_ns));
        if cells.len() != ks.len() || t_ns.len() != ks.len() {
            return Err(PyValueError::new_err(
                "ks, cells and t_ns must have the same length",
            ));
        }
        let n = sensors.n_cells as i64;
        if cells.iter().any(|&c| c < 0 || c >= n) || ks.iter().any(|&k| k < 0) {
            return Err(PyValueError::new_err("cell or sample index out of range"));
        }
        let (z, arrival) = py.detach(|| {
            let mut z = Vec::with_capacity(ks.len());
            let mut arrival = Vec::with_capacity(ks.len());
            for i in 0..ks.len() {
                let (zi, a) = sensors.noise_and_arrival(ks[i], cells[i] as usize, t_ns[i]);
                z.push(zi);
                arrival.push(a);
            }
            (z, arrival)
        });
        Ok((mat::<NORMALS>(py, z)?, col(py, arrival)))
    }

    /// Force-control ticks (see `aptkt_sim::control::run_ticks`). `phase` is
    /// ("settle", t_limit_ns, settled), ("ramp", t_start_ns, t_stop_ns, v, acc, dx, dy) or
    /// ("guard", t_end_ns, threshold, window_ns, w_end_ns); the segments are the one in force
    /// (settle, ramp) or the planned ones from now on (guard);
    /// `control` is (target, gain, max_vz, contact_z, max_depth, tick_ns, wrench_limit).
    /// Updates `state` (a `PhysicsState`) and `latest` in place; returns (status, settled or
    /// w_end_ns, samples, first segment (t0, p0, v0, a), queue (t, cell, force), last force
    /// error, chunk).
    #[allow(clippy::too_many_arguments)]
    fn force_ticks<'py>(
        &self,
        py: Python<'py>,
        state: &Bound<'py, PyAny>,
        seg_t0: PyReadonlyArray1<'py, i64>,
        seg_p0: PyReadonlyArray2<'py, f64>,
        seg_v0: PyReadonlyArray2<'py, f64>,
        seg_a: PyReadonlyArray2<'py, f64>,
        queue_t: PyReadonlyArray1<'py, i64>,
        queue_c: PyReadonlyArray1<'py, i64>,
        queue_f: PyReadonlyArray2<'py, f64>,
        mut latest: PyReadwriteArray2<'py, f64>,
        cal_gain: PyReadonlyArray2<'py, f64>,
        cal_offset: PyReadonlyArray2<'py, f64>,
        control: (f64, f64, f64, f64, f64, i64, f64),
        phase: &Bound<'py, PyTuple>,
        samples: usize,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let mut sr = StateRef::new(state)?;
        let mut full = sr.load()?;
        let st = &mut full.mech;
        self.mech().check_state(st).map_err(sim_err)?;
        let n = self.mech().cells.len();
        let latest_rows: Vec<[f64; 3]> = {
            let v = latest.as_array();
            if v.shape() != [n, 3] {
                return Err(PyValueError::new_err("latest must be (cells, 3)"));
            }
            v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect()
        };
        let mut queue = LeanQueue {
            t: vec1(&queue_t),
            cell: vec1(&queue_c),
            force: rows::<3>(&queue_f, "queue_f")?,
            latest: latest_rows,
            cal_gain: rows::<3>(&cal_gain, "cal_gain")?,
            cal_offset: rows::<3>(&cal_offset, "cal_offset")?,
        };
        if queue.cell.len() != queue.t.len()
            || queue.force.len() != queue.t.len()
            || queue.cal_gain.len() != n
            || queue.cal_offset.len() != n
            || queue.cell.iter().any(|&c| c < 0 || c as usize >= n)
        {
            return Err(PyValueError::new_err(
                "force queue or calibration does not match the patch",
            ));
        }
        let kind: String = phase.get_item(0)?.extract()?;
        let mut ph = match kind.as_str() {
            "settle" => Phase::Settle {
                t_limit_ns: phase.get_item(1)?.extract()?,
                settled: phase.get_item(2)?.extract()?,
            },
            "ramp" => Phase::Ramp {
                t_start_ns: phase.get_item(1)?.extract()?,
                t_stop_ns: phase.get_item(2)?.extract()?,
                v: phase.get_item(3)?.extract()?,
                acc: phase.get_item(4)?.extract()?,
                d: [phase.get_item(5)?.extract()?, phase.get_item(6)?.extract()?],
            },
            "guard" => Phase::Guard {
                t_end_ns: phase.get_item(1)?.extract()?,
                threshold: phase.get_item(2)?.extract()?,
                window_ns: phase.get_item(3)?.extract()?,
                w_end_ns: phase.get_item(4)?.extract()?,
            },
            other => return Err(PyValueError::new_err(format!("unknown phase {other:?}"))),
        };
        let (target, gain, max_vz, contact_z, max_depth, tick_ns, wrench_limit) = control;
        if tick_ns <= 0 {
            return Err(PyValueError::new_err("tick_ns must be > 0"));
        }
        let ctl = ForceControl {
            target,
            gain,
            max_vz,
            contact_z,
            max_depth,
            tick_ns,
            wrench_limit,
        };
        let mut segs = segments(&seg_t0, &seg_p0, &seg_v0, &seg_a)?;
        let mut samples = samples;
        let mut chunk = Chunk::default();
        let (status, err) = py.detach(|| {
            run_ticks(
                &self.physics.mech,
                &self.physics.sensors,
                &ctl,
                &mut ph,
                st,
                &mut segs,
                &mut queue,
                &mut chunk,
                &mut samples,
            )
        });
        sr.store(&full)?;
        {
            let mut v = latest.as_array_mut();
            for (c, r) in queue.latest.iter().enumerate() {
                for s in 0..3 {
                    v[[c, s]] = r[s];
                }
            }
        }
        let status = match status {
            Status::Done => "done",
            Status::Triggered => "triggered",
            Status::Timeout => "timeout",
            Status::TooDeep => "too_deep",
            Status::Wrench => "wrench",
            Status::Flush => "flush",
        };
        let settled = match ph {
            Phase::Settle { settled, .. } => settled as i64,
            Phase::Guard { w_end_ns, .. } => w_end_ns,
            Phase::Ramp { .. } => 0,
        };
        let seg = segs[0];
        let seg_t = (seg.t0, seg.p0.to_vec(), seg.v0.to_vec(), seg.a.to_vec());
        let q = (col(py, queue.t), col(py, queue.cell), mat(py, queue.force)?);
        (
            status,
            settled,
            samples,
            seg_t,
            q,
            err,
            chunk_tuple(py, chunk)?,
        )
            .into_pyobject(py)
    }
}

/// [node 0, node 1] temperatures (m, 2) of a cell-major chunk (see `aptkt_sim::thermal::heat`);
/// `state` (C, N) and `state_t` (C,) are advanced in place.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn sim_heat<'py>(
    py: Python<'py>,
    u: PyReadonlyArray3<'py, f64>,
    mu: PyReadonlyArray2<'py, f64>,
    t_ss: PyReadonlyArray2<'py, f64>,
    sqrt_c: PyReadonlyArray1<'py, f64>,
    cells: PyReadonlyArray1<'py, i64>,
    t_s: PyReadonlyArray1<'py, f64>,
    config: PyReadonlyArray1<'py, i64>,
    mut state: PyReadwriteArray2<'py, f64>,
    mut state_t: PyReadwriteArray1<'py, f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let (u, mu, t_ss) = (u.as_array(), mu.as_array(), t_ss.as_array());
    let k = u.shape()[0];
    let n = sqrt_c.len();
    if u.shape() != [k, n, n] || mu.shape() != [k, n] || t_ss.shape() != [k, n] {
        return Err(PyValueError::new_err(
            "systems must be u (k, N, N), mu and t_ss (k, N)",
        ));
    }
    let systems: Vec<System> = (0..k)
        .map(|i| System {
            u: u.index_axis(numpy::ndarray::Axis(0), i)
                .iter()
                .copied()
                .collect(),
            mu: mu.row(i).to_vec(),
            t_ss: t_ss.row(i).to_vec(),
        })
        .collect();
    let config: Vec<usize> = config
        .as_array()
        .iter()
        .map(|&c| usize::try_from(c).map_err(|_| PyValueError::new_err("negative configuration")))
        .collect::<PyResult<_>>()?;
    let (sqrt_c, cells, t_s) = (vec1(&sqrt_c), vec1(&cells), vec1(&t_s));
    let mut st: Vec<f64> = state.as_array().iter().copied().collect();
    let mut stt: Vec<f64> = state_t.as_array().iter().copied().collect();
    if state.as_array().ncols() != n {
        return Err(PyValueError::new_err("state must be (cells, N)"));
    }
    let out = py
        .detach(|| heat(&systems, &sqrt_c, &cells, &t_s, &config, &mut st, &mut stt))
        .map_err(sim_err)?;
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

/// Texture acceleration (n, 3) (see `aptkt_sim::texture::acceleration`); `constants` is
/// (cover_contact_length, contact_resonance, contact_damping, acc_bandwidth,
/// coupling_modulus, coupling_pressure, tangential_coupling, lateral_coupling, top_modulus,
/// mu_kinetic).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn sim_texture<'py>(
    py: Python<'py>,
    kvec: PyReadonlyArray2<'py, f64>,
    amplitude: PyReadonlyArray1<'py, f64>,
    phase: PyReadonlyArray1<'py, f64>,
    constants: [f64; 10],
    u: PyReadonlyArray2<'py, f64>,
    w: PyReadonlyArray2<'py, f64>,
    pressure: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let tex = Texture {
        kvec: rows::<2>(&kvec, "kvec")?,
        amplitude: vec1(&amplitude),
        phase: vec1(&phase),
    };
    if tex.amplitude.len() != tex.kvec.len() || tex.phase.len() != tex.kvec.len() {
        return Err(PyValueError::new_err(
            "kvec, amplitude and phase must have one row per wave",
        ));
    }
    let (u, w, p) = (rows::<2>(&u, "u")?, rows::<2>(&w, "w")?, vec1(&pressure));
    if w.len() != u.len() || p.len() != u.len() {
        return Err(PyValueError::new_err(
            "u, w and pressure must have one row per sample",
        ));
    }
    let k = texture_response(constants);
    let out = py.detach(|| acceleration(&tex, &k, &u, &w, &p));
    mat(py, out)
}

/// Stick-slip of one cell over a stretch of samples (see `aptkt_sim::slip::run`). `params` is
/// (mu_s, mu_k, tangential_stiffness, tangential_mass, threshold_sd, coupling, rate_hz, omega,
/// decay, gain, lag); `ring` (E, 2) the slips still ringing. Returns (acceleration, load,
/// threshold, events, ring).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn sim_slip<'py>(
    py: Python<'py>,
    params: [f64; 11],
    key: (u64, u64),
    load: f64,
    threshold: f64,
    events: i64,
    ring: PyReadonlyArray2<'py, f64>,
    t: PyReadonlyArray1<'py, f64>,
    path: PyReadonlyArray1<'py, f64>,
    force: PyReadonlyArray1<'py, f64>,
    speed: PyReadonlyArray1<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, f64, f64, i64, Bound<'py, PyAny>)> {
    let (t, path, force, speed) = (vec1(&t), vec1(&path), vec1(&force), vec1(&speed));
    if path.len() != t.len() || force.len() != t.len() || speed.len() != t.len() {
        return Err(PyValueError::new_err(
            "t, path, force and speed must have the same length",
        ));
    }
    let p = slip_params(params);
    let stream = CounterStream::new([key.0, key.1], 2);
    let mut cell = SlipCell {
        load,
        threshold,
        events,
        ring: rows::<2>(&ring, "ring")?
            .into_iter()
            .map(|r| (r[0], r[1]))
            .collect(),
    };
    let out = py.detach(|| slip_run(&p, &stream, &mut cell, &t, &path, &force, &speed));
    let ring: Vec<[f64; 2]> = cell.ring.iter().map(|&(a, b)| [a, b]).collect();
    Ok((
        col(py, out),
        cell.load,
        cell.threshold,
        cell.events,
        mat(py, ring)?,
    ))
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
    m.add_function(wrap_pyfunction!(_flush_subnormals, m)?)?;
    m.add_class::<SimContact>()?;
    m.add_class::<SimThermal>()?;
    m.add_function(wrap_pyfunction!(sim_heat, m)?)?;
    m.add_function(wrap_pyfunction!(sim_texture, m)?)?;
    m.add_function(wrap_pyfunction!(sim_slip, m)?)?;
    Ok(())
}
