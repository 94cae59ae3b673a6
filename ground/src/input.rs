//! Received bytes on their way from the reading thread to the decoder: a queue with a
//! fixed bound, and the reading threads that fill it.
//!
//! The bound counts the bytes queued plus [`CHUNK_OVERHEAD`] per read, so a flood of
//! tiny datagrams is bounded as well as a flood of big ones. When the queue is full,
//! [`Overflow`] decides:
//!
//! * [`Overflow::DropOldest`], for live links (UDP, TCP, serial): the oldest reads are
//!   dropped, counted, and reported with the next read handed out (a *gap*: the
//!   decoder should abandon the frame it was assembling). The monitor goes on
//!   decoding what arrives now instead of falling ever further behind.
//! * [`Overflow::Block`], for files and standard input: the reader waits, so the input
//!   is read as a stream at the speed of the decoder, with nothing lost.
//!
//! ```
//! use pprz_ground::input::{InputQueue, Overflow, Pop};
//! use std::time::Duration;
//! let q = InputQueue::new(1000, Overflow::DropOldest);
//! for _ in 0..100 {
//!     q.push(&[0x99, 0xFF, 0x99, 0xFF]);
//! }
//! assert!(q.stats().cost <= 1000);
//! match q.pop(Duration::ZERO) {
//!     Pop::Data { dropped_before, .. } => assert!(dropped_before.reads > 0),
//!     other => panic!("{other:?}"),
//! }
//! ```

use std::collections::VecDeque;
use std::io::{ErrorKind, Read};
use std::net::UdpSocket;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// Bytes accounted for each read queued, on top of its length (bookkeeping and
/// allocation overhead).
pub const CHUNK_OVERHEAD: usize = 64;

/// Default bound of the input queue, in accounted bytes.
pub const DEFAULT_CAPACITY: usize = 4 << 20;

/// Smallest bound accepted (larger ones are used as given).
pub const MIN_CAPACITY: usize = 4 * CHUNK_OVERHEAD;

/// Size of the buffer of the reading threads of streams (files, TCP, serial, stdin).
pub const READ_BUFFER: usize = 4096;

/// Size of the buffer of the UDP reading thread (the largest datagram).
pub const DATAGRAM_BUFFER: usize = 65_536;

/// What to do with a read that does not fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overflow {
    /// Drop the oldest reads queued (live links).
    DropOldest,
    /// Wait for room (files and pipes, read as a stream).
    Block,
}

/// Input dropped under overload.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Drops {
    /// Bytes dropped.
    pub bytes: u64,
    /// Reads (datagrams, chunks of a stream) dropped or cut.
    pub reads: u64,
}

impl Drops {
    /// Whether nothing was dropped.
    pub fn is_empty(&self) -> bool {
        self.bytes == 0 && self.reads == 0
    }

    fn add(&mut self, other: Drops) {
        self.bytes += other.bytes;
        self.reads += other.reads;
    }
}

/// How the input ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// End of file, or the peer closed the connection.
    Eof,
    /// A read failed.
    Error(String),
}

/// What [`InputQueue::pop`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Pop {
    /// The oldest read queued.
    Data {
        /// Its bytes.
        bytes: Vec<u8>,
        /// Input dropped just before these bytes since the previous `pop` (a gap in
        /// the stream when not empty).
        dropped_before: Drops,
    },
    /// Nothing arrived within the timeout.
    Idle,
    /// The input ended and everything queued was handed out.
    End(End),
}

/// The queue's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct QueueStats {
    /// Bytes queued.
    pub queued_bytes: usize,
    /// Reads queued.
    pub queued_reads: usize,
    /// Accounted size now: bytes plus [`CHUNK_OVERHEAD`] per read; at most the bound.
    pub cost: usize,
    /// Largest accounted size seen.
    pub peak_cost: usize,
    /// Everything dropped so far.
    pub dropped: Drops,
}

#[derive(Debug, Default)]
struct State {
    reads: VecDeque<Vec<u8>>,
    stats: QueueStats,
    /// Dropped since the last pop.
    gap: Drops,
    end: Option<End>,
    /// The consumer is gone: pushes are refused.
    closed: bool,
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    readable: Condvar,
    writable: Condvar,
    capacity: usize,
    overflow: Overflow,
}

/// A bounded queue of reads, shared by one consumer and any number of producers
/// (clones of the handle).
#[derive(Debug, Clone)]
pub struct InputQueue {
    shared: Arc<Shared>,
}

