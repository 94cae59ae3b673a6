//! The monitor on a secure link (`--secure`), against an in-memory aircraft made of
//! pprz-secure's `Responder` and `SecureChannel` with the published test keys: the
//! handshake, encrypted telemetry decoded, PINGs sealed, and everything that is not
//! authenticated rejected and counted, never shown as a message. Then the command line:
//! refused combinations, bad key files, and a whole run over loopback UDP.

use std::path::{Path, PathBuf};

use pprz_ground::cli::Transport;
use pprz_ground::monitor::{Event, Monitor, Notice};
use pprz_ground::secure::{GroundSecure, HandshakeEvent, Incoming, SecureSetupError};
use pprz_ground::set::RuntimeSet;
use pprz_ground::uplink;
use pprz_secure::initiator::MSG3_RESENDS;
use pprz_secure::keys::{INSECURE_TEST_KEY_FILE, KeyFileErrorKind};
use pprz_secure::rand_core::{CryptoRng, RngCore};
use pprz_secure::{
    InitiatorState, KEY_EXCHANGE_GCS, KeyError, KeyExchange, KeyExchangeIds, KeyFile, KeyName,
    MsgType, OVERHEAD, Policy, Reject, Responder, ResponderEvent, SealError, SecureChannel,
};
use pprz_test_support::rng::Rng;
use pprz_transports::{AnyTransport, Encoder, Framing, MsgHeader, PprzV2, TxMeta};

mod common;

use common::{MESSAGES, monitor, run};

const KEY_FILE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../secure/keys/INSECURE-TEST-ONLY.keys"
);

/// A deterministic generator (the workspace's seeded one) for reproducible tests: never
/// for a real link.
struct TestRng(Rng);

impl TestRng {
    const fn new(seed: u64) -> Self {
        Self(Rng::new(seed))
    }
}

impl RngCore for TestRng {
    fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    fn fill_bytes(&mut self, dst: &mut [u8]) {
        self.0.fill_bytes(dst);
    }
}

impl CryptoRng for TestRng {}

fn keys() -> KeyFile {
    KeyFile::parse(INSECURE_TEST_KEY_FILE).unwrap()
}

fn ground(ac_id: u8) -> GroundSecure {
    GroundSecure::with_rng(ac_id, keys().ground().unwrap(), TestRng::new(1))
}

fn set() -> RuntimeSet {
    RuntimeSet::load(Path::new(MESSAGES)).unwrap()
}

fn secure_monitor() -> Monitor {
    Monitor::new(set(), PprzV2::new().into())
        .with_secure(ground(7))
        .unwrap()
}

