//! The ground's links to aircraft: where bytes are read (UDP, TCP, a serial port, a
//! file, standard input) and where uplink frames are written.
//!
//! `pprz-monitor` opens one from its options; `pprz-gateway` opens several, each
//! described by a [`LinkSpec`] (`--link NAME=KIND:TARGET[,OPTION=VALUE]...`).
//! `pprz-monitor --zenoh` reads a whole fleet from a gateway on the fleet bus instead:
//! a [`Source::Queue`] that the bus fills, and an [`Uplink::Commands`] that turns each
//! uplink frame back into a command ([`command`]).
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

use crate::cli::{Transport, parse_baud};
use crate::input::{self, DEFAULT_CAPACITY, InputQueue, Overflow};
use crate::set::RuntimeSet;
use clap::ValueEnum;
use pprz_transports::{Framing, PprzV2};

/// The receive buffer asked for a UDP link, in bytes: datagrams wait there while the
/// reader is busy (50 000 frames a second of about 40 bytes fill the Linux default of
/// 208 KiB in about 5 ms). The system may grant less.
pub const UDP_RECEIVE_BUFFER: usize = 4 << 20;

/// Where uplink frames are written.
pub enum Uplink {
    /// Datagrams to an address.
    Udp(UdpSocket, SocketAddr),
    /// The stream the link reads (TCP, serial port).
    Stream(Box<dyn Write + Send>),
    /// Commands (on the fleet bus): each frame turned back into one ([`CommandUplink`]).
    Commands(Box<CommandUplink>),
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
            Self::Commands(c) => c.send(frame),
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
    /// A queue that something else fills (the fleet bus's subscriber).
    Queue(InputQueue),
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
            Self::Queue(q) => q,
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
                // Best effort: the system may cap it (Linux: net.core.rmem_max).
                let _ = socket2::SockRef::from(&socket).set_recv_buffer_size(UDP_RECEIVE_BUFFER);
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

/// A command: the datalink message an uplink frame carries, for the fleet bus
/// (`pprz/<ac_id>/uplink/<MESSAGE>`, the JSON of its fields).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Command {
    /// The aircraft: the frame's destination.
    pub ac_id: u8,
    /// The message's name.
    pub message: &'static str,
    /// Its fields, as a JSON object ([`json::message`](crate::json::message)).
    pub fields: String,
}

/// Where commands go (a put on the fleet bus).
pub type CommandSink = Box<dyn FnMut(Command) -> std::io::Result<()> + Send>;

/// The uplink of a ground station that sends commands instead of frames: each uplink
/// frame (PPRZ v2, as [`uplink::frame`](crate::uplink::frame) builds it) is turned back
/// into the [`Command`] it carries, which the sink puts on the bus; the gateway frames
/// it again for the aircraft.
pub struct CommandUplink {
    set: RuntimeSet,
    sink: CommandSink,
}

impl CommandUplink {
    /// Commands of the datalink messages of `set`, handed to `sink`.
    pub fn new(set: RuntimeSet, sink: CommandSink) -> Self {
        Self { set, sink }
    }

    /// Hands the command that `frame` carries to the sink.
    ///
    /// # Errors
    /// The frame carries no command ([`command`]), or the sink failed.
    pub fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        let c = command(&self.set, frame).map_err(std::io::Error::other)?;
        (self.sink)(c)
    }
}

/// The command an uplink frame carries.
///
/// ```
/// use pprz_ground::{device, set::RuntimeSet, uplink};
/// use pprz_transports::PprzV2;
/// let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="datalink" id="2">
///     <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
///     </msg_class></protocol>"#).unwrap();
/// let f = uplink::frame(&set, PprzV2::new().into(), 8, "SETTING", &[("index", 2.0), ("value", 1.5)]).unwrap();
/// let c = device::command(&set, &f).unwrap();
/// assert_eq!((c.ac_id, c.message), (8, "SETTING"));
/// assert_eq!(c.fields, r#"{"index":2,"ac_id":8,"value":1.5}"#);
/// ```
///
/// # Errors
/// Why the frame carries no command (not one valid PPRZ v2 frame, not a datalink
/// message of the set, a payload that does not match the message).
pub fn command(set: &RuntimeSet, frame: &[u8]) -> Result<Command, String> {
    let (f, len) = PprzV2::new()
        .parse(frame)
        .map_err(|e| format!("not a PPRZ v2 frame: {e}"))?;
    if len != frame.len() {
        return Err(format!("{} bytes after the frame", frame.len() - len));
    }
    let desc = set
        .find(f.class(), f.msg_id())
        .filter(|d| d.class_name == "datalink")
        .ok_or_else(|| {
            format!(
                "class {} message {} is no datalink message of the set",
                f.class(),
                f.msg_id()
            )
        })?;
    let fields =
        crate::json::message(desc, f.payload()).map_err(|e| format!("{}: {e}", desc.name))?;
    Ok(Command {
        ac_id: f.destination().unwrap_or(pprz_transports::BROADCAST_ID),
        message: desc.name,
        fields,
    })
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
    fn only_a_datalink_frame_of_the_set_is_a_command() {
        use pprz_transports::{Encoder, MsgHeader, TxMeta};
        let set = RuntimeSet::parse(
            "m.xml",
            r#"<protocol>
            <msg_class name="telemetry" id="1"><message name="PONG" id="3"/></msg_class>
            <msg_class name="datalink" id="2">
              <message name="PING" id="8"/>
              <message name="GET_SETTING" id="16"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/></message>
            </msg_class></protocol>"#,
        )
        .unwrap();
        let t = PprzV2::new();
        let frame = |class, id, payload: &[u8]| {
            let mut buf = [0u8; 64];
            let meta = TxMeta::new(MsgHeader::new(0, 9, class, id));
            let n = t.encode(&meta, payload, &mut buf).unwrap();
            buf[..n].to_vec()
        };
        let ping = Command {
            ac_id: 9,
            message: "PING",
            fields: "{}".into(),
        };
        assert_eq!(command(&set, &frame(2, 8, &[])), Ok(ping));
        let get = command(&set, &frame(2, 16, &[3, 9])).unwrap();
        assert_eq!(
            (get.ac_id, get.message, get.fields.as_str()),
            (9, "GET_SETTING", r#"{"index":3,"ac_id":9}"#)
        );
        let mut two = frame(2, 8, &[]);
        two.extend(frame(2, 8, &[]));
        let mut bad_sum = frame(2, 8, &[]);
        *bad_sum.last_mut().unwrap() ^= 1;
        for (f, says) in [
            (frame(1, 3, &[]), "no datalink message"),
            (frame(2, 99, &[]), "no datalink message"),
            (frame(2, 16, &[3]), "GET_SETTING"),
            (two, "bytes after the frame"),
            (bad_sum, "not a PPRZ v2 frame"),
            (Vec::new(), "not a PPRZ v2 frame"),
            (vec![0x99], "not a PPRZ v2 frame"),
        ] {
            let e = command(&set, &f).unwrap_err();
            assert!(e.contains(says), "{f:?}: {e}");
        }
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
