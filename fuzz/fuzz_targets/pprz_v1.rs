//! Fuzz the pprz_v1 decoder: arbitrary bytes in arbitrary chunks.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pprz_transports::AnyTransport;

fuzz_target!(|data: &[u8]| {
    pprz_transports_fuzz::run(AnyTransport::PprzV1(pprz_transports::PprzV1::new(1)), data);
});
