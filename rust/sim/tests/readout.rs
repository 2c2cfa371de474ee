//! Properties of a whole time step's readings (`aptkt_sim::readout`): closed forms at rest, the
//! thermal systems asked for before anything changes, and steps that do not depend on how a
//! motion is cut. The numpy formulation it replaced is compared in tests/sim.

use aptkt_sim::mechanics::{Chunk, Law, MechState, Mechanics, Relaxation, Segment, Shape};
use aptkt_sim::readout::{
    Accelerometers, CellFrames, ContactHeat, Frames, Physics, Proximity, Readout, ThermalSystems,
    Thermometers, TrialState,
};
use aptkt_sim::sensors::Sensors;
use aptkt_sim::slip::{Ringing, SlipCell, SlipParams};
use aptkt_sim::texture::{ContactVibration, Texture, TextureCoupling, TextureResponse};
use aptkt_sim::thermal::System;
use proptest::prelude::*;

mod common;

const N: usize = 3;
const G: f64 = 9.80665;

/// A 3-cell patch on a flat face; `noise` scales every random term; `mu_s` is the static
/// friction (the kinetic one is 0.8: above it, slow slides stick and slip).
fn physics(noise: f64, mu_s: f64) -> Physics {
    let mut sigma = vec![0.0];
    for i in 0..2000 {
        sigma.push(10f64.powf(-4.0 + 10.0 * i as f64 / 1999.0));
    }
    let delta = sigma.iter().map(|s| s / 2e7 + 0.01 * s / 5e4).collect();
    let cells = common::cells([0.0; 3]);
    let shape = Shape {
        centre: [0.55, 0.0],
        rotation: 0.0,
        surface_z: 0.02,
        tilt: [0.0, 0.0],
        crown_radius: 0.0,
        waves: vec![],
        size: [0.2, 0.2],
    };
    let mech = Mechanics::new(
        cells,
        shape,
        Law::new(delta, sigma, 2e7).unwrap(),
        Relaxation {
            weights: vec![0.3],
            times: vec![0.2],
        },
        1e-5,
    )
    .unwrap();
    let sensors = Sensors::new(
        [7, 11],
        vec![[1.0; 3]; N],
        vec![[0.1; 3]; N],
        noise * 1.5e-3,
        1_000_000,
        noise * 2e-4,
    )
    .unwrap();
    let texture = Texture {
        kvec: vec![[500.0, 0.0], [300.0, 400.0]],
        amplitude: vec![2e-6, 1e-6],
        phase: vec![0.3, 1.1],
    };
    let response = TextureResponse {
        vibration: ContactVibration {
            cover_contact_length: 2.5e-4,
            contact_resonance: 90.0,
            contact_damping: 0.3,
            acc_bandwidth: 125.0,
        },
        coupling: TextureCoupling {
            coupling_modulus: 1e6,
            coupling_pressure: 500.0,
            tangential_coupling: 0.5,
            lateral_coupling: 0.3,
        },
        top_modulus: 1e9,
        mu_kinetic: 0.8,
    };
    let slip = SlipParams {
        mu_s,
        mu_k: 0.8,
        tangential_stiffness: 2000.0,
        tangential_mass: 0.002,
        threshold_sd: 0.1,
        rate_hz: 250.0,
        ring: Ringing {
            coupling: 0.5,
            omega: 2.0 * std::f64::consts::PI * 300.0,
            decay: 0.1 * 2.0 * std::f64::consts::PI * 300.0,
            gain: 0.4,
            lag: -1.2,
        },
    };
    let readout = Readout {
        cells: CellFrames {
            centres: (0..N).map(|c| [c as f64 * 0.01, 0.0]).collect(),
            axes: vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; N],
            acc_bias: vec![[0.0; 3]; N],
            cell_ids: vec![1, 2, 3],
        },
        acc: Accelerometers {
            gravity: G,
            acc_noise: noise * 0.004,
            arm_vibration: noise * 0.0025,
            arm_modes: vec![[40.0, 0.1, 1.0, 0.0, 0.0], [85.0, 0.7, 0.0, 0.6, 0.8]],
        },
        temp: Thermometers {
            die_self_heating: 1.5,
            die_temp_noise: noise * 0.05,
            temp_noise: noise * 0.03,
        },
        prox: Proximity {
            prox_dark: 100.0,
            prox_gain: 5000.0,
            prox_distance: 0.01,
            prox_noise: noise * 2.0,
            reflectivity: 0.5,
            table_reflectivity: 0.3,
        },
        heat: ContactHeat {
            contact_pressure_half: 120.0,
            conductance_scale: 1.0,
            contact_steps: 20.0,
            speed_step: 0.002,
        },
    };
    Physics::new(
        mech,
        sensors,
        texture,
        response,
        slip,
        vec![[1, 2], [3, 4], [5, 6]],
        readout,
    )
    .unwrap()
}

