//! Host adapters against real peers: loopback TCP and UDP sockets, real files,
//! `/dev/full`, and one run on the Embassy std executor.
//!
//! Futures are driven by `common::block_on`, which polls again only when woken: a
//! missing wake-up from an I/O thread fails the test instead of being hidden by
//! busy polling.

mod common;

use std::io::{Read as _, Write as _};
use std::net::{TcpListener, UdpSocket};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use common::block_on;
use embedded_io_async::{Read, Write};
use pprz_devices::host::{HostConfig, HostDevice, HostError, HostRx, HostTx};
use pprz_transports::{Encoder, MsgHeader, PprzLog, PprzLogDecoder, TxMeta, write_frame};

/// Waits (really) until `cond` holds, up to 5 s.
fn eventually(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(5);
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        thread::sleep(Duration::from_millis(2));
    }
}

async fn read_exactly(rx: &mut impl Read<Error = HostError>, n: usize) -> Vec<u8> {
    let mut out = vec![0u8; n];
    rx.read_exact(&mut out).await.expect("read_exact");
    out
}

fn pattern(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + i / 251) as u8).collect()
}

#[test]
fn tcp_loopback_both_ways() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    // The peer echoes everything back.
    let peer = thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut buf = [0u8; 1000];
        let mut total = 0;
        loop {
            let n = s.read(&mut buf).unwrap();
            if n == 0 {
                return total;
            }
            s.write_all(&buf[..n]).unwrap();
            total += n;
        }
    });
    let config = HostConfig {
        tx_buffer: 512,
        rx_buffer: 512,
        ..HostConfig::default()
    };
    let dev = HostDevice::tcp_connect(addr, config).unwrap();
    let (mut rx, mut tx) = dev.split();
    let data = pattern(50_000);
    // Small buffers: the writer must wait for room, the reader for bytes.
    let (w, echoed) = block_on(embassy_futures::join::join(
        async {
            tx.write_all(&data).await?;
            tx.flush().await
        },
        read_exactly(&mut rx, data.len()),
    ));
    w.unwrap();
    assert_eq!(echoed, data);
    let stats = tx.stats();
    assert_eq!((stats.bytes_out, stats.bytes_in), (50_000, 50_000));
    assert_eq!((stats.tx_errors, stats.rx_errors), (0, 0));
    // Dropping the sending half shuts the stream down for writing: the peer sees EOF.
    drop(tx);
    assert_eq!(peer.join().unwrap(), 50_000);
    drop(rx);
}

#[test]
fn tcp_peer_gone_reads_eof_and_writes_fail_fast() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let peer = thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.write_all(b"bye").unwrap();
        // Closed here.
    });
    let (mut rx, mut tx) = HostDevice::tcp_connect(addr, HostConfig::default())
        .unwrap()
        .split();
    peer.join().unwrap();
    assert_eq!(block_on(read_exactly(&mut rx, 3)), b"bye");
    let mut buf = [0u8; 8];
    assert_eq!(block_on(rx.read(&mut buf)).unwrap(), 0, "end of stream");
    assert_eq!(
        block_on(rx.read(&mut buf)).unwrap(),
        0,
        "and it stays ended"
    );

    // The first send reaches a closed socket (the peer answers with a reset); a later
    // one fails. From then on every write fails at once.
    let mut error = None;
    for _ in 0..100 {
        if let Err(e) = block_on(async {
            tx.write_all(&[0x99; 100]).await?;
            tx.flush().await
        }) {
            error = Some(e);
            break;
        }
        thread::sleep(Duration::from_millis(5));
    }
    let Some(HostError::Io(kind)) = error else {
        panic!("writes to a closed peer never failed: {error:?}");
    };
    assert!(
        matches!(
            kind,
            std::io::ErrorKind::BrokenPipe
                | std::io::ErrorKind::ConnectionReset
                | std::io::ErrorKind::ConnectionAborted
        ),
        "{kind:?}"
    );
    let before = tx.stats().tx_errors;
    let started = Instant::now();
    assert_eq!(block_on(tx.write(&[1, 2, 3])), Err(HostError::Io(kind)));
    assert!(started.elapsed() < Duration::from_millis(100), "fails fast");
    assert_eq!(
        tx.stats().tx_errors,
        before + 1,
        "refused writes are counted"
    );
}

