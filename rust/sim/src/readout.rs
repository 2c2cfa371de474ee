//! The second half of a time step (`aptkt.sim.physics.ContactPhysics.finish`): from the
//! samples the mechanics produced (TCP motion and contact stress) to every sensor value of every
//! cell — heat exchange, stick-slip, texture, the arm's vibration, the accelerometers'
//! orientation, sensor noise, the proximity sensor — and the frames in arrival order.
//!
//! Every operation follows the numpy formulation it replaced in the same order of floating-point
//! operations (sums left to right, as numpy reduces three or four terms), so that the packets
//! (quantised to the protocol's resolutions) are the same bytes; the numpy formulation is kept
//! in the tests (`tests/sim/numpy_reference.py`) as the reference.

use std::collections::HashMap;

use crate::mechanics::{Chunk, MechState, Mechanics, Segment, SENSORS};
use crate::philox::CounterStream;
use crate::sensors::Sensors;
use crate::slip::{run as slip_run, SlipCell, SlipParams};
use crate::texture::{acceleration, Texture, TextureResponse};
use crate::thermal::{heat_at, HeatSamples, System};
use crate::SimError;

/// The per-trial constants of the readings (patch, object and trial), by sensor.
#[derive(Clone, Debug)]
pub struct Readout {
    pub cells: CellFrames,
    pub acc: Accelerometers,
    pub temp: Thermometers,
    pub prox: Proximity,
    pub heat: ContactHeat,
}

/// Where each cell sits and how its accelerometer is mounted.
#[derive(Clone, Debug)]
pub struct CellFrames {
    /// (C, 2) cell centres relative to the TCP (m)
    pub centres: Vec<[f64; 2]>,
    /// (C, 3, 3) cell accelerometer axes in the base frame: `acc_c[j] = Σ_i world[i] axes[i][j]`
    pub axes: Vec<[[f64; 3]; 3]>,
    /// (C, 3) zero-g offsets (g)
    pub acc_bias: Vec<[f64; 3]>,
    pub cell_ids: Vec<i64>,
}

/// The accelerometers: gravity, their noise, and the arm's own vibration.
#[derive(Clone, Debug)]
pub struct Accelerometers {
    /// standard gravity (m/s²): accelerometers report specific force in g
    pub gravity: f64,
    pub acc_noise: f64,
    /// the arm's own vibration: g rms at 5 cm/s, modes (Hz, phase, dx, dy, dz)
    pub arm_vibration: f64,
    pub arm_modes: Vec<[f64; 5]>,
}

/// The temperature sensors: the accelerometer die's self-heating and noise, the LM71's noise.
#[derive(Clone, Copy, Debug)]
pub struct Thermometers {
    pub die_self_heating: f64,
    pub die_temp_noise: f64,
    pub temp_noise: f64,
}

/// The proximity sensor: dark reading, gain, distance scale, noise, and the reflectivity of
/// the object and of the table.
#[derive(Clone, Copy, Debug)]
pub struct Proximity {
    pub prox_dark: f64,
    pub prox_gain: f64,
    pub prox_distance: f64,
    pub prox_noise: f64,
    pub reflectivity: f64,
    pub table_reflectivity: f64,
}

/// The heat exchange's contact: contact fraction φ = p / (p + p½), the trial's contact quality
/// (scales φ), and the quantisation of the thermal configurations (φ steps, speed step m/s).
#[derive(Clone, Copy, Debug)]
pub struct ContactHeat {
    pub contact_pressure_half: f64,
    pub conductance_scale: f64,
    pub contact_steps: f64,
    pub speed_step: f64,
}

/// Everything one trial's physics needs (one object under one trial's conditions).
#[derive(Clone, Debug)]
pub struct Physics {
    pub mech: Mechanics,
    pub sensors: Sensors,
    pub texture: Texture,
    pub texture_response: TextureResponse,
    pub slip: SlipParams,
    /// one 2-slot stream per cell (its slips' thresholds)
    pub slip_streams: Vec<CounterStream>,
    pub readout: Readout,
}

