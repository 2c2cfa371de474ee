//! Contact mechanics of one trial, sample by sample: which samples fall due, the TCP motion at
//! their times, the surface height under every force sensor, the layered indentation law and
//! the quasi-linear viscoelastic relaxation (docs/simulation.md, "Indentation").
//!
//! This is the per-time-step loop of `aptkt.sim.physics.ContactPhysics.mechanics`; the numpy
//! formulation there is kept as the reference the tests compare against.

use crate::SimError;

/// Sensors per cell.
pub const SENSORS: usize = 3;
/// Prony terms the relaxation may have.
pub const MAX_TERMS: usize = 8;

/// One segment of the TCP trajectory: constant acceleration from `t0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub t0: i64,
    pub p0: [f64; 3],
    pub v0: [f64; 3],
    pub a: [f64; 3],
}

impl Segment {
    /// Position, velocity and acceleration at `t_ns` (the segment extends backwards at rest).
    #[inline]
    pub fn at(&self, t_ns: i64) -> ([f64; 3], [f64; 3], [f64; 3]) {
        let tau = (((t_ns - self.t0) as f64) * 1e-9).max(0.0);
        let mut p = [0.0; 3];
        let mut v = [0.0; 3];
        for i in 0..3 {
            p[i] = self.p0[i] + self.v0[i] * tau + 0.5 * self.a[i] * (tau * tau);
            v[i] = self.v0[i] + self.a[i] * tau;
        }
        (p, v, self.a)
    }
}

/// The segment in force at `t_ns`: the last one starting at or before it (the first if none).
#[inline]
pub fn segment_at(segs: &[Segment], t_ns: i64) -> &Segment {
    let i = segs.partition_point(|s| s.t0 <= t_ns);
    &segs[i.saturating_sub(1)]
}

/// The object's top face in the base frame (`aptkt.sim.mechanics.SurfaceShape`).
#[derive(Clone, Debug)]
pub struct Shape {
    pub centre: [f64; 2],
    pub rotation: f64,
    pub surface_z: f64,
    pub tilt: [f64; 2],
    pub crown_radius: f64,
    /// (k_x, k_y cycles/m, amplitude m, phase rad)
    pub waves: Vec<[f64; 4]>,
    pub size: [f64; 2],
}

impl Shape {
    #[inline]
    pub fn to_object(&self, xy: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.rotation.sin_cos();
        let d = [xy[0] - self.centre[0], xy[1] - self.centre[1]];
        [c * d[0] + s * d[1], -s * d[0] + c * d[1]]
    }

    /// Surface height at a base-frame point; `-inf` off the face.
    #[inline]
    pub fn height(&self, xy: [f64; 2]) -> f64 {
        let u = self.to_object(xy);
        let mut z = self.surface_z + self.tilt[0] * u[0] + self.tilt[1] * u[1];
        if self.crown_radius > 0.0 {
            z -= u[1] * u[1] / (2.0 * self.crown_radius);
        }
        let mut w = 0.0;
        for wave in &self.waves {
            let arg = 2.0 * std::f64::consts::PI * (u[0] * wave[0] + u[1] * wave[1]) + wave[3];
            w += wave[2] * arg.sin();
        }
        z += w;
        if u[0].abs() <= self.size[0] / 2.0 && u[1].abs() <= self.size[1] / 2.0 {
            z
        } else {
            f64::NEG_INFINITY
        }
    }
}

/// Tabulated `σ(δ)` of the skin pressed into a layered object, monotone (`IndentationLaw`).
#[derive(Clone, Debug)]
pub struct Law {
    delta: Vec<f64>,
    sigma: Vec<f64>,
    slopes: Vec<f64>,
    skin_stiffness: f64,
}

impl Law {
    pub fn new(delta: Vec<f64>, sigma: Vec<f64>, skin_stiffness: f64) -> Result<Self, SimError> {
        if delta.len() != sigma.len() || delta.len() < 2 {
            return Err(SimError::invalid(
                "indentation table: need >= 2 (delta, sigma) pairs",
            ));
        }
        if delta.windows(2).any(|w| !(w[1] > w[0])) || !delta.iter().all(|d| d.is_finite()) {
            return Err(SimError::invalid("indentation table: depths must increase"));
        }
        let slopes = (0..delta.len() - 1)
            .map(|i| (sigma[i + 1] - sigma[i]) / (delta[i + 1] - delta[i]))
            .collect();
        Ok(Self {
            delta,
            sigma,
            slopes,
            skin_stiffness,
        })
    }

    /// Elastic pressure (Pa) at local indentation `d` (m); 0 out of contact.
    #[inline]
    pub fn stress(&self, d: f64) -> f64 {
        self.stress_near(d, &mut 0)
    }