#[test]
fn udp_loopback_keeps_datagrams() {
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let local = socket.local_addr().unwrap();
    socket.connect(peer.local_addr().unwrap()).unwrap();
    let (mut rx, mut tx) = HostDevice::udp(socket, HostConfig::default())
        .unwrap()
        .split();

    // Three frames, three datagrams.
    let frames: Vec<Vec<u8>> = (0..3u8).map(|i| vec![0x99, 5 + i, i, i, i]).collect();
    block_on(async {
        for f in &frames {
            tx.write_all(f).await.unwrap();
        }
        tx.flush().await.unwrap();
    });
    let mut buf = [0u8; 100];
    for f in &frames {
        let (n, from) = peer.recv_from(&mut buf).unwrap();
        assert_eq!(from, local);
        assert_eq!(&buf[..n], f.as_slice());
    }

    // Datagrams from the peer become one byte stream.
    peer.send_to(b"abc", local).unwrap();
    peer.send_to(b"defg", local).unwrap();
    assert_eq!(block_on(read_exactly(&mut rx, 7)), b"abcdefg");
    let stats = rx.stats();
    assert_eq!((stats.bytes_in, stats.bytes_out), (7, 15));
}

#[test]
fn udp_long_write_is_split_into_datagrams() {
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let config = HostConfig {
        max_datagram: 100,
        ..HostConfig::default()
    };
    let (_rx, mut tx) = HostDevice::udp_bind("127.0.0.1:0", peer.local_addr().unwrap(), config)
        .unwrap()
        .split();
    let data = pattern(250);
    block_on(async {
        tx.write_all(&data).await.unwrap();
        tx.flush().await.unwrap();
    });
    let mut got = Vec::new();
    let mut buf = [0u8; 1000];
    for expected in [100, 100, 50] {
        let n = peer.recv(&mut buf).unwrap();
        assert_eq!(n, expected);
        got.extend_from_slice(&buf[..n]);
    }
    assert_eq!(got, data);
}

#[test]
fn udp_full_rx_buffer_drops_whole_datagrams() {
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let local = socket.local_addr().unwrap();
    socket.connect(peer.local_addr().unwrap()).unwrap();
    let config = HostConfig {
        rx_buffer: 100,
        ..HostConfig::default()
    };
    let (mut rx, _tx) = HostDevice::udp(socket, config).unwrap().split();
    for i in 0..5u8 {
        peer.send_to(&[i; 40], local).unwrap();
    }
    eventually("five datagrams handled", || {
        let s = rx.stats();
        s.bytes_in + 40 * s.rx_dropped_datagrams == 200
    });
    assert_eq!(rx.stats().rx_dropped_datagrams, 3);
    let got = block_on(read_exactly(&mut rx, 80));
    assert_eq!(got, [[0u8; 40], [1u8; 40]].concat());
}

#[test]
fn udp_without_listener_never_blocks_or_fails() {
    // A port nobody listens on any more.
    let gone = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let (_rx, mut tx) = HostDevice::udp_bind("127.0.0.1:0", gone, HostConfig::default())
        .unwrap()
        .split();
    for _ in 0..20 {
        block_on(async {
            tx.write_all(&[0x99; 30]).await.unwrap();
            tx.flush().await.unwrap();
        });
        thread::sleep(Duration::from_millis(2));
    }
    // Linux reports the ICMP "port unreachable" on the next send or receive: counted,
    // the datagram dropped, the link still usable.
    let s = tx.stats();
    assert!(s.tx_errors + s.rx_errors > 0, "{s:?}");
    assert_eq!(s.bytes_out + 30 * s.tx_errors, 600, "{s:?}");
}

#[test]
fn file_log_written_and_replayed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flight.log");
    let mut tx = HostTx::create_file(&path, HostConfig::default()).unwrap();
    let mut expected = Vec::new();
    block_on(async {
        for i in 0..100u32 {
            let meta = TxMeta::new(MsgHeader::new(7, 0, 1, (i % 250) as u8)).at(i * 10);
            let fields = i.to_le_bytes();
            let mut frame = [0u8; 32];
            let n = PprzLog::TELEMETRY
                .encode(&meta, &fields, &mut frame)
                .unwrap();
            expected.extend_from_slice(&frame[..n]);
            write_frame(&mut tx, &PprzLog::TELEMETRY, &meta, &fields)
                .await
                .unwrap();
        }
        tx.flush().await.unwrap();
    });
    assert_eq!(tx.stats().bytes_out, expected.len() as u64);
    drop(tx);
    assert_eq!(std::fs::read(&path).unwrap(), expected, "the file on disk");

    // Replay: read it back through the adapter and decode every record.
    let mut rx = HostRx::open_file(&path, HostConfig::default()).unwrap();
    let mut decoder = PprzLogDecoder::new(PprzLog::TELEMETRY);
    let mut timestamps = Vec::new();
    block_on(async {
        let mut buf = [0u8; 100];
        loop {
            let n = rx.read(&mut buf).await.unwrap();
            if n == 0 {
                break;
            }
            let mut input = &buf[..n];
            while let Some(f) = decoder.feed(&mut input) {
                timestamps.push(f.timestamp().unwrap());
            }
        }
    });
    assert_eq!(timestamps, (0..100).map(|i| i * 10).collect::<Vec<_>>());
    assert_eq!(decoder.stats().errors(), 0);
    assert!(HostRx::open_file(dir.path().join("missing"), HostConfig::default()).is_err());
}

