//! Properties of the simulation core: Philox against numpy's output, chunking invariance of
//! the mechanics, the relaxation's limits, the indentation law, the heat solution's steady
//! state and the force loop's bookkeeping.

use aptkt_sim::control::{numpy_sum, run_ticks, ForceControl, LeanQueue, Phase, Status, TickRun};
use aptkt_sim::mechanics::{Chunk, Law, MechState, Mechanics, Relaxation, Segment, Shape};
use aptkt_sim::philox::{block, CounterStream};
use aptkt_sim::sensors::Sensors;
use aptkt_sim::texture::{
    acceleration, ContactVibration, Texture, TextureCoupling, TextureResponse,
};
use aptkt_sim::thermal::{heat, HeatSamples, System};
use proptest::prelude::*;

mod common;

#[test]
fn philox_matches_numpy() {
    // numpy: Philox(key=[0x0123456789abcdef, 0xfedcba9876543210], counter=[7,0,0,0]).random_raw(8)
    let key = [0x0123_4567_89ab_cdef, 0xfedc_ba98_7654_3210];
    let expect = [
        0xcd065aa747a6e46d_u64,
        0x154605f80dde3ada,
        0xc5d8a6fd189c2301,
        0x736a662a867273d6,
        0xd53828d2cb3b4681,
        0x00a911dc89ee5781,
        0x616cc813b14623dc,
        0x6b7aabb072a74503,
    ];
    assert_eq!(block([8, 0, 0, 0], key), expect[..4]);
    assert_eq!(block([9, 0, 0, 0], key), expect[4..]);
    // A stream of 8 slots: sample 3 starts at block 3*2+1 = 7 + 1.
    let s = CounterStream::new(key, 6);
    let mut w = [0u64; 6];
    s.words(3, &mut w);
    let b0 = block([7, 0, 0, 0], key);
    let b1 = block([8, 0, 0, 0], key);
    assert_eq!(w, [b0[0], b0[1], b0[2], b0[3], b1[0], b1[1]]);
}

#[test]
fn numpy_sum_orders() {
    let a: Vec<f64> = (0..21)
        .map(|i| (i as f64 * 0.37).sin() * 10f64.powi(i % 7 - 3))
        .collect();
    let mut r = [0.0; 8];
    r.copy_from_slice(&a[..8]);
    for j in 0..8 {
        r[j] += a[8 + j];
    }
    let mut expect = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for x in &a[16..] {
        expect += x;
    }
    assert_eq!(numpy_sum(&a).to_bits(), expect.to_bits());
    assert_eq!(numpy_sum(&a[..5]), a[..5].iter().sum::<f64>());
}

fn law(k_skin: f64, e: f64, h: f64, eps_d: f64) -> Law {
    // Closed-form inverse law of one layer in series with the skin (as IndentationLaw).
    let mut sigma = vec![0.0];
    for i in 0..4000 {
        sigma.push(10f64.powf(-4.0 + 11.0 * i as f64 / 3999.0));
    }
    let delta = sigma
        .iter()
        .map(|s| s / k_skin + h * s / (e + s / eps_d))
        .collect();
    Law::new(delta, sigma, k_skin).unwrap()
}

fn mechanics(weights: Vec<f64>, times: Vec<f64>) -> Mechanics {
    let cells = common::cells([1e-6, -2e-6, 0.0]);
    let shape = Shape {
        centre: [0.55, 0.0],
        rotation: 0.3,
        surface_z: 0.02,
        tilt: [0.001, -0.002],
        crown_radius: 0.5,
        waves: vec![[30.0, 10.0, 2e-5, 0.4], [-5.0, 40.0, 1e-5, 1.0]],
        size: [0.1, 0.08],
    };
    Mechanics::new(
        cells,
        shape,
        law(2e7, 5e4, 0.01, 0.6),
        Relaxation { weights, times },
        1e-5,
    )
    .unwrap()
}

fn rest_state(m: &Mechanics) -> MechState {
    let n = m.cells.len();
    let t = m.relaxation.weights.len();
    MechState {
        t_ns: 0,
        next_k: vec![0; n],
        relax_h: vec![0.0; t * n * 3],
        relax_last: vec![0.0; n * 3],
        latest_force: vec![0.0; n],
    }
}

