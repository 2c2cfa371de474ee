//! Any bytes, any chunking: the streaming parser agrees with the naive reference parser,
//! keeps its byte accounting and its ≤ 19-byte carry, and never panics.
//! Run: `cd rust/skin/fuzz && cargo +nightly fuzz run parse_stream`
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    aptkt_skin::testing::fuzz_check(data);
});
