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
//! arrival time) plus at most 1.3 KiB of state, most of it the XBee modem's (a
//! 270-byte frame buffer and 16 frame slots of 48 bytes), present whether XBee is used
//! or not; a [`SimLink`] is twice that. No allocation, no `unsafe`.
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

use core::cell::RefCell;
use core::convert::Infallible;
use core::future::poll_fn;
use core::task::Poll;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::waitqueue::WakerRegistration;
use embassy_time::{Duration, Instant, TICK_HZ, Timer};
use embedded_io_async::{ErrorType, Read, Write};
use pprz_transports::xbee as api;

/// What a direction does with written bytes when its modem buffer is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Overflow {
    /// Drop them and count them (a radio modem without flow control). Writes never wait
    /// for room.
    #[default]
    Drop,
    /// Stop the UART until there is room (hardware flow control, CTS).
    Wait,
}

/// Parameters of both directions of a [`SimLink`]; see the [module docs](self).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SimConfig {
    /// Bytes per second on the air; 0 for no serialisation delay.
    pub byte_rate: u32,
    /// Delay from the end of a byte's transmission to its arrival.
    pub latency: Duration,
    /// Bytes the modem buffer holds (values below 1 count as 1; in XBee API mode, at
    /// least one frame of the largest size).
    pub buffer: usize,
    /// Probability that a bit is flipped (0 to 1).
    pub bit_error_rate: f64,
    /// Seed of the bit-error (and XBee failure) generator.
    pub seed: u64,
    /// Behaviour when the modem buffer (or the receiver's ring) is full.
    pub overflow: Overflow,
    /// Bytes per second on the UART between the writer and its modem; 0 (the default)
    /// for instant transfers.
    pub serial_rate: u32,
    /// The XBee API modem, or `None` (the default) for a transparent modem.
    pub xbee: Option<XBeeModem>,
}

impl SimConfig {
    /// `byte_rate` bytes/s on the air, an instant UART, no latency, a 256-byte buffer,
    /// no bit errors, seed 1, [`Overflow::Drop`], a transparent modem.
    pub const fn new(byte_rate: u32) -> Self {
        Self {
            byte_rate,
            latency: Duration::from_ticks(0),
            buffer: 256,
            bit_error_rate: 0.0,
            seed: 1,
            overflow: Overflow::Drop,
            serial_rate: 0,
            xbee: None,
        }
    }

    /// Sets [`latency`](Self::latency).
    pub const fn latency(mut self, latency: Duration) -> Self {
        self.latency = latency;
        self
    }

    /// Sets [`buffer`](Self::buffer).
    pub const fn buffer(mut self, bytes: usize) -> Self {
        self.buffer = bytes;
        self
    }

    /// Sets [`bit_error_rate`](Self::bit_error_rate).
    pub const fn bit_error_rate(mut self, ber: f64) -> Self {
        self.bit_error_rate = ber;
        self
    }

    /// Sets [`seed`](Self::seed).
    pub const fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Sets [`overflow`](Self::overflow).
    pub const fn overflow(mut self, overflow: Overflow) -> Self {
        self.overflow = overflow;
        self
    }

    /// Sets [`serial_rate`](Self::serial_rate), in bytes per second (baud / 10 for 8N1).
    pub const fn serial_rate(mut self, bytes_per_s: u32) -> Self {
        self.serial_rate = bytes_per_s;
        self
    }

    /// Makes the modem an XBee in API mode; see [`xbee`](Self::xbee).
    pub const fn xbee(mut self, modem: XBeeModem) -> Self {
        self.xbee = Some(modem);
        self
    }
}

/// The XBee module family, which sets the API frame layouts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum XBeeVariant {
    /// 802.15.4 ("Series 1", 2.4 GHz): TX16 (0x01), RX16 (0x81), status 0x89; RF
    /// payload up to 100 bytes.
    #[default]
    XBee24,
    /// 868 MHz: transmit request 0x10, receive packet 0x90, status 0x8B; RF payload up
    /// to 256 bytes.
    XBee868,
}

impl XBeeVariant {
    /// The largest RF payload of a frame.
    pub const fn max_rf_payload(self) -> usize {
        match self {
            Self::XBee24 => api::MAX_RF_PAYLOAD_24,
            Self::XBee868 => api::MAX_RF_PAYLOAD_868,
        }
    }

    /// Length of the transmit request's `FRAME_DATA` before the RF data.
    const fn tx_header(self) -> usize {
        match self {
            Self::XBee24 => api::field::tx16::DATA,
            Self::XBee868 => api::field::tx868::DATA,
        }
    }

    /// Length of the receive packet's `FRAME_DATA` before the RF data.
    const fn rx_header(self) -> usize {
        match self {
            Self::XBee24 => api::field::rx16::DATA,
            Self::XBee868 => api::field::rx868::DATA,
        }
    }

    /// The largest transmit request, framing included (109 bytes for 802.15.4, 274
    /// for 868).
    pub const fn max_api_frame(self) -> usize {
        self.tx_header() + self.max_rf_payload() + xbee::FRAMING
    }
}

/// An XBee module in API mode; see the [module docs](self#xbee-api-modem).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct XBeeModem {
    /// The module family.
    pub variant: XBeeVariant,
    /// Time from the end of a transmission to its acknowledgement (or to giving up on
    /// it); the modem sends nothing meanwhile. Statuses are written at its end.
    pub ack_delay: Duration,
    /// Probability that a transmission is not acknowledged (lost), 0 to 1.
    pub failure_rate: f64,
    /// Retries after a transmission that was not acknowledged.
    pub retries: u8,
    /// Bytes that each transmission adds on the air to the RF data.
    pub air_overhead: u16,
    /// Address of endpoint A's module, the source of the frames B receives (802.15.4:
    /// the low 16 bits, `MY`; 868: the 64-bit serial number).
    pub address_a: u64,
    /// Address of endpoint B's module, the source of the frames A receives.
    pub address_b: u64,
    /// The RSSI byte of 802.15.4 RX frames (minus dBm: 40 is -40 dBm).
    pub rssi: u8,
    /// B writes API frames too (otherwise plain bytes, delivered unchanged).
    pub api_uplink: bool,
    /// Answer a frame dropped because the modem is full with a status (802.15.4 3
    /// "purged", 868 0x32 "no free buffers"), if its frame id is not 0.
    pub purge_status: bool,
}

