//! Stick-slip of one cell over a stretch of samples (`aptkt.sim.texture.StickSlip.run`,
//! docs/simulation.md "Vibration"): a spring-block that sticks until the spring force reaches
//! the (jittered) static friction, then slips, dropping the force and ringing the cover's
//! shear mode. The numpy formulation is the reference the tests compare against.

use crate::philox::{box_muller, unit, CounterStream};

/// Constants of the spring-block: static and kinetic friction, the tangential spring (N/m) and
/// mass (kg), the relative spread of the static threshold, the sample rate (Hz).
#[derive(Clone, Copy, Debug)]
pub struct SlipParams {
    pub mu_s: f64,
    pub mu_k: f64,
    pub tangential_stiffness: f64,
    pub tangential_mass: f64,
    pub threshold_sd: f64,
    pub rate_hz: f64,
    pub ring: Ringing,
}

/// The cover's shear mode a slip rings: the share of the force drop that reaches the
/// accelerometer, angular frequency (rad/s), decay rate (1/s), and the accelerometer's gain and
/// phase lag at that frequency.
#[derive(Clone, Copy, Debug)]
pub struct Ringing {
    pub coupling: f64,
    pub omega: f64,
    pub decay: f64,
    pub gain: f64,
    pub lag: f64,
}

/// One cell's state: spring load, next slip threshold (inf: none pending), slips so far and
/// the slips still ringing (time s, peak m/s²).
#[derive(Clone, Debug, PartialEq)]
pub struct SlipCell {
    pub load: f64,
    pub threshold: f64,
    pub events: i64,
    pub ring: Vec<(f64, f64)>,
}

/// Standard normal deviate of a cell's `event`-th slip: sample `256 b + (e mod 256) / 2`,
/// slot `e mod 2` of the cell's 2-slot stream (`StickSlip._z`).
fn z(stream: &CounterStream, event: i64) -> f64 {
    let (block, off) = (event.div_euclid(256), event.rem_euclid(256));
    let mut w = [0u64; 2];
    stream.words((block * 256 + off / 2) as u64, &mut w);
    let (a, b) = box_muller(unit(w[0]), unit(w[1]));
    if off % 2 == 0 {
        a
    } else {
        b
    }
}

fn threshold(p: &SlipParams, stream: &CounterStream, event: i64, force: f64) -> f64 {
    p.mu_s * force * (1.0 + p.threshold_sd * z(stream, event)).max(0.5)
}

/// numpy's `searchsorted(a, key, side="left")` for one key: a plain binary search (also on the
/// not quite sorted arrays left after a slip, exactly as the reference does).
fn searchsorted_left(a: &[f64], key: f64) -> usize {
    let (mut lo, mut hi) = (0usize, a.len());
    while lo < hi {
        let mid = lo + ((hi - lo) >> 1);
        if a[mid] < key {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Tangential acceleration (m/s²) of the cell at sample times `t` (s); `path` is the sliding
/// distance since the previous sample, `force` the cell's normal force, `speed` its sliding
/// speed. Updates `cell`.
pub fn run(
    p: &SlipParams,
    stream: &CounterStream,
    cell: &mut SlipCell,
    t: &[f64],
    path: &[f64],
    force: &[f64],
    speed: &[f64],
) -> Vec<f64> {
    let n = t.len();
    if n == 0 || path.len() != n || force.len() != n || speed.len() != n {
        return vec![0.0; n];
    }
    let dmu = p.mu_s - p.mu_k;
    let root = (p.tangential_stiffness * p.tangential_mass).sqrt();
    let strength: Vec<f64> = (0..n)
        .map(|i| {
            let v_c = if force[i] > 0.0 {
                dmu * force[i] / root
            } else {
                0.0
            };
            if v_c > 0.0 && speed[i] < v_c {
                1.0 - speed[i] / v_c.max(1e-300)
            } else {
                0.0
            }
        })
        .collect();
    let active: Vec<bool> = (0..n).map(|i| strength[i] > 0.0 && path[i] > 0.0).collect();
    let t_before = if n > 0 { t[0] - 1.0 / p.rate_hz } else { 0.0 };
    let mut load = Vec::new();
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j < n && active[j] == active[i] {
            j += 1;
        }
        if !active[i] {
            cell.load = if force[j - 1] > 0.0 && path[j - 1] > 0.0 {
                p.mu_k * force[j - 1]
            } else {
                0.0
            };
            cell.threshold = f64::INFINITY;
        } else {
            if !cell.threshold.is_finite() {
                cell.threshold = threshold(p, stream, cell.events, force[i]);
            }
            load.clear();
            let mut acc = 0.0;
            for &x in &path[i..j] {
                acc += x;
                load.push(cell.load + p.tangential_stiffness * acc);
            }
            loop {
                let hit = searchsorted_left(&load, cell.threshold);
                if hit >= load.len() {
                    break;
                }
                let s = i + hit;
                let before = if hit > 0 { load[hit - 1] } else { cell.load };
                let t0 = if s > 0 { t[s - 1] } else { t_before };
                let frac = (cell.threshold - before) / (load[hit] - before).max(1e-15);
                let drop = 2.0 * dmu * force[s];
                cell.ring.push((
                    t0 + frac.clamp(0.0, 1.0) * (t[s] - t0),
                    strength[s] * p.ring.coupling * drop / p.tangential_mass,
                ));
                for x in &mut load[hit..] {
                    *x -= drop;
                }
                cell.events += 1;
                cell.threshold = threshold(p, stream, cell.events, force[s]);
            }
            cell.load = load[load.len() - 1];
        }
        i = j;
    }
    let mut out = vec![0.0; n];
    if !cell.ring.is_empty() {
        for (k, o) in out.iter_mut().enumerate() {
            let mut sum = 0.0;
            for &(te, peak) in &cell.ring {
                let tau = t[k] - te;
                if tau >= 0.0 {
                    sum += peak
                        * p.ring.gain
                        * (-p.ring.decay * tau).exp()
                        * (p.ring.omega * tau + p.ring.lag).sin();
                }
            }
            *o = sum;
        }
        // Forget slips that have rung out (< 0.1 % of their peak).
        let t_last = t[n - 1];
        cell.ring
            .retain(|&(te, _)| (t_last - te) * p.ring.decay <= 7.0);
    }
    out
}
