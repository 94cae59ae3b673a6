//! Fuzz the xbee24 decoder: arbitrary bytes in arbitrary chunks.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pprz_transports::AnyTransport;

fuzz_target!(|data: &[u8]| {
    pprz_transports_fuzz::run(AnyTransport::XBee24(pprz_transports::XBee24::new()), data);
});