impl XBeeModem {
    /// A module of `variant`: 1 ms ACK delay, no failures, 3 retries, no air overhead,
    /// address A 0x0001, address B 0x0100 (the ground's, in Paparazzi), RSSI 40, a
    /// plain uplink, no purge status.
    pub const fn new(variant: XBeeVariant) -> Self {
        Self {
            variant,
            ack_delay: Duration::from_millis(1),
            failure_rate: 0.0,
            retries: 3,
            air_overhead: 0,
            address_a: 0x0001,
            address_b: 0x0100,
            rssi: 40,
            api_uplink: false,
            purge_status: false,
        }
    }

    /// Sets [`ack_delay`](Self::ack_delay).
    pub const fn ack_delay(mut self, delay: Duration) -> Self {
        self.ack_delay = delay;
        self
    }

    /// Sets [`failure_rate`](Self::failure_rate).
    pub const fn failure_rate(mut self, probability: f64) -> Self {
        self.failure_rate = probability;
        self
    }

    /// Sets [`retries`](Self::retries).
    pub const fn retries(mut self, retries: u8) -> Self {
        self.retries = retries;
        self
    }

    /// Sets [`air_overhead`](Self::air_overhead).
    pub const fn air_overhead(mut self, bytes: u16) -> Self {
        self.air_overhead = bytes;
        self
    }

    /// Sets [`address_a`](Self::address_a) and [`address_b`](Self::address_b).
    pub const fn addresses(mut self, a: u64, b: u64) -> Self {
        self.address_a = a;
        self.address_b = b;
        self
    }

    /// Sets [`rssi`](Self::rssi).
    pub const fn rssi(mut self, rssi: u8) -> Self {
        self.rssi = rssi;
        self
    }

    /// Sets [`api_uplink`](Self::api_uplink).
    pub const fn api_uplink(mut self, on: bool) -> Self {
        self.api_uplink = on;
        self
    }

    /// Sets [`purge_status`](Self::purge_status).
    pub const fn purge_status(mut self, on: bool) -> Self {
        self.purge_status = on;
        self
    }
}

/// XBee API facts of the simulated modem.
///
/// Frame layouts, API ids and status codes are those of [`pprz_transports::xbee`],
/// re-exported here under the modem's names; this module adds the option bits the
/// modem reads and writes and [`api_frame`](xbee::api_frame) to frame `FRAME_DATA`.
pub mod xbee {
    use pprz_transports::xbee::{HEADER_LEN, Packet};

    pub use pprz_transports::checksum::xbee as checksum;
    pub use pprz_transports::xbee::status::{
        CCA_FAILURE as STATUS_CCA_FAILURE, DISCOVERY_NONE, NETWORK_ACK_FAILURE as DELIVERY_NO_ACK,
        NO_ACK as STATUS_NO_ACK, PURGED as STATUS_PURGED, RESOURCE_ERROR as DELIVERY_NO_BUFFERS,
        SUCCESS as STATUS_SUCCESS,
    };
    pub use pprz_transports::xbee::{
        API_RX_868, API_RX16, API_TX_868, API_TX_STATUS, API_TX_STATUS_868, API_TX16,
        BROADCAST_ADDRESS as BROADCAST_16, OVERHEAD as FRAMING, START,
    };

    /// Transmit option "disable ACK" (both variants).
    pub const OPTION_DISABLE_ACK: u8 = 0x01;
    /// Receive option "acknowledged" (868).
    pub const RX_OPTION_ACKED: u8 = 0x01;
    /// Receive option "broadcast" (both variants).
    pub const RX_OPTION_BROADCAST: u8 = 0x02;
    /// 868 broadcast address: [`BROADCAST_16`] in the low bits.
    pub const BROADCAST_64: u64 = pprz_transports::xbee::address64(pprz_transports::BROADCAST_ID);

    /// Writes the API frame `7E len frame_data ck` to `out`; returns its length, or
    /// `None` if `out` is too short or `frame_data` longer than 65535 bytes.
    pub fn api_frame(frame_data: &[u8], out: &mut [u8]) -> Option<usize> {
        let len = frame_data.len();
        u16::try_from(len).ok()?;
        let out = out.get_mut(..len + FRAMING)?;
        out[HEADER_LEN..HEADER_LEN + len].copy_from_slice(frame_data);
        Some(frame_in_place(out, len))
    }

    /// Frames the `len` bytes of `FRAME_DATA` at `out[HEADER_LEN..]` in place (`len`
    /// at most 65535); returns the frame's length.
    pub(super) fn frame_in_place(out: &mut [u8], len: usize) -> usize {
        let mut packet = Packet::new_unchecked(out);
        packet.set_start(START);
        packet.set_length(len as u16);
        packet.fill_checksum();
        len + FRAMING
    }
}

/// A direction of a [`SimLink`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// Written on endpoint A (the aircraft), read on endpoint B.
    AToB,
    /// Written on endpoint B (the ground), read on endpoint A.
    BToA,
}

impl Direction {
    const fn index(self) -> usize {
        match self {
            Self::AToB => 0,
            Self::BToA => 1,
        }
    }

    const fn other(self) -> Self {
        match self {
            Self::AToB => Self::BToA,
            Self::BToA => Self::AToB,
        }
    }
}

/// Counters of one direction of a [`SimLink`]. The `u32` counters wrap around.
///
/// Transparent modem: `bytes_written == bytes_sent + dropped_bytes + overrun_bytes`.
/// XBee API modem: `bytes_written == bytes_sent + dropped_bytes + overrun_bytes +
/// discarded_bytes + ` the bytes of a frame still being received, the byte counters
/// counting the API bytes of whole frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SimStats {
    /// Bytes that crossed the UART into the modem.
    pub bytes_written: u32,
    /// Bytes the modem accepted for transmission (API mode: the API bytes of the frames
    /// sent, except those lost to a receiver overrun).
    pub bytes_sent: u32,
    /// Bytes returned by `read` on this direction (RX frames and statuses included).
    pub bytes_delivered: u32,
    /// Bytes dropped because the modem buffer was full ([`Overflow::Drop`]).
    pub dropped_bytes: u32,
    /// Bytes dropped because the receiver's ring was full ([`Overflow::Drop`], or a
    /// frame larger than the ring).
    pub overrun_bytes: u32,
    /// Bits flipped.
    pub bit_errors: u32,
    /// Bytes with at least one flipped bit (API mode: such a transmission fails).
    pub corrupted_bytes: u32,
    /// Time the UART spent transferring bytes into the modem, in µs (rounded down).
    pub serial_busy_us: u64,
    /// Time the air spent carrying this direction's bytes, in µs (rounded down), up to
    /// now (transmissions scheduled for later are not counted yet).
    pub air_busy_us: u64,
    /// API frames accepted by the modem and transmitted.
    pub frames_sent: u32,
    /// API frames dropped whole because the modem buffer was full.
    pub frames_dropped: u32,
    /// API frames sent (and acknowledged) but lost because the receiver's ring could
    /// not hold them (their API bytes are in `overrun_bytes`).
    pub frames_overrun: u32,
    /// Malformed API frames (bad length or checksum, unexpected API id, RF data too
    /// long), dropped.
    pub malformed_frames: u32,
    /// Bytes the API parser dropped: malformed frames and bytes outside frames.
    pub discarded_bytes: u32,
    /// Transmissions of API frames that failed (random failure or bit error).
    pub failed_attempts: u32,
    /// API frames that failed every attempt (never received).
    pub frames_lost: u32,
    /// Transmit statuses written back to this direction's writer.
    pub statuses: u32,
    /// Transmit statuses lost because the writer's receiver ring was full.
    pub statuses_lost: u32,
}

