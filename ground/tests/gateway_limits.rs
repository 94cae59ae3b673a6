//! The gateway's bus under hostile sizes and slow rates, in process: a gateway session
//! (a peer listening on a loopback TCP port) and a client session connected to it,
//! multicast scouting and gossip off, nothing but loopback.
//!
//! * A command or a settings query with a payload one byte over the bound comes to
//!   the loop as a [`Request::TooLarge`] (not copied); one of a megabyte never comes
//!   (Zenoh drops it before reassembling it); one of exactly the bound comes whole.
//! * The service refuses and counts the oversized ones (`too_large`), answers the
//!   query with an error, and still sends the normal command that follows.
//! * At half a command a second, one command goes every two seconds of the service's
//!   clock (the `now` it is given).

use std::net::{TcpListener, UdpSocket};
use std::time::{Duration, Instant};

use pprz_ground::bus::{Bus, BusConfig, MAX_PAYLOAD, Request, keys};
use pprz_ground::device::Uplink;
use pprz_ground::gateway::serve::{Refusal, Service};
use pprz_ground::gateway::{Gateway, GatewayLink};
use pprz_ground::set::RuntimeSet;
use pprz_transports::PprzV2;
use serde_json::Value;
use zenoh::Wait;
use zenoh::qos::CongestionControl;

const XML: &str = r#"<protocol>
  <msg_class name="telemetry" id="1">
    <message name="COUNT" id="3"><field name="n" type="uint16"/></message>
  </msg_class>
  <msg_class name="datalink" id="2">
    <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
  </msg_class></protocol>"#;

/// How long anything may take to cross the loopback.
const PATIENCE: Duration = Duration::from_secs(10);

/// A normal command's fields.
const FIELDS: &str = r#"{"index": 3, "value": 1.5}"#;

/// A megabyte: far beyond what Zenoh is let reassemble.
const HUGE: usize = 1 << 20;

fn set() -> RuntimeSet {
    RuntimeSet::parse("m.xml", XML).unwrap()
}

