//! The gateway's merging and routing on mock time.

use super::*;
use crate::monitor::Monitor;
use pprz_transports::{Encoder, PprzV2, XBee24};

const XML: &str = r#"<protocol>
  <msg_class name="telemetry" id="1">
    <message name="ALIVE" id="2"><field name="md5sum" type="uint8[]"/></message>
    <message name="COUNT" id="3"><field name="n" type="uint16"/></message>
  </msg_class>
  <msg_class name="datalink" id="2">
    <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
  </msg_class></protocol>"#;

fn set() -> RuntimeSet {
    RuntimeSet::parse("m.xml", XML).unwrap()
}

fn frame(t: AnyTransport, ac: u8, n: u16) -> Vec<u8> {
    let meta = TxMeta::new(MsgHeader::new(ac, GROUND_ID, 1, 3));
    let mut out = vec![0u8; t.max_frame_len()];
    let len = t.encode(&meta, &n.to_le_bytes(), &mut out).unwrap();
    out.truncate(len);
    out
}

fn two_links() -> Gateway {
    let links = vec![
        GatewayLink::new("a", set(), PprzV2::new().into(), true),
        GatewayLink::new("b", set(), XBee24::default().into(), true),
    ];
    Gateway::new(set(), links)
}

/// Feeds a frame, returns the delivered lines.
fn feed(gw: &mut Gateway, link: usize, now: f64, bytes: &[u8]) -> Vec<String> {
    let mut out = Vec::new();
    gw.feed(link, now, bytes, |d| out.push(d.message.line.to_owned()));
    out
}

#[test]
fn a_message_on_two_links_is_delivered_once_whatever_the_framing() {
    let mut gw = two_links();
    let a = frame(PprzV2::new().into(), 7, 1);
    let b = frame(XBee24::default().into(), 7, 1);
    assert_eq!(feed(&mut gw, 0, 0.0, &a), ["7 telemetry COUNT n=1"]);
    assert!(feed(&mut gw, 1, 0.02, &b).is_empty());
    assert_eq!(gw.link_merge(0).first, 1);
    assert_eq!(gw.link_merge(1).duplicates, 1);
    assert_eq!(gw.fleet().aircraft_state(7).unwrap().frames(), 1);
}

#[test]
fn a_repeat_on_one_link_is_delivered_and_its_copies_are_not() {
    let mut gw = two_links();
    let a = frame(PprzV2::new().into(), 7, 5);
    let b = frame(XBee24::default().into(), 7, 5);
    // The aircraft sends the same content twice; link a brings both, b both later.
    assert_eq!(feed(&mut gw, 0, 0.0, &a).len(), 1);
    assert_eq!(feed(&mut gw, 0, 0.1, &a).len(), 1);
    assert!(feed(&mut gw, 1, 0.15, &b).is_empty());
    assert!(feed(&mut gw, 1, 0.2, &b).is_empty());
    // Link a lost the first: b's first is new, a's is its copy... and b's second is
    // a second instance.
    let mut gw = two_links();
    assert_eq!(feed(&mut gw, 0, 0.0, &a).len(), 1);
    assert!(feed(&mut gw, 1, 0.05, &b).is_empty());
    assert_eq!(feed(&mut gw, 1, 0.1, &b).len(), 1);
    assert_eq!(gw.fleet().aircraft_state(7).unwrap().frames(), 2);
}

#[test]
fn after_the_window_a_late_copy_is_delivered_again() {
    let mut gw = two_links().with_window(0.5, 1000);
    let a = frame(PprzV2::new().into(), 7, 9);
    let b = frame(XBee24::default().into(), 7, 9);
    assert_eq!(feed(&mut gw, 0, 0.0, &a).len(), 1);
    assert_eq!(feed(&mut gw, 1, 0.6, &b).len(), 1);
    // Each was alone in its window: the figures show the link's delay as loss.
    gw.tick(2.0);
    assert_eq!(gw.link_merge(0).alone, 1);
    assert_eq!(gw.link_merge(1).alone, 1);
    assert_eq!(gw.fleet().aircraft_state(7).unwrap().frames(), 2);
}

