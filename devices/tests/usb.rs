//! The USB CDC-ACM adapter's logic against a fake endpoint (embassy-usb's own types
//! need a USB peripheral): packetisation, zero-length packets, fail-fast when the host
//! is away, write timeouts under mock time, reading.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::future::Future;
use std::pin::pin;
use std::rc::Rc;
use std::sync::{Mutex, MutexGuard};
use std::task::{Context, Poll, Waker};

use embassy_time::{Duration, Instant, MockDriver};
use embassy_usb::driver::EndpointError;
use embedded_io_async::{Read, Write};
use pprz_devices::usb::{
    PacketReceiver, PacketSender, UsbConfig, UsbCounters, UsbError, UsbRx, UsbStats, UsbTx,
};
use pprz_transports::{MsgHeader, PprzV2, PprzV2Decoder, TxMeta, write_frame};

static MOCK_TIME: Mutex<()> = Mutex::new(());

fn mock_time() -> MutexGuard<'static, ()> {
    let guard = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    guard
}

/// Polls `fut` to completion, advancing mock time by `step` whenever it is pending;
/// returns the output and the mock time it took.
fn run<F: Future>(fut: F, step: Duration) -> (F::Output, Duration) {
    let start = Instant::now();
    let mut fut = pin!(fut);
    let mut cx = Context::from_waker(Waker::noop());
    for _ in 0..100_000 {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return (v, Instant::now() - start);
        }
        MockDriver::get().advance(step);
    }
    panic!("did not finish");
}

/// Polls once: the future must complete without waiting.
fn now<F: Future>(fut: F) -> F::Output {
    let mut fut = pin!(fut);
    match fut.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
        Poll::Ready(v) => v,
        Poll::Pending => panic!("waited"),
    }
}

/// The host side of a fake CDC-ACM interface.
#[derive(Default)]
struct Host {
    configured: bool,
    dtr: bool,
    /// The host does not read: IN packets are never taken.
    stalled: bool,
    /// Take this many more packets, then deconfigure (cable pulled mid-transfer).
    unplug_after: Option<usize>,
    /// Packets the device sent.
    packets: Vec<Vec<u8>>,
    /// OUT packets to deliver (`None`: the device is deconfigured at that point).
    out: VecDeque<Option<Vec<u8>>>,
}

#[derive(Clone)]
struct Fake(Rc<RefCell<Host>>, u16);

impl PacketSender for Fake {
    fn max_packet_size(&self) -> u16 {
        self.1
    }

    fn dtr(&self) -> bool {
        self.0.borrow().dtr
    }

    async fn write_packet(&mut self, data: &[u8]) -> Result<(), EndpointError> {
        assert!(data.len() <= usize::from(self.1));
        {
            let mut h = self.0.borrow_mut();
            if let Some(0) = h.unplug_after {
                h.configured = false;
            }
            if let Some(n) = h.unplug_after.as_mut() {
                *n = n.saturating_sub(1);
            }
            if !h.configured {
                return Err(EndpointError::Disabled);
            }
            if !h.stalled {
                h.packets.push(data.to_vec());
                return Ok(());
            }
        }
        std::future::pending().await
    }
}

impl PacketReceiver for Fake {
    fn max_packet_size(&self) -> u16 {
        self.1
    }

    async fn read_packet(&mut self, data: &mut [u8]) -> Result<usize, EndpointError> {
        let next = self.0.borrow_mut().out.pop_front();
        match next {
            Some(Some(p)) => {
                data[..p.len()].copy_from_slice(&p);
                Ok(p.len())
            }
            Some(None) => {
                self.0.borrow_mut().configured = false;
                Err(EndpointError::Disabled)
            }
            None => std::future::pending().await,
        }
    }

    async fn wait_connection(&mut self) {
        // The host comes back after 5 ms.
        embassy_time::Timer::after(Duration::from_millis(5)).await;
        self.0.borrow_mut().configured = true;
    }
}

