//! `sitl --foxglove`, checked live by an independent client: npm's
//! `@foxglove/ws-protocol` client (`ground/tests/foxglove/ws_client.mjs`) subscribes to
//! the SITL's topics; the values it receives are the ones the SITL's monitor prints
//! (`--lines`), the location follows GPS_INT, and the link statistics carry the
//! aircraft's own per-level figures. A client that vanishes mid-stream changes nothing.
//!
//! The client is found with `pprz_test_support::viewer_tools` (skipped, with a printed
//! reason, when it is not installed; a failure when `PPRZ_REQUIRE_REFERENCE` is set).

use std::net::UdpSocket;
use std::process::{Command, Stdio};

use serde_json::Value;

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The `name=value` fields of a monitor line (labels and units left out).
fn line_fields(line: &str) -> Vec<(String, String)> {
    line.split_whitespace()
        .skip(3)
        .filter_map(|t| {
            let (name, value) = t.split_once('=')?;
            let value = value.split('(').next().unwrap_or(value);
            Some((name.to_owned(), value.to_owned()))
        })
        .collect()
}

/// Whether a JSON message has the values of a monitor line (every numeric field equal).
fn same_values(message: &Value, line: &str) -> bool {
    let fields = line_fields(line);
    !fields.is_empty()
        && fields.iter().all(|(name, text)| {
            let json = &message[name.as_str()];
            match (json.as_f64(), text.parse::<f64>()) {
                (Some(a), Ok(b)) => a == b,
                _ => json.is_array() || json.is_string(),
            }
        })
}

#[test]
fn a_foxglove_client_receives_the_values_the_monitor_prints() {
    let who = "pprz-sitl a_foxglove_client_receives_the_values_the_monitor_prints";
    let Some(client) = pprz_test_support::viewer_tools::node_client(who) else {
        return;
    };
    let ground = format!("127.0.0.1:{}", free_port());
    let uplink = format!("127.0.0.1:{}", free_port());
    let mut sitl = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .args(["--duration", "16", "--speed", "2", "--lines"])
        .args(["--ground", &ground, "--uplink", &uplink])
        .args(["--foxglove", "127.0.0.1:0"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Standard error: the server's address, then whatever else (read to the end).
    let (url, reader) = pprz_test_support::viewer_tools::served_url(sitl.stderr.take().unwrap());

    // A setting written from the viewer: the SETTING goes to the aircraft, and the answer
    // is the value its DL_VALUE reports (setting 2 is the example's `gain`;
    // before the SITL's own SETTING of it, at 3 s).
    let params = Command::new("node")
        .args([client.to_str().unwrap(), &url])
        .args([
            "--params",
            "/ac/7/settings/gain",
            "--set",
            "1.5",
            "--timeout",
            "20",
        ])
        .output()
        .unwrap();
    let params_out = String::from_utf8_lossy(&params.stdout).into_owned();
    let params_err = String::from_utf8_lossy(&params.stderr).into_owned();

    // A client that vanishes without a close handshake.
    let vanished = Command::new("node")
        .args([client.to_str().unwrap(), &url, "--vanish"])
        .output()
        .unwrap();
    assert!(
        vanished.status.success(),
        "{}",
        String::from_utf8_lossy(&vanished.stderr)
    );

    let out = Command::new("node")
        .args([client.to_str().unwrap(), &url])
        .args(["--topic", "/ac/7/telemetry/ATTITUDE"])
        .args(["--topic", "/ac/7/telemetry/GPS_INT"])
        .args(["--topic", "/ac/7/location"])
        .args(["--topic", "/ac/7/link"])
        .args(["--count", "30", "--timeout", "25"])
        .output()
        .unwrap();
    let client_err = String::from_utf8_lossy(&out.stderr).into_owned();
    let sitl_out = sitl.wait_with_output().unwrap();
    let sitl_err = reader.join().unwrap();
    assert!(
        out.status.success(),
        "client: {client_err}\nsitl: {sitl_err}"
    );
    assert!(sitl_out.status.success(), "{sitl_err}");
    let lines = String::from_utf8_lossy(&sitl_out.stdout).into_owned();

    assert!(params.status.success(), "{params_err}");
    let reply: Vec<Value> = params_out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(
        reply
            .iter()
            .any(|r| r.to_string().contains("/ac/7/settings/gain") && r.to_string().contains("1.5")),
        "{params_out}"
    );
    assert!(
        lines
            .lines()
            .any(|l| l == "7 telemetry DL_VALUE index=2 value=1.5 setting=gain"),
        "the aircraft never reported the new value"
    );
    let received: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(received.len(), 30, "{client_err}");
    let mut seen = std::collections::BTreeSet::new();
    for r in &received {
        let topic = r["topic"].as_str().unwrap();
        seen.insert(topic.to_owned());
        let m = &r["message"];
        match topic {
            "/ac/7/telemetry/ATTITUDE" | "/ac/7/telemetry/GPS_INT" => {
                let name = topic.rsplit('/').next().unwrap();
                let prefix = format!("7 telemetry {name} ");
                assert!(
                    lines
                        .lines()
                        .filter(|l| l.starts_with(&prefix))
                        .any(|l| same_values(m, l)),
                    "no monitor line has the values of {m}"
                );
                assert_eq!(r["schemaName"], format!("pprz.telemetry.{name}"));
            }
            "/ac/7/location" => {
                assert_eq!(r["schemaName"], "foxglove.LocationFix");
                let (lat, lon) = (
                    m["latitude"].as_f64().unwrap(),
                    m["longitude"].as_f64().unwrap(),
                );
                // The same fix as one of the GPS_INT lines (1e7 degrees).
                assert!(
                    lines
                        .lines()
                        .filter(|l| l.starts_with("7 telemetry GPS_INT "))
                        .any(|l| {
                            let f = line_fields(l);
                            let get = |n: &str| {
                                f.iter()
                                    .find(|(k, _)| k == n)
                                    .and_then(|(_, v)| v.parse::<f64>().ok())
                            };
                            get("lat") == Some((lat * 1e7).round())
                                && get("lon") == Some((lon * 1e7).round())
                        }),
                    "no GPS_INT line at {lat} {lon}"
                );
            }
            "/ac/7/link" => {
                assert_eq!(r["schemaName"], "pprz.LinkStats");
                let levels = m["levels"].as_array().unwrap();
                assert_eq!(levels.len(), 3);
                for l in levels {
                    let (submitted, sent) = (l["submitted"].as_u64(), l["sent"].as_u64());
                    assert!(submitted.is_some() && sent <= submitted, "{l}");
                }
            }
            other => panic!("not subscribed: {other}"),
        }
    }
    for topic in [
        "/ac/7/telemetry/ATTITUDE",
        "/ac/7/telemetry/GPS_INT",
        "/ac/7/location",
    ] {
        assert!(seen.contains(topic), "nothing on {topic}: {seen:?}");
    }
}
