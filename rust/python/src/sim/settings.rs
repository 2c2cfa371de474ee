//! The frozen settings objects one trial's physics is built from. Each holds one core struct
//! (`aptkt_sim`), is built in Python by keyword or position from plain numbers and lists, and
//! is checked where the core checks it (when `SimContact` is built).

use aptkt_sim::mechanics::{Law, Relaxation};
use aptkt_sim::sensors::Sensors;
use aptkt_sim::{control, mechanics, readout, slip, texture};
use pyo3::prelude::*;

use crate::errors::Result;
use crate::settings::settings_class;

settings_class! {
    /// The patch's cells as the mechanics sees them: sample clocks (Hz, s), the force sensors'
    /// heights (C, 3) and positions relative to the TCP (C, 3, 2).
    PatchCells(mechanics::Cells) {
        clock_rate: Vec<f64>,
        clock_phase: Vec<f64>,
        sensor_height: Vec<[f64; 3]>,
        sensor_xy: Vec<[[f64; 2]; 3]>,
    }
}

settings_class! {
    /// The object's top face in the base frame: centre, rotation, height, tilt, crown radius,
    /// waviness waves (k_x, k_y, amplitude, phase) and size.
    SurfaceShape(mechanics::Shape) {
        centre: [f64; 2],
        rotation: f64,
        surface_z: f64,
        tilt: [f64; 2],
        crown_radius: f64,
        waves: Vec<[f64; 4]>,
        size: [f64; 2],
    }
}

settings_class! {
    /// The surface's plane waves (object frame): wave vectors (M, 2), amplitudes, phases.
    TextureField(texture::Texture) {
        kvec: Vec<[f64; 2]>,
        amplitude: Vec<f64>,
        phase: Vec<f64>,
    }
}

settings_class! {
    /// How a cell vibrates on its contact (see `aptkt_sim::texture::ContactVibration`).
    ContactVibration(texture::ContactVibration) {
        cover_contact_length: f64,
        contact_resonance: f64,
        contact_damping: f64,
        acc_bandwidth: f64,
    }
}

settings_class! {
    /// How strongly the surface drives a cell (see `aptkt_sim::texture::TextureCoupling`).
    TextureCoupling(texture::TextureCoupling) {
        coupling_modulus: f64,
        coupling_pressure: f64,
        tangential_coupling: f64,
        lateral_coupling: f64,
    }
}

settings_class! {
    /// The shear mode a slip rings (see `aptkt_sim::slip::Ringing`).
    Ringing(slip::Ringing) {
        coupling: f64,
        omega: f64,
        decay: f64,
        gain: f64,
        lag: f64,
    }
}

settings_class! {
    /// Where each cell sits (C, 2), its accelerometer's axes (C, 3, 3) and zero-g offsets
    /// (C, 3), and its id.
    CellFrames(readout::CellFrames) {
        centres: Vec<[f64; 2]>,
        axes: Vec<[[f64; 3]; 3]>,
        acc_bias: Vec<[f64; 3]>,
        cell_ids: Vec<i64>,
    }
}

settings_class! {
    /// The accelerometers: gravity, their noise, the arm's own vibration and its modes
    /// (Hz, phase, dx, dy, dz).
    Accelerometers(readout::Accelerometers) {
        gravity: f64,
        acc_noise: f64,
        arm_vibration: f64,
        arm_modes: Vec<[f64; 5]>,
    }
}

settings_class! {
    /// The temperature sensors: the accelerometer die's self-heating and noise, the LM71's noise.
    Thermometers(readout::Thermometers) {
        die_self_heating: f64,
        die_temp_noise: f64,
        temp_noise: f64,
    }
}

settings_class! {
    /// The proximity sensor and the reflectivity of the object and of the table.
    Proximity(readout::Proximity) {
        prox_dark: f64,
        prox_gain: f64,
        prox_distance: f64,
        prox_noise: f64,
        reflectivity: f64,
        table_reflectivity: f64,
    }
}

settings_class! {
    /// The heat exchange's contact fraction and the quantisation of the thermal configurations.
    ContactHeat(readout::ContactHeat) {
        contact_pressure_half: f64,
        conductance_scale: f64,
        contact_steps: f64,
        speed_step: f64,
    }
}

settings_class! {
    /// The admittance law of the force loop and the limits the robot enforces in it: target
    /// (N), gain (m/s per N), |v_z| limit, contact height and depth limit (m), tick (ns), wrench
    /// limit (N).
    ForceControl(control::ForceControl) {
        target: f64,
        gain: f64,
        max_vz: f64,
        contact_z: f64,
        max_depth: f64,
        tick_ns: i64,
        wrench_limit: f64,
    }
}

/// The skin's texture response on one object: its vibration and coupling, and the object's
/// top modulus (Pa) and kinetic friction.
#[pyclass(module = "aptkt._core", frozen)]
pub struct TextureResponse(pub texture::TextureResponse);

