//! Settings from a Foxglove client, attacked: `pprz-monitor --foxglove` over loopback
//! UDP (`--udp`, `--uplink` to a socket of the test that collects what the ground
//! sends), driven by npm's `@foxglove/ws-protocol` client (`ground/tests/foxglove/
//! ws_client.mjs`).
//!
//! * A parameter set to a finite double that does not fit a float (1e300, -1e39) is
//!   refused as `--setting` refuses it: no SETTING goes out, the client gets an error
//!   status, the end-of-run line counts it.
//! * Reading the settings of 40 aircraft never heard does not lock the real aircraft
//!   out: aircraft 7, heard next, is tracked and published.
//! * On a secure link, a SETTING asked before the session exists is not sent, and the
//!   client is told so at once (error status), and it is counted.
//!
//! Skipped, with a printed reason, when node or the client is not installed (a failure
//! when `PPRZ_REQUIRE_REFERENCE` is set).

mod common;

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use common::MESSAGES;
use pprz_ground::set::RuntimeSet;
use pprz_test_support::viewer_tools;
use pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};
use serde_json::Value;

const KEY_FILE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../secure/keys/INSECURE-TEST-ONLY.keys"
);

/// A `pprz-monitor --foxglove` on loopback UDP.
struct Ground {
    child: Child,
    url: String,
    stderr: JoinHandle<String>,
    /// Where the monitor listens for telemetry.
    input: String,
    /// What the monitor sends (its `--uplink`).
    uplink: UdpSocket,
}

impl Ground {
    fn start(extra: &[&str]) -> Self {
        let uplink = UdpSocket::bind("127.0.0.1:0").unwrap();
        let input = {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            s.local_addr().unwrap().to_string()
        };
        let mut child = Command::new(env!("CARGO_BIN_EXE_pprz-monitor"))
            .args(["--messages", MESSAGES, "--lines", "--duration", "60"])
            .args(["--udp", &input, "--uplink"])
            .arg(uplink.local_addr().unwrap().to_string())
            .args(["--foxglove", "127.0.0.1:0"])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (url, stderr) = viewer_tools::served_url(child.stderr.take().unwrap());
        Self {
            child,
            url,
            stderr,
            input,
            uplink,
        }
    }

    /// Ends the run (Ctrl-C): the monitor's standard error, and the frames it sent.
    fn stop(mut self) -> (String, Vec<(u8, u8)>) {
        let status = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let status = self.child.wait().unwrap();
        let err = self.stderr.join().unwrap();
        assert_eq!(status.code(), Some(0), "{err}");
        (err, sent(&self.uplink))
    }
}

/// The (class, id) of every frame `uplink` received.
fn sent(uplink: &UdpSocket) -> Vec<(u8, u8)> {
    uplink
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut out = Vec::new();
    let mut buf = [0u8; 2048];
    while let Ok(n) = uplink.recv(&mut buf) {
        let mut input = &buf[..n];
        while let Some(f) = decoder.feed(&mut input) {
            out.push((f.class(), f.msg_id()));
        }
    }
    out
}

