//! The ground's links to aircraft: where bytes are read (UDP, TCP, a serial port, a
//! file, standard input) and where uplink frames are written.
//!
//! `pprz-monitor` opens one from its options; `pprz-gateway` opens several, each
//! described by a [`LinkSpec`] (`--link NAME=KIND:TARGET[,OPTION=VALUE]...`).
//!
//! ```
//! use pprz_ground::device::{Endpoint, LinkSpec};
//! let l: LinkSpec = "radio=udp:127.0.0.1:4242,uplink=127.0.0.1:4243,transport=xbee".parse().unwrap();
//! assert_eq!(l.name, "radio");
//! assert!(matches!(l.endpoint, Endpoint::Udp { uplink: Some(_), .. }));
//! assert!("radio=ftp:somewhere".parse::<LinkSpec>().is_err());
//! ```

use std::io::Write;
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use clap::ValueEnum;

use crate::cli::{Transport, parse_baud};
use crate::input::{self, DEFAULT_CAPACITY, InputQueue, Overflow};

/// Where uplink frames are written.
pub enum Uplink {
    /// Datagrams to an address.
    Udp(UdpSocket, SocketAddr),
    /// The stream the link reads (TCP, serial port).
    Stream(Box<dyn Write + Send>),
    /// The link cannot send (a file, standard input, UDP without an uplink address).
    None,
}

impl Uplink {
    /// Writes one frame.
    ///
    /// # Errors
    /// The write failed, or the link cannot send.
    pub fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        match self {
            Self::Udp(socket, to) => socket.send_to(frame, *to).map(drop),
            Self::Stream(w) => w.write_all(frame).and_then(|()| w.flush()),
            Self::None => Err(std::io::Error::other(
                "no uplink: give an uplink address with UDP, or use TCP or a serial port",
            )),
        }
    }

    /// Whether frames can be written.
    pub fn can_send(&self) -> bool {
        !matches!(self, Self::None)
    }
}

/// An input opened but not read yet.
pub enum Source {
    /// A UDP socket: each datagram is one read.
    Udp(UdpSocket),
    /// A byte stream, and what to do when its queue is full (a file waits; a live link
    /// drops the oldest reads).
    Stream(Box<dyn std::io::Read + Send>, Overflow),
}

impl Source {
    /// Starts the thread that reads it into a queue of [`DEFAULT_CAPACITY`] bytes.
    pub fn start(self) -> InputQueue {
        match self {
            Self::Udp(socket) => {
                let q = InputQueue::new(DEFAULT_CAPACITY, Overflow::DropOldest);
                input::spawn_udp(socket, q.clone());
                q
            }
            Self::Stream(reader, overflow) => {
                let q = InputQueue::new(DEFAULT_CAPACITY, overflow);
                input::spawn_stream(reader, q.clone());
                q
            }
        }
    }
}

/// Where a link reads.
#[derive(Debug, Clone, PartialEq)]
pub enum Endpoint {
    /// UDP datagrams received on `listen`; uplink frames sent to `uplink`.
    Udp {
        /// Address to listen on.
        listen: SocketAddr,
        /// Address of the aircraft's datalink port.
        uplink: Option<SocketAddr>,
    },
    /// A TCP server to connect to.
    Tcp(SocketAddr),
    /// A serial port at a baud rate.
    Serial {
        /// The device (e.g. /dev/ttyUSB0).
        device: String,
        /// Its baud rate.
        baud: u32,
    },
    /// A file to replay.
    File(PathBuf),
    /// Standard input.
    Stdin,
}

