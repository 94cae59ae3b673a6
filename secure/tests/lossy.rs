//! The initiator and the responder over a simulated lossy link: lost, duplicated and
//! reordered handshake messages, random loss both ways, a restarted ground and a
//! rebooted aircraft. The ground polls every 100 ms; the aircraft sends ALIVE every
//! 100 ms once it has a session (nothing before: the channel refuses it) and answers
//! PING with PONG.

mod common;

use common::*;
use pprz_secure::{InitiatorState, Protection, ResponderState, SealError};

/// What the link does with the n-th frame of a direction.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fate {
    Deliver,
    Lose,
    Duplicate,
    /// Held back and delivered after the next frame of the same direction.
    Delay,
}

/// Decides the fate of the n-th frame of a direction.
type LinkModel = Box<dyn FnMut(usize, &[u8]) -> Fate>;

struct Sim {
    air: Aircraft,
    ground: Ground,
    now: u64,
    rng: TestRng,
    /// Fates of the uplink and downlink frames, by index (default: deliver).
    up: LinkModel,
    down: LinkModel,
    up_count: usize,
    down_count: usize,
    up_held: Vec<Vec<u8>>,
    down_held: Vec<Vec<u8>>,
    /// Plain frames delivered to the aircraft's application and the ground's.
    air_app: Vec<Vec<u8>>,
    ground_app: Vec<Vec<u8>>,
    /// Last counter seen on the wire per direction (must increase strictly).
    last_up: u32,
    last_down: u32,
}

fn is_kx(wire: &[u8], msg_type: u8) -> bool {
    // AA src dst cc id ...: KEY_EXCHANGE_GCS has ac_id first, KEY_EXCHANGE_UAV not.
    match wire.get(2..8) {
        Some([0xAA, _, _, 2, 159, _]) => wire.get(8) == Some(&msg_type),
        Some([0xAA, _, _, 1, 239, t]) => *t == msg_type,
        _ => false,
    }
}

fn counter(wire: &[u8]) -> Option<u32> {
    (wire.get(2) == Some(&0x55)).then(|| u32::from_be_bytes(wire[3..7].try_into().unwrap()))
}

impl Sim {
    fn new(seed: u64) -> Self {
        Self {
            air: Aircraft::new(),
            ground: Ground::new(),
            now: 0,
            rng: TestRng::new(seed),
            up: Box::new(|_, _| Fate::Deliver),
            down: Box::new(|_, _| Fate::Deliver),
            up_count: 0,
            down_count: 0,
            up_held: vec![],
            down_held: vec![],
            air_app: vec![],
            ground_app: vec![],
            last_up: 0,
            last_down: 0,
        }
    }

    /// One 100 ms step.
    fn step(&mut self) {
        self.now += 100;
        self.ground.poll(self.now, &mut self.rng);
        if self.now.is_multiple_of(500) && self.ground.ch.has_session() {
            self.ground.send(&ping()).unwrap();
        }
        match self.air.send(&alive()) {
            Ok(()) | Err(SealError::NoSession) => {}
            Err(e) => panic!("{e}"),
        }
        // Uplink.
        let frames = std::mem::take(&mut self.ground.out);
        let mut deliver = vec![];
        for f in frames {
            if let Some(c) = counter(&f) {
                assert!(
                    c > self.last_up || self.last_up == 0 || c == 1,
                    "uplink counters"
                );
                self.last_up = c;
            }
            let fate = (self.up)(self.up_count, &f);
            self.up_count += 1;
            match fate {
                Fate::Deliver => {
                    deliver.push(f);
                    deliver.append(&mut self.up_held);
                }
                Fate::Lose => {}
                Fate::Duplicate => {
                    deliver.push(f.clone());
                    deliver.push(f);
                    deliver.append(&mut self.up_held);
                }
                Fate::Delay => self.up_held.push(f),
            }
        }
        for f in deliver {
            if let Rx::App(p, Protection::Encrypted { .. }) =
                self.air.receive(&f, self.now, &mut self.rng)
            {
                if p == ping() {
                    self.air.send(&pong()).unwrap();
                }
                self.air_app.push(p);
            }
        }
        // Downlink.
        let frames = std::mem::take(&mut self.air.out);
        let mut deliver = vec![];
        for f in frames {
            if let Some(c) = counter(&f) {
                assert!(c > self.last_down || c == 1, "downlink counters");
                self.last_down = c;
            }
            let fate = (self.down)(self.down_count, &f);
            self.down_count += 1;
            match fate {
                Fate::Deliver => {
                    deliver.push(f);
                    deliver.append(&mut self.down_held);
                }
                Fate::Lose => {}
                Fate::Duplicate => {
                    deliver.push(f.clone());
                    deliver.push(f);
                    deliver.append(&mut self.down_held);
                }
                Fate::Delay => self.down_held.push(f),
            }
        }
        for f in deliver {
            if let Rx::App(p, Protection::Encrypted { .. }) = self.ground.receive(&f, self.now) {
                self.ground_app.push(p);
            }
        }
    }

