//! Fuzz the fleet gateway's logic with the full PPRZLINK reference message set: two
//! links (each with its own transport) fed arbitrary bytes in interleaved chunks,
//! merged and decoded by the fleet's monitor; and the rest of the input as the JSON of
//! a command, parsed against every datalink message.
//!
//! Input layout: byte 0 selects the two links' transports, byte 1 seeds the chunk
//! sizes, byte 2 the split between the stream and the command text; then the bytes.
//!
//! Checked: no panic; every delivered line is free of control characters; the gateway
//! never delivers more messages than its links decoded; what it remembers stays within
//! its bound; a command the parser accepts encodes to a payload whose JSON form parses
//! back to a payload that is a fixed point of the round trip.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pprz_ground::gateway::{Gateway, GatewayLink};
use pprz_ground::json;

const CAPACITY: usize = 64;

fuzz_target!(|data: &[u8]| {
    let set = pprz_transports_fuzz::reference_set("gateway");
    let (selector, seed, split, rest) = match data {
        [a, b, c, rest @ ..] => (*a, *b, *c, rest),
        _ => return,
    };
    let at = rest.len() * usize::from(split) / 256;
    let (stream, command) = rest.split_at(at);
    let links = vec![
        GatewayLink::new("a", set, pprz_transports_fuzz::transport(selector), true),
        GatewayLink::new(
            "b",
            set,
            pprz_transports_fuzz::transport(selector / 5),
            true,
        ),
    ];
    let mut gw = Gateway::new(set, links).with_window(0.05, CAPACITY);
    let mut rng = pprz_test_support::rng::Rng::new(u64::from(seed));
    let mut delivered = 0u64;
    let mut now = 0.0;
    let mut left = stream;
    while !left.is_empty() {
        let r = (rng.next_u64() >> 32) as u32;
        let (chunk, tail) = left.split_at((1 + r as usize % 64).min(left.len()));
        left = tail;
        now += f64::from(r >> 26) * 0.001;
        gw.feed((r >> 8) as usize % 2, now, chunk, |d| {
            delivered += 1;
            assert!(
                !d.message.line.chars().any(char::is_control),
                "{:?}",
                d.message.line
            );
        });
        if r % 7 == 0 {
            gw.tick(now);
        }
        assert!(gw.dedup().len() <= CAPACITY);
    }
    let decoded: u64 = gw
        .links()
        .iter()
        .map(|l| u64::from(l.monitor().decoder_stats().frames))
        .sum();
    assert!(
        delivered <= decoded,
        "{delivered} delivered of {decoded} decoded"
    );
    let Ok(text) = std::str::from_utf8(command) else {
        return;
    };
    for desc in set
        .set()
        .messages()
        .iter()
        .filter(|d| d.class_name == "datalink")
    {
        // A payload from JSON shows as JSON that parses back to a payload whose JSON
        // parses back to it (one step may normalise text: trailing NULs).
        if let Ok(first) = json::parse_message_str(desc, text) {
            let shown = json::message(desc, &first).expect("a parsed payload decodes");
            let second = json::parse_message_str(desc, &shown).expect("its JSON parses back");
            let again = json::message(desc, &second).expect("a parsed payload decodes");
            assert_eq!(
                json::parse_message_str(desc, &again).as_ref(),
                Ok(&second),
                "{again}"
            );
        }
    }
});