/// The whole state of a trial's physics (`PhysicsState`).
#[derive(Clone, Debug, PartialEq)]
pub struct TrialState {
    pub mech: MechState,
    /// (C × N) node temperatures of each cell's network
    pub thermal: Vec<f64>,
    /// (C) time of each cell's thermal state (s)
    pub thermal_t: Vec<f64>,
    /// (C) cell centre at its last sample (m)
    pub last_xy: Vec<[f64; 2]>,
    pub slip: Vec<SlipCell>,
}

/// One (contact, speed) configuration's operator for an object, before a trial's temperatures:
/// `u` (N×N row-major), `mu` (N) and the steady state per watt of heater power, per kelvin of
/// room and per kelvin of object temperature (the steady state is linear in them).
#[derive(Clone, Debug)]
pub struct ObjectSystem {
    pub u: Vec<f64>,
    pub mu: Vec<f64>,
    pub ss_heater: Vec<f64>,
    pub ss_ambient: Vec<f64>,
    pub ss_object: Vec<f64>,
}

impl ObjectSystem {
    /// The operator under a trial's heater power (W), room and object temperatures (°C).
    pub fn for_trial(&self, heater_power: f64, ambient: f64, object: f64) -> System {
        let t_ss = (0..self.mu.len())
            .map(|i| {
                (heater_power * self.ss_heater[i] + ambient * self.ss_ambient[i])
                    + object * self.ss_object[i]
            })
            .collect();
        System {
            u: self.u.clone(),
            mu: self.mu.clone(),
            t_ss,
        }
    }

    pub fn check(&self, nodes: usize) -> Result<(), SimError> {
        let n = nodes;
        if self.u.len() != n * n
            || [&self.mu, &self.ss_heater, &self.ss_ambient, &self.ss_object]
                .iter()
                .any(|v| v.len() != n)
        {
            return Err(SimError::invalid(
                "thermal: a system must have the network's size",
            ));
        }
        Ok(())
    }
}

/// The thermal solution operators met so far, by (contact step, speed step). They are made
/// outside (an eigen-decomposition each) and added when a chunk needs one not yet here.
#[derive(Clone, Debug)]
pub struct ThermalSystems {
    pub sqrt_c: Vec<f64>,
    systems: Vec<System>,
    index: HashMap<(i64, i64), usize>,
}

impl ThermalSystems {
    pub fn new(sqrt_c: Vec<f64>) -> Result<Self, SimError> {
        if sqrt_c.len() < 2 || sqrt_c.iter().any(|c| !(*c > 0.0)) {
            return Err(SimError::invalid(
                "thermal: need >= 2 nodes with capacities > 0",
            ));
        }
        Ok(Self {
            sqrt_c,
            systems: Vec::new(),
            index: HashMap::new(),
        })
    }

    pub fn nodes(&self) -> usize {
        self.sqrt_c.len()
    }

    pub fn insert(&mut self, key: (i64, i64), system: System) -> Result<(), SimError> {
        let n = self.nodes();
        if system.u.len() != n * n || system.mu.len() != n || system.t_ss.len() != n {
            return Err(SimError::invalid(
                "thermal: a system must have the network's size",
            ));
        }
        match self.index.get(&key) {
            Some(&i) => self.systems[i] = system,
            None => {
                self.index.insert(key, self.systems.len());
                self.systems.push(system);
            }
        }
        Ok(())
    }

    /// The distinct keys of `keys` not held yet, in order of first appearance.
    pub fn missing(&self, keys: &[(i64, i64)]) -> Vec<(i64, i64)> {
        let mut out: Vec<(i64, i64)> = Vec::new();
        let mut last = None;
        for &k in keys {
            if last == Some(k) {
                continue;
            }
            last = Some(k);
            if !self.index.contains_key(&k) && !out.contains(&k) {
                out.push(k);
            }
        }
        out
    }
}

/// Sensor samples of all cells in arrival order, in physical units (`Frames`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Frames {
    pub cell_index: Vec<i64>,
    pub cell_id: Vec<i64>,
    pub t_sample_ns: Vec<i64>,
    /// arrival time on the PC
    pub t_ns: Vec<i64>,
    pub proximity: Vec<f64>,
    /// g
    pub acc: Vec<[f64; 3]>,
    /// °C: accelerometer die, LM71
    pub temp: Vec<[f64; 2]>,
    /// normalised reading (offset + F / gain)
    pub force: Vec<[f64; SENSORS]>,
    /// N, true normal force on the cell
    pub force_true: Vec<f64>,
}

