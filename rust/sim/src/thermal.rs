//! Exact solution of the cells' linear thermal networks over a chunk of samples
//! (`ContactPhysics._heat` / `CellThermal.propagate_many`, docs/simulation.md "Heat exchange").
//!
//! For a fixed (contact, speed) configuration the network `C dT/dt = -K T + q` is linear
//! time-invariant; with `S = C^-1/2 K C^-1/2 = U diag(mu) U^T` and the steady state `T_ss`,
//! `T(t) = T_ss + C^-1/2 U exp(-mu t) U^T C^1/2 (T(0) - T_ss)`. The eigen-decompositions are
//! made (and cached) on the Python side; this loop evaluates them at every sample.

use crate::SimError;

/// One configuration's operator: `u` (N×N row-major), `mu` (N), `t_ss` (N).
#[derive(Clone, Debug)]
pub struct System {
    pub u: Vec<f64>,
    pub mu: Vec<f64>,
    pub t_ss: Vec<f64>,
}

/// The samples of a cell-major chunk to heat: each sample's cell, time (s) and configuration
/// (an index into the systems).
#[derive(Clone, Copy, Debug)]
pub struct HeatSamples<'a> {
    pub cells: &'a [i64],
    pub t_s: &'a [f64],
    pub config: &'a [usize],
}

/// Temperatures [node 0, node 1] of every sample of `samples`. `state` (C×N) and `state_t` (C)
/// are each cell's network state and its time; both are advanced to the cell's last sample.
/// Returns (m × 2) temperatures.
pub fn heat(
    systems: &[System],
    sqrt_c: &[f64],
    samples: &HeatSamples<'_>,
    state: &mut [f64],
    state_t: &mut [f64],
) -> Result<Vec<[f64; 2]>, SimError> {
    heat_at(systems, sqrt_c, samples, state, state_t, None)
}

/// [`heat`] with the temperatures computed only at the samples where `wanted` is true (zero
/// elsewhere); the state is advanced over every sample all the same, with the same arithmetic.
pub fn heat_at(
    systems: &[System],
    sqrt_c: &[f64],
    samples: &HeatSamples<'_>,
    state: &mut [f64],
    state_t: &mut [f64],
    wanted: Option<&[bool]>,
) -> Result<Vec<[f64; 2]>, SimError> {
    let HeatSamples { cells, t_s, config } = *samples;
    let n = sqrt_c.len();
    let m = cells.len();
    if t_s.len() != m || config.len() != m || wanted.is_some_and(|w| w.len() != m) {
        return Err(SimError::invalid(
            "heat: cells, times and configurations differ in length",
        ));
    }
    if n < 2 || state.len() != state_t.len() * n {
        return Err(SimError::invalid(
            "heat: state must be (cells, nodes) with >= 2 nodes",
        ));
    }
    for s in systems {
        if s.u.len() != n * n || s.mu.len() != n || s.t_ss.len() != n {
            return Err(SimError::invalid(
                "heat: every system must have the network's size",
            ));
        }
    }
    if config.iter().any(|&c| c >= systems.len()) {
        return Err(SimError::invalid("heat: configuration index out of range"));
    }
    if cells.iter().any(|&c| c < 0 || c as usize >= state_t.len()) {
        return Err(SimError::invalid("heat: cell index out of range"));
    }
    let mut out = vec![[0.0; 2]; m];
    let mut z0 = vec![0.0; n];
    let mut zd = vec![0.0; n];
    let mut factor = vec![0.0; n];
    let mut i = 0;
    while i < m {
        let c = cells[i] as usize;
        let cfg = config[i];
        let mut j = i;
        while j < m && cells[j] as usize == c && config[j] == cfg {
            j += 1;
        }
        let sys = &systems[cfg];
        let x = &mut state[c * n..(c + 1) * n];
        // z0 = U^T C^1/2 (T - T_ss)
        z0.iter_mut().for_each(|v| *v = 0.0);
        for (r, xr) in x.iter().enumerate() {
            let d = (xr - sys.t_ss[r]) * sqrt_c[r];
            let row = &sys.u[r * n..(r + 1) * n];
            for (zk, ur) in z0.iter_mut().zip(row) {
                *zk += d * ur;
            }
        }
        let r0 = &sys.u[0..n];
        let r1 = &sys.u[n..2 * n];
        let t0 = state_t[c];
        // Samples of a run are (almost always) evenly spaced: the modes then decay by the same
        // factor from one sample to the next, a multiplication instead of an exponential
        // (relative rounding ~1e-16 per step, re-anchored at every change of spacing).
        let mut h = f64::NAN;
        for s in i..j {
            let dt = t_s[s] - t0;
            let step = if s > i { t_s[s] - t_s[s - 1] } else { f64::NAN };
            let even = s > i && (step - h).abs() <= 1e-12 * h.abs();
            if !even {
                for k in 0..n {
                    zd[k] = (-dt * sys.mu[k]).exp() * z0[k];
                }
                if s > i {
                    h = step;
                    for k in 0..n {
                        factor[k] = (-h * sys.mu[k]).exp();
                    }
                }
            } else {
                for k in 0..n {
                    zd[k] *= factor[k];
                }
            }
            if wanted.is_some_and(|w| !w[s]) {
                continue;
            }
            let (mut a, mut b) = (0.0, 0.0);
            for k in 0..n {
                a += zd[k] * r0[k];
                b += zd[k] * r1[k];
            }
            out[s] = [sys.t_ss[0] + a / sqrt_c[0], sys.t_ss[1] + b / sqrt_c[1]];
        }
        // The state at the run's last sample (zd holds its decayed modes).
        for (r, xr) in x.iter_mut().enumerate() {
            let row = &sys.u[r * n..(r + 1) * n];
            let v: f64 = row.iter().zip(&zd).map(|(u, z)| u * z).sum();
            *xr = sys.t_ss[r] + v / sqrt_c[r];
        }
        state_t[c] = t_s[j - 1];
        i = j;
    }
    Ok(out)
}