/// Two nodes decaying at rates that depend on the configuration, about (30, 31) °C.
fn system(key: (i64, i64)) -> System {
    let slow = 0.1 + 0.05 * key.0 as f64 + 0.01 * key.1 as f64;
    System {
        u: vec![1.0, 0.0, 0.0, 1.0],
        mu: vec![slow, 3.0 * slow],
        t_ss: vec![30.0 - 0.1 * key.0 as f64, 31.0],
    }
}

fn rest(p: &Physics, t_ns: i64, x: f64) -> TrialState {
    TrialState {
        mech: MechState {
            t_ns,
            next_k: vec![0; N],
            relax_h: vec![0.0; N * 3],
            relax_last: vec![0.0; N * 3],
            latest_force: vec![0.0; N],
        },
        thermal: vec![32.0; N * 2],
        thermal_t: vec![0.0; N],
        last_xy: p
            .readout
            .cells
            .centres
            .iter()
            .map(|c| [x + c[0], c[1]])
            .collect(),
        slip: vec![
            SlipCell {
                load: 0.0,
                threshold: f64::INFINITY,
                events: 0,
                ring: vec![],
            };
            N
        ],
    }
}

/// Down into the face, hold, a slow slide (sticking) then a fast one, and up.
fn motion(slow: f64) -> Vec<Segment> {
    let seg = |t0: i64, p0: [f64; 3], v0: [f64; 3]| Segment {
        t0,
        p0,
        v0,
        a: [0.0; 3],
    };
    vec![
        seg(0, [0.5, 0.0, 0.021], [0.0, 0.0, -0.004]),
        seg(500_000_000, [0.5, 0.0, 0.019], [0.0; 3]),
        seg(900_000_000, [0.5, 0.0, 0.019], [slow, 0.0, 0.0]),
        seg(
            2_000_000_000,
            [0.5 + 1.1 * slow, 0.0, 0.019],
            [0.05, 0.0, 0.0],
        ),
        seg(
            2_600_000_000,
            [0.53 + 1.1 * slow, 0.0, 0.019],
            [0.0, 0.0, 0.01],
        ),
    ]
}

/// Run `segs` to each of `ends`, fetching thermal systems as they are met.
fn run(
    p: &Physics,
    th: &mut ThermalSystems,
    st: &mut TrialState,
    segs: &[Segment],
    ends: &[i64],
) -> Vec<Frames> {
    let mut out = Vec::new();
    for &t in ends {
        let mut chunk = Chunk::default();
        p.mech.step(&mut st.mech, segs, t, &mut chunk);
        let keys = p.thermal_keys(&chunk);
        for key in th.missing(&keys) {
            th.insert(key, system(key)).unwrap();
        }
        let (frames, trace) = p.finish(th, st, &chunk, &keys, true).unwrap();
        assert_eq!(trace.cells, chunk.cells);
        assert!(frames.t_ns.windows(2).all(|w| w[0] <= w[1]));
        out.push(frames);
    }
    out
}

/// Every sample's (cell, sample time) and readings, sorted.
fn samples(frames: &[Frames]) -> Vec<(i64, i64, Vec<f64>)> {
    let mut v: Vec<_> = frames
        .iter()
        .flat_map(|f| {
            (0..f.len()).map(move |i| {
                let mut x = vec![f.proximity[i], f.force_true[i]];
                x.extend(f.acc[i]);
                x.extend(f.temp[i]);
                x.extend(f.force[i]);
                (f.cell_index[i], f.t_sample_ns[i], x)
            })
        })
        .collect();
    v.sort_by_key(|a| (a.0, a.1));
    v
}