impl Frames {
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }
}

/// True normal force of every sample, cell-major (`ForceTrace`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    pub cells: Vec<i64>,
    pub t_ns: Vec<i64>,
    pub force: Vec<f64>,
}

impl Physics {
    pub fn new(
        mech: Mechanics,
        sensors: Sensors,
        texture: Texture,
        texture_response: TextureResponse,
        slip: SlipParams,
        slip_keys: Vec<[u64; 2]>,
        readout: Readout,
    ) -> Result<Self, SimError> {
        let n = mech.cells.len();
        let r = &readout;
        if sensors.n_cells != n
            || slip_keys.len() != n
            || r.cells.centres.len() != n
            || r.cells.axes.len() != n
            || r.cells.acc_bias.len() != n
            || r.cells.cell_ids.len() != n
        {
            return Err(SimError::invalid(
                "physics: sensors, slip streams, centres, axes, biases and ids need one row per cell",
            ));
        }
        if texture.amplitude.len() != texture.kvec.len()
            || texture.phase.len() != texture.kvec.len()
        {
            return Err(SimError::invalid(
                "texture: kvec, amplitude and phase need one row per wave",
            ));
        }
        if !(r.heat.contact_steps > 0.0
            && r.heat.speed_step > 0.0
            && r.prox.prox_distance > 0.0
            && r.acc.gravity > 0.0)
        {
            return Err(SimError::invalid(
                "readout: contact steps, speed step, proximity distance and gravity must be > 0",
            ));
        }
        Ok(Self {
            mech,
            sensors,
            texture,
            texture_response,
            slip,
            slip_streams: slip_keys
                .into_iter()
                .map(|k| CounterStream::new(k, 2))
                .collect(),
            readout,
        })
    }

    /// Check that `st` belongs to this physics with a thermal network of `nodes` nodes.
    pub fn check_state(&self, st: &TrialState, nodes: usize) -> Result<(), SimError> {
        self.mech.check_state(&st.mech)?;
        let n = self.mech.cells.len();
        if st.thermal.len() != n * nodes
            || st.thermal_t.len() != n
            || st.last_xy.len() != n
            || st.slip.len() != n
        {
            return Err(SimError::invalid(
                "physics state does not match the patch or the thermal network",
            ));
        }
        Ok(())
    }

    /// Cell mean contact pressure (Pa) of a sample: the mean of its sensors' stresses.
    #[inline]
    fn pressure(sigma: &[f64; SENSORS]) -> f64 {
        ((sigma[0] + sigma[1]) + sigma[2]) / SENSORS as f64
    }

    /// Thermal configuration (contact step, speed step) of every sample of `chunk`.
    pub fn thermal_keys(&self, chunk: &Chunk) -> Vec<(i64, i64)> {
        let r = &self.readout;
        (0..chunk.len())
            .map(|i| {
                let p = Self::pressure(&chunk.sigma[i]);
                let phi = p / (p + r.heat.contact_pressure_half);
                let phi = (phi * r.heat.conductance_scale).min(1.0);
                let phi_bin = (phi * r.heat.contact_steps)
                    .round_ties_even()
                    .clamp(0.0, r.heat.contact_steps) as i64;
                let v_bin = if p > 0.0 {
                    let v = chunk.vel[i];
                    (v[0].hypot(v[1]) / r.heat.speed_step).round_ties_even() as i64
                } else {
                    0
                };
                (phi_bin, v_bin)
            })
            .collect()
    }

    /// The mechanics and readings of a step to `t_end_ns` (see [`Physics::finish`]).
    pub fn step(
        &self,
        thermal: &ThermalSystems,
        st: &mut TrialState,
        segs: &[Segment],
        t_end_ns: i64,
        detail: bool,
    ) -> Result<(Frames, Trace), SimError> {
        let mut chunk = Chunk::default();
        self.mech.step(&mut st.mech, segs, t_end_ns, &mut chunk);
        let keys = self.thermal_keys(&chunk);
        self.finish(thermal, st, &chunk, &keys, detail)
    }

