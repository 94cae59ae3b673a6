//! `--zenoh`: the monitor as a client of a `pprz-gateway` on the fleet bus.

use pprz_ground::bus::{Bus, BusConfig, keys};
use pprz_ground::device::{Command, CommandUplink, Source, Uplink};
use pprz_ground::escape;
use pprz_ground::input::{DEFAULT_CAPACITY, InputQueue, Overflow};
use pprz_ground::set::RuntimeSet;
use zenoh::Wait;
use zenoh::pubsub::Subscriber;

/// Opens a client session to the gateway at `endpoint` (e.g. `tcp/127.0.0.1:7447`).
/// The input is every frame the gateway delivers (`pprz/*/frame`, PPRZ v2), each
/// pushed by the subscriber into a queue bounded as a live link's is (the oldest
/// dropped and counted when it is full). The uplink turns the frames of `set`'s
/// datalink messages into commands on `pprz/<ac_id>/uplink/<MESSAGE>`; it holds the
/// session and the subscriber, which live as long as it does.
///
/// # Errors
/// A message naming the endpoint: Zenoh refused it, or nothing answers there (the
/// session does not wait for a gateway to come up).
pub fn open(endpoint: &str, set: RuntimeSet) -> Result<(Source, Uplink), String> {
    let bus = Bus::open(&BusConfig::client(endpoint)).map_err(|e| {
        // Zenoh's messages end with the place in its source: not for the user.
        let why = e.split("  at ").next().unwrap_or_default();
        format!(
            "cannot reach the gateway at {} (is pprz-gateway listening there?): {}",
            escape::token(endpoint),
            escape::lines(why)
        )
    })?;
    let queue = InputQueue::new(DEFAULT_CAPACITY, Overflow::DropOldest);
    let q = queue.clone();
    let frames = bus
        .session()
        .declare_subscriber(keys::FRAMES_ALL)
        .callback(move |sample| {
            q.push(&sample.payload().to_bytes());
        })
        .wait()
        .map_err(|e| format!("zenoh: cannot subscribe to {}: {e}", keys::FRAMES_ALL))?;
    let mut session = Session {
        bus,
        _frames: frames,
    };
    let sink = move |c: Command| session.put(c);
    let uplink = CommandUplink::new(set, Box::new(sink));
    Ok((Source::Queue(queue), Uplink::Commands(Box::new(uplink))))
}

/// The session with the gateway, and the subscriber that feeds the input.
struct Session {
    bus: Bus,
    _frames: Subscriber<()>,
}

impl Session {
    /// Puts a command on `pprz/<ac_id>/uplink/<MESSAGE>`.
    fn put(&mut self, c: Command) -> std::io::Result<()> {
        let key = keys::uplink(c.ac_id, c.message);
        let refused = self.bus.put_errors();
        self.bus.put(&key, c.fields, None);
        if self.bus.put_errors() > refused {
            return Err(std::io::Error::other(format!(
                "zenoh refused the put on {key}"
            )));
        }
        Ok(())
    }
}