impl SimStats {
    /// [`serial_busy_us`](Self::serial_busy_us) as a [`Duration`].
    pub const fn serial_busy(&self) -> Duration {
        Duration::from_micros(self.serial_busy_us)
    }

    /// [`air_busy_us`](Self::air_busy_us) as a [`Duration`].
    pub const fn air_busy(&self) -> Duration {
        Duration::from_micros(self.air_busy_us)
    }
}

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, every seed is good.
#[derive(Debug)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Largest `FRAME_DATA` of a transmit request (868: 14-byte header + 256 bytes).
const MAX_FRAME_DATA: usize = XBeeVariant::XBee868.tx_header() + api::MAX_RF_PAYLOAD_868;
/// Largest RX frame, framing included (868: 12-byte header + 256 bytes).
const MAX_RX_FRAME: usize = rx_frame_len(XBeeVariant::XBee868, api::MAX_RF_PAYLOAD_868);
/// Frames the XBee modem holds.
const MODEM_FRAMES: usize = 16;

/// Derived constants. Times are in units of `1 / (TICK_HZ * scale)` s.
#[derive(Clone, Copy, Debug)]
struct Timing {
    /// Units per tick: `max(byte_rate, 1) * max(serial_rate, 1)`.
    scale: u128,
    /// Units per byte on the air (0: instant).
    air_byte: u128,
    /// Units per byte on the UART (0: instant).
    uart_byte: u128,
    /// Latency in ticks.
    latency: u64,
    /// XBee ACK wait in units.
    ack_wait: u128,
    /// Bit-flip probability as a fraction of 2^64.
    ber: u64,
    /// XBee failure probability as a fraction of 2^64.
    failure: u64,
}

impl Timing {
    const fn new(config: &SimConfig) -> Self {
        let air = config.byte_rate as u128;
        let serial = config.serial_rate as u128;
        let air1 = if air == 0 { 1 } else { air };
        let serial1 = if serial == 0 { 1 } else { serial };
        let hz = TICK_HZ as u128;
        let scale = air1 * serial1;
        let (ack_wait, failure) = match &config.xbee {
            Some(x) => (
                x.ack_delay.as_ticks() as u128 * scale,
                probability_threshold(x.failure_rate),
            ),
            None => (0, 0),
        };
        Self {
            scale,
            air_byte: if air == 0 { 0 } else { hz * serial1 },
            uart_byte: if serial == 0 { 0 } else { hz * air1 },
            latency: config.latency.as_ticks(),
            ack_wait,
            ber: probability_threshold(config.bit_error_rate),
            failure,
        }
    }

    /// The first tick at or after `units`.
    fn ticks_ceil(&self, units: u128) -> u64 {
        u64::try_from(units.div_ceil(self.scale)).unwrap_or(u64::MAX)
    }

    fn micros(&self, units: u128) -> u64 {
        let per_us = self.scale * u128::from(TICK_HZ);
        u64::try_from(units.saturating_mul(1_000_000) / per_us).unwrap_or(u64::MAX)
    }
}

/// A probability as a fraction of 2^64.
const fn probability_threshold(p: f64) -> u64 {
    // `as` saturates (and maps NaN to 0), so any input is safe.
    (p * 18_446_744_073_709_551_616.0) as u64
}

/// A frame in the XBee modem, from its acceptance to the end of its last attempt (and
/// ACK wait).
#[derive(Clone, Copy, Debug)]
struct InModem {
    /// Start of the first attempt.
    start: u128,
    /// Air time of one attempt.
    air: u128,
    attempts: u16,
    /// The modem waits for an acknowledgement after each attempt.
    acked: bool,
    /// API bytes it occupies in the buffer.
    weight: u16,
}

impl InModem {
    const EMPTY: Self = Self {
        start: 0,
        air: 0,
        attempts: 0,
        acked: false,
        weight: 0,
    };

    fn period(&self, ack_wait: u128) -> u128 {
        self.air + if self.acked { ack_wait } else { 0 }
    }

    fn end(&self, ack_wait: u128) -> u128 {
        self.start + u128::from(self.attempts) * self.period(ack_wait)
    }

