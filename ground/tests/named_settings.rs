//! `pprz-monitor --settings` through its command line: settings files with errors and
//! warnings, `--setting NAME=VALUE` refused before anything is sent, and
//! `--read-settings` against an aircraft on loopback UDP that loses a request.

mod common;

use std::io::Write as _;
use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use common::{MESSAGES, monitor, run};
use pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};

/// The example application's settings.
const APP: &str = r#"<settings>
 <dl_settings>
  <dl_settings name="app">
   <dl_setting var="telemetry_mode" min="0" max="2" values="default|debug|minimal"/>
   <dl_setting var="payload_flood" min="0" max="1" values="OFF|ON"/>
   <dl_setting var="gain" min="0" max="10" step="0.1" persistent="true"/>
   <dl_setting var="ap_mode" min="0" max="19" values="KILL|FAILSAFE|HOME|RATE_DIRECT|ATTITUDE_DIRECT|RATE_RC_CLIMB|ATTITUDE_RC_CLIMB|ATTITUDE_CLIMB|RATE_Z_HOLD|ATTITUDE_Z_HOLD|HOVER_DIRECT|HOVER_CLIMB|HOVER_Z_HOLD|NAV|RC_DIRECT|CARE_FREE|FORWARD|MODULE|FLIP|GUIDED"/>
  </dl_settings>
 </dl_settings>
</settings>
"#;

/// A settings file with `text`.
fn file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::Builder::new().suffix(".xml").tempfile().unwrap();
    f.write_all(text.as_bytes()).unwrap();
    f
}

fn path(f: &tempfile::NamedTempFile) -> &str {
    f.path().to_str().unwrap()
}

/// A free loopback UDP address.
fn free_addr() -> String {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string()
}

#[test]
fn settings_files_with_errors_exit_2_with_their_location_and_warnings_come_once() {
    let bad = file(
        "<settings><dl_settings>\n  <dl_setting var=\"gain\" min=\"0\"/>\n</dl_settings></settings>\n",
    );
    let (code, _, err) =
        run(monitor().args(["--messages", MESSAGES, "--stdin", "--settings", path(&bad)]));
    assert_eq!(code, Some(2), "{err}");
    let at = format!("error: {}:2:3: ", path(&bad));
    assert!(err.contains(&at), "{err}");
    assert!(err.contains("max"), "{err}");
    let warned = file(
        "<settings><dl_settings>\n  <dl_setting var=\"gain\" min=\"0\" max=\"1\" persistent=\"false\"/>\n</dl_settings></settings>\n",
    );
    let (code, _, err) = run(monitor().args([
        "--messages",
        MESSAGES,
        "--stdin",
        "--settings",
        path(&warned),
    ]));
    assert_eq!(code, Some(0), "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning: ")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(
        warnings[0].contains(&format!("{}:2:", path(&warned))),
        "{err}"
    );
}

#[test]
fn a_setting_out_of_bounds_is_refused_before_anything_is_sent() {
    let app = file(APP);
    let uplink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = uplink.local_addr().unwrap().to_string();
    let input = free_addr();
    let base = [
        "--messages",
        MESSAGES,
        "--udp",
        &input,
        "--uplink",
        &to,
        "--duration",
        "1",
    ];
    for (setting, expected) in [
        (
            "gain=12",
            "setting gain (index 2): 12 is outside its bounds [0, 10]",
        ),
        (
            "2=10.5",
            "setting gain (index 2): 10.5 is outside its bounds [0, 10]",
        ),
        ("ap_mode=WARP", "`WARP` is neither a number nor a label"),
        ("nope=1", "no setting is named `nope`"),
    ] {
        let (code, _, err) =
            run(monitor()
                .args(base)
                .args(["--settings", path(&app), "--setting", setting]));
        assert_eq!(code, Some(2), "{setting}: {err}");
        assert!(
            err.contains(&format!("error: --setting {setting}: ")),
            "{err}"
        );
        assert!(err.contains(expected), "{setting}: {err}");
    }
    let (code, _, err) = run(monitor().args(base).args(["--setting", "gain=1"]));
    assert_eq!(code, Some(2));
    assert!(err.contains("a name needs the settings files"), "{err}");
    uplink
        .set_read_timeout(Some(Duration::from_millis(300)))
        .unwrap();
    let mut buf = [0u8; 64];
    assert!(uplink.recv(&mut buf).is_err(), "nothing was sent");
}