/// Runs the Foxglove client against `url` with `args`: its output lines, as JSON.
fn client(js: &Path, url: &str, args: &[&str]) -> Vec<Value> {
    let Output { status, stdout, .. } = Command::new("node")
        .arg(js)
        .arg(url)
        .args(args)
        .args(["--timeout", "20"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&stdout).into_owned();
    assert!(status.success(), "{out}");
    out.lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The messages of the error statuses in `reply`.
fn errors(reply: &[Value]) -> Vec<String> {
    reply
        .iter()
        .filter(|r| r["op"] == "status" && r["level"] == 2)
        .map(|r| r["message"].as_str().unwrap_or_default().to_owned())
        .collect()
}

/// The id of SETTING in the set.
fn setting_id() -> (u8, u8) {
    let set = RuntimeSet::load(MESSAGES).unwrap();
    let d = set.find_by_name("datalink", "SETTING").unwrap();
    (d.class_id, d.id)
}

fn node_client(who: &str) -> Option<PathBuf> {
    viewer_tools::node_client(&format!("pprz-ground {who}"))
}

/// Issue: a parameter set to 1e300 went out as SETTING value=+inf, -1e39 as -inf.
#[test]
fn a_value_that_does_not_fit_a_float_is_refused_answered_and_counted() {
    let Some(js) = node_client("a_value_that_does_not_fit_a_float_is_refused") else {
        return;
    };
    let ground = Ground::start(&[]);
    let mut replies = Vec::new();
    for (name, value) in [("/ac/7/settings/2", "1e300"), ("/ac/7/settings/3", "-1e39")] {
        let reply = client(&js, &ground.url, &["--params", name, "--set", value]);
        replies.push((value, reply));
    }
    let (err, sent) = ground.stop();
    assert!(!sent.contains(&setting_id()), "a SETTING went out: {err}");
    for (value, reply) in replies {
        let errors = errors(&reply);
        assert!(
            errors.iter().any(|e| e.contains(&format!(
                "refused: {value} is not a finite number that fits a float"
            ))),
            "{reply:?}"
        );
        assert!(
            reply
                .iter()
                .any(|r| r["op"] == "parameterValues" && r["id"] == "ws_client-set"),
            "{reply:?}"
        );
    }
    assert!(
        err.contains(
            "settings from viewers not sent: 2 refused (not a float, or outside the bounds)"
        ),
        "{err}"
    );
}

/// With `--settings`, the parameters are named after the settings files, and a value
/// outside a setting's bounds is refused with a status naming them; a label is
/// accepted.
#[test]
fn named_parameters_are_bound_checked() {
    let Some(js) = node_client("named_parameters_are_bound_checked") else {
        return;
    };
    let mut file = tempfile::Builder::new().suffix(".xml").tempfile().unwrap();
    std::io::Write::write_all(
        &mut file,
        br#"<settings><dl_settings>
          <dl_setting var="telemetry_mode" min="0" max="2" values="default|debug|minimal"/>
          <dl_setting var="payload_flood" min="0" max="1" values="OFF|ON"/>
          <dl_setting var="gain" min="0" max="10"/>
          <dl_setting var="ap_mode" min="0" max="13" values="KILL|FAILSAFE|HOME|RATE_DIRECT|ATTITUDE_DIRECT|RATE_RC_CLIMB|ATTITUDE_RC_CLIMB|ATTITUDE_CLIMB|RATE_Z_HOLD|ATTITUDE_Z_HOLD|HOVER_DIRECT|HOVER_CLIMB|HOVER_Z_HOLD|NAV"/>
        </dl_settings></settings>"#,
    )
    .unwrap();
    let path = file.path().to_str().unwrap().to_owned();
    let ground = Ground::start(&["--settings", &path]);
    let refused = client(
        &js,
        &ground.url,
        &["--params", "/ac/7/settings/gain", "--set", "12"],
    );
    let (err, sent) = ground.stop();
    assert!(!sent.contains(&setting_id()), "a SETTING went out: {err}");
    assert!(
        errors(&refused).iter().any(|e| e.contains(
            "/ac/7/settings/gain refused: setting gain (index 2): 12 is outside its bounds [0, 10]"
        )),
        "{refused:?}"
    );
    let ground = Ground::start(&["--settings", &path]);
    let label = client(
        &js,
        &ground.url,
        &["--params", "/ac/7/settings/ap_mode", "--set", "\"HOME\""],
    );
    let (err, sent) = ground.stop();
    assert!(errors(&label).is_empty(), "{label:?}");
    assert!(sent.contains(&setting_id()), "no SETTING went out: {err}");
}

/// Issue: getParameters for `/ac/100..139/settings/0` made the ground track 40
/// aircraft never heard, so the real aircraft 7 was untracked: not published, absent
/// from the table.
#[test]
fn requests_to_aircraft_never_heard_do_not_lock_the_real_one_out() {
    let Some(js) = node_client("requests_to_aircraft_never_heard_do_not_lock_the_real_one_out")
    else {
        return;
    };
    let ground = Ground::start(&[]);
    // 40 aircraft, in two requests (at most 32 names each), at once.
    let names = |ids: std::ops::Range<u8>| -> Vec<String> {
        ids.flat_map(|ac| ["--params".to_owned(), format!("/ac/{ac}/settings/0")])
            .collect()
    };
    let readers: Vec<_> = [names(100..120), names(120..140)]
        .into_iter()
        .map(|args| {
            let (js, url) = (js.clone(), ground.url.clone());
            std::thread::spawn(move || {
                let args: Vec<&str> = args.iter().map(String::as_str).collect();
                client(&js, &url, &args)
            })
        })
        .collect();
    for r in readers {
        // Answered (with nothing known) once the GET_SETTINGs went unanswered.
        let reply = r.join().unwrap();
        assert!(
            reply.iter().any(|r| r["op"] == "parameterValues"),
            "{reply:?}"
        );
    }
    // Then aircraft 7 talks, until a client has seen its attitude (at most 2000
    // frames, 10 ms apart: a hang guard).
    let stop = Arc::new(AtomicBool::new(false));
    let talker = {
        let (stop, to) = (stop.clone(), ground.input.clone());
        std::thread::spawn(move || {
            let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
            let mut buf = [0u8; 64];
            let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 6));
            let n = PprzV2::new().encode(&meta, &[0; 12], &mut buf).unwrap();
            for _ in 0..2000 {
                if stop.load(Ordering::SeqCst) {
                    break;
                }
                socket.send_to(&buf[..n], &to).unwrap();
                std::thread::sleep(Duration::from_millis(10));
            }
        })
    };
    let seen = client(
        &js,
        &ground.url,
        &["--topic", "/ac/7/telemetry/ATTITUDE", "--count", "1"],
    );
    stop.store(true, Ordering::SeqCst);
    talker.join().unwrap();
    let (err, sent) = ground.stop();
    assert_eq!(seen.len(), 1, "{err}");
    assert!(
        sent.len() >= 40,
        "the GET_SETTINGs were sent all the same: {sent:?}"
    );
    assert!(err.contains(", 0 from untracked aircraft"), "{err}");
    assert!(!err.contains("not tracked"), "{err}");
}

/// Issue: a SETTING asked before the secure session existed was rightly not sent, but
/// neither counted nor answered as not sent (only "no answer" 3 s later).
#[test]
fn a_setting_before_the_secure_session_is_answered_not_sent_and_counted() {
    let Some(js) = node_client("a_setting_before_the_secure_session_is_answered_not_sent") else {
        return;
    };
    // No aircraft answers the key exchange: the session never exists.
    let ground = Ground::start(&["--secure", KEY_FILE, "--ac-id", "7"]);
    let reply = client(
        &js,
        &ground.url,
        &["--params", "/ac/7/settings/2", "--set", "1.5"],
    );
    let (err, sent) = ground.stop();
    assert!(!sent.contains(&setting_id()), "{err}");
    let errors = errors(&reply);
    assert!(
        errors
            .iter()
            .any(|e| e.contains("/ac/7/settings/2 not sent: no secure session yet")),
        "{reply:?}"
    );
    // Answered at once, not when the request times out.
    assert!(
        !reply.iter().any(|r| r["message"]
            .as_str()
            .is_some_and(|m| m.contains("no answer"))),
        "{reply:?}"
    );
    assert!(err.contains("1 with no link to send them"), "{err}");
}