/// A loopback TCP endpoint free a moment ago.
fn free_endpoint() -> String {
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

/// The gateway's session serving requests, and a client connected to it.
fn sessions() -> (Bus, Bus) {
    let endpoint = free_endpoint();
    let config = BusConfig {
        peer: true,
        listen: vec![endpoint.clone()],
        connect: Vec::new(),
        multicast: false,
    };
    let gateway = Bus::open(&config).unwrap().serving().unwrap();
    let client = Bus::open(&BusConfig::client(&endpoint)).unwrap();
    (gateway, client)
}

/// `len` bytes of JSON text: the fields padded with spaces.
fn padded(len: usize) -> Vec<u8> {
    let mut v = FIELDS.as_bytes().to_vec();
    v.resize(len, b' ');
    v
}

/// Puts `payload` on `key`, waiting for room rather than dropping it on the way out.
fn put(client: &Bus, key: &str, payload: Vec<u8>) {
    client
        .session()
        .put(key, payload)
        .congestion_control(CongestionControl::Block)
        .wait()
        .unwrap();
}

/// Keys of the requests that only wait for the sessions to know each other (of
/// aircraft 9, never the subject of a test).
const WARM_COMMAND: &str = "pprz/9/uplink/NOPE";
const WARM_SETTING: &str = "pprz/9/settings/3";

/// The next request the gateway's session queued, waiting for it (a late one on a
/// warm-up key skipped).
fn next(gateway: &Bus) -> Request {
    let start = Instant::now();
    loop {
        match gateway.next_request() {
            Some(Request::Command { key, .. }) if key == WARM_COMMAND => continue,
            Some(Request::Setting(q)) if q.key_expr().as_str() == WARM_SETTING => continue,
            Some(r) => return r,
            None => {}
        }
        assert!(start.elapsed() < PATIENCE, "no request came");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Repeats `send` until the gateway's session queues something (the client may not
/// know the gateway's subscriber or queryable at first).
fn until_heard(gateway: &Bus, send: impl Fn()) {
    let start = Instant::now();
    loop {
        send();
        std::thread::sleep(Duration::from_millis(50));
        if std::iter::from_fn(|| gateway.next_request()).count() > 0 {
            break;
        }
        assert!(start.elapsed() < PATIENCE, "the gateway heard nothing");
    }
}

fn describe(r: &Request) -> String {
    match r {
        Request::Command { key, payload } => format!("command on {key}, {} bytes", payload.len()),
        Request::Setting(q) => format!("settings query on {}", q.key_expr()),
        Request::TooLarge { key, len } => format!("too large on {key}, {len} bytes"),
    }
}

#[test]
fn oversized_payloads_are_never_copied_and_the_largest_taken_comes_whole() {
    let (gateway, client) = sessions();
    let command = keys::uplink(7, "SETTING");
    let setting = "pprz/7/settings/3";
    until_heard(&gateway, || put(&client, WARM_COMMAND, FIELDS.into()));

    // One byte over: dropped unread, its length noted.
    put(&client, &command, padded(MAX_PAYLOAD + 1));
    // A megabyte: Zenoh drops it; the loop never hears of it.
    put(&client, &command, padded(HUGE));
    // The bound: taken whole.
    put(&client, &command, padded(MAX_PAYLOAD));
    let r = next(&gateway);
    assert!(
        matches!(&r, Request::TooLarge { key, len } if *key == command && *len == MAX_PAYLOAD + 1),
        "{}",
        describe(&r)
    );
    let r = next(&gateway);
    assert!(
        matches!(&r, Request::Command { key, payload } if *key == command && payload.len() == MAX_PAYLOAD),
        "{}",
        describe(&r)
    );

    // Settings queries: the same bounds; the oversized one is answered at once.
    let get_on = |key: &str, payload: Vec<u8>, timeout: Duration| {
        client
            .session()
            .get(key)
            .payload(payload)
            .timeout(timeout)
            .wait()
            .unwrap()
    };
    let get = |payload: Vec<u8>, timeout: Duration| get_on(setting, payload, timeout);
    until_heard(&gateway, || {
        drop(get_on(
            WARM_SETTING,
            FIELDS.into(),
            Duration::from_millis(100),
        ))
    });
    let replies = get(padded(MAX_PAYLOAD + 1), PATIENCE);
    let reply = replies.recv().expect("an answer");
    let error = reply.result().expect_err("an error");
    let why = error.payload().try_to_string().unwrap().into_owned();
    assert!(why.contains(&format!("at most {MAX_PAYLOAD}")), "{why}");
    let r = next(&gateway);
    assert!(
        matches!(&r, Request::TooLarge { key, len } if key == setting && *len == MAX_PAYLOAD + 1),
        "{}",
        describe(&r)
    );
    // A megabyte: no answer but Zenoh's own when its time is up, nothing queued.
    let replies = get(padded(HUGE), Duration::from_secs(1));
    let answers: Vec<String> = std::iter::from_fn(|| replies.recv().ok())
        .map(|r| match r.result() {
            Ok(_) => "a value".to_owned(),
            Err(e) => e.payload().try_to_string().unwrap().into_owned(),
        })
        .collect();
    assert_eq!(answers, ["Timeout"]);
    let _pending = get(padded(MAX_PAYLOAD), PATIENCE);
    let r = next(&gateway);
    assert!(
        matches!(&r, Request::Setting(q) if q.payload().map(|p| p.len()) == Some(MAX_PAYLOAD)),
        "{}",
        describe(&r)
    );
}

/// A service over one link whose uplink writes to a loopback socket (the aircraft).
fn service(gateway: Bus, rate: Option<f64>) -> (Service, UdpSocket) {
    let aircraft = UdpSocket::bind("127.0.0.1:0").unwrap();
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let uplink = Uplink::Udp(socket, aircraft.local_addr().unwrap());
    let links = vec![GatewayLink::new("a", set(), PprzV2::new().into(), true)];
    let mut service = Service::new("gw", Gateway::new(set(), links), vec![uplink], gateway);
    if let Some(rate) = rate {
        service = service.with_uplink_rate(rate);
    }
    aircraft
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    (service, aircraft)
}

/// Datagrams the aircraft received.
fn received(aircraft: &UdpSocket) -> usize {
    let mut buf = [0u8; 512];
    std::iter::from_fn(|| aircraft.recv(&mut buf).ok()).count()
}

/// Serves requests at `now` until `done` holds.
fn serve_until(service: &mut Service, now: f64, done: impl Fn(&Service) -> bool) {
    let start = Instant::now();
    while !done(service) {
        assert!(start.elapsed() < PATIENCE, "{}", service.stats_json());
        service.serve_requests(now, 64);
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Puts an unknown command until the service refuses one (the client may not know
/// the gateway's subscriber at first); late copies are refused for the same reason,
/// which no test counts, and touch no aircraft's rate.
fn warm_up(service: &mut Service, client: &Bus) {
    let start = Instant::now();
    while refused(service, Refusal::UnknownMessage) == 0 {
        assert!(start.elapsed() < PATIENCE, "{}", service.stats_json());
        put(client, WARM_COMMAND, FIELDS.into());
        std::thread::sleep(Duration::from_millis(50));
        service.serve_requests(0.0, 64);
    }
}

fn refused(service: &Service, reason: Refusal) -> u64 {
    service.stats().refused.get(&reason).copied().unwrap_or(0)
}

#[test]
fn oversized_commands_and_queries_are_refused_and_counted_while_a_normal_command_goes() {
    let (gateway, client) = sessions();
    let refusals = client
        .session()
        .declare_subscriber(keys::refused("gw"))
        .wait()
        .unwrap();
    let (mut service, aircraft) = service(gateway, None);
    let command = keys::uplink(7, "SETTING");
    warm_up(&mut service, &client);
    // Wait for the client to know the refusals' subscriber too.
    std::thread::sleep(Duration::from_millis(200));

    put(&client, &command, padded(MAX_PAYLOAD + 1));
    let replies = client
        .session()
        .get("pprz/7/settings/3")
        .payload(padded(MAX_PAYLOAD + 1))
        .timeout(PATIENCE)
        .wait()
        .unwrap();
    put(&client, &command, FIELDS.into());
    serve_until(&mut service, 1.0, |s| {
        s.stats().commands > 0 && refused(s, Refusal::TooLarge) == 2
    });

    assert_eq!(service.stats().commands, 1);
    assert_eq!(
        received(&aircraft),
        1,
        "the normal command reached the aircraft"
    );
    let stats = service.stats_json();
    assert_eq!(stats["refused"]["too_large"], 2, "{stats}");
    let reasons: Vec<&String> = stats["refused"].as_object().unwrap().keys().collect();
    assert_eq!(reasons, ["too_large", "unknown_message"], "{stats}");
    let reply = replies.recv().expect("an answer");
    let error = reply.result().expect_err("an error");
    let why = error.payload().try_to_string().unwrap().into_owned();
    assert!(why.contains(&format!("at most {MAX_PAYLOAD}")), "{why}");
    // Both refusals published, with their reason (after those of the warm-up).
    let mut too_large = Vec::new();
    while too_large.len() < 2 {
        let sample = refusals
            .recv_timeout(PATIENCE)
            .unwrap()
            .expect("a refusal published");
        let body: Value = serde_json::from_slice(&sample.payload().to_bytes()).unwrap();
        if body["reason"] == "too_large" {
            too_large.push(body["key"].as_str().unwrap().to_owned());
        }
    }
    assert_eq!(too_large, [command.as_str(), "pprz/7/settings/3"]);
}

#[test]
fn at_half_a_command_a_second_one_goes_every_two_seconds() {
    let (gateway, client) = sessions();
    let (mut service, aircraft) = service(gateway, Some(0.5));
    warm_up(&mut service, &client);

    // Aircraft 7, one command at each time: whether it goes.
    let command = keys::uplink(7, "SETTING");
    let times = [10.0, 10.5, 11.0, 11.9, 12.0, 13.0, 14.0, 30.0, 30.0, 32.0];
    let expect = [
        true, false, false, false, true, false, true, true, false, true,
    ];
    let mut went = Vec::new();
    for &now in &times {
        let handled = |s: &Service| s.stats().commands + refused(s, Refusal::Rate);
        let before = (service.stats().commands, handled(&service));
        put(&client, &command, FIELDS.into());
        serve_until(&mut service, now, |s| handled(s) > before.1);
        went.push(service.stats().commands > before.0);
    }
    assert_eq!(went, expect, "at {times:?}");
    let n = expect.iter().filter(|&&g| g).count();
    assert_eq!(received(&aircraft), n);
    let refusals = expect.iter().filter(|&&g| !g).count() as u64;
    assert_eq!(refused(&service, Refusal::Rate), refusals);
}