#[test]
fn file_append_keeps_what_was_there() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.log");
    std::fs::write(&path, b"old").unwrap();
    let mut tx = HostTx::append_file(&path, HostConfig::default()).unwrap();
    block_on(async {
        tx.write_all(b"new").await.unwrap();
        tx.flush().await.unwrap();
    });
    assert_eq!(std::fs::read(&path).unwrap(), b"oldnew");
}

#[test]
fn write_error_is_sticky_and_counted() {
    // /dev/full fails every write with "no space left on device".
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        pprz_test_support::reference::skip_test(
            "write_error_is_sticky_and_counted",
            "no /dev/full here",
        );
        return;
    };
    let mut tx = HostTx::from_writer(full, HostConfig::default()).unwrap();
    let result = block_on(async {
        tx.write_all(&[1; 10]).await?;
        tx.flush().await
    });
    assert_eq!(result, Err(HostError::Io(std::io::ErrorKind::StorageFull)));
    assert_eq!(
        block_on(tx.write(&[1])),
        Err(HostError::Io(std::io::ErrorKind::StorageFull))
    );
    let s = tx.stats();
    assert_eq!((s.bytes_out, s.tx_dropped_bytes), (0, 10));
    assert!(s.tx_errors >= 3, "{s:?}");
}

/// A reader and a writer that claim more bytes than they were given.
struct Boaster;

impl std::io::Read for Boaster {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        Ok(buf.len() + 1)
    }
}

impl std::io::Write for Boaster {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        Ok(buf.len() + 1)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn a_reader_or_writer_reporting_too_many_bytes_is_an_error_not_a_panic() {
    let mut rx = HostRx::from_reader(Boaster, HostConfig::default()).unwrap();
    let mut buf = [0u8; 8];
    assert_eq!(
        block_on(rx.read(&mut buf)),
        Err(HostError::Io(std::io::ErrorKind::InvalidData))
    );
    assert_eq!(rx.stats().rx_errors, 1);
    let mut tx = HostTx::from_writer(Boaster, HostConfig::default()).unwrap();
    let result = block_on(async {
        tx.write_all(&[1; 10]).await?;
        tx.flush().await
    });
    assert_eq!(result, Err(HostError::Io(std::io::ErrorKind::InvalidData)));
    assert!(tx.stats().tx_errors >= 1, "{:?}", tx.stats());
}

static EXECUTOR: static_cell::StaticCell<embassy_executor::Executor> =
    static_cell::StaticCell::new();

#[embassy_executor::task]
async fn ping_pong(mut dev: HostDevice, done: mpsc::Sender<Vec<u8>>) {
    let mut reply = Vec::new();
    for round in 0..10u8 {
        dev.write_all(&[round; 4]).await.unwrap();
        dev.flush().await.unwrap();
        let mut buf = [0u8; 4];
        dev.read_exact(&mut buf).await.unwrap();
        reply.extend_from_slice(&buf);
    }
    done.send(reply).unwrap();
}

#[test]
fn tcp_on_the_embassy_std_executor() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let peer = thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut buf = [0u8; 4];
        for _ in 0..10 {
            s.read_exact(&mut buf).unwrap();
            s.write_all(&buf.map(|b| b + 100)).unwrap();
        }
    });
    let dev = HostDevice::tcp_connect(addr, HostConfig::default()).unwrap();
    let (done, result) = mpsc::channel();
    // The executor never returns: it runs on a thread that the test leaves behind.
    thread::spawn(move || {
        let executor = EXECUTOR.init(embassy_executor::Executor::new());
        executor.run(|spawner| spawner.spawn(ping_pong(dev, done).unwrap()));
    });
    let reply = result.recv_timeout(Duration::from_secs(10)).unwrap();
    let expected: Vec<u8> = (0..10u8).flat_map(|r| [r + 100; 4]).collect();
    assert_eq!(reply, expected);
    peer.join().unwrap();
}
