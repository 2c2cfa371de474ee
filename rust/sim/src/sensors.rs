//! The force readings and arrival times of samples (sensor noise addressed by sample index),
//! as `ContactPhysics._noise_and_arrival` and `_force_reading`.

use crate::mechanics::SENSORS;
use crate::philox::{box_muller, unit, CounterStream};
use crate::SimError;

/// Random words per sample: 10 normals, 1 uniform (arrival jitter), 1 spare.
pub const NOISE_SLOTS: usize = 12;
/// Normal deviates per sample (force 3, acc 3, temperatures 2, proximity 1, spare 1).
pub const NORMALS: usize = 10;

/// What turns a sample's true force into the patch's reading and stamps its arrival.
#[derive(Clone, Debug)]
pub struct Sensors {
    pub noise: CounterStream,
    pub n_cells: usize,
    /// (C, 3) true N per normalised unit, already divided by the trial's gain drift
    pub gain: Vec<[f64; SENSORS]>,
    /// (C, 3) true zero-load reading
    pub offset: Vec<[f64; SENSORS]>,
    pub force_noise: f64,
    pub latency_ns: i64,
    pub jitter_s: f64,
}

impl Sensors {
    pub fn new(
        key: [u64; 2],
        gain: Vec<[f64; SENSORS]>,
        offset: Vec<[f64; SENSORS]>,
        force_noise: f64,
        latency_ns: i64,
        jitter_s: f64,
    ) -> Result<Self, SimError> {
        if gain.len() != offset.len() || gain.is_empty() {
            return Err(SimError::invalid(
                "sensors: one gain and offset row per cell",
            ));
        }
        Ok(Self {
            noise: CounterStream::new(key, NOISE_SLOTS),
            n_cells: gain.len(),
            gain,
            offset,
            force_noise,
            latency_ns,
            jitter_s,
        })
    }

    /// Normal deviates and arrival time of sample `k` of `cell` sampled at `t_ns`.
    #[inline]
    pub fn noise_and_arrival(&self, k: i64, cell: usize, t_ns: i64) -> ([f64; NORMALS], i64) {
        let mut w = [0u64; NOISE_SLOTS];
        self.noise
            .words((k as u64) * (self.n_cells as u64) + cell as u64, &mut w);
        let mut z = [0.0; NORMALS];
        for i in 0..NORMALS / 2 {
            let (a, b) = box_muller(unit(w[2 * i]), unit(w[2 * i + 1]));
            z[2 * i] = a;
            z[2 * i + 1] = b;
        }
        let jitter = (unit(w[10]) * self.jitter_s * 1e6).round_ties_even() as i64;
        (z, t_ns + self.latency_ns + 1000 * jitter)
    }

    /// Normalised force reading (offset + (F + noise) / gain) of `cell`'s sensors.
    #[inline]
    pub fn reading(&self, cell: usize, f_true: [f64; SENSORS], z: &[f64]) -> [f64; SENSORS] {
        let mut r = [0.0; SENSORS];
        for s in 0..SENSORS {
            r[s] =
                self.offset[cell][s] + (f_true[s] + self.force_noise * z[s]) / self.gain[cell][s];
        }
        r
    }
}