    /// Air time after `now`.
    fn air_after(&self, now: u128, ack_wait: u128) -> u128 {
        let period = self.period(ack_wait);
        (0..u128::from(self.attempts))
            .map(|i| {
                let from = self.start + i * period;
                (from + self.air).saturating_sub(from.max(now))
            })
            .sum()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Parse {
    /// Looking for the start delimiter.
    Idle,
    LengthHigh,
    LengthLow,
    Data,
    Checksum,
}

/// The XBee modem's API parser.
struct Parser {
    state: Parse,
    /// `FRAME_DATA` length announced.
    length: usize,
    /// `FRAME_DATA` bytes received.
    got: usize,
    /// API bytes of the current frame received so far.
    bytes: u32,
    data: [u8; MAX_FRAME_DATA],
}

/// A valid transmit request in the parser.
#[derive(Clone, Copy, Debug)]
struct TxRequest {
    frame_id: u8,
    broadcast: bool,
    acked: bool,
    /// RF data: `data[rf_start..]`.
    rf_start: usize,
}

impl Parser {
    const fn new() -> Self {
        Self {
            state: Parse::Idle,
            length: 0,
            got: 0,
            bytes: 0,
            data: [0; MAX_FRAME_DATA],
        }
    }

    /// API bytes of a frame being received.
    fn in_progress(&self) -> u32 {
        if self.state == Parse::Idle {
            0
        } else {
            self.bytes
        }
    }

    /// The transmit request completed by `checksum`, if it is one and valid.
    fn request(&self, variant: XBeeVariant, checksum: u8) -> Option<TxRequest> {
        let data = &self.data[..self.length];
        if self.state != Parse::Checksum || xbee::checksum(data) != checksum {
            return None;
        }
        let header = variant.tx_header();
        if data.len() < header || data.len() - header > variant.max_rf_payload() {
            return None;
        }
        let (broadcast, options) = match variant {
            XBeeVariant::XBee24 if data[0] == xbee::API_TX16 => {
                let mut dest = [0u8; 2];
                dest.copy_from_slice(&data[api::field::tx16::DEST]);
                let broadcast = u16::from_be_bytes(dest) == xbee::BROADCAST_16;
                (broadcast, data[api::field::tx16::OPTIONS])
            }
            XBeeVariant::XBee868 if data[0] == xbee::API_TX_868 => {
                let mut dest = [0u8; 8];
                dest.copy_from_slice(&data[api::field::tx868::DEST64]);
                let broadcast = u64::from_be_bytes(dest) == xbee::BROADCAST_64;
                (broadcast, data[api::field::tx868::OPTIONS])
            }
            _ => return None,
        };
        // The frame id is at the same offset in both requests.
        Some(TxRequest {
            frame_id: data[api::field::tx16::FRAME_ID],
            broadcast,
            acked: !broadcast && options & xbee::OPTION_DISABLE_ACK == 0,
            rf_start: header,
        })
    }
}

/// One direction: the UART, the modem and the receiver's ring.
///
/// Ring invariants: `len <= N`, `head < N`; `data`/`due` hold the bytes in delivery
/// order from `head`, with non-decreasing `due` (except right after a partly read run,
/// see `insert`).
struct Dir<const N: usize> {
    data: [u8; N],
    /// Arrival tick of each byte.
    due: [u64; N],
    head: usize,
    len: usize,
    /// The run of equal arrival times at `head` has been partly read: nothing is
    /// inserted before its end (an RX frame is never split).
    partial: bool,
    /// When the last byte crossed the UART.
    uart_end: u128,
    /// UART time used.
    uart_busy: u128,
    /// When the modem is done with everything it accepted.
    tx_end: u128,
    /// Air time scheduled.
    air_total: u128,
    /// Frames in the XBee modem, oldest first, from `frames_head`.
    frames: [InModem; MODEM_FRAMES],
    frames_head: usize,
    frames_len: usize,
    parser: Parser,
    rng: SplitMix64,
    stats: SimStats,
    rx_waker: WakerRegistration,
    tx_waker: WakerRegistration,
}

/// What a push or pop attempt asks the caller to do.
enum Step {
    Done(usize),
    /// Try again at this tick.
    At(u64),
    /// Try again when the reader has freed this many bytes of the ring.
    Room(usize),
    /// Try again when the writer made progress.
    Peer,
}

/// Progress of one `write` call.
struct Cursor {
    /// Bytes that crossed the UART.
    done: usize,
    /// The UART (re)starts now: at the beginning and after waiting for the reader.
    fresh: bool,
}

/// A simulated radio link; see the [module docs](self).
///
/// `M` is the mutex kind (`NoopRawMutex` when both endpoints run on one executor,
/// `CriticalSectionRawMutex` otherwise); `N` is the per-direction ring size.
/// `new` is `const`, so a link can be a `static`.
pub struct SimLink<M: RawMutex, const N: usize> {
    config: SimConfig,
    timing: Timing,
    dirs: [Mutex<M, RefCell<Dir<N>>>; 2],
}

impl<M: RawMutex, const N: usize> SimLink<M, N> {
    const VALID: () = assert!(N > 0, "a SimLink needs a ring of at least one byte");

    /// A link with both directions empty and zero counters. `N = 0` does not compile.
    pub const fn new(config: SimConfig) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::VALID;
        Self {
            config,
            timing: Timing::new(&config),
            dirs: [
                Mutex::new(RefCell::new(Dir::new(config.seed))),
                Mutex::new(RefCell::new(Dir::new(config.seed ^ 0x5DEE_CE66_D1CE_4E5B))),
            ],
        }
    }

    /// The configuration.
    pub const fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The two endpoints, A and B. Take them once: each direction wakes one reader and
    /// one writer.
    pub fn endpoints(&self) -> (SimEnd<'_, M, N>, SimEnd<'_, M, N>) {
        (
            SimEnd::new(self, Direction::AToB, Direction::BToA),
            SimEnd::new(self, Direction::BToA, Direction::AToB),
        )
    }

    /// Counters of one direction, busy times up to now.
    pub fn stats(&self, direction: Direction) -> SimStats {
        let t = &self.timing;
        let now = Self::now_units(t);
        let api = self.modem(direction).is_some();
        self.with(direction, |d| {
            let mut stats = d.stats;
            stats.serial_busy_us = t.micros(d.uart_busy);
            let ahead = if api {
                d.frames_iter().map(|f| f.air_after(now, t.ack_wait)).sum()
            } else {
                d.tx_end.saturating_sub(now)
            };
            stats.air_busy_us = t.micros(d.air_total.saturating_sub(ahead));
            stats
        })
    }

    /// Bytes in the modem of `direction` now: waiting or on the air (transparent), or
    /// the API bytes of the frames not yet done and of a frame being received (XBee).
    pub fn modem_occupancy(&self, direction: Direction) -> usize {
        let t = &self.timing;
        let now = Self::now_units(t);
        let api = self.modem(direction).is_some();
        self.with(direction, |d| {
            let bytes = if api {
                d.frames_iter()
                    .filter(|f| f.end(t.ack_wait) > now)
                    .map(|f| u128::from(f.weight))
                    .sum::<u128>()
                    + u128::from(d.parser.in_progress())
            } else if t.air_byte == 0 {
                0
            } else {
                d.queued(now, t.air_byte)
            };
            usize::try_from(bytes).unwrap_or(usize::MAX)
        })
    }

    fn with<R>(&self, direction: Direction, f: impl FnOnce(&mut Dir<N>) -> R) -> R {
        self.dirs[direction.index()].lock(|d| f(&mut d.borrow_mut()))
    }

    fn now_units(t: &Timing) -> u128 {
        u128::from(Instant::now().as_ticks()) * t.scale
    }

    /// The XBee modem of `direction`, if it speaks API.
    fn modem(&self, direction: Direction) -> Option<&XBeeModem> {
        match (&self.config.xbee, direction) {
            (Some(x), Direction::AToB) => Some(x),
            (Some(x), Direction::BToA) if x.api_uplink => Some(x),
            _ => None,
        }
    }

    /// The modem buffer, in bytes.
    fn buffer(&self, modem: Option<&XBeeModem>) -> u128 {
        let min = modem.map_or(1, |x| x.variant.max_api_frame());
        self.config.buffer.max(min) as u128
    }

    fn push(&self, direction: Direction, buf: &[u8], cursor: &mut Cursor) -> Step {
        let t = &self.timing;
        let now = Self::now_units(t);
        let modem = self.modem(direction);
        let wait = self.config.overflow == Overflow::Wait;
        self.with(direction, |d| {
            if cursor.fresh {
                d.uart_end = d.uart_end.max(now);
                cursor.fresh = false;
            }
            let before = cursor.done;
            let mut step = Step::Done(buf.len());
            while let Some(&byte) = buf.get(cursor.done) {
                let mut start = d.uart_end;
                if wait {
                    match self.room(d, start, modem) {
                        Ok(at) => start = start.max(at),
                        Err(need) => {
                            step = Step::Room(need);
                            break;
                        }
                    }
                }
                let end = start + t.uart_byte;
                if end > now {
                    step = Step::At(t.ticks_ceil(end));
                    break;
                }
                if wait
                    && let Some(x) = modem
                    && let Some(req) = d.parser.request(x.variant, byte)
                {
                    let need = rx_frame_len(x.variant, d.parser.length - req.rf_start);
                    if need <= N && N - d.len < need {
                        step = Step::Room(need);
                        break;
                    }
                }
                d.uart_end = end;
                d.uart_busy += t.uart_byte;
                d.stats.bytes_written = d.stats.bytes_written.wrapping_add(1);
                cursor.done += 1;
                match modem {
                    Some(x) => self.api_byte(direction, d, x, byte, end),
                    None => self.transparent_byte(d, byte, end),
                }
            }
            if matches!(step, Step::Room(_)) {
                cursor.fresh = true;
            }
            if cursor.done > before {
                d.rx_waker.wake();
            }
            step
        })
    }

    /// When (at or after `at`) the modem can take the next byte, or `Err(bytes)` if
    /// the receiver must first free that many bytes of the ring.
    fn room(&self, d: &Dir<N>, at: u128, modem: Option<&XBeeModem>) -> Result<u128, usize> {
        let t = &self.timing;
        let buffer = self.buffer(modem);
        if modem.is_none() {
            if d.len >= N {
                return Err(1);
            }
            if t.air_byte == 0 || d.queued(at, t.air_byte) < buffer {
                return Ok(at);
            }
            // Room again once the queue has drained to `buffer - 1` bytes.
            return Ok(d.tx_end - (buffer - 1) * t.air_byte);
        }
        let mut bytes = u128::from(d.parser.in_progress());
        let mut count = 0;
        for f in d.frames_iter().filter(|f| f.end(t.ack_wait) > at) {
            bytes += u128::from(f.weight);
            count += 1;
        }
        if bytes < buffer && count < MODEM_FRAMES {
            return Ok(at);
        }
        for f in d.frames_iter().filter(|f| f.end(t.ack_wait) > at) {
            bytes -= u128::from(f.weight);
            count -= 1;
            if bytes < buffer && count < MODEM_FRAMES {
                return Ok(f.end(t.ack_wait));
            }
        }
        // Unreachable: the buffer holds the largest frame.
        Ok(at)
    }

    /// A byte enters the transparent modem at `at`.
    fn transparent_byte(&self, d: &mut Dir<N>, byte: u8, at: u128) {
        let t = &self.timing;
        let full = t.air_byte > 0 && d.queued(at, t.air_byte) >= self.buffer(None);
        let s = &mut d.stats;
        if full {
            s.dropped_bytes = s.dropped_bytes.wrapping_add(1);
            return;
        }
        if d.len >= N {
            s.overrun_bytes = s.overrun_bytes.wrapping_add(1);
            return;
        }
        d.tx_end = d.tx_end.max(at) + t.air_byte;
        d.air_total += t.air_byte;
        let due = t.ticks_ceil(d.tx_end).saturating_add(t.latency);
        let byte = d.corrupt(byte, t.ber);
        d.insert(&[byte], due);
        d.stats.bytes_sent = d.stats.bytes_sent.wrapping_add(1);
    }

    /// A byte enters the XBee modem's API parser at `at`.
    fn api_byte(&self, direction: Direction, d: &mut Dir<N>, x: &XBeeModem, byte: u8, at: u128) {
        let p = &mut d.parser;
        if p.state != Parse::Idle {
            p.bytes += 1;
        }
        match p.state {
            Parse::Idle => {
                if byte == xbee::START {
                    p.state = Parse::LengthHigh;
                    p.bytes = 1;
                } else {
                    d.stats.discarded_bytes = d.stats.discarded_bytes.wrapping_add(1);
                }
            }
            Parse::LengthHigh => {
                p.length = usize::from(byte) << 8;
                p.state = Parse::LengthLow;
            }
            Parse::LengthLow => {
                p.length |= usize::from(byte);
                p.got = 0;
                if p.length == 0 || p.length > MAX_FRAME_DATA {
                    let bytes = p.bytes;
                    p.state = Parse::Idle;
                    d.malformed(bytes);
                } else {
                    p.state = Parse::Data;
                }
            }
            Parse::Data => {
                p.data[p.got] = byte;
                p.got += 1;
                if p.got == p.length {
                    p.state = Parse::Checksum;
                }
            }
            Parse::Checksum => {
                let request = p.request(x.variant, byte);
                let bytes = p.bytes;
                p.state = Parse::Idle;
                match request {
                    Some(req) => self.send_frame(direction, d, x, req, bytes, at),
                    None => d.malformed(bytes),
                }
            }
        }
    }

    /// A valid transmit request of `bytes` API bytes is complete at `at`.
    fn send_frame(
        &self,
        direction: Direction,
        d: &mut Dir<N>,
        x: &XBeeModem,
        req: TxRequest,
        bytes: u32,
        at: u128,
    ) {
        let t = &self.timing;
        d.prune(at, t.ack_wait);
        let occupied: u128 = d.frames_iter().map(|f| u128::from(f.weight)).sum();
        if occupied + u128::from(bytes) > self.buffer(Some(x)) || d.frames_len == MODEM_FRAMES {
            d.stats.frames_dropped = d.stats.frames_dropped.wrapping_add(1);
            d.stats.dropped_bytes = d.stats.dropped_bytes.wrapping_add(bytes);
            if x.purge_status && req.frame_id != 0 {
                let status = match x.variant {
                    XBeeVariant::XBee24 => xbee::STATUS_PURGED,
                    XBeeVariant::XBee868 => xbee::DELIVERY_NO_BUFFERS,
                };
                self.status(direction, d, x, req.frame_id, 0, status, t.ticks_ceil(at));
            }
            return;
        }
        let rf_len = d.parser.length - req.rf_start;
        // Transmit, retrying until acknowledged.
        let air_bytes = rf_len + usize::from(x.air_overhead);
        let max_attempts = if req.acked {
            u16::from(x.retries) + 1
        } else {
            1
        };
        let mut attempts = 0;
        let mut received = false;
        while attempts < max_attempts && !received {
            attempts += 1;
            received = d.attempt(air_bytes, t);
        }
        let frame = InModem {
            start: d.tx_end.max(at),
            air: air_bytes as u128 * t.air_byte,
            attempts,
            acked: req.acked,
            weight: bytes as u16,
        };
        let end = frame.end(t.ack_wait);
        d.tx_end = end;
        d.air_total += u128::from(attempts) * frame.air;
        d.frames[(d.frames_head + d.frames_len) % MODEM_FRAMES] = frame;
        d.frames_len += 1;
        let s = &mut d.stats;
        s.frames_sent = s.frames_sent.wrapping_add(1);
        s.failed_attempts = s
            .failed_attempts
            .wrapping_add(u32::from(attempts - u16::from(received)));
        let mut stored = true;
        if received {
            let last = frame.start + u128::from(attempts - 1) * frame.period(t.ack_wait);
            let due = t.ticks_ceil(last + frame.air).saturating_add(t.latency);
            let source = match direction {
                Direction::AToB => x.address_a,
                Direction::BToA => x.address_b,
            };
            let mut rx = [0u8; MAX_RX_FRAME];
            let n = rx_frame(x, source, &req, &d.parser.data[..d.parser.length], &mut rx);
            stored = d.insert(&rx[..n], due);
        } else {
            s.frames_lost = s.frames_lost.wrapping_add(1);
        }
        let s = &mut d.stats;
        if stored {
            s.bytes_sent = s.bytes_sent.wrapping_add(bytes);
        } else {
            // Received over the air (and acknowledged), lost at the receiver's UART.
            s.frames_overrun = s.frames_overrun.wrapping_add(1);
            s.overrun_bytes = s.overrun_bytes.wrapping_add(bytes);
        }
        if req.frame_id != 0 {
            let status = match (received || !req.acked, x.variant) {
                (true, _) => xbee::STATUS_SUCCESS,
                (false, XBeeVariant::XBee24) => xbee::STATUS_NO_ACK,
                (false, XBeeVariant::XBee868) => xbee::DELIVERY_NO_ACK,
            };
            let retries = u8::try_from(attempts - 1).unwrap_or(u8::MAX);
            self.status(
                direction,
                d,
                x,
                req.frame_id,
                retries,
                status,
                t.ticks_ceil(end),
            );
        }
    }

    /// Queues a transmit status for the writer of `direction` (its own reader, on the
    /// other direction's ring), readable at `due`.
    #[allow(clippy::too_many_arguments)]
    fn status(
        &self,
        direction: Direction,
        d: &mut Dir<N>,
        x: &XBeeModem,
        frame_id: u8,
        retries: u8,
        status: u8,
        due: u64,
    ) {
        let mut frame = [0u8; api::TX_STATUS_868_FRAME_LEN];
        let encoded = match x.variant {
            XBeeVariant::XBee24 => api::encode_tx_status_24(frame_id, status, &mut frame),
            XBeeVariant::XBee868 => api::encode_tx_status_868(
                frame_id,
                retries,
                status,
                xbee::DISCOVERY_NONE,
                &mut frame,
            ),
        };
        // The buffer holds the larger of the two frames.
        let Ok(n) = encoded else { return };
        let stored = self.with(direction.other(), |o| {
            let stored = o.insert(&frame[..n], due);
            if stored {
                o.rx_waker.wake();
            }
            stored
        });
        let s = &mut d.stats;
        if stored {
            s.statuses = s.statuses.wrapping_add(1);
        } else {
            s.statuses_lost = s.statuses_lost.wrapping_add(1);
        }
    }

    fn pop(&self, direction: Direction, buf: &mut [u8]) -> Step {
        let now = Instant::now().as_ticks();
        self.with(direction, |d| {
            let mut n = 0;
            let mut last = 0;
            while n < buf.len() && d.len > 0 && d.due[d.head] <= now {
                buf[n] = d.data[d.head];
                last = d.due[d.head];
                d.head = (d.head + 1) % N;
                d.len -= 1;
                n += 1;
            }
            if n > 0 {
                d.partial = d.len > 0 && d.due[d.head] == last;
                d.stats.bytes_delivered = d.stats.bytes_delivered.wrapping_add(crate::len_u32(n));
                d.tx_waker.wake();
                Step::Done(n)
            } else if d.len > 0 {
                Step::At(d.due[d.head])
            } else {
                Step::Peer
            }
        })
    }

    /// When the modem will be done with everything it accepted.
    fn drained_at(&self, direction: Direction) -> Option<u64> {
        let now = Self::now_units(&self.timing);
        self.with(direction, |d| {
            (d.tx_end > now).then(|| self.timing.ticks_ceil(d.tx_end))
        })
    }

    /// Waits until the reader of `direction` freed `need` bytes of the ring.
    async fn wait_reader(&self, direction: Direction, need: usize) {
        poll_fn(|cx| {
            self.with(direction, |d| {
                if N - d.len >= need {
                    Poll::Ready(())
                } else {
                    d.tx_waker.register(cx.waker());
                    Poll::Pending
                }
            })
        })
        .await;
    }

    /// Waits until something was put in the ring of `direction`.
    async fn wait_writer(&self, direction: Direction) {
        poll_fn(|cx| {
            self.with(direction, |d| {
                if d.len > 0 {
                    Poll::Ready(())
                } else {
                    d.rx_waker.register(cx.waker());
                    Poll::Pending
                }
            })
        })
        .await;
    }

    async fn write(&self, direction: Direction, buf: &[u8]) -> usize {
        let mut cursor = Cursor {
            done: 0,
            fresh: true,
        };
        loop {
            match self.push(direction, buf, &mut cursor) {
                Step::Done(n) => return n,
                Step::At(tick) => Timer::at(Instant::from_ticks(tick)).await,
                Step::Room(need) => self.wait_reader(direction, need).await,
                Step::Peer => unreachable!("push never waits for a writer"),
            }
        }
    }

    async fn read(&self, direction: Direction, buf: &mut [u8]) -> usize {
        if buf.is_empty() {
            return 0;
        }
        loop {
            match self.pop(direction, buf) {
                Step::Done(n) => return n,
                Step::At(tick) => Timer::at(Instant::from_ticks(tick)).await,
                Step::Peer | Step::Room(_) => self.wait_writer(direction).await,
            }
        }
    }
}

/// Length of the RX frame carrying `rf_len` bytes of RF data.
const fn rx_frame_len(variant: XBeeVariant, rf_len: usize) -> usize {
    variant.rx_header() + rf_len + xbee::FRAMING
}

/// Writes the RX frame of `req` (whose `FRAME_DATA` is `data`) to `out`; returns its
/// length.
fn rx_frame(
    x: &XBeeModem,
    source: u64,
    req: &TxRequest,
    data: &[u8],
    out: &mut [u8; MAX_RX_FRAME],
) -> usize {
    let rf = &data[req.rf_start..];
    let header = x.variant.rx_header();
    let fd = &mut out[api::HEADER_LEN..];
    match x.variant {
        XBeeVariant::XBee24 => {
            use api::field::rx16;
            fd[rx16::API_ID] = xbee::API_RX16;
            fd[rx16::SOURCE].copy_from_slice(&(source as u16).to_be_bytes());
            fd[rx16::RSSI] = x.rssi;
            fd[rx16::OPTIONS] = if req.broadcast {
                xbee::RX_OPTION_BROADCAST
            } else {
                0
            };
        }
        XBeeVariant::XBee868 => {
            use api::field::rx868;
            fd[rx868::API_ID] = xbee::API_RX_868;
            fd[rx868::SOURCE64].copy_from_slice(&source.to_be_bytes());
            fd[rx868::SOURCE16].copy_from_slice(&[0xFF, 0xFE]);
            fd[rx868::OPTIONS] = if req.broadcast {
                xbee::RX_OPTION_BROADCAST
            } else if req.acked {
                xbee::RX_OPTION_ACKED
            } else {
                0
            };
        }
    }
    fd[header..header + rf.len()].copy_from_slice(rf);
    xbee::frame_in_place(out, header + rf.len())
}

impl<const N: usize> Dir<N> {
    const fn new(seed: u64) -> Self {
        Self {
            data: [0; N],
            due: [0; N],
            head: 0,
            len: 0,
            partial: false,
            uart_end: 0,
            uart_busy: 0,
            tx_end: 0,
            air_total: 0,
            frames: [InModem::EMPTY; MODEM_FRAMES],
            frames_head: 0,
            frames_len: 0,
            parser: Parser::new(),
            rng: SplitMix64(seed),
            stats: SimStats {
                bytes_written: 0,
                bytes_sent: 0,
                bytes_delivered: 0,
                dropped_bytes: 0,
                overrun_bytes: 0,
                bit_errors: 0,
                corrupted_bytes: 0,
                serial_busy_us: 0,
                air_busy_us: 0,
                frames_sent: 0,
                frames_dropped: 0,
                frames_overrun: 0,
                malformed_frames: 0,
                discarded_bytes: 0,
                failed_attempts: 0,
                frames_lost: 0,
                statuses: 0,
                statuses_lost: 0,
            },
            rx_waker: WakerRegistration::new(),
            tx_waker: WakerRegistration::new(),
        }
    }

