//! Fuzz the pprzlog decoder: arbitrary bytes in arbitrary chunks.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pprz_transports::AnyTransport;

fuzz_target!(|data: &[u8]| {
    pprz_transports_fuzz::run(
        AnyTransport::PprzLog(pprz_transports::PprzLog::TELEMETRY),
        data,
    );
});
