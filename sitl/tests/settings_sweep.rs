//! The ground reads every setting of a 100-setting file (generated here) over the SITL's
//! simulated radio at 57600 baud, on embassy-time's mock clock: the monitor's sweep
//! (`pprz-monitor --read-settings`) against an aircraft whose settings table the file
//! describes, while the aircraft sends telemetry beside the answers and the ground PINGs
//! it once a second, as the SITL's ground does.

use std::cell::RefCell;
use std::future::Future;
use std::pin::pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::task::{Context, Poll, Wake, Waker};

use embassy_futures::select::{Either, select, select3};
use embassy_time::{Duration, Instant, MockDriver, Timer};
use embedded_io_async::{Read, Write};
use pprz_default::messages::Set;
use pprz_default::messages::telemetry::Attitude;
use pprz_devices::sim::{Overflow, SimConfig, SimLink};
use pprz_ground::monitor::Monitor;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::{SettingsTable, SweepConfig};
use pprz_ground::uplink;
use pprz_messages::settings::SettingDesc;
use pprz_telemetry::settings::Binding;
use pprz_telemetry::{FrameArena, Link, LinkMutex};
use pprz_transports::PprzV2;

/// Settings in the file.
const COUNT: usize = 100;

/// The aircraft's id.
const AC_ID: u8 = 7;

static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
static LINK: Link<'static, Set, 32, 128> = Link::new(&ARENA, AC_ID);
static VALUES: [AtomicU32; COUNT] = [const { AtomicU32::new(0) }; COUNT];

/// The SITL's radio at its defaults (`sitl --baud 57600`): a 57600-baud UART (5760 B/s),
/// as fast on the air, a 64-byte modem buffer with flow control, 5 ms of latency.
fn sitl_radio() -> SimConfig {
    SimConfig::new(5760)
        .serial_rate(5760)
        .latency(Duration::from_millis(5))
        .buffer(64)
        .overflow(Overflow::Wait)
        .seed(7)
}

/// A settings file of `n` settings in 4 groups, of several kinds: plain, with labels,
/// with a display unit.
fn settings_xml(n: usize) -> String {
    let mut xml = String::from("<settings>\n <dl_settings>\n");
    for group in 0..4 {
        xml.push_str(&format!("  <dl_settings name=\"group{group}\">\n"));
        for i in (group * n / 4)..((group + 1) * n / 4) {
            let line = match i % 3 {
                0 => format!(r#"<dl_setting var="g{group}.s{i}" min="0" max="100" step="0.5"/>"#),
                1 => format!(
                    r#"<dl_setting var="s{i}" shortname="mode{i}" min="0" max="2" values="OFF|ON|AUTO"/>"#
                ),
                _ => format!(
                    r#"<dl_setting var="angle{i}" min="-90" max="90" unit="rad" alt_unit="deg"/>"#
                ),
            };
            xml.push_str(&format!("   {line}\n"));
        }
        xml.push_str("  </dl_settings>\n");
    }
    xml.push_str(" </dl_settings>\n</settings>\n");
    xml
}

/// The aircraft's settings table, from the file's table (as the generator would emit
/// it), each setting starting at a value of its own within its bounds.
fn register(table: &SettingsTable) {
    for def in &table.set().settings {
        let i = usize::from(def.index);
        let var: &'static str = Box::leak(def.var.clone().into_boxed_str());
        let desc: &'static SettingDesc<'static> =
            Box::leak(Box::new(SettingDesc::new(def.index, var, def.min, def.max)));
        let start = def.min + (def.max - def.min) * (i % 7) as f32 / 7.0;
        VALUES[i].store(start.to_bits(), Ordering::Relaxed);
        let get: &'static (dyn Fn() -> f32 + Sync) = Box::leak(Box::new(move || {
            f32::from_bits(VALUES[i].load(Ordering::Relaxed))
        }));
        let set: &'static (dyn Fn(f32) + Sync) = Box::leak(Box::new(move |v: f32| {
            VALUES[i].store(v.to_bits(), Ordering::Relaxed)
        }));
        LINK.settings()
            .add_desc(desc, Binding::Fns(get, set))
            .unwrap();
    }
}

/// Wakes by setting a flag.
struct Flag(AtomicBool);

impl Wake for Flag {
    fn wake(self: Arc<Self>) {
        self.0.store(true, Ordering::SeqCst);
    }
}

/// Polls `fut` like an executor: again at once while it was woken, otherwise after
/// advancing the mock clock by `step`; panics after `max_steps` steps.
fn run<F: Future>(fut: F, step: Duration, max_steps: u64) -> F::Output {
    let flag = Arc::new(Flag(AtomicBool::new(false)));
    let waker = Waker::from(flag.clone());
    let mut cx = Context::from_waker(&waker);
    let mut fut = pin!(fut);
    for _ in 0..max_steps {
        loop {
            flag.0.store(false, Ordering::SeqCst);
            if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
                return v;
            }
            if !flag.0.load(Ordering::SeqCst) {
                break;
            }
        }
        MockDriver::get().advance(step);
    }
    panic!("the simulation did not finish in {max_steps} steps");
}