    /// Bytes in the transparent modem at `at` (the one on the air counts): they leave
    /// back to back until `tx_end`.
    fn queued(&self, at: u128, air_byte: u128) -> u128 {
        self.tx_end.saturating_sub(at).div_ceil(air_byte)
    }

    /// Inserts `bytes`, arriving at `due`, after every byte arriving at or before
    /// `due` (and never into a partly read run). Returns `false` if they do not fit.
    fn insert(&mut self, bytes: &[u8], due: u64) -> bool {
        let k = bytes.len();
        if k > N - self.len {
            return false;
        }
        let at = |i: usize| (self.head + i) % N;
        let mut pos = self.len;
        while pos > 0 && self.due[at(pos - 1)] > due {
            pos -= 1;
        }
        if self.partial && pos < self.len {
            // Not before the end of the partly read run.
            let run = self.due[self.head];
            let mut end = 0;
            while end < self.len && self.due[at(end)] == run {
                end += 1;
            }
            pos = pos.max(end);
        }
        let mut i = self.len;
        while i > pos {
            i -= 1;
            let (from, to) = (at(i), at(i + k));
            self.data[to] = self.data[from];
            self.due[to] = self.due[from];
        }
        for (j, &b) in bytes.iter().enumerate() {
            let to = at(pos + j);
            self.data[to] = b;
            self.due[to] = due;
        }
        self.len += k;
        true
    }