fn connected() -> Rc<RefCell<Host>> {
    Rc::new(RefCell::new(Host {
        configured: true,
        dtr: true,
        ..Host::default()
    }))
}

fn lens(host: &Rc<RefCell<Host>>) -> Vec<usize> {
    host.borrow_mut()
        .packets
        .drain(..)
        .map(|p| p.len())
        .collect()
}

#[test]
fn writes_are_split_into_packets_with_zlp_on_boundaries() {
    let host = connected();
    let counters = UsbCounters::new();
    let mut tx = UsbTx::new(Fake(host.clone(), 64), &counters, UsbConfig::default());
    let data: Vec<u8> = (0..=255).collect();
    for (len, packets) in [
        (150, vec![64, 64, 22]),
        (128, vec![64, 64, 0]),
        (64, vec![64, 0]),
        (10, vec![10]),
        (63, vec![63]),
        (256, vec![64, 64, 64, 64, 0]),
    ] {
        assert_eq!(now(tx.write(&data[..len])), Ok(len), "write of {len}");
        assert_eq!(lens(&host), packets, "write of {len}");
    }
    assert_eq!(now(tx.write(&[])), Ok(0));
    assert!(lens(&host).is_empty(), "an empty write sends nothing");
    assert_eq!(now(tx.flush()), Ok(()));
    assert_eq!(
        counters.snapshot(),
        UsbStats {
            bytes_written: 150 + 128 + 64 + 10 + 63 + 256,
            packets: 3 + 2 + 1 + 1 + 1 + 4,
            zlps: 3,
            ..UsbStats::default()
        }
    );
}

#[test]
fn frames_reach_the_host_as_whole_transfers() {
    let host = connected();
    let counters = UsbCounters::new();
    let mut tx = UsbTx::new(Fake(host.clone(), 64), &counters, UsbConfig::default());
    // A 64-byte frame (56 field bytes) and a 20-byte one.
    for fields in [56usize, 12] {
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
        now(write_frame(
            &mut tx,
            &PprzV2::new(),
            &meta,
            &vec![0xAB; fields],
        ))
        .unwrap();
    }
    // The host's bulk reads end at each short (or zero-length) packet.
    let packets = std::mem::take(&mut host.borrow_mut().packets);
    let mut transfers = vec![Vec::new()];
    for p in &packets {
        transfers.last_mut().unwrap().extend_from_slice(p);
        if p.len() < 64 {
            transfers.push(Vec::new());
        }
    }
    transfers.pop();
    assert_eq!(
        transfers.iter().map(Vec::len).collect::<Vec<_>>(),
        [64, 20],
        "each frame completes its own transfer"
    );
    let mut decoder = PprzV2Decoder::new(PprzV2::new());
    for t in &transfers {
        let mut input = t.as_slice();
        assert!(decoder.feed(&mut input).is_some());
    }
}

#[test]
fn host_not_connected_fails_fast_and_is_counted() {
    let _t = mock_time();
    let host = Rc::new(RefCell::new(Host::default()));
    let counters = UsbCounters::new();
    let mut tx = UsbTx::new(Fake(host.clone(), 64), &counters, UsbConfig::default());
    // Not configured, DTR low: refused at the first poll.
    for _ in 0..3 {
        assert_eq!(now(tx.write(&[0x99; 20])), Err(UsbError::NotConnected));
    }
    assert!(!tx.host_ready());
    // Configured but the port is closed (DTR low): still refused.
    host.borrow_mut().configured = true;
    assert_eq!(now(tx.write(&[0x99; 20])), Err(UsbError::NotConnected));
    // Without the DTR requirement, an unconfigured device is refused by the endpoint.
    let mut no_dtr = UsbTx::new(
        Fake(host.clone(), 64),
        &counters,
        UsbConfig {
            require_dtr: false,
            ..UsbConfig::default()
        },
    );
    host.borrow_mut().configured = false;
    assert_eq!(now(no_dtr.write(&[0x99; 20])), Err(UsbError::NotConnected));
    assert!(host.borrow().packets.is_empty());
    assert_eq!(counters.snapshot().not_connected, 5);
    assert_eq!(counters.snapshot().packets, 0);
}

