//! The `aptkt._core` extension: a thin layer over the pure-Rust crates. It converts numpy
//! arrays to and from Rust types, releases the GIL around numerical work and maps core errors
//! to typed Python exceptions. No numerics live here.

use pyo3::prelude::*;

mod errors;
mod features;
mod gp;
mod sim;
mod skin;

/// glibc raises its mmap threshold each time a large mmapped block is freed, after which the
/// GP's many same-sized n × n temporaries come from the heap arenas and are kept there: at
/// n = 1,000 a fit's peak resident memory doubled (420 MB against 205 MB). A fixed threshold
/// (glibc's initial 128 KiB) returns every large block to the system when it is freed.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn fix_mmap_threshold() {
    extern "C" {
        fn mallopt(param: i32, value: i32) -> i32;
    }
    const M_MMAP_THRESHOLD: i32 = -3;
    // SAFETY: mallopt only changes an allocator setting; it is safe to call at any time.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 128 * 1024);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn fix_mmap_threshold() {}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    fix_mmap_threshold();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    features::register(m)?;
    gp::register(m)?;
    sim::register(m)?;
    skin::register(m)?;
    Ok(())
}