/// The test's aircraft 7 on loopback UDP: answers GET_SETTING and SETTING with DL_VALUE
/// (the values of `values`, changed by SETTINGs), except the first GET_SETTING of
/// index 2, which it loses.
struct FakeAircraft {
    uplink: String,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<Vec<(u8, u8)>>,
}

impl FakeAircraft {
    fn start(ground: String, mut values: [f32; 4]) -> Self {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let uplink = socket.local_addr().unwrap().to_string();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
            let mut seen = Vec::new();
            let mut lost = false;
            let mut buf = [0u8; 512];
            while !flag.load(Ordering::SeqCst) {
                let Ok(n) = socket.recv(&mut buf) else {
                    continue;
                };
                let mut input = &buf[..n];
                while let Some(f) = decoder.feed(&mut input) {
                    let p = f.payload();
                    seen.push((f.msg_id(), p[0]));
                    let index = usize::from(p[0]);
                    match f.msg_id() {
                        16 if index == 2 && !lost => {
                            lost = true;
                            continue;
                        }
                        16 => {}
                        4 => values[index] = f32::from_le_bytes([p[2], p[3], p[4], p[5]]),
                        _ => continue,
                    }
                    let mut payload = vec![p[0]];
                    payload.extend(values[index].to_le_bytes());
                    let mut out = [0u8; 64];
                    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 31));
                    let n = PprzV2::new().encode(&meta, &payload, &mut out).unwrap();
                    socket.send_to(&out[..n], &ground).unwrap();
                }
            }
            seen
        });
        Self {
            uplink,
            stop,
            thread,
        }
    }

    /// Stops it: the (message id, index) of every request it received.
    fn stop(self) -> Vec<(u8, u8)> {
        self.stop.store(true, Ordering::SeqCst);
        self.thread.join().unwrap()
    }
}

#[test]
fn every_setting_is_read_and_shown_by_name() {
    let app = file(APP);
    let input = free_addr();
    let aircraft = FakeAircraft::start(input.clone(), [1.0, 0.0, 2.5, 13.0]);
    let (code, out, err) = run(monitor().args([
        "--messages",
        MESSAGES,
        "--udp",
        &input,
        "--uplink",
        &aircraft.uplink,
        "--settings",
        path(&app),
        "--read-settings",
        "--setting",
        "ap_mode=HOME",
        "--lines",
        "--duration",
        "3",
    ]));
    let seen = aircraft.stop();
    assert_eq!(code, Some(0), "{err}");
    // The SETTING first, then the GET_SETTINGs, index 2 twice (the first one lost).
    assert_eq!(seen[0], (4, 3), "{seen:?}");
    let gets: Vec<u8> = seen.iter().filter(|s| s.0 == 16).map(|s| s.1).collect();
    assert_eq!(gets, [0, 1, 2, 3, 2], "{seen:?}");
    assert!(
        err.contains("DL_VALUE ap_mode (index 3) = HOME (2): SETTING acknowledged after"),
        "{err}"
    );
    assert!(err.contains("settings: 0/4 read"), "progress: {err}");
    assert!(err.contains("settings: 4/4 read in "), "end: {err}");
    for line in [
        "7 telemetry DL_VALUE index=0 value=1 setting=telemetry_mode",
        "7 telemetry DL_VALUE index=2 value=2.5 setting=gain",
    ] {
        assert!(out.lines().any(|l| l == line), "{line}\n{out}");
    }
    // The summary lists every setting with its value.
    for line in [
        "settings: 4 of 4 known (index, name, value, bounds)",
        "    0 telemetry_mode           debug (1)            [0, 2]",
        "    1 payload_flood            OFF (0)              [0, 1]",
        "    2 gain                     2.5                  [0, 10]",
        "    3 ap_mode                  HOME (2)             [0, 19]",
    ] {
        assert!(err.lines().any(|l| l == line), "{line}\n{err}");
    }
}