    /// Steps until the link is up both ways (the ground decrypted telemetry and got a
    /// PONG) or `limit_ms` passes; returns the time it took.
    fn run_until_up(&mut self, limit_ms: u64) -> u64 {
        let start = self.now;
        let pongs = self.ground_app.iter().filter(|p| **p == pong()).count();
        while self.now - start < limit_ms {
            self.step();
            let up = self.ground.hs.state() == InitiatorState::Confirmed
                && self.ground_app.iter().filter(|p| **p == pong()).count() > pongs;
            if up {
                return self.now - start;
            }
        }
        panic!(
            "link not up after {limit_ms} ms: ground {:?} {:?}, aircraft {:?} {:?}",
            self.ground.hs.state(),
            self.ground.hs.stats(),
            self.air.hs.state(),
            self.air.hs.stats()
        );
    }
}

#[test]
fn perfect_link() {
    let mut sim = Sim::new(1);
    let t = sim.run_until_up(2_000);
    assert!(t <= 500, "{t}");
    let (g, a) = (sim.ground.hs.stats(), sim.air.hs.stats());
    assert_eq!((g.started, g.completed, g.refused()), (1, 1, 0));
    assert_eq!((a.started, a.completed, a.refused()), (1, 1, 0));
    // Nothing was sent before the session: no telemetry in plaintext.
    assert!(sim.air.ch.stats().no_session_tx >= 1);
    assert_eq!(sim.air.ch.stats().sent_plaintext, 1, "message 2 only");
}

#[test]
fn lost_message_1() {
    let mut sim = Sim::new(2);
    sim.up = Box::new(|i, f| {
        if i == 0 && is_kx(f, 0) {
            Fate::Lose
        } else {
            Fate::Deliver
        }
    });
    sim.run_until_up(3_000);
    assert_eq!(sim.ground.hs.stats().resent, 1);
    assert_eq!(sim.air.hs.stats().started, 1);
}

#[test]
fn lost_message_2() {
    // The ground repeats message 1 with the same key; the aircraft answers from its
    // cache, without new work.
    let mut sim = Sim::new(3);
    sim.down = Box::new(|i, f| {
        if i == 0 && is_kx(f, 1) {
            Fate::Lose
        } else {
            Fate::Deliver
        }
    });
    sim.run_until_up(3_000);
    let a = sim.air.hs.stats();
    assert_eq!((a.started, a.resent, a.completed), (1, 1, 1));
}

#[test]
fn lost_message_3() {
    // The aircraft waits for the signature and sends nothing; the ground, not hearing
    // it under the new session, sends message 3 again.
    let mut sim = Sim::new(4);
    let mut lost = false;
    sim.up = Box::new(move |_, f| {
        if is_kx(f, 2) && !lost {
            lost = true;
            Fate::Lose
        } else {
            Fate::Deliver
        }
    });
    sim.run_until_up(3_000);
    assert_eq!(sim.ground.hs.stats().resent, 1);
    assert_eq!(sim.air.hs.stats().completed, 1);
}

#[test]
fn message_3_lost_every_time_restarts_the_handshake() {
    let mut sim = Sim::new(5);
    let mut sigs = 0;
    sim.up = Box::new(move |_, f| {
        if is_kx(f, 2) {
            sigs += 1;
            if sigs <= 1 + pprz_secure::initiator::MSG3_RESENDS as usize {
                return Fate::Lose;
            }
        }
        Fate::Deliver
    });
    sim.run_until_up(10_000);
    let g = sim.ground.hs.stats();
    assert_eq!(g.started, 2, "a new handshake after the resends");
    assert_eq!(
        sim.air.hs.stats().started,
        2,
        "a fresh P_AE replaces the pending one"
    );
}