#[pymethods]
impl TextureResponse {
    #[new]
    fn new(
        vibration: PyRef<'_, ContactVibration>,
        coupling: PyRef<'_, TextureCoupling>,
        top_modulus: f64,
        mu_kinetic: f64,
    ) -> Self {
        Self(texture::TextureResponse {
            vibration: vibration.0,
            coupling: coupling.0,
            top_modulus,
            mu_kinetic,
        })
    }

    fn __repr__(&self) -> String {
        format!("{:?}", self.0)
    }
}

/// The spring-block of each cell's stick-slip (see `aptkt_sim::slip::SlipParams`).
#[pyclass(module = "aptkt._core", frozen)]
pub struct SlipParams(pub slip::SlipParams);

#[pymethods]
impl SlipParams {
    #[new]
    fn new(
        mu_s: f64,
        mu_k: f64,
        tangential_stiffness: f64,
        tangential_mass: f64,
        threshold_sd: f64,
        rate_hz: f64,
        ring: PyRef<'_, Ringing>,
    ) -> Self {
        Self(slip::SlipParams {
            mu_s,
            mu_k,
            tangential_stiffness,
            tangential_mass,
            threshold_sd,
            rate_hz,
            ring: ring.0,
        })
    }

    fn __repr__(&self) -> String {
        format!("{:?}", self.0)
    }
}

/// What the skin's vibration meets on the object's surface: its texture, the skin's response
/// to it, the stick-slip of the cells and each cell's random stream key for its slips.
#[pyclass(module = "aptkt._core", frozen)]
pub struct Surface {
    pub texture: texture::Texture,
    pub response: texture::TextureResponse,
    pub slip: slip::SlipParams,
    pub slip_keys: Vec<[u64; 2]>,
}

#[pymethods]
impl Surface {
    #[new]
    fn new(
        texture: PyRef<'_, TextureField>,
        response: PyRef<'_, TextureResponse>,
        slip: PyRef<'_, SlipParams>,
        slip_keys: Vec<[u64; 2]>,
    ) -> Self {
        Self {
            texture: texture.0.clone(),
            response: response.0,
            slip: slip.0,
            slip_keys,
        }
    }
}

/// The per-trial constants of the readings, by sensor.
#[pyclass(module = "aptkt._core", frozen)]
pub struct Readout(pub readout::Readout);

#[pymethods]
impl Readout {
    #[new]
    fn new(
        cells: PyRef<'_, CellFrames>,
        acc: PyRef<'_, Accelerometers>,
        temp: PyRef<'_, Thermometers>,
        prox: PyRef<'_, Proximity>,
        heat: PyRef<'_, ContactHeat>,
    ) -> Self {
        Self(readout::Readout {
            cells: cells.0.clone(),
            acc: acc.0.clone(),
            temp: temp.0,
            prox: prox.0,
            heat: heat.0,
        })
    }
}

/// The contact law of the skin on the object: the indentation law's table (δ → σ), the
/// skin's own stiffness (Pa/m), the relaxation's Prony series and each force sensor's area.
#[pyclass(module = "aptkt._core", frozen)]
pub struct ContactLaw {
    pub law: Law,
    pub relaxation: Relaxation,
    pub sensor_area: f64,
}

#[pymethods]
impl ContactLaw {
    #[new]
    fn new(
        delta: Vec<f64>,
        sigma: Vec<f64>,
        skin_stiffness: f64,
        relax_weights: Vec<f64>,
        relax_times: Vec<f64>,
        sensor_area: f64,
    ) -> Result<Self> {
        Ok(Self {
            law: Law::new(delta, sigma, skin_stiffness)?,
            relaxation: Relaxation {
                weights: relax_weights,
                times: relax_times,
            },
            sensor_area,
        })
    }
}

/// What turns a sample's true force into the patch's reading and stamps its arrival: the
/// noise stream's key, per-cell gain and offset (C, 3), force noise, link latency and jitter.
#[pyclass(module = "aptkt._core", frozen)]
pub struct ForceSensors(pub Sensors);

#[pymethods]
impl ForceSensors {
    #[new]
    fn new(
        noise_key: [u64; 2],
        gain: Vec<[f64; 3]>,
        offset: Vec<[f64; 3]>,
        force_noise: f64,
        latency_ns: i64,
        jitter_s: f64,
    ) -> Result<Self> {
        Sensors::new(noise_key, gain, offset, force_noise, latency_ns, jitter_s)
            .map(Self)
            .map_err(Into::into)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PatchCells>()?;
    m.add_class::<SurfaceShape>()?;
    m.add_class::<ContactLaw>()?;
    m.add_class::<ForceSensors>()?;
    m.add_class::<TextureField>()?;
    m.add_class::<ContactVibration>()?;
    m.add_class::<TextureCoupling>()?;
    m.add_class::<TextureResponse>()?;
    m.add_class::<Ringing>()?;
    m.add_class::<SlipParams>()?;
    m.add_class::<Surface>()?;
    m.add_class::<CellFrames>()?;
    m.add_class::<Accelerometers>()?;
    m.add_class::<Thermometers>()?;
    m.add_class::<Proximity>()?;
    m.add_class::<ContactHeat>()?;
    m.add_class::<Readout>()?;
    m.add_class::<ForceControl>()
}