    fn frames_iter(&self) -> impl Iterator<Item = &InModem> {
        (0..self.frames_len).map(|i| &self.frames[(self.frames_head + i) % MODEM_FRAMES])
    }

    /// Forgets the frames the modem is done with at `at`.
    fn prune(&mut self, at: u128, ack_wait: u128) {
        while self.frames_len > 0 && self.frames[self.frames_head].end(ack_wait) <= at {
            self.frames_head = (self.frames_head + 1) % MODEM_FRAMES;
            self.frames_len -= 1;
        }
    }

    fn malformed(&mut self, bytes: u32) {
        let s = &mut self.stats;
        s.malformed_frames = s.malformed_frames.wrapping_add(1);
        s.discarded_bytes = s.discarded_bytes.wrapping_add(bytes);
    }

    /// One transmission of `air_bytes` bytes: `true` if it is received and
    /// acknowledged (no bit error, no random failure).
    fn attempt(&mut self, air_bytes: usize, t: &Timing) -> bool {
        let mut clean = true;
        if t.ber > 0 {
            for _ in 0..air_bytes {
                clean &= self.corrupt(0, t.ber) == 0;
            }
        }
        clean && (t.failure == 0 || self.rng.next() >= t.failure)
    }

    fn corrupt(&mut self, byte: u8, threshold: u64) -> u8 {
        if threshold == 0 {
            return byte;
        }
        let mut flips = 0u8;
        for bit in 0..8 {
            if self.rng.next() < threshold {
                flips |= 1 << bit;
            }
        }
        if flips != 0 {
            self.stats.bit_errors = self.stats.bit_errors.wrapping_add(flips.count_ones());
            self.stats.corrupted_bytes = self.stats.corrupted_bytes.wrapping_add(1);
        }
        byte ^ flips
    }
}

/// One endpoint of a [`SimLink`]: reads what the other endpoint writes and the other
/// way round. [`split`](Self::split) it to give the halves to a reader and a writer task.
pub struct SimEnd<'a, M: RawMutex, const N: usize> {
    /// The receiving half.
    pub rx: SimRx<'a, M, N>,
    /// The sending half.
    pub tx: SimTx<'a, M, N>,
}

