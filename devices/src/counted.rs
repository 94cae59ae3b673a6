//! [`Counted`]: byte and error counters around any device.
//!
//! A driver's errors are handed to the caller unchanged; the wrapper only counts them,
//! so a health report (DATALINK_REPORT, a log) can show how a link behaves. The
//! counters live in an [`IoCounters`] the firmware places where every task that
//! reports can see it, typically a `static`:
//!
//! ```
//! use pprz_devices::{Counted, IoCounters, Write};
//!
//! static RADIO: IoCounters = IoCounters::new();
//!
//! # embassy_futures::block_on(async {
//! let mut out = [0u8; 8];
//! let mut uart = Counted::new(&mut out[..], &RADIO); // any embedded-io-async device
//! uart.write_all(&[0x99, 0x04, 0x00, 0x00]).await.unwrap();
//! assert_eq!(RADIO.snapshot().bytes_written, 4);
//! # });
//! ```
//!
//! Each counter must be updated by one task only (the owner of the device half it
//! counts: the reader task updates the read counters, the writer task the write
//! counters); any task may read them.

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use embedded_io_async::{ErrorType, Read, Write};

use crate::{bump, len_u32};

/// Shared byte and error counters of one device; see the [module docs](self).
#[derive(Debug, Default)]
pub struct IoCounters {
    bytes_read: AtomicU32,
    bytes_written: AtomicU32,
    read_errors: AtomicU32,
    write_errors: AtomicU32,
}

/// A copy of an [`IoCounters`]. All counters wrap around.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IoStats {
    /// Bytes returned by `read`.
    pub bytes_read: u32,
    /// Bytes accepted by `write`.
    pub bytes_written: u32,
    /// `read` calls that failed.
    pub read_errors: u32,
    /// `write` and `flush` calls that failed.
    pub write_errors: u32,
}

impl IoCounters {
    /// Zero counters; `const`, so they can live in a `static`.
    pub const fn new() -> Self {
        Self {
            bytes_read: AtomicU32::new(0),
            bytes_written: AtomicU32::new(0),
            read_errors: AtomicU32::new(0),
            write_errors: AtomicU32::new(0),
        }
    }

    /// The current values.
    pub fn snapshot(&self) -> IoStats {
        IoStats {
            bytes_read: self.bytes_read.load(Relaxed),
            bytes_written: self.bytes_written.load(Relaxed),
            read_errors: self.read_errors.load(Relaxed),
            write_errors: self.write_errors.load(Relaxed),
        }
    }
}

/// A device whose traffic and errors are counted in an [`IoCounters`]; it reads and
/// writes exactly like the device it wraps.
#[derive(Debug)]
pub struct Counted<'c, D> {
    inner: D,
    counters: &'c IoCounters,
}

impl<'c, D> Counted<'c, D> {
    /// Wraps `inner`, counting into `counters`.
    pub const fn new(inner: D, counters: &'c IoCounters) -> Self {
        Self { inner, counters }
    }

    /// The counters.
    pub fn counters(&self) -> &'c IoCounters {
        self.counters
    }

    /// The wrapped device.
    pub fn inner(&self) -> &D {
        &self.inner
    }

    /// The wrapped device, mutably (bytes moved through it directly are not counted).
    pub fn inner_mut(&mut self) -> &mut D {
        &mut self.inner
    }

    /// Unwraps the device.
    pub fn into_inner(self) -> D {
        self.inner
    }
}

impl<D: ErrorType> ErrorType for Counted<'_, D> {
    type Error = D::Error;
}

impl<D: Read> Read for Counted<'_, D> {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let result = self.inner.read(buf).await;
        match &result {
            Ok(n) => bump(&self.counters.bytes_read, len_u32(*n)),
            Err(_) => bump(&self.counters.read_errors, 1),
        }
        result
    }
}