/// The mock clock, in seconds.
fn now() -> f64 {
    Instant::now().as_micros() as f64 / 1e6
}

#[test]
fn a_hundred_settings_are_read_over_the_57600_baud_radio_in_under_10_s() {
    MockDriver::get().reset();
    let xml = settings_xml(COUNT);
    let table = Arc::new(SettingsTable::parse(&[("hundred.xml", &xml)]).unwrap());
    assert_eq!(table.len(), COUNT);
    register(&table);
    let set = RuntimeSet::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml")).unwrap();
    let monitor =
        RefCell::new(Monitor::new(set, PprzV2::new().into()).with_settings(table.clone()));
    monitor
        .borrow_mut()
        .read_settings(AC_ID, table.len(), SweepConfig::default());
    let radio = SimLink::<LinkMutex, 16_384>::new(sitl_radio());
    let (air, ground) = radio.endpoints();
    let (air_rx, air_tx) = air.split();
    let (mut ground_rx, mut ground_tx) = ground.split();

    let aircraft = LINK.run(air_tx, air_rx);
    // Telemetry beside the answers: ATTITUDE at 100 Hz, about 2000 B/s of the 5760.
    let telemetry = async {
        loop {
            let _ = LINK.send(&Attitude {
                phi: 0.1,
                psi: 0.2,
                theta: 0.3,
            });
            Timer::after(Duration::from_millis(10)).await;
        }
    };
    let receive = async {
        let mut buf = [0u8; 256];
        loop {
            let n = ground_rx.read(&mut buf).await.unwrap();
            monitor.borrow_mut().feed(now(), &buf[..n], |_| {});
        }
    };
    let sweep = async {
        let mut sent_bytes = 0usize;
        let mut next_ping = 0.0;
        while monitor.borrow().sweeping() {
            let t = now();
            // The SITL's ground PINGs once a second: replies too.
            if t >= next_ping {
                let frame = uplink::frame(
                    monitor.borrow().set(),
                    PprzV2::new().into(),
                    AC_ID,
                    "PING",
                    &[],
                )
                .unwrap();
                ground_tx.write_all(&frame).await.unwrap();
                monitor.borrow_mut().ping_sent(Some(AC_ID), t);
                next_ping += 1.0;
            }
            let requests = monitor.borrow_mut().sweep_requests(t);
            for (ac, index) in requests {
                let values = [("index", f64::from(index)), ("ac_id", f64::from(ac))];
                let frame = {
                    let m = monitor.borrow();
                    uplink::frame(m.set(), PprzV2::new().into(), ac, "GET_SETTING", &values)
                        .unwrap()
                };
                ground_tx.write_all(&frame).await.unwrap();
                sent_bytes += frame.len();
                monitor
                    .borrow_mut()
                    .get_setting_sent(Some(ac), now(), index);
            }
            monitor.borrow_mut().tick(t);
            Timer::after(Duration::from_millis(5)).await;
        }
        sent_bytes
    };
    let background = select3(aircraft, telemetry, receive);
    let sent_bytes = match run(
        select(background, sweep),
        Duration::from_micros(100),
        200_000,
    ) {
        Either::Second(bytes) => bytes,
        Either::First(_) => unreachable!("the aircraft, its telemetry and the reader run forever"),
    };

    let m = monitor.borrow();
    let a = m.aircraft_state(AC_ID).unwrap();
    let sweep = a.sweep().unwrap();
    let seconds = sweep.duration().unwrap();
    eprintln!(
        "{} ({} GET_SETTING, {sent_bytes} bytes up; {} telemetry messages sent)",
        sweep.line(Some(&table)),
        sweep.sends(),
        LINK.stats().downlink.sent,
    );
    assert_eq!((sweep.read(), sweep.failed()), (COUNT, Vec::new()));
    // Within the aircraft's reply limit (20 per second, the PINGs included): no request
    // lost, none sent twice.
    let stats = LINK.stats();
    assert_eq!(stats.downlink.dropped.rate_limited, 0);
    assert_eq!(sweep.sends(), COUNT as u64);
    assert!(stats.services.pings >= 5, "{:?}", stats.services);
    assert!(seconds < 10.0, "{seconds} s");
    // Every value is the aircraft's.
    for (&index, &value) in a.setting_values() {
        let expected = f32::from_bits(VALUES[usize::from(index)].load(Ordering::Relaxed));
        assert_eq!(value, f64::from(expected), "setting {index}");
    }
    assert_eq!(a.setting_values().len(), COUNT);
    assert_eq!(a.settings().pending(), 0);
    // The live view names them.
    let view = m.render(now());
    assert!(view.contains("settings: 100 of 100 known"), "{view}");
    assert!(view.contains(" mode1 "), "{view}");
    assert!(view.contains("[-90, 90] deg"), "{view}");
}
