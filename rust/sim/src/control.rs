//! The simulated arm's force loop on the skin's reading, tick by tick (the slide's admittance
//! control of `aptkt.sim.robot.SimRobot`), with the reading computed from the packets before
//! they are made (`SimEngine.lean_*`): the force fields quantised to the wire's 12 bits,
//! calibrated with the skin's calibration, newest packet per cell by arrival time.

use aptkt_skin::column;

use crate::mechanics::{Chunk, MechState, Mechanics, Segment, SENSORS};
use crate::sensors::Sensors;

/// Packets computed but not yet arrived, and each cell's newest calibrated reading.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LeanQueue {
    pub t: Vec<i64>,
    pub cell: Vec<i64>,
    pub force: Vec<[f64; SENSORS]>,
    /// (C, 3) N as the skin reads it
    pub latest: Vec<[f64; SENSORS]>,
    /// skin calibration (C, 3)
    pub cal_gain: Vec<[f64; SENSORS]>,
    pub cal_offset: Vec<[f64; SENSORS]>,
}

impl LeanQueue {
    /// Queue the readings of `chunk[from..]` (arrival order kept stable, as a stable argsort).
    pub fn push_chunk(&mut self, sensors: &Sensors, mech: &Mechanics, chunk: &Chunk, from: usize) {
        for i in from..chunk.len() {
            let c = chunk.cells[i] as usize;
            let (z, arrival) = sensors.noise_and_arrival(chunk.ks[i], c, chunk.t_ns[i]);
            let mut f_true = [0.0; SENSORS];
            for s in 0..SENSORS {
                f_true[s] = chunk.sigma[i][s] * mech.sensor_area;
            }
            let norm = sensors.reading(c, f_true, &z);
            self.push(arrival, c, norm);
        }
    }

    /// Queue one packet's normalised force readings `norm` of cell `c`, arriving at
    /// `arrival`, as the skin reads them: quantised to the wire's force field, calibrated with
    /// the skin's calibration (after every packet queued with an arrival at or before it).
    pub fn push(&mut self, arrival: i64, c: usize, norm: [f64; SENSORS]) {
        let mut newtons = [0.0; SENSORS];
        for s in 0..SENSORS {
            let raw = column::FORCE.nearest_raw(norm[s]);
            newtons[s] =
                self.cal_gain[c][s] * (column::FORCE.to_physical(raw) - self.cal_offset[c][s]);
        }
        let at = self.t.partition_point(|&t| t <= arrival);
        self.t.insert(at, arrival);
        self.cell.insert(at, c as i64);
        self.force.insert(at, newtons);
    }

    /// Apply the packets that have arrived by `t_ns` (the newest of each cell wins).
    pub fn deliver(&mut self, t_ns: i64) {
        let due = self.t.partition_point(|&t| t <= t_ns);
        for i in 0..due {
            self.latest[self.cell[i] as usize] = self.force[i];
        }
        self.t.drain(..due);
        self.cell.drain(..due);
        self.force.drain(..due);
    }

    /// Total normal force as the skin reads it, summed as numpy sums a contiguous array
    /// (pairwise with eight accumulators), so that both implementations agree to the bit.
    pub fn reading(&self) -> f64 {
        let flat: Vec<f64> = self.latest.iter().flat_map(|r| r.iter().copied()).collect();
        numpy_sum(&flat)
    }
}

/// numpy's pairwise summation of a contiguous float64 array (sequential below 8 elements,
/// eight accumulators up to 128, halves beyond).
pub fn numpy_sum(a: &[f64]) -> f64 {
    pairwise(a)
}

fn pairwise(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        let mut res = -0.0;
        for x in a {
            res += *x;
        }
        res
    } else if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - (n % 8) {
            for j in 0..8 {
                r[j] += a[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            res += a[i];
            i += 1;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise(&a[..n2]) + pairwise(&a[n2..])
    }
}

/// The admittance law and the limits the robot enforces in its force loop.
#[derive(Clone, Copy, Debug)]
pub struct ForceControl {
    pub target: f64,
    pub gain: f64,
    pub max_vz: f64,
    pub contact_z: f64,
    pub max_depth: f64,
    pub tick_ns: i64,
    pub wrench_limit: f64,
}

/// What a run of ticks does.
#[derive(Clone, Copy, Debug)]
pub enum Phase {
    /// Hold position in x/y until the error stays below 10 % for five ticks in a row.
    Settle { t_limit_ns: i64, settled: u32 },
    /// Move along `d` at `v + acc (t - t_start)` until `t_stop`.
    Ramp {
        t_start_ns: i64,
        t_stop_ns: i64,
        v: f64,
        acc: f64,
        d: [f64; 2],
    },
    /// A guarded move on a planned trajectory (the segments given): tick until the reading
    /// exceeds `threshold` or `t_end` is reached. The force law is not used. Ticks follow
    /// `SimEngine.run`'s speculation windows: every `tick_ns` from a window's start and one at
    /// its end `w_end_ns` (a new window of `window_ns` starts when `now` reaches it).
    Guard {
        t_end_ns: i64,
        threshold: f64,
        window_ns: i64,
        w_end_ns: i64,
    },
}

/// Why a run of ticks returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// Settled (settle), reached t_stop (ramp) or t_end without contact (guard).
    Done,
    /// Guard only: the reading exceeded the threshold at the last tick.
    Triggered,
    /// Settle only: past the time limit without settling.
    Timeout,
    /// The next tick would start deeper than `max_depth` below contact (nothing done for it).
    TooDeep,
    /// The true force crossed the wrench limit during the last tick.
    Wrench,
    /// More than `FLUSH_SAMPLES` samples since the last flush: make the packets (and reset
    /// the count), then call again.
    Flush,
}