#[test]
fn what_each_link_alone_delivered_and_missed() {
    let mut gw = two_links();
    let (ta, tb): (AnyTransport, AnyTransport) = (PprzV2::new().into(), XBee24::default().into());
    // 10 messages; a loses n = 0..3, b loses n = 7..10.
    for n in 0..10u16 {
        let now = f64::from(n) * 0.1;
        if n >= 3 {
            feed(&mut gw, 0, now, &frame(ta, 7, n));
        }
        if n < 7 {
            feed(&mut gw, 1, now + 0.01, &frame(tb, 7, n));
        }
    }
    gw.tick(10.0);
    assert_eq!(gw.fleet().aircraft_state(7).unwrap().frames(), 10);
    let (a, b) = (gw.link_merge(0), gw.link_merge(1));
    assert_eq!((a.alone, a.missed), (3, 3));
    assert_eq!((b.alone, b.missed), (3, 3));
    assert_eq!(a.first + b.first, 10);
    assert_eq!(a.duplicates + b.duplicates, 4);
}

#[test]
fn the_bound_on_remembered_contents_holds() {
    let mut gw = two_links().with_window(10.0, 4);
    let ta: AnyTransport = PprzV2::new().into();
    for n in 0..100u16 {
        feed(&mut gw, 0, f64::from(n) * 0.001, &frame(ta, 7, n));
    }
    assert_eq!(gw.dedup().len(), 4);
    assert_eq!(gw.dedup().evicted(), 96);
}

#[test]
fn commands_take_the_link_that_heard_the_aircraft_first() {
    let mut gw = two_links();
    let (ta, tb): (AnyTransport, AnyTransport) = (PprzV2::new().into(), XBee24::default().into());
    feed(&mut gw, 1, 0.0, &frame(tb, 7, 1));
    feed(&mut gw, 0, 0.01, &frame(ta, 7, 1));
    feed(&mut gw, 0, 0.1, &frame(ta, 8, 1));
    let set = set();
    let desc = set.find_by_name("datalink", "SETTING").unwrap();
    let payload = [2, 7, 0, 0, 0xC0, 0x3F];
    let out = gw.uplink(0.2, 7, desc, &payload).unwrap();
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].0, 1);
    assert_eq!(out[0].1[0], 0x7E, "XBee framing on link b");
    let out = gw.uplink(0.2, 8, desc, &payload).unwrap();
    assert_eq!(out.iter().map(|o| o.0).collect::<Vec<_>>(), [0]);
    assert_eq!(&out[0].1[..6], &[0x99, 14, 0, 8, 2, 4]);
    // Never heard: every link; `All`: both links that heard 7.
    assert_eq!(gw.uplink(0.2, 9, desc, &payload).unwrap().len(), 2);
    let mut gw = gw.with_policy(Policy::All);
    assert_eq!(gw.uplink(0.2, 7, desc, &payload).unwrap().len(), 2);
    // Heard too long ago: every link again.
    assert_eq!(gw.uplink(100.0, 8, desc, &payload).unwrap().len(), 2);
}

#[test]
fn a_link_that_cannot_send_is_never_chosen() {
    let links = vec![
        GatewayLink::new("file", set(), PprzV2::new().into(), false),
        GatewayLink::new("radio", set(), PprzV2::new().into(), true),
    ];
    let mut gw = Gateway::new(set(), links);
    feed(&mut gw, 0, 0.0, &frame(PprzV2::new().into(), 7, 1));
    let set = set();
    let desc = set.find_by_name("datalink", "SETTING").unwrap();
    let out = gw.uplink(0.1, 7, desc, &[0; 6]).unwrap();
    assert_eq!(out.iter().map(|o| o.0).collect::<Vec<_>>(), [1]);
    let only_file = vec![GatewayLink::new("file", set, PprzV2::new().into(), false)];
    let mut gw = Gateway::new(set, only_file);
    assert!(gw.uplink(0.1, 7, desc, &[0; 6]).is_err());
}

#[test]
fn garbage_and_unknown_links_deliver_nothing() {
    let mut gw = two_links();
    assert!(feed(&mut gw, 5, 0.0, &frame(PprzV2::new().into(), 7, 1)).is_empty());
    let junk: Vec<u8> = (0..2000u32).map(|i| (i * 37 % 251) as u8).collect();
    assert!(feed(&mut gw, 0, 0.0, &junk).is_empty());
    let _ = Monitor::new(set(), PprzV2::new().into());
}