impl InputQueue {
    /// A queue bounded to `capacity` accounted bytes (at least [`MIN_CAPACITY`]).
    pub fn new(capacity: usize, overflow: Overflow) -> Self {
        Self {
            shared: Arc::new(Shared {
                state: Mutex::new(State::default()),
                readable: Condvar::new(),
                writable: Condvar::new(),
                capacity: capacity.max(MIN_CAPACITY),
                overflow,
            }),
        }
    }

    /// The bound, in accounted bytes.
    pub fn capacity(&self) -> usize {
        self.shared.capacity
    }

    /// The overflow policy.
    pub fn overflow(&self) -> Overflow {
        self.shared.overflow
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic elsewhere while holding the lock leaves consistent counters: go on.
        self.shared
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Queues a read. Under [`Overflow::DropOldest`], drops the oldest reads to make
    /// room (a read larger than the whole queue keeps only its newest bytes); under
    /// [`Overflow::Block`], waits for room (a large read is queued in pieces). Returns
    /// `false`, queueing nothing, once the consumer has [closed](Self::close) the queue.
    pub fn push(&self, bytes: &[u8]) -> bool {
        if bytes.is_empty() {
            return !self.lock().closed;
        }
        let largest = self.shared.capacity - CHUNK_OVERHEAD;
        match self.shared.overflow {
            Overflow::DropOldest => {
                let mut st = self.lock();
                if st.closed {
                    return false;
                }
                let mut piece = bytes;
                if piece.len() > largest {
                    let cut = piece.len() - largest;
                    let d = Drops {
                        bytes: cut as u64,
                        reads: 1,
                    };
                    st.stats.dropped.add(d);
                    // Everything queued is older than this read: it goes too.
                    st.gap.add(d);
                    piece = &piece[cut..];
                }
                let cost = piece.len() + CHUNK_OVERHEAD;
                while st.stats.cost + cost > self.shared.capacity {
                    let Some(old) = st.reads.pop_front() else {
                        break;
                    };
                    let d = Drops {
                        bytes: old.len() as u64,
                        reads: 1,
                    };
                    st.stats.dropped.add(d);
                    st.gap.add(d);
                    st.stats.queued_bytes -= old.len();
                    st.stats.queued_reads -= 1;
                    st.stats.cost -= old.len() + CHUNK_OVERHEAD;
                }
                Self::enqueue(&mut st, piece);
                drop(st);
                self.shared.readable.notify_one();
                true
            }
            Overflow::Block => {
                for piece in bytes.chunks(largest) {
                    let cost = piece.len() + CHUNK_OVERHEAD;
                    let mut st = self.lock();
                    while !st.closed && st.stats.cost + cost > self.shared.capacity {
                        st = self
                            .shared
                            .writable
                            .wait(st)
                            .unwrap_or_else(std::sync::PoisonError::into_inner);
                    }
                    if st.closed {
                        return false;
                    }
                    Self::enqueue(&mut st, piece);
                    drop(st);
                    self.shared.readable.notify_one();
                }
                true
            }
        }
    }

    fn enqueue(st: &mut State, piece: &[u8]) {
        st.reads.push_back(piece.to_vec());
        st.stats.queued_bytes += piece.len();
        st.stats.queued_reads += 1;
        st.stats.cost += piece.len() + CHUNK_OVERHEAD;
        st.stats.peak_cost = st.stats.peak_cost.max(st.stats.cost);
    }

    /// Marks the end of the input (the first end given wins); the consumer gets it
    /// after the reads still queued.
    pub fn end(&self, end: End) {
        let mut st = self.lock();
        if st.end.is_none() {
            st.end = Some(end);
        }
        drop(st);
        self.shared.readable.notify_all();
    }

    /// The consumer stops: producers are woken and refused from now on, and what is
    /// queued is released. Returns the input lost that the consumer was not told about:
    /// the reads discarded now (counted as dropped) and the drops not yet reported by a
    /// [`Pop::Data`].
    pub fn close(&self) -> Drops {
        let mut st = self.lock();
        st.closed = true;
        let discarded = Drops {
            bytes: st.stats.queued_bytes as u64,
            reads: st.stats.queued_reads as u64,
        };
        st.stats.dropped.add(discarded);
        let mut lost = std::mem::take(&mut st.gap);
        lost.add(discarded);
        st.reads.clear();
        st.stats.queued_bytes = 0;
        st.stats.queued_reads = 0;
        st.stats.cost = 0;
        drop(st);
        self.shared.writable.notify_all();
        lost
    }

    /// Takes the oldest read, waiting at most `timeout` for one.
    pub fn pop(&self, timeout: Duration) -> Pop {
        let mut st = self.lock();
        if st.reads.is_empty() && st.end.is_none() && !timeout.is_zero() {
            st = self
                .shared
                .readable
                .wait_timeout_while(st, timeout, |st| st.reads.is_empty() && st.end.is_none())
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        let Some(bytes) = st.reads.pop_front() else {
            return match &st.end {
                Some(end) => Pop::End(end.clone()),
                None => Pop::Idle,
            };
        };
        st.stats.queued_bytes -= bytes.len();
        st.stats.queued_reads -= 1;
        st.stats.cost -= bytes.len() + CHUNK_OVERHEAD;
        let dropped_before = std::mem::take(&mut st.gap);
        drop(st);
        self.shared.writable.notify_all();
        Pop::Data {
            bytes,
            dropped_before,
        }
    }

    /// The counters now.
    pub fn stats(&self) -> QueueStats {
        self.lock().stats
    }
}

/// Reads `reader` with a fixed [`READ_BUFFER`] until its end or an error, queueing
/// each read, then marks the end of `queue`. Timeouts and interruptions (a serial port
/// without traffic) are retried. Returns when the input ends or the queue is closed.
pub fn read_stream(mut reader: impl Read, queue: &InputQueue) {
    let mut buf = [0u8; READ_BUFFER];
    loop {
        match reader.read(&mut buf) {
            Ok(0) => return queue.end(End::Eof),
            Ok(n) => {
                if !queue.push(&buf[..n]) {
                    return;
                }
            }
            Err(e) if matches!(e.kind(), ErrorKind::Interrupted | ErrorKind::TimedOut) => {}
            Err(e) => return queue.end(End::Error(e.to_string())),
        }
    }
}

/// [`read_stream`] on a thread of its own.
pub fn spawn_stream(reader: impl Read + Send + 'static, queue: InputQueue) -> JoinHandle<()> {
    std::thread::spawn(move || read_stream(reader, &queue))
}

/// Receives datagrams of `socket` on a thread of its own, queueing each whole (up to
/// [`DATAGRAM_BUFFER`] bytes), until an error or until the queue is closed.
pub fn spawn_udp(socket: UdpSocket, queue: InputQueue) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let mut buf = vec![0u8; DATAGRAM_BUFFER];
        loop {
            match socket.recv_from(&mut buf) {
                Ok((n, _)) => {
                    if !queue.push(&buf[..n]) {
                        return;
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::Interrupted
                            | ErrorKind::TimedOut
                            | ErrorKind::WouldBlock
                            | ErrorKind::ConnectionReset
                    ) => {}
                Err(e) => return queue.end(End::Error(e.to_string())),
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(p: Pop) -> (Vec<u8>, Drops) {
        match p {
            Pop::Data {
                bytes,
                dropped_before,
            } => (bytes, dropped_before),
            other => panic!("{other:?}"),
        }
    }

    /// Issue: a 10 s flood of `99 FF` false starts over UDP grew the monitor from 119 MB
    /// to 838 MB. The queue stays within its bound, and counts what it drops.
    #[test]
    fn a_flood_is_bounded_and_every_drop_counted() {
        let q = InputQueue::new(64 * 1024, Overflow::DropOldest);
        let datagram: Vec<u8> = [0x99, 0xFF].repeat(700);
        let n = 100_000u64;
        for _ in 0..n {
            assert!(q.push(&datagram));
            let st = q.stats();
            assert!(st.cost <= 64 * 1024);
        }
        let st = q.stats();
        assert!(st.peak_cost <= q.capacity());
        let per = (datagram.len() + CHUNK_OVERHEAD) as u64;
        let kept = (64 * 1024) as u64 / per;
        assert_eq!(st.queued_reads as u64, kept);
        assert_eq!(
            st.dropped,
            Drops {
                bytes: (n - kept) * datagram.len() as u64,
                reads: n - kept
            }
        );
        // The first read handed out reports the gap before it; the others do not.
        let (bytes, gap) = data(q.pop(Duration::ZERO));
        assert_eq!(bytes, datagram);
        assert_eq!(gap, st.dropped);
        let (_, gap) = data(q.pop(Duration::ZERO));
        assert!(gap.is_empty());
        let mut rest = 0;
        while let Pop::Data { dropped_before, .. } = q.pop(Duration::ZERO) {
            assert!(dropped_before.is_empty());
            rest += 1;
        }
        assert_eq!(rest + 2, kept);
        assert_eq!(q.pop(Duration::ZERO), Pop::Idle);
    }

    #[test]
    fn the_newest_input_is_kept() {
        let q = InputQueue::new(MIN_CAPACITY, Overflow::DropOldest);
        for i in 0..10u8 {
            q.push(&[i; 10]);
        }
        let mut got = Vec::new();
        while let Pop::Data { bytes, .. } = q.pop(Duration::ZERO) {
            got.push(bytes[0]);
        }
        assert_eq!(got, [7, 8, 9]);
        // A read larger than the queue keeps its newest bytes.
        let big: Vec<u8> = (0..=255).cycle().take(1000).map(|b: i32| b as u8).collect();
        q.push(&big);
        let (bytes, gap) = data(q.pop(Duration::ZERO));
        assert_eq!(bytes.len(), MIN_CAPACITY - CHUNK_OVERHEAD);
        assert_eq!(&bytes[..], &big[1000 - bytes.len()..]);
        assert_eq!(
            gap,
            Drops {
                bytes: (1000 - bytes.len()) as u64,
                reads: 1
            }
        );
        q.end(End::Eof);
        q.end(End::Error("later".into()));
        assert_eq!(q.pop(Duration::from_secs(1)), Pop::End(End::Eof));
    }

    #[test]
    fn closing_reports_the_input_not_handed_out() {
        let q = InputQueue::new(MIN_CAPACITY, Overflow::DropOldest);
        for i in 0..10u8 {
            q.push(&[i; 10]);
        }
        // Seven reads dropped, three queued: all lost when the consumer stops.
        assert_eq!(
            q.close(),
            Drops {
                bytes: 100,
                reads: 10
            }
        );
        assert_eq!(
            q.stats().dropped,
            Drops {
                bytes: 100,
                reads: 10
            }
        );
        assert_eq!(q.pop(Duration::ZERO), Pop::Idle);
    }

    /// A 64 MiB input read as a stream through a small blocking queue: nothing is
    /// lost and the queue never holds more than its bound (the issue: `--file` of a
    /// 200 MB file used 197 MB).
    #[test]
    fn a_file_is_read_as_a_stream_without_loss() {
        struct Endless {
            left: usize,
        }
        impl Read for Endless {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                let n = buf.len().min(self.left);
                buf[..n].fill(0x99);
                self.left -= n;
                Ok(n)
            }
        }
        let total = 64 << 20;
        let q = InputQueue::new(32 * 1024, Overflow::Block);
        let reader = spawn_stream(Endless { left: total }, q.clone());
        let mut got = 0;
        loop {
            match q.pop(Duration::from_secs(10)) {
                Pop::Data {
                    bytes,
                    dropped_before,
                } => {
                    assert!(dropped_before.is_empty());
                    got += bytes.len();
                }
                Pop::Idle => {}
                Pop::End(end) => {
                    assert_eq!(end, End::Eof);
                    break;
                }
            }
        }
        reader.join().unwrap();
        assert_eq!(got, total);
        let st = q.stats();
        assert!(st.peak_cost <= 32 * 1024, "{st:?}");
        assert!(st.dropped.is_empty());
    }

    #[test]
    fn read_errors_end_the_input_with_the_error() {
        struct Failing(bool);
        impl Read for Failing {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                if std::mem::replace(&mut self.0, true) {
                    Err(std::io::Error::other("Is a directory"))
                } else {
                    buf[0] = 1;
                    Ok(1)
                }
            }
        }
        let q = InputQueue::new(1024, Overflow::Block);
        read_stream(Failing(false), &q);
        assert_eq!(data(q.pop(Duration::ZERO)).0, [1]);
        assert_eq!(
            q.pop(Duration::ZERO),
            Pop::End(End::Error("Is a directory".into()))
        );
    }

    #[test]
    fn closing_releases_a_blocked_reader() {
        let q = InputQueue::new(MIN_CAPACITY, Overflow::Block);
        let reader = spawn_stream(std::io::repeat(7), q.clone());
        let (bytes, _) = data(q.pop(Duration::from_secs(10)));
        assert!(bytes.iter().all(|&b| b == 7));
        let lost = q.close();
        reader.join().unwrap();
        assert!(!q.push(&[1]));
        let st = q.stats();
        assert_eq!(st.cost, 0);
        // What was queued and never handed out is counted as dropped.
        assert_eq!(st.dropped, lost);
        assert!(lost.bytes <= (MIN_CAPACITY - CHUNK_OVERHEAD) as u64);
    }
}