    /// Heat, stick-slip, texture, noise and readings of the samples of `chunk` (cell-major,
    /// following `st`'s non-mechanical state), with their thermal configurations `keys`
    /// ([`Physics::thermal_keys`], all present in `thermal`). With `detail` every sample becomes
    /// a frame, otherwise each cell's newest; the state is advanced over every sample.
    pub fn finish(
        &self,
        thermal: &ThermalSystems,
        st: &mut TrialState,
        chunk: &Chunk,
        keys: &[(i64, i64)],
        detail: bool,
    ) -> Result<(Frames, Trace), SimError> {
        let m = chunk.len();
        if keys.len() != m {
            return Err(SimError::invalid(
                "finish: one thermal configuration per sample",
            ));
        }
        self.check_state(st, thermal.nodes())?;
        let n = self.mech.cells.len();
        if chunk.cells.iter().any(|&c| c < 0 || c as usize >= n) {
            return Err(SimError::invalid("finish: cell index out of range"));
        }
        // Configurations come in runs: look each run's up once.
        let mut config = Vec::with_capacity(m);
        let mut last: Option<((i64, i64), usize)> = None;
        for k in keys {
            let i = match last {
                Some((key, i)) if key == *k => i,
                _ => *thermal.index.get(k).ok_or_else(|| {
                    SimError::invalid("finish: a thermal configuration is missing")
                })?,
            };
            last = Some((*k, i));
            config.push(i);
        }
        if m == 0 {
            return Ok((Frames::default(), Trace::default()));
        }
        let r = &self.readout;
        let area = self.mech.sensor_area;
        // Each cell's block [first, last] of the cell-major chunk.
        let mut blocks: Vec<(usize, usize, usize)> = Vec::new(); // (cell, first, end)
        let mut i = 0;
        while i < m {
            let c = chunk.cells[i] as usize;
            let mut j = i + 1;
            while j < m && chunk.cells[j] as usize == c {
                j += 1;
            }
            blocks.push((c, i, j));
            i = j;
        }
        let f_true: Vec<[f64; SENSORS]> = chunk
            .sigma
            .iter()
            .map(|s| [s[0] * area, s[1] * area, s[2] * area])
            .collect();
        let f_cell: Vec<f64> = f_true.iter().map(|f| (f[0] + f[1]) + f[2]).collect();
        let pressure: Vec<f64> = chunk.sigma.iter().map(Self::pressure).collect();
        let speed: Vec<f64> = chunk.vel.iter().map(|v| v[0].hypot(v[1])).collect();

        // --- heat exchange, per cell and piecewise in (contact fraction, sliding speed)
        let emitted: Option<Vec<bool>> = (!detail).then(|| {
            let mut w = vec![false; m];
            for &(_, _, b) in &blocks {
                w[b - 1] = true;
            }
            w
        });
        let samples = HeatSamples {
            cells: &chunk.cells,
            t_s: &chunk.t_s,
            config: &config,
        };
        let temps = heat_at(
            &thermal.systems,
            &thermal.sqrt_c,
            &samples,
            &mut st.thermal,
            &mut st.thermal_t,
            emitted.as_deref(),
        )?;

        // --- stick-slip needs every sample (it has state); texture only the emitted ones
        let centre: Vec<[f64; 2]> = (0..m)
            .map(|i| {
                let c = chunk.cells[i] as usize;
                [
                    chunk.pos[i][0] + r.cells.centres[c][0],
                    chunk.pos[i][1] + r.cells.centres[c][1],
                ]
            })
            .collect();
        let mut path = vec![0.0; m];
        for &(c, a, b) in &blocks {
            for i in a..b {
                let prev = if i == a { st.last_xy[c] } else { centre[i - 1] };
                if pressure[i] > 0.0 {
                    path[i] = (centre[i][0] - prev[0]).hypot(centre[i][1] - prev[1]);
                }
            }
            st.last_xy[c] = centre[b - 1];
        }
        let mut slip = vec![0.0; m];
        if self.may_slip(st, &f_cell, &speed, &path) {
            for &(c, a, b) in &blocks {
                let out = slip_run(
                    &self.slip,
                    &self.slip_streams[c],
                    &mut st.slip[c],
                    &chunk.t_s[a..b],
                    &path[a..b],
                    &f_cell[a..b],
                    &speed[a..b],
                );
                slip[a..b].copy_from_slice(&out);
            }
        } else {
            // No slip possible: the springs carry the kinetic friction (or nothing).
            for &(c, _, b) in &blocks {
                let (f, p) = (f_cell[b - 1], path[b - 1]);
                let cell = &mut st.slip[c];
                cell.load = if f > 0.0 && p > 0.0 {
                    self.slip.mu_k * f
                } else {
                    0.0
                };
                cell.threshold = f64::INFINITY;
            }
        }

        let rows: Vec<usize> = if detail {
            (0..m).collect()
        } else {
            blocks.iter().map(|&(_, _, b)| b - 1).collect()
        };
        let shape = &self.mech.shape;
        let (sn, cs) = (shape.rotation.sin(), shape.rotation.cos());
        let u: Vec<[f64; 2]> = rows.iter().map(|&i| shape.to_object(centre[i])).collect();
        let w: Vec<[f64; 2]> = rows
            .iter()
            .map(|&i| {
                let v = chunk.vel[i];
                [cs * v[0] + sn * v[1], -sn * v[0] + cs * v[1]]
            })
            .collect();
        let p_rows: Vec<f64> = rows.iter().map(|&i| pressure[i]).collect();
        let tex = acceleration(&self.texture, &self.texture_response, &u, &w, &p_rows);
        let arm = self.arm_vibration(chunk, &rows);

        let k = rows.len();
        let mut frames = Frames {
            cell_index: Vec::with_capacity(k),
            cell_id: Vec::with_capacity(k),
            t_sample_ns: Vec::with_capacity(k),
            t_ns: Vec::with_capacity(k),
            proximity: Vec::with_capacity(k),
            acc: Vec::with_capacity(k),
            temp: Vec::with_capacity(k),
            force: Vec::with_capacity(k),
            force_true: Vec::with_capacity(k),
        };
        for (e, &i) in rows.iter().enumerate() {
            let c = chunk.cells[i] as usize;
            let s = slip[i];
            let t = [tex[e][0] + s, tex[e][1], tex[e][2] + 0.3 * s];
            let sp = speed[i];
            let v = chunk.vel[i];
            let dir = if sp > 1e-9 {
                let d = sp.max(1e-12);
                [v[0] / d, v[1] / d]
            } else {
                [1.0, 0.0]
            };
            let a = chunk.acc[i];
            let mut world = [a[0] + arm[e][0], a[1] + arm[e][1], a[2] + arm[e][2]];
            world[0] += t[0] * dir[0] + t[1] * -dir[1];
            world[1] += t[0] * dir[1] + t[1] * dir[0];
            // Specific force: an accelerometer at rest reads +1 g up.
            world[2] += t[2] + r.acc.gravity;
            let ax = &r.cells.axes[c];
            let mut acc_cell = [0.0; 3];
            for (j, out) in acc_cell.iter_mut().enumerate() {
                *out = ((world[0] * ax[0][j] + world[1] * ax[1][j]) + world[2] * ax[2][j])
                    / r.acc.gravity;
            }
            // --- sensor noise (addressed by sample index and cell) and readings
            let (z, arrival) = self
                .sensors
                .noise_and_arrival(chunk.ks[i], c, chunk.t_ns[i]);
            let force = self.sensors.reading(c, f_true[i], &z);
            let mut acc_g = [0.0; 3];
            for j in 0..3 {
                acc_g[j] = (acc_cell[j] + r.cells.acc_bias[c][j]) + r.acc.acc_noise * z[3 + j];
            }
            let temp = [
                (temps[i][1] + r.temp.die_self_heating) + r.temp.die_temp_noise * z[6],
                temps[i][0] + r.temp.temp_noise * z[7],
            ];
            let below = shape.height(centre[i]);
            let on_face = below.is_finite();
            let gap = (chunk.pos[i][2] - if on_face { below } else { 0.0 }).max(0.0);
            let refl = if on_face {
                r.prox.reflectivity
            } else {
                r.prox.table_reflectivity
            };
            let g = gap / r.prox.prox_distance;
            let prox = (r.prox.prox_dark + r.prox.prox_gain * refl / (1.0 + g * g))
                + r.prox.prox_noise * z[8];
            frames.cell_index.push(c as i64);
            frames.cell_id.push(r.cells.cell_ids[c]);
            frames.t_sample_ns.push(chunk.t_ns[i]);
            frames.t_ns.push(arrival);
            frames.proximity.push(prox);
            frames.acc.push(acc_g);
            frames.temp.push(temp);
            frames.force.push(force);
            frames.force_true.push(f_cell[i]);
        }
        let trace = Trace {
            cells: chunk.cells.clone(),
            t_ns: chunk.t_ns.clone(),
            force: f_cell,
        };
        Ok((arrival_order(frames), trace))
    }

