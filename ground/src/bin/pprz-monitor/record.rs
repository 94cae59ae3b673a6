//! Recording received frames to a PPRZLOG file, without ever losing data silently.
//!
//! * [`open_recording`] refuses a recording file that is one of the inputs (the file
//!   replayed, standard input redirected from a file, the `messages.xml`), whatever
//!   path names it: the same path, another spelling, a symbolic link or a hard link.
//!   Files are compared by identity (device and inode on Unix), and the recording is
//!   opened *before* it is truncated, so a refused file is left untouched.
//! * [`Recorder`] keeps the first write error, stops writing, and reports it; its
//!   [`finish`](Recorder::finish) flushes and reports a flush error too.
//! * Time stamps, 100 µs ticks since the start in 32 bits, wrap to 0 after 2^32 ticks
//!   (429 496.7296 s, about 5 days) instead of sticking at their largest value: no
//!   record loses its time, a reader adds 2^32 ticks at each wrap ([`log_stamp`]).

use std::fmt;
use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use pprz_transports::{AnyTransport, Encoder, Framing, MsgHeader, PprzLog, TxMeta};

/// The identity of a file: two paths with the same identity are the same file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileId(Id);

#[derive(Debug, Clone, PartialEq, Eq)]
enum Id {
    #[cfg(unix)]
    Inode { dev: u64, ino: u64 },
    #[cfg_attr(unix, allow(dead_code))]
    Path(PathBuf),
}

impl FileId {
    /// The identity of the file `path` names (following symbolic links).
    ///
    /// # Errors
    /// The file does not exist or cannot be examined.
    pub fn of_path(path: &Path) -> io::Result<Self> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt as _;
            let m = std::fs::metadata(path)?;
            Ok(Self(Id::Inode {
                dev: m.dev(),
                ino: m.ino(),
            }))
        }
        #[cfg(not(unix))]
        {
            Ok(Self(Id::Path(std::fs::canonicalize(path)?)))
        }
    }

    /// The identity of the open `file`, opened from `path`.
    ///
    /// # Errors
    /// The file cannot be examined.
    pub fn of_file(path: &Path, file: &File) -> io::Result<Self> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt as _;
            let _ = path;
            let m = file.metadata()?;
            Ok(Self(Id::Inode {
                dev: m.dev(),
                ino: m.ino(),
            }))
        }
        #[cfg(not(unix))]
        {
            let _ = file;
            Ok(Self(Id::Path(std::fs::canonicalize(path)?)))
        }
    }

    /// The identity of the file standard input reads, where the platform tells it.
    pub fn of_stdin() -> Option<Self> {
        #[cfg(unix)]
        {
            use std::os::fd::AsFd as _;
            use std::os::unix::fs::MetadataExt as _;
            let fd = io::stdin().as_fd().try_clone_to_owned().ok()?;
            let m = File::from(fd).metadata().ok()?;
            Some(Self(Id::Inode {
                dev: m.dev(),
                ino: m.ino(),
            }))
        }
        #[cfg(not(unix))]
        {
            None
        }
    }
}

/// Why a recording could not be opened.
#[derive(Debug)]
pub enum OpenError {
    /// The file is one of the inputs.
    OntoInput {
        /// The recording path.
        path: PathBuf,
        /// Which input it is (`the --file input`...).
        input: String,
    },
    /// The file could not be opened or truncated.
    Io {
        /// The recording path.
        path: PathBuf,
        /// The error.
        error: io::Error,
    },
}

impl fmt::Display for OpenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OntoInput { path, input } => write!(
                f,
                "refusing to record to {}: it is {input}, which recording would destroy",
                path.display()
            ),
            Self::Io { path, error } => {
                write!(f, "cannot record to {}: {error}", path.display())
            }
        }
    }
}

impl std::error::Error for OpenError {}