    /// [`Law::stress`], looking first at the table interval `hint` (the previous sample's, which
    /// the next one nearly always shares or neighbours) before searching the whole table; the
    /// interval found is left in `hint`. The same interval, hence the same value, either way.
    #[inline]
    pub fn stress_near(&self, d: f64, hint: &mut usize) -> f64 {
        if d.is_nan() || d <= 0.0 {
            return 0.0;
        }
        let n = self.delta.len();
        let last = self.delta[n - 1];
        if d > last {
            return self.sigma[n - 1] + (d - last) * self.skin_stiffness;
        }
        if d < self.delta[0] {
            return 0.0;
        }
        // Largest j with delta[j] <= d (as numpy's interp).
        let h = *hint;
        let j = if h + 1 < n && self.delta[h] <= d && d < self.delta[h + 1] {
            h
        } else if h + 2 < n && self.delta[h + 1] <= d && d < self.delta[h + 2] {
            h + 1
        } else if h >= 1 && h < n && self.delta[h - 1] <= d && d < self.delta[h] {
            h - 1
        } else {
            self.delta.partition_point(|&x| x <= d) - 1
        };
        *hint = j;
        if j == n - 1 || self.delta[j] == d {
            return self.sigma[j];
        }
        self.slopes[j] * (d - self.delta[j]) + self.sigma[j]
    }
}

/// Prony series of the quasi-linear viscoelastic relaxation.
#[derive(Clone, Debug, Default)]
pub struct Relaxation {
    pub weights: Vec<f64>,
    pub times: Vec<f64>,
}

impl Relaxation {
    pub fn long_term(&self) -> f64 {
        1.0 - self.weights.iter().sum::<f64>()
    }
}

/// The patch's cells as the mechanics sees them.
#[derive(Clone, Debug)]
pub struct Cells {
    pub clock_rate: Vec<f64>,
    pub clock_phase: Vec<f64>,
    /// (C, 3) m, sensors recessed (+) or proud (-) of the skin plane
    pub sensor_height: Vec<[f64; SENSORS]>,
    /// (C, 3, 2) sensor positions relative to the TCP
    pub sensor_xy: Vec<[[f64; 2]; SENSORS]>,
}

impl Cells {
    pub fn len(&self) -> usize {
        self.clock_rate.len()
    }

    pub fn is_empty(&self) -> bool {
        self.clock_rate.is_empty()
    }
}

/// Hereditary and bookkeeping state of the mechanics (a part of `PhysicsState`).
#[derive(Clone, Debug, PartialEq)]
pub struct MechState {
    pub t_ns: i64,
    pub next_k: Vec<i64>,
    /// (terms, C, 3)
    pub relax_h: Vec<f64>,
    /// (C, 3)
    pub relax_last: Vec<f64>,
    /// (C,) N
    pub latest_force: Vec<f64>,
}

/// Samples of a stretch of time (cell-major within one step), as `MechChunk`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Chunk {
    pub cells: Vec<i64>,
    pub ks: Vec<i64>,
    pub t_s: Vec<f64>,
    pub t_ns: Vec<i64>,
    pub pos: Vec<[f64; 3]>,
    pub vel: Vec<[f64; 3]>,
    pub acc: Vec<[f64; 3]>,
    pub sigma: Vec<[f64; SENSORS]>,
}

impl Chunk {
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Chunks of consecutive stretches of time as one cell-major chunk: every sample of a cell
    /// together, in sample order.
    pub fn concat(chunks: &[&Chunk]) -> Chunk {
        let mut order: Vec<(usize, usize)> = chunks
            .iter()
            .enumerate()
            .flat_map(|(c, chunk)| (0..chunk.len()).map(move |i| (c, i)))
            .collect();
        order.sort_by_key(|&(c, i)| (chunks[c].cells[i], chunks[c].ks[i]));
        let mut out = Chunk::default();
        for (c, i) in order {
            let ch = chunks[c];
            out.cells.push(ch.cells[i]);
            out.ks.push(ch.ks[i]);
            out.t_s.push(ch.t_s[i]);
            out.t_ns.push(ch.t_ns[i]);
            out.pos.push(ch.pos[i]);
            out.vel.push(ch.vel[i]);
            out.acc.push(ch.acc[i]);
            out.sigma.push(ch.sigma[i]);
        }
        out
    }
}

/// Contact mechanics of one object in one trial.
#[derive(Clone, Debug)]
pub struct Mechanics {
    pub cells: Cells,
    pub shape: Shape,
    pub law: Law,
    pub relaxation: Relaxation,
    pub sensor_area: f64,
}

impl Mechanics {
    pub fn new(
        cells: Cells,
        shape: Shape,
        law: Law,
        relaxation: Relaxation,
        sensor_area: f64,
    ) -> Result<Self, SimError> {
        let n = cells.len();
        if n == 0 || cells.clock_phase.len() != n || cells.sensor_height.len() != n {
            return Err(SimError::invalid(
                "cells: rate, phase and heights must have one row per cell",
            ));
        }
        if cells.sensor_xy.len() != n {
            return Err(SimError::invalid(
                "cells: sensor positions must have one row per cell",
            ));
        }
        if cells
            .clock_rate
            .iter()
            .any(|r| !(*r > 0.0 && r.is_finite()))
        {
            return Err(SimError::invalid(
                "cells: clock rates must be finite and > 0",
            ));
        }
        if relaxation.weights.len() != relaxation.times.len()
            || relaxation.times.iter().any(|t| !(*t > 0.0))
            || relaxation.weights.len() > MAX_TERMS
        {
            return Err(SimError::invalid(
                "relaxation: one time > 0 per weight, at most 8 terms",
            ));
        }
        Ok(Self {
            cells,
            shape,
            law,
            relaxation,
            sensor_area,
        })
    }