impl<D: Write> Write for Counted<'_, D> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let result = self.inner.write(buf).await;
        match &result {
            Ok(n) => bump(&self.counters.bytes_written, len_u32(*n)),
            Err(_) => bump(&self.counters.write_errors, 1),
        }
        result
    }

    async fn flush(&mut self) -> Result<(), Self::Error> {
        let result = self.inner.flush().await;
        if result.is_err() {
            bump(&self.counters.write_errors, 1);
        }
        result
    }
}

/// Reads from `inner`, counting and skipping the errors `counter_of` maps to a
/// counter (errors that only cost data, like UART line errors); other errors are
/// returned.
#[cfg_attr(not(feature = "stm32"), allow(dead_code))]
pub(crate) async fn read_on_errors<'c, R: Read>(
    inner: &mut R,
    buf: &mut [u8],
    counter_of: impl Fn(&R::Error) -> Option<&'c AtomicU32>,
) -> Result<usize, R::Error> {
    loop {
        match inner.read(buf).await {
            Ok(n) => return Ok(n),
            Err(e) => match counter_of(&e) {
                Some(counter) => bump(counter, 1),
                None => return Err(e),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_io_async::ErrorKind;

    /// A device that fails every other call.
    struct Flaky(bool);

    impl ErrorType for Flaky {
        type Error = ErrorKind;
    }

    impl Read for Flaky {
        async fn read(&mut self, buf: &mut [u8]) -> Result<usize, ErrorKind> {
            self.0 = !self.0;
            if self.0 {
                Ok(buf.len())
            } else {
                Err(ErrorKind::Other)
            }
        }
    }

    impl Write for Flaky {
        async fn write(&mut self, buf: &[u8]) -> Result<usize, ErrorKind> {
            self.0 = !self.0;
            if self.0 {
                Ok(buf.len())
            } else {
                Err(ErrorKind::Other)
            }
        }

        async fn flush(&mut self) -> Result<(), ErrorKind> {
            Ok(())
        }
    }

    #[test]
    fn read_on_errors_counts_and_skips_line_errors() {
        /// Yields scripted results.
        struct Script(std::vec::Vec<Result<u8, ErrorKind>>);
        impl ErrorType for Script {
            type Error = ErrorKind;
        }
        impl Read for Script {
            async fn read(&mut self, buf: &mut [u8]) -> Result<usize, ErrorKind> {
                let b = self.0.remove(0)?;
                buf[0] = b;
                Ok(1)
            }
        }
        let skipped = AtomicU32::new(0);
        let mut rx = Script(std::vec![
            Err(ErrorKind::InvalidData),
            Err(ErrorKind::InvalidData),
            Ok(7),
            Err(ErrorKind::Other),
        ]);
        let classify = |e: &ErrorKind| (*e == ErrorKind::InvalidData).then_some(&skipped);
        let mut buf = [0u8; 4];
        embassy_futures::block_on(async {
            assert_eq!(read_on_errors(&mut rx, &mut buf, classify).await, Ok(1));
            assert_eq!(buf[0], 7);
            assert_eq!(
                read_on_errors(&mut rx, &mut buf, classify).await,
                Err(ErrorKind::Other)
            );
        });
        assert_eq!(skipped.load(Relaxed), 2);
    }

    #[test]
    fn counts_bytes_and_errors() {
        let counters = IoCounters::new();
        let mut dev = Counted::new(Flaky(false), &counters);
        embassy_futures::block_on(async {
            let mut buf = [0u8; 5];
            assert_eq!(dev.read(&mut buf).await, Ok(5));
            assert_eq!(dev.read(&mut buf).await, Err(ErrorKind::Other));
            assert_eq!(dev.write(&buf[..3]).await, Ok(3));
            assert_eq!(dev.write(&buf[..3]).await, Err(ErrorKind::Other));
        });
        assert_eq!(
            counters.snapshot(),
            IoStats {
                bytes_read: 5,
                bytes_written: 3,
                read_errors: 1,
                write_errors: 1
            }
        );
    }
}