/// Samples after which the packets of a stretch are made (`SimEngine.lean_advance`).
pub const FLUSH_SAMPLES: usize = 2000;

/// A run of control ticks: the phase (and its progress), the trajectory it moves on, the
/// samples it made and how many were made since the last flush.
#[derive(Clone, Debug)]
pub struct TickRun {
    pub phase: Phase,
    /// Force phases (settle, ramp): the segment in force, replaced by each tick's motion; a
    /// guard: the planned segments.
    pub segs: Vec<Segment>,
    /// The new samples, appended.
    pub chunk: Chunk,
    pub samples: usize,
}

/// Run control ticks from `st.t_ns`, the packets' readings in `queue`. Returns the status and
/// the force error of the last tick (guard: the reading minus the threshold).
pub fn run_ticks(
    mech: &Mechanics,
    sensors: &Sensors,
    ctl: &ForceControl,
    st: &mut MechState,
    queue: &mut LeanQueue,
    run: &mut TickRun,
) -> (Status, f64) {
    let TickRun {
        phase,
        segs,
        chunk,
        samples,
    } = run;
    let mut err = f64::NAN;
    if segs.is_empty() {
        return (Status::Done, err);
    }
    loop {
        let now = st.t_ns;
        if let Phase::Guard {
            t_end_ns,
            threshold,
            window_ns,
            ref mut w_end_ns,
        } = *phase
        {
            // engine.run with a stop predicate: at each tick the wrench first, then the skin's
            // reading.
            if now >= t_end_ns {
                return (Status::Done, err);
            }
            if now >= *w_end_ns {
                *w_end_ns = t_end_ns.min(now + window_ns.max(1));
            }
            let end = (*w_end_ns).min(now + ctl.tick_ns);
            let before = chunk.len();
            mech.step(st, segs, end, chunk);
            let added = chunk.len() - before;
            if added > 0 {
                *samples += added;
                queue.push_chunk(sensors, mech, chunk, before);
            }
            queue.deliver(end);
            let wrench: f64 = st.latest_force.iter().sum();
            if wrench > ctl.wrench_limit {
                return (Status::Wrench, err);
            }
            err = queue.reading() - threshold;
            if err > 0.0 {
                return (Status::Triggered, err);
            }
            if *samples > FLUSH_SAMPLES {
                return (Status::Flush, err);
            }
            continue;
        }
        let seg = &mut segs[0];
        let (vxy, axy, end) = match *phase {
            Phase::Settle { .. } => ([0.0, 0.0], [0.0, 0.0], now + ctl.tick_ns),
            Phase::Guard { .. } => unreachable!("handled above"),
            Phase::Ramp {
                t_start_ns,
                t_stop_ns,
                v,
                acc,
                d,
            } => {
                if now >= t_stop_ns {
                    return (Status::Done, err);
                }
                let tau = ((now - t_start_ns) as f64) * 1e-9;
                let speed = v + acc * tau;
                (
                    [d[0] * speed, d[1] * speed],
                    [d[0] * acc, d[1] * acc],
                    t_stop_ns.min(now + ctl.tick_ns),
                )
            }
        };
        err = ctl.target - queue.reading();
        let vz = -(ctl.gain * err).clamp(-ctl.max_vz, ctl.max_vz);
        let (p, _, _) = seg.at(now);
        if p[2] < ctl.contact_z - ctl.max_depth {
            return (Status::TooDeep, err);
        }
        *seg = Segment {
            t0: now,
            p0: p,
            v0: [vxy[0], vxy[1], vz],
            a: [axy[0], axy[1], 0.0],
        };
        let before = chunk.len();
        mech.step(st, std::slice::from_ref(seg), end, chunk);
        let added = chunk.len() - before;
        if added > 0 {
            *samples += added;
            queue.push_chunk(sensors, mech, chunk, before);
        }
        queue.deliver(end);
        // The caller makes the packets (and resets `samples`) after any return with
        // `samples > FLUSH_SAMPLES`, before acting on the status, as `lean_advance` does.
        let flush = *samples > FLUSH_SAMPLES;
        let wrench: f64 = st.latest_force.iter().sum();
        if wrench > ctl.wrench_limit {
            return (Status::Wrench, err);
        }
        if let Phase::Settle {
            t_limit_ns,
            ref mut settled,
        } = *phase
        {
            *settled = if err.abs() < 0.1 * ctl.target {
                *settled + 1
            } else {
                0
            };
            if st.t_ns > t_limit_ns {
                return (Status::Timeout, err);
            }
            if *settled >= 5 {
                return (Status::Done, err);
            }
        }
        if flush {
            return (Status::Flush, err);
        }
    }
}