#[test]
fn host_that_stops_reading_times_out() {
    let _t = mock_time();
    let host = connected();
    host.borrow_mut().stalled = true;
    let counters = UsbCounters::new();
    let mut tx = UsbTx::new(Fake(host.clone(), 64), &counters, UsbConfig::default());
    let (result, took) = run(tx.write(&[1; 100]), Duration::from_millis(1));
    assert_eq!(result, Err(UsbError::Timeout));
    assert_eq!(took, Duration::from_millis(50));
    assert_eq!(counters.snapshot().timeouts, 1);
    // The host reads again: writes go through.
    host.borrow_mut().stalled = false;
    assert_eq!(
        run(tx.write(&[1; 100]), Duration::from_millis(1)).0,
        Ok(100)
    );
    assert_eq!(lens(&host), [64, 36]);
}

#[test]
fn a_timeout_too_long_for_the_clock_never_expires() {
    let _t = mock_time();
    let host = connected();
    let counters = UsbCounters::new();
    let config = UsbConfig {
        write_timeout: Some(Duration::MAX),
        ..UsbConfig::default()
    };
    let mut tx = UsbTx::new(Fake(host.clone(), 64), &counters, config);
    // Past the clock's start, so that `now + timeout` overflows.
    MockDriver::get().advance(Duration::from_secs(1));
    assert_eq!(
        run(tx.write(&[1; 100]), Duration::from_millis(1)).0,
        Ok(100)
    );
    assert_eq!(counters.snapshot().timeouts, 0);
}

#[test]
fn unplugged_mid_write_reports_what_was_sent() {
    let host = connected();
    host.borrow_mut().unplug_after = Some(1);
    let counters = UsbCounters::new();
    let mut tx = UsbTx::new(Fake(host.clone(), 64), &counters, UsbConfig::default());
    assert_eq!(
        now(tx.write(&[2; 200])),
        Ok(64),
        "the first packet went out"
    );
    assert_eq!(now(tx.write(&[2; 136])), Err(UsbError::NotConnected));
    let s = counters.snapshot();
    assert_eq!((s.packets, s.bytes_written, s.not_connected), (1, 64, 2));
}

#[test]
fn reads_any_length_skip_zlps_and_wait_for_the_host() {
    let _t = mock_time();
    let host = connected();
    let full: Vec<u8> = (100..164).collect();
    host.borrow_mut().out = VecDeque::from([
        Some(vec![]),
        Some(b"abc".to_vec()),
        Some(full.clone()),
        None, // unplugged; comes back 5 ms later
        Some(vec![]),
        Some(b"xyz".to_vec()),
    ]);
    let counters = UsbCounters::new();
    let mut rx = UsbRx::<_, 64>::new(Fake(host.clone(), 64), &counters).unwrap();
    let expected = [b"abc".as_slice(), &full, b"xyz"].concat();
    let (got, took) = run(
        async {
            let mut got = Vec::new();
            let mut buf = [0u8; 5];
            while got.len() < expected.len() {
                let n = rx.read(&mut buf).await.unwrap();
                assert!(n > 0);
                got.extend_from_slice(&buf[..n]);
            }
            got
        },
        Duration::from_millis(1),
    );
    assert_eq!(got, expected);
    assert_eq!(took, Duration::from_millis(5), "waited for the host once");
    let s = counters.snapshot();
    assert_eq!((s.bytes_read, s.disconnects), (70, 1));

    assert!(matches!(
        UsbRx::<_, 32>::new(Fake(host, 64), &counters),
        Err(UsbError::BufferTooSmall)
    ));
}