/// Opens `path` for a new recording, unless it is one of `inputs` (identity and a
/// description of each). The file is examined before it is truncated: a refused file
/// keeps its content. A regular file is emptied; a device (`/dev/null`) is written as is.
///
/// # Errors
/// The file is an input, or cannot be opened.
pub fn open_recording(path: &Path, inputs: &[(FileId, String)]) -> Result<File, OpenError> {
    let io_error = |error| OpenError::Io {
        path: path.to_owned(),
        error,
    };
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(io_error)?;
    let id = FileId::of_file(path, &file).map_err(io_error)?;
    if let Some((_, input)) = inputs.iter().find(|(input, _)| *input == id) {
        return Err(OpenError::OntoInput {
            path: path.to_owned(),
            input: input.clone(),
        });
    }
    if file.metadata().map_err(io_error)?.is_file() {
        file.set_len(0).map_err(io_error)?;
    }
    Ok(file)
}

/// The PPRZLOG time stamp of `now` seconds since the start: 100 µs ticks, modulo 2^32
/// (a recording longer than 429 496.7296 s wraps, as the format does, rather than
/// giving every later record the same, largest stamp). Negative or NaN times stamp 0.
pub fn log_stamp(now: f64) -> u32 {
    // `as u64` saturates (NaN to 0); a year of ticks is far below `u64::MAX`.
    let ticks = (now * 10_000.0) as u64;
    (ticks & u64::from(u32::MAX)) as u32
}

/// Writes received frames as PPRZLOG records (time stamps in 100 µs ticks, see
/// [`log_stamp`]) and keeps the first error.
#[derive(Debug)]
pub struct Recorder<W: Write> {
    out: W,
    transport: AnyTransport,
    log: PprzLog,
    buf: Vec<u8>,
    records: u64,
    error: Option<io::Error>,
}

impl<W: Write> Recorder<W> {
    /// A recorder of frames of `transport` into `out` (buffer `out` yourself, e.g. with
    /// a [`std::io::BufWriter`]).
    pub fn new(out: W, transport: AnyTransport) -> Self {
        let log = PprzLog::TELEMETRY;
        Self {
            out,
            transport,
            log,
            buf: vec![0; log.max_frame_len()],
            records: 0,
            error: None,
        }
    }

    /// Appends the frame `raw` (one frame of the recorder's transport) received at `now`
    /// seconds. A frame that does not parse or fit a record is skipped.
    ///
    /// # Errors
    /// Writing failed, now or before (the recorder writes nothing after an error); the
    /// first error is also returned by [`finish`](Self::finish).
    pub fn record(&mut self, now: f64, raw: &[u8]) -> io::Result<()> {
        if let Some(e) = &self.error {
            return Err(io::Error::new(e.kind(), e.to_string()));
        }
        let Ok((frame, _)) = self.transport.parse(raw) else {
            return Ok(());
        };
        let header = MsgHeader::new(
            frame.source(),
            frame.destination().unwrap_or(0),
            frame.class(),
            frame.msg_id(),
        )
        .with_component(frame.component());
        let meta = TxMeta::new(header).at(log_stamp(now));
        let Ok(n) = self.log.encode(&meta, frame.payload(), &mut self.buf) else {
            return Ok(());
        };
        match self.out.write_all(&self.buf[..n]) {
            Ok(()) => {
                self.records += 1;
                Ok(())
            }
            Err(e) => {
                let copy = io::Error::new(e.kind(), e.to_string());
                self.error = Some(e);
                Err(copy)
            }
        }
    }

    /// Records written (handed to the writer).
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Whether a write failed (the run reads the error from the writes themselves).
    #[cfg(test)]
    pub fn failed(&self) -> bool {
        self.error.is_some()
    }