fn press() -> Vec<Segment> {
    // Down at 5 mm/s from 1 mm above the face (at the object's centre), then hold.
    vec![
        Segment {
            t0: 0,
            p0: [0.55, 0.0, 0.021],
            v0: [0.0, 0.0, -0.005],
            a: [0.0; 3],
        },
        Segment {
            t0: 600_000_000,
            p0: [0.55, 0.0, 0.018],
            v0: [0.0; 3],
            a: [0.0; 3],
        },
    ]
}

fn sorted(mut c: Chunk) -> Vec<(i64, i64, [u64; 3])> {
    let mut v: Vec<_> = (0..c.len())
        .map(|i| (c.cells[i], c.ks[i], c.sigma[i].map(f64::to_bits)))
        .collect();
    v.sort();
    c.cells.clear();
    v
}

proptest! {
    #[test]
    fn mechanics_does_not_depend_on_chunking(cuts in proptest::collection::vec(1i64..3_000_000_000, 0..6)) {
        let m = mechanics(vec![0.3, 0.2], vec![0.05, 1.5]);
        let segs = press();
        let mut whole = rest_state(&m);
        let mut a = Chunk::default();
        m.step(&mut whole, &segs, 3_000_000_000, &mut a);
        let mut parts = rest_state(&m);
        let mut b = Chunk::default();
        let mut cuts = cuts.clone();
        cuts.sort();
        for t in cuts.into_iter().chain([3_000_000_000]) {
            m.step(&mut parts, &segs, t, &mut b);
        }
        prop_assert_eq!(&whole, &parts);
        prop_assert_eq!(sorted(a), sorted(b));
    }

    #[test]
    fn a_hint_never_changes_the_stress(d in -1e-4f64..6e-3, hint in 0usize..4100) {
        let l = law(2e5, 5e4, 0.01, 0.6);
        let mut h = hint.min(4000);
        prop_assert_eq!(l.stress_near(d, &mut h).to_bits(), l.stress(d).to_bits());
        // and the hint found serves the next, nearby depth
        let mut h2 = h;
        prop_assert_eq!(l.stress_near(d * 1.001, &mut h2).to_bits(), l.stress(d * 1.001).to_bits());
    }

    #[test]
    fn stress_is_monotone_and_zero_out_of_contact(d1 in -1e-3f64..5e-3, d2 in -1e-3f64..5e-3) {
        let l = law(2e5, 5e4, 0.01, 0.6);
        let (lo, hi) = if d1 <= d2 { (d1, d2) } else { (d2, d1) };
        prop_assert!(l.stress(lo) <= l.stress(hi));
        if lo <= 0.0 { prop_assert_eq!(l.stress(lo), 0.0); }
    }
}

#[test]
fn stress_inverts_the_depth_law() {
    let l = law(2e5, 5e4, 0.01, 0.6);
    for s in [10.0, 300.0, 5e3, 4e4] {
        let d = s / 2e5 + 0.01 * s / (5e4 + s / 0.6);
        assert!((l.stress(d) - s).abs() < 1e-3 * s, "{s}: {}", l.stress(d));
    }
}

#[test]
fn long_hold_relaxes_to_the_long_term_fraction() {
    let relaxed = mechanics(vec![0.3, 0.2], vec![0.05, 0.5]);
    let elastic = mechanics(vec![], vec![]);
    let segs = press();
    let (mut a, mut b) = (Chunk::default(), Chunk::default());
    relaxed.step(&mut rest_state(&relaxed), &segs, 20_000_000_000, &mut a);
    elastic.step(&mut rest_state(&elastic), &segs, 20_000_000_000, &mut b);
    assert_eq!(a.len(), b.len());
    let last = a.len() - 1;
    assert!(b.sigma[last][0] > 0.0);
    for s in 0..3 {
        let r = a.sigma[last][s] / b.sigma[last][s];
        assert!((r - 0.5).abs() < 1e-9, "{r}");
    }
    // Right after the press ends the relaxed stress is above the long-term value.
    let i = a.t_ns.iter().position(|&t| t > 600_000_000).unwrap();
    assert!(a.sigma[i][0] > 0.5 * b.sigma[i][0] * 1.05);
}