#[test]
fn at_rest_in_the_air_the_readings_are_the_closed_forms() {
    let p = physics(0.0, 1.2);
    let mut th = ThermalSystems::new(vec![1.0, 1.0]).unwrap();
    let mut st = rest(&p, 0, 0.5);
    let still = [Segment {
        t0: 0,
        p0: [0.5, 0.0, 0.03],
        v0: [0.0; 3],
        a: [0.0; 3],
    }];
    let frames = run(&p, &mut th, &mut st, &still, &[100_000_000]).remove(0);
    assert!(frames.len() >= 3 * 24);
    for i in 0..frames.len() {
        // Specific force of a skin at rest: +1 g along its z axis.
        assert_eq!(frames.acc[i], [0.0, 0.0, 1.0]);
        assert_eq!(frames.force[i], [0.1; 3]);
        assert_eq!(frames.force_true[i], 0.0);
        // 10 mm above a face of reflectivity 0.5.
        let gap: f64 = 0.03 - 0.02;
        let want = 100.0 + 5000.0 * 0.5 / (1.0 + (gap / 0.01).powi(2));
        assert!((frames.proximity[i] - want).abs() < 1e-9);
        // Out of contact: configuration (0, 0) about (30, 31) °C, from 32 °C.
        let t = frames.t_sample_ns[i] as f64 * 1e-9;
        let lm71 = 30.0 + 2.0 * (-0.1 * t).exp();
        assert!((frames.temp[i][1] - lm71).abs() < 1e-9, "{t}");
        assert!((frames.temp[i][0] - (31.0 + 1.0 * (-0.3 * t).exp() + 1.5)).abs() < 1e-9);
    }
}

#[test]
fn a_missing_thermal_system_is_reported_before_anything_changes() {
    let p = physics(1.0, 1.2);
    let th = ThermalSystems::new(vec![1.0, 1.0]).unwrap();
    let mut st = rest(&p, 0, 0.5);
    let mut chunk = Chunk::default();
    p.mech
        .step(&mut st.mech, &motion(0.002), 700_000_000, &mut chunk);
    let keys = p.thermal_keys(&chunk);
    let missing = th.missing(&keys);
    assert!(missing.len() >= 2 && missing.contains(&(0, 0)));
    let before = st.clone();
    assert!(p.finish(&th, &mut st, &chunk, &keys, true).is_err());
    assert_eq!(st, before);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]
    #[test]
    fn readings_do_not_depend_on_how_the_motion_is_cut(
        cuts in proptest::collection::vec(1i64..3_000_000_000, 0..5),
        slow in 0.0005f64..0.004,
    ) {
        // Without stick-slip: where a slip falls depends on where a stretch of samples starts
        // (the slip search runs over the stretch, as the numpy formulation did).
        let p = physics(1.0, 0.8);
        let segs = motion(slow);
        let mut th = ThermalSystems::new(vec![1.0, 1.0]).unwrap();
        let mut whole = rest(&p, 0, 0.5);
        let a = run(&p, &mut th, &mut whole, &segs, &[3_000_000_000]);
        let mut parts = rest(&p, 0, 0.5);
        let mut ends = cuts.clone();
        ends.sort();
        ends.push(3_000_000_000);
        let b = run(&p, &mut th, &mut parts, &segs, &ends);
        let (a, b) = (samples(&a), samples(&b));
        prop_assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            prop_assert_eq!((x.0, x.1), (y.0, y.1));
            for (u, v) in x.2.iter().zip(&y.2) {
                prop_assert!((u - v).abs() <= 1e-9 * (1.0 + u.abs()), "{:?} vs {:?}", x, y);
            }
        }
        prop_assert_eq!(&whole.mech, &parts.mech);
        prop_assert_eq!(&whole.last_xy, &parts.last_xy);
        for (u, v) in whole.thermal.iter().zip(&parts.thermal) {
            prop_assert!((u - v).abs() <= 1e-9);
        }
        prop_assert_eq!(&whole.slip, &parts.slip);
    }
}
