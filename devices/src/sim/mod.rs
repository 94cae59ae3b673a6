//! A simulated radio link for tests and host runs (feature `sim`).
//!
//! [`SimLink`] is a pair of connected endpoints, A (the aircraft) and B (the ground).
//! Each direction models a radio modem behind a UART, as SiK/3DR radios, XBee modules
//! and serial-to-LoRa bridges are:
//!
//! ```text
//!          serial_rate                          byte_rate   bit_error_rate   latency
//! write ──> [ UART ] ──> [ modem buffer ] ──> [  air  ] ──> (seeded) ──> + latency ──> [ receiver ring ] ──> read
//!             ▲           `buffer` bytes                                                  N bytes
//!             │           full: Drop: the modem drops (counted)
//!             └── CTS ─── full: Wait: the UART stops until there is room
//! ```
//!
//! * **Serial rate** ([`SimConfig::serial_rate`], bytes/s; 0, the default: instant): a
//!   byte enters the modem when its last bit has crossed the UART, one every
//!   `1 / serial_rate` s, so a long write fills the modem buffer while it is under way.
//!   The `write` future completes when its last byte has crossed the UART (cancelling
//!   it keeps the bytes that already crossed, like a UART DMA transfer stopped half-way).
//!   For a UART with 8N1 framing, `serial_rate = baud / 10`.
//! * **Air rate** ([`SimConfig::byte_rate`], bytes/s; 0: instant): the modem sends
//!   the bytes of its buffer one after the other, one every `1 / byte_rate` s.
//! * **Modem buffer** ([`SimConfig::buffer`]): at most `buffer` bytes wait in the modem
//!   (the byte on the air counts). A real modem does not push back on its UART: when it
//!   is full, [`Overflow::Drop`] (the default) drops the bytes that arrive and counts
//!   them in [`SimStats::dropped_bytes`]; the write still completes, as a UART write to
//!   a modem does. [`Overflow::Wait`] models hardware flow control (CTS): the UART
//!   stops while the buffer is full, so nothing is dropped and the backlog stays in the
//!   writer's queue, where it can be shed by priority. With a serial rate above the air
//!   rate and `Drop`, a sustained writer overfills the modem and loses bytes at random,
//!   unless it paces itself to the air rate.
//! * **Bit errors** ([`SimConfig::bit_error_rate`]): every bit sent is flipped with that
//!   probability, drawn from a SplitMix64 generator seeded with [`SimConfig::seed`]
//!   (the other direction uses a derived seed), so a run is reproducible. Flipped bits
//!   are counted.
//! * **Latency** ([`SimConfig::latency`]): a byte can be read `latency` after its last
//!   bit was sent. The receiving modem's UART is not modelled: a byte (or an API frame)
//!   is readable as soon as it has arrived.
//! * **Receiver ring** (`N`, the const parameter): the bytes accepted by the modem,
//!   those in the air and those arrived but not yet read share one ring of `N` bytes per
//!   direction. If the receiver does not read and the ring fills, further bytes are lost
//!   as receiver overruns ([`SimStats::overrun_bytes`]) with `Drop`, or the writer waits
//!   with `Wait`.
//! * **Outages** ([`SimLink::add_outage`]): windows of time in which a direction
//!   delivers nothing (the radio out of range). The modem does not know: it sends at its
//!   air rate as usual, and the bytes whose transmission ends in a window are lost and
//!   counted ([`SimStats::outage_bytes`]).
//!
//! The UART and air time are measured ([`SimStats::serial_busy_us`],
//! [`SimStats::air_busy_us`]): divided by the elapsed time they give the utilisation of
//! the UART and of the radio channel.
//!
//! # XBee API modem
//!
//! [`SimConfig::xbee`] turns the modem into an XBee in API mode (API 1, no escaping),
//! 802.15.4 ([`XBeeVariant::XBee24`]) or 868 MHz ([`XBeeVariant::XBee868`]):
//!
//! ```text
//! A write: TX request ──> [ UART ] ──> API parser ──> [ modem: whole frames ] ──> air: RF data ──> B read: RX frame
//!                                      malformed:       full: Drop (whole frame)    + air_overhead,
//!                                      counted, dropped       or Wait (CTS)         retries
//! A read:  TX status (frame id != 0) <──── ack_delay after the last attempt ───────────┘
//! ```
//!
//! * Endpoint A writes API transmit requests: 802.15.4 TX16
//!   `7E len | 01 frame_id dest_hi dest_lo options RF-data | ck`, 868
//!   `7E len | 10 frame_id dest64(8) FF FE radius options RF-data | ck`, with
//!   `ck = 0xFF - sum(FRAME_DATA)`. Bytes outside a frame, frames with a bad length or
//!   checksum, other API ids and RF data longer than the module's maximum (100 bytes
//!   for 802.15.4, 256 for 868) are dropped and counted
//!   ([`SimStats::malformed_frames`], [`SimStats::discarded_bytes`]).
//! * Only the RF data goes over the air, plus [`XBeeModem::air_overhead`] bytes per
//!   transmission (MAC header, preamble, acknowledgement). Endpoint B reads it as an RX
//!   frame: 802.15.4 `81 src_hi src_lo rssi options RF-data`, 868
//!   `90 src64(8) FF FE options RF-data`, with a valid checksum. The source is
//!   [`XBeeModem::address_a`]; the options say "broadcast" (0x02) when the destination
//!   was the broadcast address (and, on 868, "acknowledged" (0x01) otherwise). The
//!   destination address is not otherwise checked: B receives every frame.
//! * A unicast frame is acknowledged: each transmission fails with probability
//!   [`XBeeModem::failure_rate`] (seeded, reproducible) or when a bit error hits it (a
//!   real receiver drops a frame whose CRC fails), and is then retried up to
//!   [`XBeeModem::retries`] times. Each attempt occupies the air again, and after each
//!   attempt the modem waits [`XBeeModem::ack_delay`] for the acknowledgement, sending
//!   nothing meanwhile. A frame that failed every attempt is lost. A broadcast, or a
//!   frame with the "disable ACK" option (0x01), is sent once, and may be lost.
//! * When the last attempt is over (plus the ACK wait for an acknowledged frame), the
//!   modem writes a transmit status back to A's reader if the frame id is not 0:
//!   802.15.4 `89 frame_id status` (0 delivered, 1 no ACK; a broadcast always reports
//!   0), 868 `8B frame_id FF FE retries delivery discovery` (delivery 0x00 or 0x21).
//!   The status codes are in [`xbee`].
//! * The modem buffer holds whole frames: `buffer` counts the API bytes of the frame
//!   being received from the UART and of every frame not yet sent (until its last
//!   attempt and ACK wait are over), and is at least one frame of the largest size
//!   ([`XBeeVariant::max_api_frame`]); the modem holds at most 16 frames. A frame that
//!   does not fit is dropped whole with `Drop` ([`SimStats::frames_dropped`]; a real
//!   module loses bytes and then rejects the broken frame). With
//!   [`XBeeModem::purge_status`], the modem also answers such a frame with a status
//!   (802.15.4 3 "purged", 868 0x32 "no free buffers") so a test can see it. With `Wait`
//!   the UART stops (CTS) while the buffer cannot take the next byte.
//! * An RX frame that the receiver's ring cannot hold is lost with `Drop`
//!   ([`SimStats::frames_overrun`]): it was sent and acknowledged, the far modem's UART
//!   output overflowed. With `Wait`, the frame's last byte waits on the UART until the
//!   reader has made room.
//! * The uplink (B to A) carries plain bytes, as without XBee, unless
//!   [`XBeeModem::api_uplink`] is set: B then writes API frames too, A reads RX frames
//!   (source [`XBeeModem::address_b`]) and B reads the statuses of its frames. With a
//!   plain uplink, A's statuses come in between the plain bytes.
//!
//! # Choosing the parameters
//!
//! * **SiK / 3DR radios** (transparent): `serial_rate` is `SERIAL_SPEED` (57 for 57600
//!   baud: 5760 bytes/s). The air rate is `AIR_SPEED` kbit/s over 8 bits, halved by
//!   `ECC` (Golay coding doubles every byte), and shared by both directions in TDM
//!   (each gets about half when both are busy), minus framing: `AIR_SPEED = 64` gives
//!   at most 8000 bytes/s, about 4000 in each direction when both are busy, 2000 with
//!   ECC. So at 57600 baud the UART outruns the air as soon as ECC is on or the uplink
//!   is busy, and without flow control (`RTSCTS=0`, the usual wiring) a writer that does
//!   not pace itself overfills the modem. The buffer is the firmware's serial receive
//!   FIFO (1850 bytes in the Si1000 firmware, which deasserts CTS at 17 bytes free).
//! * **XBee 802.15.4** (API): the air carries 250 kbit/s (`byte_rate = 31_250`), so at
//!   57600 baud (`serial_rate = 5760`) the UART, not the air, is the bottleneck; the
//!   serial receive buffer of an XBee (Series 1) holds about 202 bytes. Per transmission
//!   add about 20 bytes of `air_overhead` (PHY preamble and header, MAC header and CRC,
//!   the acknowledgement frame) and an `ack_delay` of about 1 ms (802.15.4 waits 864 µs
//!   for an acknowledgement); the MAC retries 3 times.
//! * **XBee 868**: the air is much slower (24 kbit/s for the XBee-PRO 868, 10 or
//!   80 kbit/s for the 868LP), so with RF payloads up to 256 bytes the air, not the
//!   UART, is the bottleneck.
//!
//! # Time and memory
//!
//! Time is embassy-time's: under the mock driver (`embassy-time/mock-driver`) a
//! simulation is deterministic and runs as fast as the test advances the clock; on
//! the host with the `std` driver it runs in real time. The crate does not pick a
//! driver: the final binary does. The model keeps its own clock in fractions of a
//! tick (ticks x `byte_rate` x `serial_rate`), so rates that do not divide the tick
//! rate stay exact: a byte's entry time into the modem does not depend on when its
//! writer happened to be polled.
//!
//! Memory per direction: `9 * N` bytes for the receiver ring (each byte carries its
//! arrival time) plus at most 1.5 KiB of state, most of it the XBee modem's (a
//! 270-byte frame buffer and 16 frame slots of 48 bytes) and the outage windows (16
//! bytes each), present whether XBee or outages are used or not; a [`SimLink`] is twice
//! that. No allocation, no `unsafe`.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::NoopRawMutex;
//! use embassy_time::Duration;
//! use pprz_devices::sim::{SimConfig, SimLink};
//!
//! // A SiK radio at 57600 baud (5760 bytes/s on the UART), 4000 bytes/s on the air,
//! // 20 ms latency, 1850-byte modem buffer, BER 1e-5.
//! let config = SimConfig::new(4000)
//!     .serial_rate(5760)
//!     .latency(Duration::from_millis(20))
//!     .buffer(1850)
//!     .bit_error_rate(1e-5)
//!     .seed(42);
//! let link = SimLink::<NoopRawMutex, 4096>::new(config);
//! let (aircraft, ground) = link.endpoints();
//! let (uplink_rx, downlink_tx) = aircraft.split(); // for a reader task and a writer task
//! # let _ = (ground, uplink_rx, downlink_tx);
//! ```
//!
//! An XBee 802.15.4 at 57600 baud:
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::NoopRawMutex;
//! use embassy_time::Duration;
//! use pprz_devices::sim::{SimConfig, SimLink, XBeeModem, XBeeVariant};
//!
//! let modem = XBeeModem::new(XBeeVariant::XBee24)
//!     .air_overhead(20)
//!     .ack_delay(Duration::from_millis(1))
//!     .failure_rate(0.05)
//!     .retries(3);
//! let config = SimConfig::new(31_250).serial_rate(5760).buffer(202).xbee(modem);
//! let link = SimLink::<NoopRawMutex, 2048>::new(config);
//! # let _ = link.endpoints();
//! ```

mod config;
mod dir;
mod end;
mod link;
mod modem;
mod outage;
mod stats;
mod timing;
mod transmit;
pub mod xbee;

pub use config::{Overflow, SimConfig, XBeeModem, XBeeVariant};
pub use end::{SimEnd, SimRx, SimTx};
pub use link::{Direction, SimLink};
pub use outage::{MAX_OUTAGES, OutageError};
pub use stats::SimStats;
