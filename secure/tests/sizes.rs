//! RAM of the secure layer's state (what a firmware keeps in statics or task stacks).
//! Printed with `--nocapture`; the bounds keep them from growing unnoticed.

use pprz_secure::{Initiator, KeyExchange, Responder, SecureChannel};

#[test]
fn state_sizes() {
    let sizes = [
        ("SecureChannel", size_of::<SecureChannel>(), 256),
        ("KeyExchange", size_of::<KeyExchange>(), 128),
        // salty's key pair keeps the expanded key and the decompressed public points.
        ("Responder", size_of::<Responder>(), 1600),
        ("Initiator", size_of::<Initiator>(), 1600),
    ];
    for (name, size, bound) in sizes {
        println!("{name}: {size} bytes");
        assert!(size <= bound, "{name}: {size} > {bound}");
    }
}