#[test]
fn heat_reaches_the_steady_state_and_is_exact_in_time() {
    // Two nodes, diagonal system: decay rates 1 and 3 per second about T_ss = (20, 30).
    let sys = System {
        u: vec![1.0, 0.0, 0.0, 1.0],
        mu: vec![1.0, 3.0],
        t_ss: vec![20.0, 30.0],
    };
    let sqrt_c = [1.0, 1.0];
    let t: Vec<f64> = (1..=100).map(|i| i as f64 * 0.1).collect();
    let cells = vec![0i64; t.len()];
    let mut state = vec![25.0, 10.0];
    let mut state_t = vec![0.0];
    let config = vec![0; t.len()];
    let samples = |cells, t_s, config| HeatSamples { cells, t_s, config };
    let out = heat(
        std::slice::from_ref(&sys),
        &sqrt_c,
        &samples(&cells, &t, &config),
        &mut state,
        &mut state_t,
    )
    .unwrap();
    for (i, ti) in t.iter().enumerate() {
        assert!((out[i][0] - (20.0 + 5.0 * (-ti).exp())).abs() < 1e-12);
        assert!((out[i][1] - (30.0 - 20.0 * (-3.0 * ti).exp())).abs() < 1e-12);
    }
    // Two halves give the same end state.
    let mut s2 = vec![25.0, 10.0];
    let mut t2 = vec![0.0];
    for half in [0..50, 50..100] {
        heat(
            std::slice::from_ref(&sys),
            &sqrt_c,
            &samples(&cells[half.clone()], &t[half.clone()], &config[..50]),
            &mut s2,
            &mut t2,
        )
        .unwrap();
    }
    assert!((s2[0] - state[0]).abs() < 1e-12 && (s2[1] - state[1]).abs() < 1e-12);
    let missing = vec![1; t.len()];
    assert!(heat(
        &[sys],
        &sqrt_c,
        &samples(&cells, &t, &missing),
        &mut s2,
        &mut t2
    )
    .is_err());
}

#[test]
fn texture_is_silent_at_rest_and_scales_with_amplitude() {
    let tex = Texture {
        kvec: vec![[500.0, 0.0], [0.0, 800.0]],
        amplitude: vec![1e-5, 2e-6],
        phase: vec![0.1, 0.2],
    };
    let k = TextureResponse {
        vibration: ContactVibration {
            cover_contact_length: 0.25e-3,
            contact_resonance: 90.0,
            contact_damping: 0.35,
            acc_bandwidth: 125.0,
        },
        coupling: TextureCoupling {
            coupling_modulus: 1e5,
            coupling_pressure: 150.0,
            tangential_coupling: 1.2,
            lateral_coupling: 0.35,
        },
        top_modulus: 1e6,
        mu_kinetic: 0.5,
    };
    let u = [[0.001, 0.002], [0.003, -0.001]];
    let w = [[0.0, 0.0], [0.01, 0.0]];
    let a = acceleration(&tex, &k, &u, &w, &[500.0, 500.0]);
    assert_eq!(a[0], [0.0; 3]);
    assert!(a[1][2] != 0.0);
    let tex2 = Texture {
        amplitude: vec![2e-5, 4e-6],
        ..tex
    };
    let b = acceleration(&tex2, &k, &u, &w, &[500.0, 500.0]);
    for j in 0..3 {
        assert!((b[1][j] - 2.0 * a[1][j]).abs() <= 1e-12 * b[1][j].abs().max(1e-300));
    }
}

/// The patch's force sensors (gain 0.5, offset 1, a little noise, 0.8 ms latency).
fn patch_sensors(key: [u64; 2], n: usize) -> Sensors {
    Sensors::new(
        key,
        vec![[0.5; 3]; n],
        vec![[1.0; 3]; n],
        1e-3,
        800_000,
        6e-4,
    )
    .unwrap()
}

