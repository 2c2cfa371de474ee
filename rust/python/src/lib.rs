//! The `aptkt._core` extension over the pure-Rust crates. It defines the typed classes Python
//! builds and reads (settings built by keyword, state the core advances in place), converts
//! numpy arrays to and from Rust types, releases the GIL around numerical work and maps core
//! errors to typed Python exceptions. No numerics live here.

use pyo3::prelude::*;

mod errors;
mod features;
mod gp;
mod settings;
mod sim;
mod skin;

/// glibc raises its mmap threshold each time a large mmapped block is freed, after which the
/// GP's many same-sized n × n temporaries come from the heap arenas and are kept there: at
/// n = 1,000 a fit's peak resident memory doubled (420 MB against 205 MB). A fixed threshold
/// returns every large block to the system when it is freed. It is fixed at 4 MiB (n × n
/// doubles up to n ≈ 720), not at glibc's initial 128 KiB: below it, mapping a block afresh
/// for every temporary costs a page fault per 4 KiB, and at the n ≈ 200–450 of the learning
/// loop's transferring fits that was a tenth of their CPU time (system time), for memory the
/// heap keeps anyway. The trim threshold (fixed along with it) is glibc's own rule, twice the
/// mmap threshold, so that a block freed at the heap's top is not returned and faulted in again.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn fix_mmap_threshold() {
    extern "C" {
        fn mallopt(param: i32, value: i32) -> i32;
    }
    const M_TRIM_THRESHOLD: i32 = -1;
    const M_MMAP_THRESHOLD: i32 = -3;
    const MMAP_THRESHOLD: i32 = 4 << 20; // 4 MiB
                                         // SAFETY: mallopt only changes allocator settings; it is safe to call at any time.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD);
        mallopt(M_TRIM_THRESHOLD, 2 * MMAP_THRESHOLD);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn fix_mmap_threshold() {}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    fix_mmap_threshold();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    features::register(m)?;
    gp::register(m)?;
    sim::register(m)?;
    skin::register(m)?;
    Ok(())
}
