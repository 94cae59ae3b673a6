//! The simulated radio: what the options describe ([`RadioPlan`], checked as a whole),
//! the modem and air of the simulation ([`RadioPlan::sim_config`]) and the radio device
//! of the downlink ([`RadioPlan::device_config`]).

use embassy_time::Duration;
use pprz_devices::sim::{Overflow, SimConfig, SimLink, XBeeModem, XBeeVariant};
use pprz_example_app::M;
use pprz_secure::link::SecureLink;
use pprz_telemetry::{DeliveryWindow, DeviceConfig, Pacing};

use crate::fleet;
use crate::options::{Args, FlowControl, OnOff, TransportArg};

/// Receive ring of each direction of the simulated radio: bytes in the modem, on the
/// air and received but not yet read.
pub const RADIO_RING: usize = 16_384;

/// The modem buffer without `--modem-buffer` for a transparent modem (what the SITL
/// always had).
const DEFAULT_MODEM_BUFFER: usize = 64;
/// The modem buffer without `--modem-buffer` for an XBee: the serial receive buffer of an
/// XBee Series 1.
const DEFAULT_XBEE_BUFFER: usize = 202;

/// The over-the-air rate of XBee 802.15.4 (250 kbit/s), the default with
/// `--transport xbee`.
const XBEE_AIR_RATE: u32 = 31_250;

/// Most bytes the derived pacing budget allows: one and a half of the largest frame the
/// example sends (its 129-byte PAYLOAD frames), so the air stays busy while an
/// acknowledgement waits at most about two such frame times.
const MAX_DERIVED_BUDGET: usize = 192;

/// Time after which the radio device stops waiting for a transmit status: far above the
/// 802.15.4 transmission, retries and acknowledgement waits of a frame (about 25 ms),
/// and above the pacer's clock steps at `--speed 100`.
const DELIVERY_TIMEOUT_MS: u32 = 500;

/// A simulated radio (both directions).
pub type Radio = SimLink<M, RADIO_RING>;

/// The radio as the options describe it, checked together (each option alone was
/// checked when parsed).
#[derive(Debug, Clone, Copy)]
pub struct RadioPlan {
    /// What the radio speaks.
    pub transport: TransportArg,
    /// The UART's bytes per second (`baud / 10`).
    pub serial_rate: u32,
    /// The modem's bytes per second over the air.
    pub air_rate: u32,
    /// The modem's buffer, in bytes.
    pub modem_buffer: usize,
    /// The radio device's pacing (`--pacing on`).
    pub pacing: Option<Pacing>,
    /// XBee: the frames awaiting their transmit status.
    pub window: Option<DeliveryWindow>,
    /// `--overload`: the flood's bytes per second (0 without).
    pub flood_bytes_per_s: u32,
    /// `--secure`: the radio reserves the secure overhead after every frame.
    pub secure: bool,
    /// `--bit-error-rate`: the probability that a bit on the air is flipped.
    pub bit_error_rate: f64,
    /// `--seed`: each radio's seed derives from it.
    pub seed: u64,
    /// `--radios`: radios from each aircraft to the ground (1 or 2).
    pub radios: u8,
    /// `--frame-loss`: the probability that a frame is lost on a radio to the ground.
    pub frame_loss: f64,
}

/// The checks of `--radios`, `--frame-loss` and `--zenoh` with the other options.
fn check_redundant(args: &Args, xbee: bool) -> Result<(), String> {
    if args.radios > 1 {
        let refused = [
            (
                xbee,
                "--transport xbee (the second radio carries PPRZ v2 frames)",
            ),
            (
                args.relay,
                "--relay (aircraft 7's second radio is the relay's)",
            ),
            (
                args.secure.is_some(),
                "--secure (the secure link is one radio's)",
            ),
        ];
        if let Some((_, why)) = refused.iter().find(|(on, _)| *on) {
            return Err(format!("--radios 2 cannot run with {why}"));
        }
    }
    if args.gateway() && args.secure.is_some() {
        return Err(
            "--secure needs one plain radio: --radios 2, --frame-loss and --zenoh merge the radios with the gateway, which has no secure link"
                .to_owned(),
        );
    }
    if args.zenoh.is_some() && args.headless {
        return Err("--zenoh serves the in-process ground's gateway: drop --headless (or run pprz-gateway beside it)".to_owned());
    }
    Ok(())
}

/// The checks of `--fleet` and `--relay` with the other options.
fn check_fleet(args: &Args, xbee: bool) -> Result<(), String> {
    let n = args.fleet;
    if args.relay && n != 2 {
        return Err(format!(
            "--relay needs --fleet 2 (aircraft 8 reaches the ground only through aircraft 7); --fleet {n} puts every aircraft on a radio of its own"
        ));
    }
    if n > 1 && xbee {
        return Err(format!(
            "--fleet {n} needs --transport pprz2 (the fleet's radios and the relay carry PPRZ v2 frames)"
        ));
    }
    if n > 1 && args.secure.is_some() {
        return Err(format!(
            "--fleet {n} cannot run with --secure: the secure link is between one aircraft and the ground (use --fleet 1)"
        ));
    }
    Ok(())
}