impl Endpoint {
    /// Opens it: the input, and where uplink frames go.
    ///
    /// # Errors
    /// A message naming the endpoint and the failure.
    pub fn open(&self) -> Result<(Source, Uplink), String> {
        match self {
            Self::Udp { listen, uplink } => {
                let socket = UdpSocket::bind(listen)
                    .map_err(|e| format!("cannot bind UDP {listen}: {e}"))?;
                let recv = socket.try_clone().map_err(|e| e.to_string())?;
                let sink = match uplink {
                    Some(to) => Uplink::Udp(socket, *to),
                    None => Uplink::None,
                };
                Ok((Source::Udp(recv), sink))
            }
            Self::Tcp(addr) => {
                let stream = TcpStream::connect(addr)
                    .map_err(|e| format!("cannot connect to {addr}: {e}"))?;
                let write = stream.try_clone().map_err(|e| e.to_string())?;
                let source = Source::Stream(Box::new(stream), Overflow::DropOldest);
                Ok((source, Uplink::Stream(Box::new(write))))
            }
            Self::Serial { device, baud } => {
                let port = serialport::new(device, *baud)
                    .timeout(Duration::from_millis(100))
                    .open()
                    .map_err(|e| format!("cannot open serial port {device}: {e}"))?;
                let write = port.try_clone().map_err(|e| e.to_string())?;
                let source = Source::Stream(Box::new(port), Overflow::DropOldest);
                Ok((source, Uplink::Stream(Box::new(write))))
            }
            Self::File(path) => {
                let file = open_file(path)?;
                Ok((
                    Source::Stream(Box::new(file), Overflow::Block),
                    Uplink::None,
                ))
            }
            Self::Stdin => {
                let source = Source::Stream(Box::new(std::io::stdin()), Overflow::Block);
                Ok((source, Uplink::None))
            }
        }
    }
}

/// Opens a file to replay: a directory is an error now, not a read error later.
///
/// # Errors
/// A message naming the file and the failure.
pub fn open_file(path: &Path) -> Result<std::fs::File, String> {
    let cannot = |e: &dyn std::fmt::Display| format!("cannot read {}: {e}", path.display());
    let file = std::fs::File::open(path).map_err(|e| cannot(&e))?;
    let meta = file.metadata().map_err(|e| cannot(&e))?;
    if meta.is_dir() {
        return Err(cannot(&"it is a directory"));
    }
    Ok(file)
}

/// The longest link name.
pub const MAX_NAME: usize = 32;

/// One link of `pprz-gateway`: `NAME=KIND:TARGET[,OPTION=VALUE]...` where KIND:TARGET is
/// `udp:ADDR`, `tcp:ADDR`, `serial:DEVICE`, `file:PATH` or `stdin:`, and the options
/// are `uplink=ADDR` (UDP), `baud=N` (serial, default 57600) and `transport=T` (as
/// `--transport`, default pprz2). NAME: 1 to [`MAX_NAME`] letters, digits, `-` or `_`.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSpec {
    /// Its name (in statistics and bus keys).
    pub name: String,
    /// Where it reads.
    pub endpoint: Endpoint,
    /// Its framing.
    pub transport: Transport,
}

impl FromStr for LinkSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let shown = crate::escape::token(s);
        let (name, rest) = s.split_once('=').ok_or_else(|| {
            format!("`{shown}`: give NAME=KIND:TARGET, e.g. radio=udp:127.0.0.1:4242")
        })?;
        check_name("link name", name)?;
        let (kind, rest) = rest.split_once(':').ok_or_else(|| {
            format!("link {name}: give KIND:TARGET (udp, tcp, serial, file, stdin)")
        })?;
        let mut parts = rest.split(',');
        let target = parts.next().unwrap_or_default();
        let (mut uplink, mut baud, mut transport) = (None, 57_600, Transport::Pprz2);
        for opt in parts {
            let (k, v) = opt.split_once('=').ok_or_else(|| {
                format!(
                    "link {name}: option `{}` is not KEY=VALUE",
                    crate::escape::token(opt)
                )
            })?;
            match k {
                "uplink" if kind == "udp" => uplink = Some(addr(name, v)?),
                "baud" if kind == "serial" => {
                    baud = parse_baud(v).map_err(|e| format!("link {name}: {e}"))?
                }
                "transport" => {
                    transport = Transport::from_str(v, true)
                        .map_err(|_| format!("link {name}: unknown transport `{}` (pprz2, pprz1, xbee, xbee868, pprzlog)", crate::escape::token(v)))?;
                }
                _ => {
                    return Err(format!(
                        "link {name}: option `{}` does not apply to {} links",
                        crate::escape::token(k),
                        crate::escape::token(kind)
                    ));
                }
            }
        }
        let endpoint = match kind {
            "udp" => Endpoint::Udp {
                listen: addr(name, target)?,
                uplink,
            },
            "tcp" => Endpoint::Tcp(addr(name, target)?),
            "serial" if !target.is_empty() => Endpoint::Serial {
                device: target.to_owned(),
                baud,
            },
            "file" if !target.is_empty() => Endpoint::File(PathBuf::from(target)),
            "stdin" if target.is_empty() => Endpoint::Stdin,
            "serial" | "file" | "stdin" => {
                return Err(format!(
                    "link {name}: `{}` is not a {kind} target",
                    crate::escape::token(target)
                ));
            }
            _ => {
                return Err(format!(
                    "link {name}: unknown kind `{}` (udp, tcp, serial, file, stdin)",
                    crate::escape::token(kind)
                ));
            }
        };
        Ok(Self {
            name: name.to_owned(),
            endpoint,
            transport,
        })
    }
}

