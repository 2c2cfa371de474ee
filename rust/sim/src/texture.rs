//! Texture-driven acceleration of sliding cells (`aptkt.sim.texture.texture_acceleration`,
//! docs/simulation.md "Vibration"): every plane wave of the surface height seen at its
//! temporal frequency, through the cover's smoothing, the cell's transmissibility on its
//! contact stiffness and the accelerometer's low-pass.

use std::f64::consts::PI;

/// The surface's plane waves (object frame).
#[derive(Clone, Debug)]
pub struct Texture {
    /// (M, 2) cycles per metre
    pub kvec: Vec<[f64; 2]>,
    pub amplitude: Vec<f64>,
    pub phase: Vec<f64>,
}

/// How a cell vibrates on its contact: the cover's smoothing over its contact length (m), the
/// resonance (Hz) and damping ratio of the contact stiffness, the accelerometer's bandwidth (Hz).
#[derive(Clone, Copy, Debug)]
pub struct ContactVibration {
    pub cover_contact_length: f64,
    pub contact_resonance: f64,
    pub contact_damping: f64,
    pub acc_bandwidth: f64,
}

/// How strongly the surface drives the cell: the cover's modulus (Pa) and half-coupling
/// pressure (Pa), and the tangential and lateral shares of the normal excitation.
#[derive(Clone, Copy, Debug)]
pub struct TextureCoupling {
    pub coupling_modulus: f64,
    pub coupling_pressure: f64,
    pub tangential_coupling: f64,
    pub lateral_coupling: f64,
}

/// The skin's texture response on one object: the skin's constants and the object's top
/// modulus (Pa) and kinetic friction.
#[derive(Clone, Copy, Debug)]
pub struct TextureResponse {
    pub vibration: ContactVibration,
    pub coupling: TextureCoupling,
    pub top_modulus: f64,
    pub mu_kinetic: f64,
}

#[inline]
fn cmul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

#[inline]
fn cdiv(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

/// Acceleration (along the motion, lateral, normal-up) in m/s² of cells at object-frame
/// positions `u`, velocities `w` and mean contact pressures `pressure`.
pub fn acceleration(
    tex: &Texture,
    k: &TextureResponse,
    u: &[[f64; 2]],
    w: &[[f64; 2]],
    pressure: &[f64],
) -> Vec<[f64; 3]> {
    let n = u.len();
    let mut out = vec![[0.0; 3]; n];
    if tex.amplitude.is_empty() {
        return out;
    }
    let m = tex.amplitude.len();
    let qnorm: Vec<f64> = tex.kvec.iter().map(|q| q[0].hypot(q[1])).collect();
    let smooth: Vec<f64> = qnorm
        .iter()
        .map(|q| (-((PI * k.vibration.cover_contact_length * q).powi(2))).exp())
        .collect();
    let stiff = (k.top_modulus / (k.top_modulus + k.coupling.coupling_modulus)).sqrt();
    // The response of each wave depends on the velocity only: kept while it does not change
    // (a cell sliding at constant speed), recomputed when it does.
    let mut resp = vec![(0.0, 0.0, 0.0, 0.0); m]; // (base/A-free gain, phase lag, tangential, 1)
    let mut last_w = [f64::NAN, f64::NAN];
    for i in 0..n {
        let speed = w[i][0].hypot(w[i][1]);
        let p = pressure[i];
        if !(speed > 1e-6 && p > 0.0) {
            continue;
        }
        if w[i] != last_w {
            last_w = w[i];
            for j in 0..m {
                let kv = tex.kvec[j];
                let f = (w[i][0] * kv[0] + w[i][1] * kv[1]).abs();
                let r = f / k.vibration.contact_resonance;
                let two_zr = 2.0 * k.vibration.contact_damping * r;
                let h_t = cdiv((1.0, two_zr), (1.0 - r * r, two_zr));
                let h_l = cdiv((1.0, 0.0), (1.0, f / k.vibration.acc_bandwidth));
                let h = cmul(h_t, h_l);
                let base =
                    -(tex.amplitude[j] * smooth[j]) * (2.0 * PI * f).powi(2) * h.0.hypot(h.1);
                let cross = (w[i][0] * kv[1] - w[i][1] * kv[0]) / (speed * qnorm[j].max(1e-12));
                resp[j] = (
                    base,
                    h.1.atan2(h.0),
                    k.coupling.tangential_coupling * k.mu_kinetic / (1.0 + r * r),
                    k.coupling.lateral_coupling * cross,
                );
            }
        }
        let coupling = stiff * p / (p + k.coupling.coupling_pressure);
        let (mut tang, mut lat, mut norm) = (0.0, 0.0, 0.0);
        for j in 0..m {
            let kv = tex.kvec[j];
            let (base, lag, t_gain, l_gain) = resp[j];
            let phase = 2.0 * PI * (u[i][0] * kv[0] + u[i][1] * kv[1]) + tex.phase[j];
            let (sa, ca) = (phase + lag).sin_cos();
            let normal = base * sa;
            tang += t_gain * normal;
            lat += l_gain * base * ca;
            norm += normal;
        }
        out[i] = [coupling * tang, coupling * lat, coupling * norm];
    }
    out
}