impl RadioPlan {
    /// The plan of `args`, or the message of a usage error.
    pub fn new(args: &Args) -> Result<Self, String> {
        crate::link::check(args)?;
        crate::persist::check(args)?;
        let xbee = args.transport == TransportArg::Xbee;
        let serial_rate = args.baud / 10;
        let air_rate = args
            .air_rate
            .unwrap_or(if xbee { XBEE_AIR_RATE } else { serial_rate });
        let min_xbee_buffer = XBeeVariant::XBee24.max_api_frame();
        let modem_buffer = match args.modem_buffer {
            Some(b) if xbee && b < min_xbee_buffer => {
                return Err(format!(
                    "--modem-buffer {b} is too small for --transport xbee: an XBee modem holds at least one whole API frame, {min_xbee_buffer} bytes"
                ));
            }
            Some(b) => b,
            None if xbee => DEFAULT_XBEE_BUFFER,
            None => DEFAULT_MODEM_BUFFER,
        };
        if args.headless && args.foxglove.is_some() {
            return Err("--foxglove serves the in-process ground's telemetry: drop --headless (or run pprz-monitor --foxglove beside it)".into());
        }
        check_fleet(args, xbee)?;
        check_redundant(args, xbee)?;
        if args.secure.is_some() && xbee {
            return Err(
                "--secure needs --transport pprz2 (the secure link is Paparazzi's secure PPRZ v2)"
                    .to_owned(),
            );
        }
        if args.in_modem.is_some() && !xbee {
            return Err(
                "--in-modem needs --transport xbee (only XBee API frames have transmit statuses)"
                    .into(),
            );
        }
        let pacing = match (args.pacing, args.pacing_budget) {
            (OnOff::Off, Some(_)) => {
                return Err("--pacing-budget needs --pacing on".into());
            }
            (OnOff::On, Some(budget)) if budget > modem_buffer => {
                return Err(format!(
                    "--pacing-budget {budget} is larger than the modem buffer ({modem_buffer} bytes): the modem would overflow"
                ));
            }
            (OnOff::On, budget) => {
                let budget = budget.unwrap_or((modem_buffer / 2).clamp(1, MAX_DERIVED_BUDGET));
                Some(Pacing::new(air_rate, budget as u16))
            }
            (OnOff::Off, None) => None,
        };
        let window =
            xbee.then(|| DeliveryWindow::new(args.in_modem.unwrap_or(1), DELIVERY_TIMEOUT_MS));
        // 10x the link's capacity: the slower of the UART and the air.
        let flood_bytes_per_s = if args.overload {
            serial_rate.min(air_rate) * 10
        } else {
            0
        };
        Ok(Self {
            transport: args.transport,
            serial_rate,
            air_rate,
            modem_buffer,
            pacing,
            window,
            flood_bytes_per_s,
            secure: args.secure.is_some(),
            bit_error_rate: args.bit_error_rate,
            seed: args.seed,
            radios: args.radios,
            frame_loss: args.frame_loss,
        })
    }

    /// Whether the radio speaks XBee API frames.
    pub fn xbee(&self) -> bool {
        self.transport == TransportArg::Xbee
    }

    /// The simulated radio number `index` (0: aircraft 7's radio to the ground; each
    /// radio's errors seeded apart, [`fleet::radio_seed`]).
    pub fn sim_config(&self, flow_control: FlowControl, index: u8) -> SimConfig {
        let config = SimConfig::new(self.air_rate)
            .serial_rate(self.serial_rate)
            .latency(Duration::from_millis(5))
            .buffer(self.modem_buffer)
            .overflow(match flow_control {
                FlowControl::Cts => Overflow::Wait,
                FlowControl::None => Overflow::Drop,
            })
            .bit_error_rate(self.bit_error_rate)
            .seed(fleet::radio_seed(self.seed, index));
        if self.xbee() {
            // An XBee 802.15.4 (module docs of `pprz_devices::sim`): MAC framing and
            // acknowledgement on the air, 1 ms ACK wait, 3 retries; the ground writes API
            // frames too; a frame the modem drops is answered with "purged".
            config.xbee(
                XBeeModem::new(XBeeVariant::XBee24)
                    .air_overhead(20)
                    .ack_delay(Duration::from_millis(1))
                    .retries(3)
                    .api_uplink(true)
                    .purge_status(true),
            )
        } else {
            config
        }
    }

    /// The radio device of the downlink.
    pub fn device_config(&self) -> DeviceConfig {
        let reserve = if self.secure {
            SecureLink::<M>::DEVICE.reserve
        } else {
            0
        };
        DeviceConfig::new(self.transport.any())
            .pacing(self.pacing)
            .delivery(self.window)
            .reserve(reserve)
    }
}