impl<'a, M: RawMutex, const N: usize> SimEnd<'a, M, N> {
    fn new(link: &'a SimLink<M, N>, tx: Direction, rx: Direction) -> Self {
        Self {
            rx: SimRx {
                link,
                direction: rx,
            },
            tx: SimTx {
                link,
                direction: tx,
            },
        }
    }

    /// The receiving and the sending half.
    pub fn split(self) -> (SimRx<'a, M, N>, SimTx<'a, M, N>) {
        (self.rx, self.tx)
    }
}

/// The sending half of a [`SimEnd`].
pub struct SimTx<'a, M: RawMutex, const N: usize> {
    link: &'a SimLink<M, N>,
    direction: Direction,
}

impl<M: RawMutex, const N: usize> SimTx<'_, M, N> {
    /// Counters of this half's direction.
    pub fn stats(&self) -> SimStats {
        self.link.stats(self.direction)
    }
}

/// The receiving half of a [`SimEnd`].
pub struct SimRx<'a, M: RawMutex, const N: usize> {
    link: &'a SimLink<M, N>,
    direction: Direction,
}

impl<M: RawMutex, const N: usize> SimRx<'_, M, N> {
    /// Counters of this half's direction.
    pub fn stats(&self) -> SimStats {
        self.link.stats(self.direction)
    }
}

