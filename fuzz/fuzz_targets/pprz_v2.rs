//! Fuzz the pprz_v2 decoder: arbitrary bytes in arbitrary chunks.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pprz_transports::AnyTransport;

fuzz_target!(|data: &[u8]| {
    pprz_transports_fuzz::run(AnyTransport::PprzV2(pprz_transports::PprzV2::new()), data);
});