    /// Whether any sample of this stretch can slip (or a past slip still rings).
    fn may_slip(&self, st: &TrialState, force: &[f64], speed: &[f64], path: &[f64]) -> bool {
        if st.slip.iter().any(|c| !c.ring.is_empty()) {
            return true;
        }
        let p = &self.slip;
        let root = (p.tangential_stiffness * p.tangential_mass).sqrt();
        (0..force.len()).any(|i| {
            let v_c = (p.mu_s - p.mu_k) * force[i] / root;
            speed[i] < v_c && path[i] > 0.0 && force[i] > 0.0
        })
    }

    /// The arm's own vibration while it moves (m/s², base frame) at the samples `rows`: a few
    /// modes whose amplitude grows with the TCP speed (reaching the trial's rms at 5 cm/s).
    fn arm_vibration(&self, chunk: &Chunk, rows: &[usize]) -> Vec<[f64; 3]> {
        let r = &self.readout;
        let speed: Vec<f64> = rows
            .iter()
            .map(|&i| {
                let v = chunk.vel[i];
                ((v[0] * v[0] + v[1] * v[1]) + v[2] * v[2]).sqrt()
            })
            .collect();
        let mut out = vec![[0.0; 3]; rows.len()];
        if !speed.iter().any(|&s| s > 1e-6)
            || !(r.acc.arm_vibration > 0.0)
            || r.acc.arm_modes.is_empty()
        {
            return out;
        }
        let scale =
            r.acc.arm_vibration * r.acc.gravity * (2.0 / r.acc.arm_modes.len() as f64).sqrt();
        let two_pi = 2.0 * std::f64::consts::PI;
        for (e, &i) in rows.iter().enumerate() {
            let amp = scale * (speed[e] / 0.05).min(2.0);
            let t = chunk.t_s[i];
            let mut sum = [0.0; 3];
            for (q, mode) in r.acc.arm_modes.iter().enumerate() {
                let wave = (two_pi * mode[0] * t + mode[1]).sin();
                for j in 0..3 {
                    sum[j] = if q == 0 {
                        wave * mode[2 + j]
                    } else {
                        sum[j] + wave * mode[2 + j]
                    };
                }
            }
            out[e] = [amp * sum[0], amp * sum[1], amp * sum[2]];
        }
        out
    }
}

/// Frames sorted by arrival time, then cell (stable: numpy's `lexsort((cell, arrival))`).
fn arrival_order(f: Frames) -> Frames {
    let mut order: Vec<usize> = (0..f.len()).collect();
    order.sort_by_key(|&i| (f.t_ns[i], f.cell_index[i]));
    if order.iter().enumerate().all(|(a, &b)| a == b) {
        return f;
    }
    fn pick<T: Copy>(v: &[T], order: &[usize]) -> Vec<T> {
        order.iter().map(|&i| v[i]).collect()
    }
    Frames {
        cell_index: pick(&f.cell_index, &order),
        cell_id: pick(&f.cell_id, &order),
        t_sample_ns: pick(&f.t_sample_ns, &order),
        t_ns: pick(&f.t_ns, &order),
        proximity: pick(&f.proximity, &order),
        acc: pick(&f.acc, &order),
        temp: pick(&f.temp, &order),
        force: pick(&f.force, &order),
        force_true: pick(&f.force_true, &order),
    }
}
