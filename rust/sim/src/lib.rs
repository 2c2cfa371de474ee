//! The simulated world's per-sample loops, in plain Rust (no Python): contact mechanics and
//! relaxation (`mechanics`), the slide's force-control ticks on the skin's reading
//! (`control`), the sensors' noise and readings (`sensors`, on `philox` counter streams
//! bit-identical to numpy's), the exact heat solution (`thermal`), the texture response
//! (`texture`) and, built on them, a whole time step's readings (`readout`). The model is
//! documented in docs/simulation.md; the tests keep a numpy formulation of each loop to compare
//! against.

pub mod control;
pub mod mechanics;
pub mod philox;
pub mod readout;
pub mod sensors;
pub mod slip;
pub mod texture;
pub mod thermal;

/// Errors of the simulation core (bad input only: the loops themselves cannot fail).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SimError {
    #[error("{0}")]
    InvalidInput(String),
}

impl SimError {
    pub fn invalid(msg: &str) -> Self {
        Self::InvalidInput(msg.to_string())
    }
}
