//! RAM of the secure layer's state (what a firmware puts in statics or task stacks).

use pprz_secure::{Initiator, KeyExchange, Responder, SecureChannel};

#[test]
fn state_sizes() {
    let sizes = [
        ("SecureChannel", size_of::<SecureChannel>()),
        ("Responder", size_of::<Responder>()),
        ("Initiator", size_of::<Initiator>()),
        ("KeyExchange", size_of::<KeyExchange>()),
    ];
    for (name, size) in sizes {
        println!("{name}: {size} bytes");
    }
}
