//! What the core's tests share: a patch of three cells in a row.

use aptkt_sim::mechanics::Cells;

/// Three cells 1 cm apart, each with its own clock, the force sensors at `sensor_height`.
pub fn cells(sensor_height: [f64; 3]) -> Cells {
    Cells {
        clock_rate: vec![250.0, 250.3, 249.8],
        clock_phase: vec![0.0011, 0.0023, 0.0007],
        sensor_height: vec![sensor_height; 3],
        sensor_xy: (0..3)
            .map(|c| {
                let x = c as f64 * 0.01;
                [[x, 0.002], [x - 0.002, -0.001], [x + 0.002, -0.001]]
            })
            .collect(),
    }
}