/// A plain PPRZ v2 frame.
fn plain(src: u8, dst: u8, class: u8, id: u8, fields: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(src, dst, class, id));
    let n = PprzV2::new().encode(&meta, fields, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// Aircraft 7's end of the link, in memory.
struct Aircraft {
    channel: SecureChannel,
    responder: Responder,
    rng: TestRng,
    /// Plain frames received from the ground (other than the key exchange).
    received: Vec<Vec<u8>>,
    rejected: Vec<Reject>,
    /// Key exchanges the responder refused.
    refused: Vec<pprz_secure::HandshakeError>,
}

impl Aircraft {
    fn new() -> Self {
        Self {
            channel: SecureChannel::new(Policy::aircraft(7)),
            responder: Responder::new(7, keys().aircraft().unwrap()),
            rng: TestRng::new(2),
            received: Vec::new(),
            rejected: Vec::new(),
            refused: Vec::new(),
        }
    }

    /// Seals a plain frame for the wire (`None`: refused, e.g. no session).
    fn seal(&mut self, frame: &[u8]) -> Option<Vec<u8>> {
        let mut buf = [0u8; 255 + OVERHEAD];
        buf[..frame.len()].copy_from_slice(frame);
        let sealed = self.channel.seal_in_place(&mut buf, frame.len()).ok()?;
        Some(buf[..sealed.len].to_vec())
    }

    /// Takes the bytes the ground wrote; returns the bytes the aircraft answers.
    fn receive(&mut self, mut bytes: &[u8], now_ms: u64) -> Vec<u8> {
        let mut answer = Vec::new();
        while !bytes.is_empty() {
            let (frame, used) = PprzV2::new().parse(bytes).expect("whole frames");
            bytes = &bytes[used..];
            let mut out = [0u8; 255];
            let opened = match self.channel.open(frame.data(), &mut out) {
                Ok(o) => o,
                Err(r) => {
                    self.rejected.push(r);
                    continue;
                }
            };
            if !opened.is(KEY_EXCHANGE_GCS) {
                self.received.push(opened.frame().to_vec());
                continue;
            }
            let kx = KeyExchange::parse(opened.data(), &KeyExchangeIds::PPRZLINK)
                .unwrap()
                .unwrap();
            match self.responder.handle(&kx, now_ms, &mut self.rng) {
                Ok(ResponderEvent::Reply(reply)) => {
                    let mut buf = [0u8; 255];
                    let n = reply.write_frame(&mut buf).unwrap();
                    answer.extend(self.seal(&buf[..n]).unwrap());
                }
                Ok(ResponderEvent::Established(keys)) => self.channel.install(keys),
                Err(e) => self.refused.push(e),
            }
        }
        answer
    }
}

fn feed(m: &mut Monitor, now: f64, bytes: &[u8]) -> Vec<String> {
    let mut lines = Vec::new();
    m.feed(now, bytes, |d| lines.push(d.line.to_owned()));
    lines
}

/// Runs the link for `steps` steps of 100 ms from `t0`: the monitor's handshake frames
/// to the aircraft and its answers back. Returns the time reached.
fn exchange(m: &mut Monitor, air: &mut Aircraft, t0: f64, steps: u32) -> f64 {
    let mut t = t0;
    for _ in 0..steps {
        for f in m.poll_secure(t) {
            let back = air.receive(&f, (t * 1000.0) as u64);
            assert!(
                feed(m, t, &back).is_empty(),
                "no message lines for the handshake"
            );
        }
        t += 0.1;
    }
    t
}

/// The whole session: handshake, encrypted telemetry with its values, an encrypted
/// PING, the PONG's round trip.
#[test]
fn handshake_then_encrypted_telemetry_and_ping() {
    let mut m = secure_monitor();
    let mut air = Aircraft::new();
    let st = m.secure_status().unwrap();
    assert_eq!(st.state, InitiatorState::Idle);
    assert!(
        m.render(0.0)
            .contains("secure link: waiting for the handshake")
    );
    assert!(!m.uplink_ready());

    // The aircraft cannot send telemetry before the session.
    let gps = plain(7, 0, 1, 8, &gps_fields());
    assert!(air.seal(&gps).is_none());

    let t = exchange(&mut m, &mut air, 0.0, 3);
    let st = m.secure_status().unwrap();
    assert_eq!(st.state, InitiatorState::WaitConfirm, "{st:?}");
    assert_eq!(
        (st.stats.handshake.started, st.stats.handshake.completed),
        (1, 1)
    );
    assert!(air.channel.has_session());
    assert!(m.uplink_ready());
    assert!(
        m.events()
            .any(|(_, e)| *e == Event::SecureSession { completed: 1 })
    );

    // Encrypted telemetry, decoded with its values.
    let sealed = air.seal(&gps).unwrap();
    assert_eq!(sealed.len(), gps.len() + OVERHEAD);
    let lines = feed(&mut m, t, &sealed);
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(
        lines[0].starts_with("7 telemetry GPS mode=3"),
        "{}",
        lines[0]
    );
    assert!(lines[0].contains("utm_east=37712345"), "{}", lines[0]);
    assert!(lines[0].contains("alt=152300"), "{}", lines[0]);
    let st = m.secure_status().unwrap();
    assert_eq!(st.state, InitiatorState::Confirmed);
    assert_eq!(st.stats.channel.decrypted, 1);
    assert_eq!(m.messages()[&(1, 8)].count, 1);

    // A PING, sealed by the monitor, opened by the aircraft; the PONG measured.
    let ping = uplink::frame(m.set(), PprzV2::new().into(), 7, "PING", &[]).unwrap();
    let sealed_ping = m.seal_uplink(&ping).unwrap();
    assert_eq!(sealed_ping[2], 0x55, "encrypted");
    assert_ne!(sealed_ping, ping);
    m.ping_sent(None, t);
    assert!(air.receive(&sealed_ping, 0).is_empty());
    assert_eq!(air.received, [ping]);
    let pong = air.seal(&plain(7, 0, 1, 3, &[])).unwrap();
    feed(&mut m, t + 0.05, &pong);
    assert_eq!(m.pings().answered(), 1);

    // The status shows it all.
    let view = m.render(t + 0.1);
    assert!(view.contains("secure link: session up"), "{view}");
    assert!(view.contains("handshakes started 1  completed 1"), "{view}");
    assert!(
        view.contains("secure frames: decrypted 2  rejected 0"),
        "{view}"
    );
    assert!(view.contains("encrypted 1"), "{view}");
    let summary = m.summary(t + 0.1);
    assert!(summary.contains("secure link: session up"), "{summary}");
    assert!(summary.contains("counter space left"), "{summary}");
    let left = m.secure_status().unwrap().stats.counter_space_left;
    assert!(left > u32::MAX - 10, "{left}");
}

fn gps_fields() -> Vec<u8> {
    use pprz_messages::Message as _;
    let mut buf = [0u8; 64];
    let n = common::gps().encode(&mut buf).unwrap();
    buf[..n].to_vec()
}

/// Message 1 is sent again every second until the aircraft answers; a lost message 2
/// costs a second, not the link.
#[test]
fn message_1_is_repeated_until_answered() {
    let mut m = secure_monitor();
    let mut sent = Vec::new();
    for i in 0..35 {
        let t = f64::from(i) * 0.1;
        sent.extend(m.poll_secure(t).into_iter().map(|f| (t, f)));
    }
    let times: Vec<f64> = sent.iter().map(|(t, _)| *t).collect();
    assert_eq!(times.len(), 4, "{times:?}");
    for (i, t) in times.iter().enumerate() {
        assert!((t - i as f64).abs() < 0.05, "{times:?}");
    }
    // All of them the same message 1, in plaintext (0xAA), for aircraft 7.
    for (_, f) in &sent {
        assert_eq!(f, &sent[0].1);
        assert_eq!(&f[2..7], &[0xAA, 0, 7, 2, 159]);
    }
    let st = m.secure_status().unwrap();
    assert_eq!(st.state, InitiatorState::WaitMsg2);
    assert_eq!(
        (st.stats.handshake.started, st.stats.handshake.resent),
        (1, 3)
    );
    // Nothing goes up before the session.
    let ping = uplink::frame(m.set(), PprzV2::new().into(), 7, "PING", &[]).unwrap();
    assert_eq!(m.seal_uplink(&ping), Err(SealError::NoSession));
    assert_eq!(m.secure_status().unwrap().stats.channel.no_session_tx, 1);
    let view = m.render(3.5);
    assert!(
        view.contains("secure link: waiting for the handshake (KEY_EXCHANGE_GCS sent"),
        "{view}"
    );
    assert!(view.contains("not sent (no session) 1"), "{view}");
    // The aircraft answers a late copy: the handshake completes.
    let mut air = Aircraft::new();
    let back = air.receive(&sent[3].1, 3500);
    feed(&mut m, 3.5, &back);
    let out = m.poll_secure(3.6);
    assert_eq!(out.len(), 1, "message 3");
    air.receive(&out[0], 3600);
    assert!(air.channel.has_session());
}

/// Plaintext telemetry, tampered frames, replays and frames of another aircraft are
/// rejected and counted, shown as notices, never decoded as messages.
#[test]
fn unauthenticated_frames_are_rejected_and_counted() {
    let mut m = secure_monitor();
    let mut air = Aircraft::new();
    // Before any session: plaintext telemetry is refused.
    let alive = plain(7, 0, 1, 2, &[2, 0xDE, 0xAD]);
    assert!(feed(&mut m, 0.0, &alive).is_empty());
    let t = exchange(&mut m, &mut air, 0.0, 3);
    // And after.
    assert!(feed(&mut m, t, &alive).is_empty());
    assert!(feed(&mut m, t, &alive).is_empty());
    let st = m.secure_status().unwrap();
    assert_eq!(st.stats.channel.not_secure, 3);
    assert!(m.messages().is_empty(), "nothing decoded");
    // One notice for the run of rejections within a second.
    let n: Vec<_> = m
        .notices()
        .filter(|(_, n)| matches!(n, Notice::SecureRejected { .. }))
        .collect();
    assert_eq!(n.len(), 1, "{n:?}"); // t = 0 and t = 0.3
    assert_eq!(
        n[0].1,
        Notice::SecureRejected {
            reason: Reject::NotSecure,
            count: 3
        }
    );
    assert!(
        m.render(t)
            .contains("3 frame(s) rejected by the secure link: unsecured frame")
    );
    // A second later, a new notice.
    assert!(feed(&mut m, t + 1.5, &alive).is_empty());
    assert_eq!(m.notices().count(), 2);

    // A tampered frame (a ciphertext byte changed, checksum fixed) fails its tag.
    let good = air.seal(&alive).unwrap();
    let mut bad = good.clone();
    bad[9] ^= 0x01;
    let bad = refit_checksum(bad);
    assert!(feed(&mut m, t, &bad).is_empty());
    assert_eq!(m.secure_status().unwrap().stats.channel.bad_tag, 1);
    // The genuine one still opens, once: its replay is rejected.
    assert_eq!(feed(&mut m, t, &good).len(), 1);
    assert!(feed(&mut m, t, &good).is_empty());
    let st = m.secure_status().unwrap();
    assert_eq!(st.stats.channel.replayed, 1);
    assert_eq!(st.stats.channel.decrypted, 1);
    assert_eq!(st.stats.channel.rejected(), 6);
    assert_eq!(m.messages()[&(1, 2)].count, 1);

    // Garbage in a well-formed frame: counted, no panic.
    for data in [
        &[0x55][..],
        &[0xAA],
        &[0x55; 40],
        &[0xAA, 7, 0, 1, 239, 9, 9],
    ] {
        let mut f = vec![0x99, (data.len() + 4) as u8];
        f.extend_from_slice(data);
        let f = refit_checksum([f, vec![0, 0]].concat());
        assert!(feed(&mut m, t, &f).is_empty());
    }
    let view = m.render(t);
    assert!(
        view.contains("secure frames: decrypted 1  rejected"),
        "{view}"
    );
    assert!(view.contains("bad tag 1, replayed 1"), "{view}");
}

/// Recomputes a PPRZ v2 frame's checksum.
fn refit_checksum(mut f: Vec<u8>) -> Vec<u8> {
    let n = f.len();
    let (mut a, mut b) = (0u8, 0u8);
    for &x in &f[1..n - 2] {
        a = a.wrapping_add(x);
        b = b.wrapping_add(a);
    }
    f[n - 2] = a;
    f[n - 1] = b;
    f
}

/// A forged message 2 (another aircraft's keys) is refused; the handshake continues.
#[test]
fn a_forged_key_exchange_is_refused() {
    let mut g = ground(7);
    let msg1 = g.poll(0).unwrap();
    // An impostor with freshly generated keys answers.
    let other = KeyFile::generate(&mut TestRng::new(9));
    let mut fake = Responder::new(7, other.aircraft().unwrap());
    let mut fake_channel = SecureChannel::new(Policy::aircraft(7));
    let (f, _) = PprzV2::new().parse(&msg1).unwrap();
    let mut out = [0u8; 255];
    let opened = fake_channel.open(f.data(), &mut out).unwrap();
    let kx = KeyExchange::parse(opened.data(), &KeyExchangeIds::PPRZLINK)
        .unwrap()
        .unwrap();
    let Ok(ResponderEvent::Reply(reply)) = fake.handle(&kx, 0, &mut TestRng::new(3)) else {
        panic!("the impostor answers");
    };
    let mut buf = [0u8; 255];
    let n = reply.write_frame(&mut buf).unwrap();
    let mut sealed = [0u8; 255 + OVERHEAD];
    sealed[..n].copy_from_slice(&buf[..n]);
    let len = fake_channel.seal_in_place(&mut sealed, n).unwrap().len;
    let (f, _) = PprzV2::new().parse(&sealed[..len]).unwrap();
    match g.open(f.data(), 100) {
        Incoming::Handshake {
            event: HandshakeEvent::Refused(_),
            reply: None,
        } => {}
        other => panic!("{other:?}"),
    }
    let st = g.status();
    assert_eq!(st.state, InitiatorState::WaitMsg2);
    assert_eq!(st.stats.handshake.refused(), 1);
    assert!(!g.has_session());
}

/// Whether `frame` is a plaintext `KEY_EXCHANGE_GCS` SIG (message 3) from the ground.
fn is_message_3(frame: &[u8]) -> bool {
    frame.len() > 8 && frame[2] == 0xAA && frame[6] == 159 && frame[8] == MsgType::Sig as u8
}

/// The message-3 frames the monitor writes at `t`.
fn messages_3(m: &mut Monitor, t: f64) -> usize {
    m.poll_secure(t).iter().filter(|f| is_message_3(f)).count()
}

/// A captured message 2, replayed 200 times, gets message 3 again at most
/// `MSG3_RESENDS` times while the aircraft is unconfirmed and never once it is
/// confirmed; forged copies get nothing. Every copy not answered is refused, counted
/// and shown.
#[test]
fn replayed_message_2_does_not_make_message_3_again_and_again() {
    let mut m = secure_monitor();
    let mut air = Aircraft::new();
    let msg1 = m.poll_secure(0.0);
    assert_eq!(msg1.len(), 1);
    let msg2 = air.receive(&msg1[0], 0);
    assert!(feed(&mut m, 0.0, &msg2).is_empty());
    let out = m.poll_secure(0.0);
    assert_eq!(
        out.iter().filter(|f| is_message_3(f)).count(),
        1,
        "message 3"
    );
    for f in &out {
        air.receive(f, 0);
    }
    assert!(air.channel.has_session());
    let st = m.secure_status().unwrap();
    assert_eq!(st.state, InitiatorState::WaitConfirm);

    // 200 replays while the aircraft is not yet heard under the session (same instant:
    // no message 3 is due by the clock).
    let mut sent = 0;
    for _ in 0..200 {
        assert!(feed(&mut m, 0.05, &msg2).is_empty());
        sent += messages_3(&mut m, 0.05);
    }
    assert!(
        sent <= usize::from(MSG3_RESENDS),
        "{sent} messages 3 for 200 replays"
    );

    // The aircraft is heard under the session: confirmed.
    let alive = air.seal(&plain(7, 0, 1, 2, &[2, 0xDE, 0xAD])).unwrap();
    assert_eq!(feed(&mut m, 0.1, &alive).len(), 1);
    assert_eq!(m.secure_status().unwrap().state, InitiatorState::Confirmed);
    let mut after = 0;
    for _ in 0..200 {
        assert!(feed(&mut m, 0.2, &msg2).is_empty());
        after += messages_3(&mut m, 0.2);
    }
    assert_eq!(after, 0, "no message 3 once the aircraft is confirmed");

    // Forged messages 2: a byte of the aircraft's key or of the sealed signature changed.
    for i in 0..20 {
        let mut forged = msg2.clone();
        forged[9 + i * 3] ^= 0x40;
        assert!(feed(&mut m, 0.3, &refit_checksum(forged)).is_empty());
        assert_eq!(messages_3(&mut m, 0.3), 0);
    }

    let st = m.secure_status().unwrap();
    assert_eq!(st.state, InitiatorState::Confirmed, "{st:?}");
    assert_eq!(st.stats.handshake.started, 1);
    let refused = 400 - sent as u32 + 20;
    assert_eq!(st.stats.handshake.refused(), refused, "{st:?}");
    let view = m.render(0.3);
    assert!(view.contains(&format!("refused {refused} (")), "{view}");
    // The session is unchanged: the aircraft's telemetry still opens.
    let gps = air.seal(&plain(7, 0, 1, 8, &gps_fields())).unwrap();
    assert_eq!(feed(&mut m, 0.4, &gps).len(), 1);
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pprz-secure-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn key_file_errors_are_typed() {
    let dir = temp_dir("keys");
    let err = GroundSecure::from_key_file(&dir.join("missing.keys"), 7).unwrap_err();
    assert!(matches!(err, SecureSetupError::Read { .. }), "{err:?}");
    assert!(
        err.to_string().contains("cannot read the key file"),
        "{err}"
    );
    let err = GroundSecure::from_key_file(&dir, 7).unwrap_err();
    assert!(matches!(err, SecureSetupError::Read { .. }), "{err:?}");

    let bad = dir.join("bad.keys");
    std::fs::write(&bad, "# test\nGCS_PUBLIC = 00\n").unwrap();
    match GroundSecure::from_key_file(&bad, 7).unwrap_err() {
        SecureSetupError::Parse { error, .. } => {
            assert_eq!(error.line, 2);
            assert_eq!(error.kind, KeyFileErrorKind::WrongLength);
        }
        other => panic!("{other:?}"),
    }
    let binary = dir.join("binary.keys");
    std::fs::write(&binary, [0xFF, 0xFE, 0x00]).unwrap();
    assert!(matches!(
        GroundSecure::from_key_file(&binary, 7),
        Err(SecureSetupError::Read { .. })
    ));

    // The aircraft's half of a split key set has no ground private key.
    let mut text = String::new();
    keys()
        .without(KeyName::GcsPrivate)
        .write_to(&mut text)
        .unwrap();
    let air_only = dir.join("aircraft.keys");
    std::fs::write(&air_only, text).unwrap();
    match GroundSecure::from_key_file(&air_only, 7).unwrap_err() {
        SecureSetupError::Keys { error, .. } => {
            assert_eq!(error, KeyError::Missing(KeyName::GcsPrivate));
        }
        other => panic!("{other:?}"),
    }
    // The published test file works.
    let g = GroundSecure::from_key_file(Path::new(KEY_FILE), 7).unwrap();
    assert_eq!(g.ac_id(), 7);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn secure_needs_pprz_v2() {
    for t in [
        Transport::Pprz1,
        Transport::Xbee,
        Transport::Xbee868,
        Transport::Pprzlog,
    ] {
        let transport: AnyTransport = t.any();
        let err = Monitor::new(set(), transport)
            .with_secure(ground(7))
            .err()
            .unwrap();
        assert!(matches!(err, SecureSetupError::NotPprzV2), "{err:?}");
    }
}

#[test]
fn the_command_line_refuses_bad_secure_setups() {
    let link = ["--udp", "127.0.0.1:0", "--uplink", "127.0.0.1:9"];
    let (code, _, err) = run(monitor()
        .args(["--messages", MESSAGES, "--secure", KEY_FILE])
        .args(link)
        .args(["--transport", "pprz1"]));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--secure needs --transport pprz2"), "{err}");

    let (code, _, err) =
        run(monitor().args(["--messages", MESSAGES, "--stdin", "--secure", KEY_FILE]));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--secure needs a link to the aircraft"),
        "{err}"
    );

    let dir = temp_dir("cli");
    let bad = dir.join("bad.keys");
    std::fs::write(&bad, "GCS_PRIVATE = zz\n").unwrap();
    let (code, _, err) = run(monitor()
        .args(["--messages", MESSAGES, "--secure", bad.to_str().unwrap()])
        .args(link));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("line 1"), "{err}");
    let (code, _, err) = run(monitor()
        .args(["--messages", MESSAGES, "--secure", "/nonexistent/k.keys"])
        .args(link));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("cannot read the key file"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);

    let (code, help, _) = run(monitor().arg("--help"));
    assert_eq!(code, Some(0));
    assert!(help.contains("--secure <KEYFILE>"), "{help}");
}

/// `--secure` with `--ac-id 255` (broadcast) or `--ac-id 0` (the ground itself) has no
/// aircraft to make a key exchange with: refused on the command line with one line and
/// exit status 2, before anything starts (`--duration`: a guard against a hang).
#[test]
fn the_command_line_refuses_a_secure_link_to_no_aircraft() {
    let link = ["--udp", "127.0.0.1:0", "--uplink", "127.0.0.1:9"];
    for (id, what) in [("255", "broadcast"), ("0", "the ground")] {
        let (code, out, err) = run(monitor()
            .args(["--messages", MESSAGES, "--secure", KEY_FILE, "--lines"])
            .args(link)
            .args(["--ac-id", id, "--duration", "20"]));
        assert_eq!(code, Some(2), "--ac-id {id}: {err}");
        assert!(out.is_empty(), "{out}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.starts_with("error: --secure") && err.contains(&format!("--ac-id {id}")),
            "{err}"
        );
        assert!(err.contains(what), "{err}");
    }
}

/// `pprz-monitor --secure` over loopback UDP against the in-memory aircraft in a
/// thread: the handshake completes, telemetry is decrypted, the PINGs and the SETTING
/// go encrypted and are answered, the plaintext frame sent in between is rejected.
#[test]
fn a_secure_run_over_udp() {
    use std::net::UdpSocket;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(20)))
        .unwrap();
    let port = socket.local_addr().unwrap().port();
    let done = Arc::new(AtomicBool::new(false));
    let stop = done.clone();
    let fake = std::thread::spawn(move || {
        let mut air = Aircraft::new();
        let start = Instant::now();
        let mut ground = None;
        let mut next_gps = 0.0;
        let mut buf = [0u8; 512];
        let mut sent_plaintext = false;
        while !stop.load(Ordering::SeqCst) {
            let now_ms = start.elapsed().as_millis() as u64;
            if let Ok((n, from)) = socket.recv_from(&mut buf) {
                ground = Some(from);
                let back = air.receive(&buf[..n], now_ms);
                if !back.is_empty() {
                    socket.send_to(&back, from).unwrap();
                }
                for f in std::mem::take(&mut air.received) {
                    let reply = match (f[4], f[5]) {
                        (2, 8) => plain(7, 0, 1, 3, &[]),
                        (2, 4) => plain(7, 0, 1, 31, &[f[6], f[8], f[9], f[10], f[11]]),
                        _ => continue,
                    };
                    socket.send_to(&air.seal(&reply).unwrap(), from).unwrap();
                }
            }
            let t = start.elapsed().as_secs_f64();
            if let Some(to) = ground
                && air.channel.has_session()
                && t >= next_gps
            {
                let gps = air.seal(&plain(7, 0, 1, 8, &gps_fields())).unwrap();
                socket.send_to(&gps, to).unwrap();
                if !sent_plaintext {
                    socket
                        .send_to(&plain(7, 0, 1, 2, &[2, 0xDE, 0xAD]), to)
                        .unwrap();
                    sent_plaintext = true;
                }
                next_gps = t + 0.1;
            }
        }
        air
    });
    let (code, out, err) = run(monitor().args([
        "--messages",
        MESSAGES,
        "--udp",
        "127.0.0.1:0",
        "--uplink",
        &format!("127.0.0.1:{port}"),
        "--secure",
        KEY_FILE,
        "--ac-id",
        "7",
        "--ping",
        "0.2",
        "--setting",
        "5=0.5",
        "--lines",
        "--duration",
        "2",
    ]));
    done.store(true, Ordering::SeqCst);
    let air = fake.join().unwrap();
    assert_eq!(code, Some(0), "{err}");
    assert!(air.channel.has_session(), "{err}");
    assert!(air.rejected.is_empty(), "{:?}", air.rejected);
    // Telemetry decrypted and shown; the plaintext ALIVE is not.
    assert!(out.contains("7 telemetry GPS mode=3"), "{out}");
    assert!(!out.contains("ALIVE"), "{out}");
    assert!(
        err.contains("secure link: waiting for the handshake"),
        "{err}"
    );
    assert!(err.contains("secure session established"), "{err}");
    assert!(err.contains("secure link: session up"), "{err}");
    assert!(
        err.contains("frame(s) rejected by the secure link: unsecured frame"),
        "{err}"
    );
    assert!(err.contains("PONG: round trip"), "{err}");
    assert!(
        err.contains("DL_VALUE index=5 value=0.5: SETTING acknowledged"),
        "{err}"
    );
    assert!(err.contains("handshakes started 1  completed 1"), "{err}");
    assert!(err.contains("not secure 1"), "{err}");
}