/// Checks a name of a link or a gateway (`what`): 1 to [`MAX_NAME`] letters, digits,
/// `-` or `_`.
pub(crate) fn check_name(what: &str, name: &str) -> Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= MAX_NAME
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if ok {
        Ok(())
    } else {
        Err(format!(
            "{what} `{}`: 1 to {MAX_NAME} letters, digits, `-` or `_`",
            crate::escape::token(name)
        ))
    }
}

fn addr(name: &str, s: &str) -> Result<SocketAddr, String> {
    s.parse().map_err(|_| {
        format!(
            "link {name}: `{}` is not an address (e.g. 127.0.0.1:4242)",
            crate::escape::token(s)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_and_option_parses() {
        let l: LinkSpec = "a=tcp:127.0.0.1:4000".parse().unwrap();
        assert_eq!(l.endpoint, Endpoint::Tcp("127.0.0.1:4000".parse().unwrap()));
        let l: LinkSpec = "b=serial:/dev/ttyUSB0,baud=115200,transport=xbee868"
            .parse()
            .unwrap();
        assert_eq!(
            (l.endpoint, l.transport),
            (
                Endpoint::Serial {
                    device: "/dev/ttyUSB0".into(),
                    baud: 115_200
                },
                Transport::Xbee868
            )
        );
        let l: LinkSpec = "log_1=file:x.log,transport=pprzlog".parse().unwrap();
        assert_eq!(l.endpoint, Endpoint::File("x.log".into()));
        assert_eq!(
            "s=stdin:".parse::<LinkSpec>().unwrap().endpoint,
            Endpoint::Stdin
        );
    }

    #[test]
    fn nonsense_is_refused_with_a_reason() {
        for (bad, says) in [
            ("udp:127.0.0.1:1", "NAME=KIND:TARGET"),
            ("=udp:127.0.0.1:1", "link name"),
            ("a b=udp:127.0.0.1:1", "link name"),
            ("a=udp", "KIND:TARGET"),
            ("a=udp:nowhere", "not an address"),
            ("a=tcp:127.0.0.1:1,uplink=127.0.0.1:2", "does not apply"),
            ("a=udp:127.0.0.1:1,baud=9600", "does not apply"),
            ("a=serial:/dev/x,baud=0", "a"),
            (
                "a=udp:127.0.0.1:1,transport=carrier-pigeon",
                "unknown transport",
            ),
            ("a=file:", "not a file target"),
            ("a=ftp:x", "unknown kind"),
            ("a=udp:127.0.0.1:1,junk", "KEY=VALUE"),
            ("a=udp:\u{1b}[2J", "not an address"),
        ] {
            let e = bad.parse::<LinkSpec>().unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
            assert!(!e.contains('\u{1b}'), "{e}");
        }
        let long = format!("{}=stdin:", "n".repeat(MAX_NAME + 1));
        assert!(long.parse::<LinkSpec>().is_err());
    }
}
