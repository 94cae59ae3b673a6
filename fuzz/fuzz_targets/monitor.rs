//! Fuzz the monitor's generic run-time decoder with the full PPRZLINK reference message
//! set: arbitrary bytes through every transport, and through the formatting and
//! printing paths (lines, live view, summary), with PINGs, SETTINGs, input gaps and
//! timeouts interleaved.
//!
//! Input layout: byte 0 selects the transport (mod 5), byte 1 seeds the chunk sizes and
//! the operations between chunks; the rest is the received byte stream.
//!
//! Checked: no panic; no line printed contains a control character or an invisible
//! formatting character (the text comes from the "aircraft"); the state stays bounded.
//!
//! The reference `messages.xml` is not in the repository (license): it is loaded once
//! from `$PPRZLINK_DIR/messages.xml`, else from `shared/pprzlink` next to the workspace
//! (`pprz_test_support::reference::dir`, which resolves it from the workspace's own
//! location, not from the current directory). The harness panics at start-up, naming
//! the path, when it is missing.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pprz_ground::escape;
use pprz_ground::format::MAX_FIELDS_LEN;
use pprz_ground::input::Drops;
use pprz_ground::monitor::{Decoded, Monitor, MAX_EVENTS};
use pprz_ground::ping::PingTracker;
use pprz_ground::settings::SettingTracker;

fn assert_clean(line: &str) {
    if let Some(c) = line
        .chars()
        .find(|&c| c.is_control() || escape::is_unsafe(c))
    {
        panic!("printed a control character {c:?}: {line:?}");
    }
}

fuzz_target!(|data: &[u8]| {
    let set = pprz_transports_fuzz::reference_set("monitor");
    let (selector, seed, stream) = match data {
        [a, b, rest @ ..] => (*a, *b, rest),
        _ => return,
    };
    let mut monitor = Monitor::new(set, pprz_transports_fuzz::transport(selector))
        .with_trackers(PingTracker::new(4, 0.05), SettingTracker::new(0.05));
    // Chunk sizes, times and operations from the workspace's seeded generator.
    let mut rng = pprz_test_support::rng::Rng::new(u64::from(seed));
    let mut next = move || (rng.next_u64() >> 32) as u32;
    let on_line = |d: &Decoded<'_>| {
        assert_clean(d.line);
        assert!(!d.raw.is_empty());
    };
    let mut now = 0.0;
    let mut rest = stream;
    while !rest.is_empty() {
        let r = next();
        let size = if seed == 0 {
            rest.len()
        } else {
            1 + r as usize % 300
        };
        let (chunk, tail) = rest.split_at(size.min(rest.len()));
        rest = tail;
        now += f64::from(r >> 24) * 0.001;
        monitor.feed(now, chunk, on_line);
        // Operations between chunks, drawn from the bytes just fed.
        let op = chunk[0];
        match (r >> 9) % 16 {
            0 => monitor.ping_sent(None, now),
            1 => monitor.setting_sent(None, now, op, f64::from(chunk[chunk.len() - 1]) * 0.25),
            2 => monitor.get_setting_sent(None, now, op),
            3 => monitor.input_gap(
                now,
                Drops {
                    bytes: u64::from(op),
                    reads: 1,
                },
                on_line,
            ),
            4 => monitor.tick(now),
            5 => {
                for line in monitor.render(now).lines() {
                    assert_clean(line);
                }
            }
            _ => {}
        }
    }
    monitor.flush(now, on_line);
    for line in monitor
        .render(now)
        .lines()
        .chain(monitor.summary(now).lines())
    {
        assert_clean(line);
    }
    assert!(monitor.messages().len() <= set.set().len());
    assert!(monitor.events().count() <= MAX_EVENTS);
    assert!(monitor.notices().count() <= MAX_EVENTS);
    assert!(monitor
        .messages()
        .values()
        .all(|m| m.last.len() <= MAX_FIELDS_LEN));
});