    /// State at rest (no stress history) with the given next sample indices.
    pub fn check_state(&self, st: &MechState) -> Result<(), SimError> {
        let n = self.cells.len();
        let t = self.relaxation.weights.len();
        if st.next_k.len() != n
            || st.relax_h.len() != t * n * SENSORS
            || st.relax_last.len() != n * SENSORS
            || st.latest_force.len() != n
        {
            return Err(SimError::invalid(
                "mechanics state does not match the patch",
            ));
        }
        Ok(())
    }

    /// Last sample index of `cell` whose (rounded) ns time is at or before `t_end_ns`.
    #[inline]
    fn last_due(&self, cell: usize, t_end_ns: i64) -> i64 {
        let rate = self.cells.clock_rate[cell];
        let phase = self.cells.clock_phase[cell];
        let last = (((t_end_ns as f64) * 1e-9 - phase) * rate).floor() as i64;
        let t_last = ((phase + last as f64 / rate) * 1e9).round_ties_even() as i64;
        if t_last > t_end_ns {
            last - 1
        } else {
            last
        }
    }

    /// Advance to `t_end_ns` (updates `st`), appending the due samples to `out` cell-major.
    pub fn step(&self, st: &mut MechState, segs: &[Segment], t_end_ns: i64, out: &mut Chunk) {
        st.t_ns = st.t_ns.max(t_end_ns);
        let n = self.cells.len();
        let rel = &self.relaxation;
        let terms = rel.weights.len();
        let long_term = rel.long_term();
        for c in 0..n {
            let last = self.last_due(c, st.t_ns);
            let k0 = st.next_k[c];
            if last < k0 {
                continue;
            }
            let rate = self.cells.clock_rate[c];
            let phase = self.cells.clock_phase[c];
            let dt = 1.0 / rate;
            // Per-term decay and gain of the exact convolution for piecewise-linear stress.
            let mut a = [0.0f64; MAX_TERMS];
            let mut gain = [0.0f64; MAX_TERMS];
            for i in 0..terms {
                a[i] = (-dt / rel.times[i]).exp();
                gain[i] = rel.weights[i] * (rel.times[i] / dt) * (1.0 - a[i]);
            }
            let mut prev = [0.0; SENSORS];
            prev.copy_from_slice(&st.relax_last[c * SENSORS..(c + 1) * SENSORS]);
            let mut f_last = 0.0;
            // The surface height under a sensor depends on the TCP's x, y only: kept while they
            // do not change (presses, holds and waits move along z or not at all).
            let mut last_xy = [f64::NAN; 2];
            let mut heights = [0.0; SENSORS];
            let mut hints = [0usize; SENSORS];
            for k in k0..=last {
                let t_s = phase + k as f64 / rate;
                let t_ns = (t_s * 1e9).round_ties_even() as i64;
                let (p, v, acc) = segment_at(segs, t_ns).at(t_ns);
                let mut sigma = [0.0; SENSORS];
                let mut elastic = [0.0; SENSORS];
                if p[0] != last_xy[0] || p[1] != last_xy[1] {
                    last_xy = [p[0], p[1]];
                    for (s, h) in heights.iter_mut().enumerate() {
                        let xy = self.cells.sensor_xy[c][s];
                        *h = self.shape.height([p[0] + xy[0], p[1] + xy[1]]);
                    }
                }
                for s in 0..SENSORS {
                    let depth = heights[s] - (p[2] + self.cells.sensor_height[c][s]);
                    let depth = if depth.is_finite() { depth } else { -1.0 };
                    elastic[s] = self.law.stress_near(depth, &mut hints[s]);
                }
                for s in 0..SENSORS {
                    let mut out_s = if terms == 0 {
                        elastic[s]
                    } else {
                        long_term * elastic[s]
                    };
                    let inc = elastic[s] - prev[s];
                    for i in 0..terms {
                        let idx = (i * n + c) * SENSORS + s;
                        let hv = a[i] * st.relax_h[idx] + gain[i] * inc;
                        st.relax_h[idx] = hv;
                        out_s += hv;
                    }
                    sigma[s] = out_s.max(0.0);
                }
                prev = elastic;
                f_last = sigma.iter().map(|x| x * self.sensor_area).sum::<f64>();
                out.cells.push(c as i64);
                out.ks.push(k);
                out.t_s.push(t_s);
                out.t_ns.push(t_ns);
                out.pos.push(p);
                out.vel.push(v);
                out.acc.push(acc);
                out.sigma.push(sigma);
            }
            st.next_k[c] = last + 1;
            st.relax_last[c * SENSORS..(c + 1) * SENSORS].copy_from_slice(&prev);
            st.latest_force[c] = f_last;
        }
    }
}