/// Ticks until the phase ends, past every flush (whose packets these tests do not make).
fn ticks_to_the_end(
    m: &Mechanics,
    sensors: &Sensors,
    ctl: &ForceControl,
    st: &mut MechState,
    q: &mut LeanQueue,
    run: &mut TickRun,
) -> Status {
    loop {
        run.samples = 0;
        let (status, _) = run_ticks(m, sensors, ctl, st, q, run);
        if status != Status::Flush {
            return status;
        }
    }
}

/// A skin calibration of gain 0.5 and offset 1, every cell reading 0 N.
fn lean_queue(n: usize) -> LeanQueue {
    LeanQueue {
        latest: vec![[0.0; 3]; n],
        cal_gain: vec![[0.5; 3]; n],
        cal_offset: vec![[1.0; 3]; n],
        ..Default::default()
    }
}

#[test]
fn force_loop_settles_on_the_target() {
    let m = mechanics(vec![0.3], vec![0.2]);
    let n = m.cells.len();
    let sensors = patch_sensors([1, 2], n);
    let mut st = rest_state(&m);
    // Start just touching the face.
    let segs = vec![Segment {
        t0: 0,
        p0: [0.55, 0.0, 0.02],
        v0: [0.0; 3],
        a: [0.0; 3],
    }];
    let mut q = lean_queue(n);
    let ctl = ForceControl {
        target: 0.2,
        gain: 0.02,
        max_vz: 0.005,
        contact_z: 0.02,
        max_depth: 0.005,
        tick_ns: 8_000_000,
        wrench_limit: 5.0,
    };
    let mut run = TickRun {
        phase: Phase::Settle {
            t_limit_ns: 3_000_000_000,
            settled: 0,
        },
        segs,
        chunk: Chunk::default(),
        samples: 0,
    };
    let mut status = Status::Flush;
    while status == Status::Flush {
        run.samples = 0;
        (status, _) = run_ticks(&m, &sensors, &ctl, &mut st, &mut q, &mut run);
    }
    let chunk = run.chunk;
    assert_eq!(status, Status::Done);
    assert!((q.reading() - 0.2).abs() < 0.02, "{}", q.reading());
    // Every sample is in the chunk exactly once.
    let per_cell: Vec<usize> = (0..n)
        .map(|c| chunk.cells.iter().filter(|&&x| x == c as i64).count())
        .collect();
    for c in 0..n {
        assert_eq!(per_cell[c] as i64, st.next_k[c]);
    }
}

#[test]
fn guarded_move_stops_at_the_first_tick_over_the_threshold() {
    let m = mechanics(vec![0.3], vec![0.2]);
    let n = m.cells.len();
    let sensors = patch_sensors([3, 4], n);
    let ctl = ForceControl {
        target: 0.0,
        gain: 0.0,
        max_vz: 0.0,
        contact_z: 0.0,
        max_depth: 0.0,
        tick_ns: 8_000_000,
        wrench_limit: 5.0,
    };
    // Down at 5 mm/s from 1 mm above the face.
    let plan = vec![Segment {
        t0: 0,
        p0: [0.55, 0.0, 0.021],
        v0: [0.0, 0.0, -0.005],
        a: [0.0; 3],
    }];
    let run = |threshold: f64, t_end_ns: i64| {
        let mut st = rest_state(&m);
        let mut q = lean_queue(n);
        let mut run = TickRun {
            phase: Phase::Guard {
                t_end_ns,
                threshold,
                window_ns: 250_000_000,
                w_end_ns: i64::MIN,
            },
            segs: plan.clone(),
            chunk: Chunk::default(),
            samples: 0,
        };
        let status = ticks_to_the_end(&m, &sensors, &ctl, &mut st, &mut q, &mut run);
        (status, st.t_ns, q.reading())
    };
    let (status, t, reading) = run(0.05, 2_000_000_000);
    assert_eq!(status, Status::Triggered);
    assert!(reading > 0.05 && t > 200_000_000, "{t} {reading}");
    // Up to one tick earlier the reading stayed below: a guard ending there does not fire.
    let (status_early, t_early, reading_early) = run(0.05, t - 8_000_000);
    assert_eq!((status_early, t_early), (Status::Done, t - 8_000_000));
    assert!(reading_early <= 0.05);
}