    /// Flushes the recording and gives the writer back.
    ///
    /// # Errors
    /// The first write error, or the flush error.
    pub fn finish(mut self) -> io::Result<W> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.out.flush()?;
        Ok(self.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pprz_transports::PprzV2;

    fn frame() -> Vec<u8> {
        let mut buf = [0u8; 64];
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
        let n = PprzV2::new().encode(&meta, &[1, 2, 3], &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[derive(Debug)]
    struct Full {
        accept: usize,
    }
    impl Write for Full {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if self.accept == 0 {
                return Err(io::Error::new(
                    io::ErrorKind::StorageFull,
                    "No space left on device",
                ));
            }
            let n = buf.len().min(self.accept);
            self.accept -= n;
            Ok(n)
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    /// Issue: `--record /dev/full` ended with exit 0 and no warning.
    #[test]
    fn write_errors_are_kept_and_reported() {
        let t = AnyTransport::from(PprzV2::new());
        let mut r = Recorder::new(Full { accept: 20 }, t);
        r.record(0.0, &frame()).unwrap();
        assert!(r.record(0.1, &frame()).is_err());
        assert!(r.failed());
        assert!(r.record(0.2, &frame()).is_err(), "stays failed");
        assert_eq!(r.records(), 1);
        let e = r.finish().unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::StorageFull);
    }

    #[test]
    fn flush_errors_are_reported() {
        let t = AnyTransport::from(PprzV2::new());
        let mut r = Recorder::new(io::BufWriter::new(Full { accept: 0 }), t);
        r.record(0.0, &frame()).unwrap(); // buffered
        assert!(r.finish().is_err());
        let mut r = Recorder::new(Vec::new(), t);
        r.record(1.5, &frame()).unwrap();
        r.record(1.5, b"not a frame").unwrap();
        let log = r.finish().unwrap();
        let (rec, n) = AnyTransport::from(PprzLog::TELEMETRY).parse(&log).unwrap();
        assert_eq!(n, log.len());
        assert_eq!(
            (rec.source(), rec.msg_id(), rec.payload()),
            (7, 2, &[1, 2, 3][..])
        );
        assert_eq!(rec.timestamp(), Some(15_000));
    }

    /// Past 429 497 s the stamps wrap, as the format does, rather than every later
    /// record getting the stamp `u32::MAX`.
    #[test]
    fn stamps_wrap_after_2_pow_32_ticks() {
        // Times whose ticks are exact in an `f64`.
        assert_eq!(log_stamp(0.0), 0);
        assert_eq!(log_stamp(1.5), 15_000);
        assert_eq!(log_stamp(429_496.0), 4_294_960_000);
        // 4 295 000 000 ticks - 2^32.
        assert_eq!(log_stamp(429_500.0), 32_704);
        let year = pprz_ground::cli::MAX_DURATION;
        assert_eq!(
            u64::from(log_stamp(year)),
            (year as u64 * 10_000) % (1 << 32)
        );
        assert_eq!((log_stamp(-1.0), log_stamp(f64::NAN)), (0, 0));
        let t = AnyTransport::from(PprzV2::new());
        let mut r = Recorder::new(Vec::new(), t);
        r.record(1.5, &frame()).unwrap();
        r.record(900_000.5, &frame()).unwrap();
        let log = r.finish().unwrap();
        let pprzlog = AnyTransport::from(PprzLog::TELEMETRY);
        let (first, n) = pprzlog.parse(&log).unwrap();
        assert_eq!(first.timestamp(), Some(15_000));
        let (second, _) = pprzlog.parse(&log[n..]).unwrap();
        // 9 000 005 000 ticks - 2 x 2^32: wrapped twice.
        assert_eq!(second.timestamp(), Some(410_070_408));
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("pprz-record-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Issue: `--file rec.bin --record rec.bin` truncated the input to 0 bytes.
    #[test]
    fn the_input_is_refused_under_any_name_and_left_untouched() {
        let dir = temp_dir("refuse");
        let input = dir.join("rec.bin");
        std::fs::write(&input, b"precious").unwrap();
        let inputs = [(
            FileId::of_path(&input).unwrap(),
            "the --file input".to_owned(),
        )];
        let mut names = vec![input.clone(), dir.join(".").join("rec.bin")];
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&input, dir.join("link")).unwrap();
            std::fs::hard_link(&input, dir.join("hard")).unwrap();
            names.push(dir.join("link"));
            names.push(dir.join("hard"));
        }
        for name in &names {
            let e = open_recording(name, &inputs).unwrap_err();
            assert!(matches!(e, OpenError::OntoInput { .. }), "{name:?}: {e}");
            assert!(e.to_string().contains("refusing to record"), "{e}");
            assert_eq!(std::fs::read(&input).unwrap(), b"precious");
        }
        // Another file is emptied and recorded to.
        let other = dir.join("other.bin");
        std::fs::write(&other, b"old").unwrap();
        let mut f = open_recording(&other, &inputs).unwrap();
        f.write_all(b"new").unwrap();
        drop(f);
        assert_eq!(std::fs::read(&other).unwrap(), b"new");
        assert!(matches!(
            open_recording(&dir, &inputs),
            Err(OpenError::Io { .. })
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