impl<M: RawMutex, const N: usize> ErrorType for SimTx<'_, M, N> {
    type Error = Infallible;
}

impl<M: RawMutex, const N: usize> ErrorType for SimRx<'_, M, N> {
    type Error = Infallible;
}

impl<M: RawMutex, const N: usize> ErrorType for SimEnd<'_, M, N> {
    type Error = Infallible;
}

impl<M: RawMutex, const N: usize> Write for SimTx<'_, M, N> {
    /// Sends `buf` over the UART into the modem, one byte every `1 / serial_rate` s,
    /// and completes when the last byte has crossed: it always reports the whole of
    /// `buf`. With [`Overflow::Drop`] the UART never stops (bytes the modem has no room
    /// for are dropped and counted); with [`Overflow::Wait`] it stops while the modem
    /// (or the receiver's ring) is full.
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        Ok(self.link.write(self.direction, buf).await)
    }

    /// Waits until the modem is done with every byte it accepted (in the air; XBee:
    /// every attempt and ACK wait over).
    async fn flush(&mut self) -> Result<(), Infallible> {
        while let Some(tick) = self.link.drained_at(self.direction) {
            Timer::at(Instant::from_ticks(tick)).await;
        }
        Ok(())
    }
}

impl<M: RawMutex, const N: usize> Read for SimRx<'_, M, N> {
    /// Waits until at least one byte has arrived, then returns every arrived byte that
    /// fits in `buf`.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        Ok(self.link.read(self.direction, buf).await)
    }
}

impl<M: RawMutex, const N: usize> Write for SimEnd<'_, M, N> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.tx.write(buf).await
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        self.tx.flush().await
    }
}

impl<M: RawMutex, const N: usize> Read for SimEnd<'_, M, N> {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        self.rx.read(buf).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probability_threshold_saturates() {
        assert_eq!(probability_threshold(0.0), 0);
        assert_eq!(probability_threshold(-1.0), 0);
        assert_eq!(probability_threshold(f64::NAN), 0);
        assert_eq!(probability_threshold(1.0), u64::MAX);
        assert_eq!(probability_threshold(0.5), 1 << 63);
    }

    #[test]
    fn splitmix_reference_values() {
        // First outputs for seed 1234567 from the reference C implementation.
        let mut rng = SplitMix64(1_234_567);
        assert_eq!(rng.next(), 6_457_827_717_110_365_317);
        assert_eq!(rng.next(), 3_203_168_211_198_807_973);
    }

    #[test]
    fn memory_per_direction_is_as_documented() {
        assert!(core::mem::size_of::<Dir<1>>() <= 9 + 1300);
        assert!(core::mem::size_of::<Dir<4096>>() <= 9 * 4096 + 1300);
    }

    #[test]
    fn api_frame_checksum() {
        // TX16 to 0x0100, frame id 1, no options, RF data "hi".
        let mut out = [0u8; 16];
        let n = xbee::api_frame(&[0x01, 0x01, 0x01, 0x00, 0x00, b'h', b'i'], &mut out);
        assert_eq!(n, Some(11));
        let sum: u8 = out[3..11].iter().fold(0, |a, &b| a.wrapping_add(b));
        assert_eq!(sum, 0xFF, "FRAME_DATA plus checksum sums to 0xFF");
        assert_eq!(&out[..3], &[0x7E, 0x00, 0x07]);
        assert_eq!(xbee::api_frame(&[1, 2], &mut out[..5]), None);
    }

    #[test]
    fn insert_keeps_arrival_order_and_runs_whole() {
        let mut d = Dir::<16>::new(1);
        assert!(d.insert(&[1], 10));
        assert!(d.insert(&[2], 30));
        assert!(d.insert(&[7, 7, 7], 20));
        assert!(d.insert(&[3], 30));
        let order: std::vec::Vec<_> = (0..d.len).map(|i| (d.data[i], d.due[i])).collect();
        assert_eq!(
            order,
            [(1, 10), (7, 20), (7, 20), (7, 20), (2, 30), (3, 30)]
        );
        // A partly read run is not split, even by an earlier arrival.
        d.head = 2;
        d.len = 4;
        d.partial = true;
        assert!(d.insert(&[9], 5));
        let order: std::vec::Vec<_> = (0..d.len).map(|i| d.data[(d.head + i) % 16]).collect();
        assert_eq!(order, [7, 7, 9, 2, 3]);
        assert!(!d.insert(&[0; 12], 40), "does not fit");
    }
}