#[test]
fn duplicated_handshake_messages() {
    let mut sim = Sim::new(6);
    sim.up = Box::new(|_, f| {
        if f[2] == 0xAA {
            Fate::Duplicate
        } else {
            Fate::Deliver
        }
    });
    sim.down = Box::new(|_, f| {
        if f[2] == 0xAA {
            Fate::Duplicate
        } else {
            Fate::Deliver
        }
    });
    sim.run_until_up(3_000);
    let (g, a) = (sim.ground.hs.stats(), sim.air.hs.stats());
    assert_eq!((g.completed, a.completed), (1, 1));
    // The second message 1 arrived at once: its cached answer is rate-limited. The
    // second message 2 made the ground send message 3 again; the aircraft, already up,
    // refuses the copies as unexpected.
    assert_eq!(a.rate_limited, 1);
    assert!(a.unexpected >= 1);
    assert_eq!(a.started, 1);
}

#[test]
fn reordered_frames() {
    // Message 1 held back behind the next uplink frame, and every other downlink frame
    // delayed behind the next: handshake completes, late data frames are refused as
    // old (strictly increasing counters, no window) and counted.
    let mut sim = Sim::new(7);
    sim.up = Box::new(|i, _| if i == 0 { Fate::Delay } else { Fate::Deliver });
    sim.down = Box::new(|i, _| {
        if i % 2 == 1 {
            Fate::Delay
        } else {
            Fate::Deliver
        }
    });
    sim.run_until_up(5_000);
    for _ in 0..20 {
        sim.step();
    }
    assert!(sim.ground.ch.stats().replayed > 0);
    assert!(sim.ground.ch.stats().decrypted > 0);
}

#[test]
fn random_loss_both_ways() {
    for seed in 0..20 {
        let mut sim = Sim::new(100 + seed);
        let mut loss = TestRng::new(seed);
        let mut loss2 = TestRng::new(seed + 1000);
        sim.up = Box::new(move |_, _| {
            if loss.below(100) < 30 {
                Fate::Lose
            } else {
                Fate::Deliver
            }
        });
        sim.down = Box::new(move |_, _| match loss2.below(100) {
            0..30 => Fate::Lose,
            30..35 => Fate::Duplicate,
            35..40 => Fate::Delay,
            _ => Fate::Deliver,
        });
        sim.run_until_up(30_000);
    }
}

#[test]
fn ground_restart_keeps_the_session_until_the_new_one() {
    let mut sim = Sim::new(8);
    sim.run_until_up(2_000);
    // A new ground (restarted tool): telemetry continues under the old session, which
    // the aircraft keeps until the new handshake's signature verifies.
    sim.ground = Ground::new();
    sim.now += 1_000; // past the responder's rate limit
    sim.ground.poll(sim.now, &mut sim.rng); // message 1 queued
    let before = sim.air.ch.stats().encrypted;
    let msgs = std::mem::take(&mut sim.ground.out);
    for f in &msgs {
        sim.air.receive(f, sim.now, &mut sim.rng);
    }
    assert_eq!(sim.air.hs.state(), ResponderState::EstablishedWaitSig);
    sim.air.send(&alive()).unwrap();
    assert_eq!(sim.air.ch.stats().encrypted, before + 1, "still sending");
    sim.air.out.clear();
    sim.ground.hs.restart();
    sim.now += 1_000;
    sim.run_until_up(3_000);
    assert_eq!(sim.air.hs.stats().completed, 2);
    assert_eq!(sim.air.ch.stats().sessions, 2);
}

#[test]
fn aircraft_reboot_is_detected_by_silence() {
    let mut sim = Sim::new(9);
    sim.run_until_up(2_000);
    sim.air = Aircraft::new();
    // The ground hears nothing authenticated; after 5 s it starts a new handshake.
    let t = sim.run_until_up(10_000);
    assert!(t >= 5_000, "{t}");
    assert_eq!(sim.ground.hs.stats().started, 2);
}
