//! The example aircraft: one application shared by the host simulation (SITL), the STM32
//! board examples and the emulated Cortex-M4, so every one of them runs the same code.
//!
//! It simulates a rotorcraft flying a circle (GPS, attitude, INS, energy), sends the
//! periodic telemetry of the project's `telemetry.xml` through the downlink, answers the
//! ground (PING, SETTING, GET_SETTING) through a datalink reader, and can flood the link
//! with low-priority payload to show priority shedding.
//!
//! [`run_aircraft`] builds everything that is local to the application (scheduler,
//! callbacks, settings, services, registry, reader) inside one future that never ends,
//! so nothing needs a `static` but the downlink; the firmware spawns it next to one
//! writer task per device:
//!
//! ```ignore
//! #[embassy_executor::task]
//! async fn aircraft(downlink: &'static Dl, radio_rx: BufferedUartRx<'static>) {
//!     pprz_example_app::run_aircraft(downlink, radio_rx, 0, Config::default()).await
//! }
//! ```

#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]

use core::cell::{Cell, RefCell};

use embassy_futures::join::join5;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker};
use embedded_io_async::Read;
use pprz_messages::{Message, VarArray};
use pprz_telemetry::Downlink;
use pprz_telemetry::messages::telemetry::{
    Alive, Attitude, AutopilotVersion, DatalinkReport, DlValue, Energy, GpsInt, ImuAccelRaw,
    ImuGyroRaw, ImuMagRaw, Ins, Payload, RotorcraftFp, RotorcraftStatus, UartErrors, values,
};
use pprz_telemetry::periodic::SCHEDULE;
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::Registry;
use pprz_telemetry::scheduler::Scheduler;
use pprz_telemetry::services::{LinkReporter, Services, Settings};
use pprz_transports::PprzV2;

/// The mutex of everything shared between tasks (a critical section on boards).
pub type M = CriticalSectionRawMutex;

/// Our aircraft id.
pub const AC_ID: u8 = 7;

/// What the application does besides the periodic telemetry.
#[derive(Debug, Clone, Copy, Default)]
pub struct Config {
    /// Low-priority payload bytes per second to send (0: none). 10x the link's byte rate
    /// saturates it tenfold.
    pub flood_bytes_per_s: u32,
}

/// The simulated vehicle.
#[derive(Debug, Clone, Copy)]
struct Vehicle {
    /// Seconds since start.
    t: f32,
    /// Position in metres east, north, up of the home point.
    east: f32,
    north: f32,
    up: f32,
    /// Velocity in m/s.
    veast: f32,
    vnorth: f32,
    /// Euler angles in radians.
    phi: f32,
    theta: f32,
    psi: f32,
    /// Battery.
    voltage: f32,
    current: f32,
    charge_ah: f32,
    energy_wh: f32,
}

/// Circle radius (m), speed (m/s), altitude (m).
const RADIUS: f32 = 80.0;
const SPEED: f32 = 6.0;
const ALTITUDE: f32 = 40.0;
/// Home: Toulouse (lat, lon in degrees; UTM zone 31).
const HOME_LAT: f64 = 43.4622;
const HOME_LON: f64 = 1.2731;

impl Vehicle {
    const fn new() -> Self {
        Self {
            t: 0.0,
            east: RADIUS,
            north: 0.0,
            up: 0.0,
            veast: 0.0,
            vnorth: SPEED,
            phi: 0.0,
            theta: 0.0,
            psi: 0.0,
            voltage: 16.8,
            current: 0.0,
            charge_ah: 0.0,
            energy_wh: 0.0,
        }
    }

    /// Advances the simulation by `dt` seconds: climb to altitude, then circle.
    fn step(&mut self, dt: f32) {
        self.t += dt;
        let w = SPEED / RADIUS;
        let a = w * self.t;
        self.east = RADIUS * libm::cosf(a);
        self.north = RADIUS * libm::sinf(a);
        self.veast = -SPEED * libm::sinf(a);
        self.vnorth = SPEED * libm::cosf(a);
        self.up = (self.up + 2.0 * dt).min(ALTITUDE);
        self.psi = libm::atan2f(self.veast, self.vnorth);
        self.phi = libm::atanf(SPEED * w / 9.81);
        self.theta = 0.02 * libm::sinf(3.0 * a);
        self.current = 12.0 + 2.0 * libm::sinf(0.5 * self.t);
        self.charge_ah += self.current * dt / 3600.0;
        self.voltage = 16.8 - 0.6 * self.charge_ah;
        self.energy_wh += self.voltage * self.current * dt / 3600.0;
    }

    fn lat_lon(&self) -> (f64, f64) {
        const R: f64 = 6_371_000.0;
        let lat = HOME_LAT + f64::from(self.north) / R * (180.0 / core::f64::consts::PI);
        let cos_lat = libm::cos(HOME_LAT.to_radians());
        let lon = HOME_LON + f64::from(self.east) / (R * cos_lat) * (180.0 / core::f64::consts::PI);
        (lat, lon)
    }
}

/// Sends `msg` to every device; a drop is counted by the downlink (per device, reason
/// and priority level), so the result needs no handling here.
fn send<Msg: Message, const D: usize, const Q: usize>(downlink: &Downlink<'_, M, D, Q>, msg: &Msg) {
    let _ = downlink.send(msg);
}

/// Fixed-point scales of ROTORCRAFT_FP / INS (Paparazzi's BFP formats).
const POS_FRAC: f32 = 256.0; // 2^8
const SPEED_FRAC: f32 = 524_288.0; // 2^19
const ACCEL_FRAC: f32 = 1024.0; // 2^10
const ANGLE_FRAC: f32 = 4096.0; // 2^12

/// Runs the aircraft application forever: dynamics at 50 Hz, periodic telemetry, the
/// datalink reader on `radio_rx` (its replies go to downlink device `link`), and the
/// payload flood of `config`.
pub async fn run_aircraft<R: Read, const D: usize, const Q: usize>(
    downlink: &Downlink<'_, M, D, Q>,
    radio_rx: R,
    link: usize,
    config: Config,
) -> ! {
    let vehicle: Mutex<M, RefCell<Vehicle>> = Mutex::new(RefCell::new(Vehicle::new()));
    let v = || vehicle.lock(|v| *v.borrow());
    let boot = Instant::now();

    // Settings the ground can change (indices in registration order).
    let flood_on: Mutex<M, Cell<bool>> = Mutex::new(Cell::new(config.flood_bytes_per_s > 0));
    let gain: Mutex<M, Cell<f32>> = Mutex::new(Cell::new(1.0));

    // The ground switches the telemetry mode through this signal: the scheduler applies
    // it in its own future (the settings must not borrow the scheduler, whose callbacks
    // borrow the datalink that holds the settings' subscriber).
    let mode_request: Signal<M, usize> = Signal::new();
    let mode_value: Mutex<M, Cell<u8>> = Mutex::new(Cell::new(0));
    let modes = SCHEDULE.processes.first().map_or(1, |p| p.modes.len());
    let get_mode = || f32::from(mode_value.lock(Cell::get));
    let set_mode = |x: f32| {
        // An invalid mode is refused; the acknowledgement reports the mode in force.
        if x >= 0.0 && libm::truncf(x) == x && (x as usize) < modes {
            mode_value.lock(|c| c.set(x as u8));
            mode_request.signal(x as usize);
        }
    };
    let get_flood = || f32::from(u8::from(flood_on.lock(Cell::get)));
    let set_flood = |x: f32| flood_on.lock(|c| c.set(x >= 0.5));
    let get_gain = || gain.lock(Cell::get);
    let set_gain = |x: f32| gain.lock(|c| c.set(x.clamp(0.0, 10.0)));
    let mut settings: Settings<'_, 4> = Settings::new();
    let _ = settings.add("telemetry_mode", &get_mode, &set_mode);
    let _ = settings.add("payload_flood", &get_flood, &set_flood);
    let _ = settings.add("gain", &get_gain, &set_gain);
    let services: Services<'_, '_, M, D, Q, 4> = Services::new(downlink, settings);
    let mut registry: Registry<'_, 4> = Registry::new();
    let _ = services.subscribe(&mut registry);
    let datalink: Datalink<'_, M, 4> = Datalink::new(downlink.ac_id(), registry);

    // Periodic telemetry callbacks.
    let alive = || {
        let md5 = [0x5E, 0x1F, 0x0B, 0x77, 0x21, 0x9D, 0xC4, 0x02];
        send(
            downlink,
            &Alive {
                md5sum: VarArray::new(&md5),
            },
        );
    };
    let version = || {
        send(
            downlink,
            &AutopilotVersion {
                version: 10_000,
                desc: "pprz-embassy example".into(),
            },
        );
    };
    let attitude = || {
        let v = v();
        send(
            downlink,
            &Attitude {
                phi: v.phi,
                psi: v.psi,
                theta: v.theta,
            },
        );
    };
    let gps_int = || {
        let v = v();
        let (lat, lon) = v.lat_lon();
        send(
            downlink,
            &GpsInt {
                lat: (lat * 1e7) as i32,
                lon: (lon * 1e7) as i32,
                alt: (v.up * 1000.0) as i32 + 197_000,
                hmsl: (v.up * 1000.0) as i32 + 147_000,
                pacc: 150,
                sacc: 40,
                tow: boot.elapsed().as_millis() as u32,
                pdop: 120,
                numsv: 11,
                fix: values::GpsIntFix::V3D.raw(),
                comp_id: values::GpsIntCompId::Sim.raw(),
                ..GpsInt::default()
            },
        );
    };
    let fp = || {
        let v = v();
        send(
            downlink,
            &RotorcraftFp {
                east: (v.east * POS_FRAC) as i32,
                north: (v.north * POS_FRAC) as i32,
                up: (v.up * POS_FRAC) as i32,
                veast: (v.veast * SPEED_FRAC) as i32,
                vnorth: (v.vnorth * SPEED_FRAC) as i32,
                vup: 0,
                phi: (v.phi * ANGLE_FRAC) as i32,
                theta: (v.theta * ANGLE_FRAC) as i32,
                psi: (v.psi * ANGLE_FRAC) as i32,
                carrot_east: (v.east * POS_FRAC) as i32,
                carrot_north: (v.north * POS_FRAC) as i32,
                carrot_up: (ALTITUDE * POS_FRAC) as i32,
                carrot_psi: (v.psi * ANGLE_FRAC) as i32,
                thrust: 6_000,
                flight_time: v.t as u16,
            },
        );
    };
    let ins = || {
        let v = v();
        send(
            downlink,
            &Ins {
                ins_x: (v.north * POS_FRAC) as i32,
                ins_y: (v.east * POS_FRAC) as i32,
                ins_z: (-v.up * POS_FRAC) as i32,
                ins_xd: (v.vnorth * SPEED_FRAC) as i32,
                ins_yd: (v.veast * SPEED_FRAC) as i32,
                ins_zd: 0,
                ins_xdd: (-v.north * (SPEED / RADIUS) * (SPEED / RADIUS) * ACCEL_FRAC) as i32,
                ins_ydd: (-v.east * (SPEED / RADIUS) * (SPEED / RADIUS) * ACCEL_FRAC) as i32,
                ins_zdd: 0,
            },
        );
    };
    let energy = || {
        let v = v();
        send(
            downlink,
            &Energy {
                throttle: 55,
                voltage: v.voltage,
                current: v.current,
                power: v.voltage * v.current,
                avg_power: v.voltage * 12.0,
                charge: v.charge_ah,
                energy: v.energy_wh,
            },
        );
    };
    let status = || {
        let v = v();
        send(
            downlink,
            &RotorcraftStatus {
                frame_rate: 50,
                gps_status: values::RotorcraftStatusGpsStatus::V3D.raw(),
                ap_mode: values::RotorcraftStatusApMode::Nav.raw(),
                ap_in_flight: u8::from(v.up > 1.0),
                ap_motors_on: 1,
                arming_status: values::RotorcraftStatusArmingStatus::Armed.raw(),
                ap_h_mode: values::RotorcraftStatusApHMode::Nav.raw(),
                ap_v_mode: values::RotorcraftStatusApVMode::Nav.raw(),
                cpu_time: v.t as u16,
                vsupply: v.voltage,
                vboard: 5.0,
                ..RotorcraftStatus::default()
            },
        );
    };
    let reporter = Mutex::<M, _>::new(RefCell::new(LinkReporter::new()));
    let report = || {
        let up = datalink.stats();
        let down = downlink.stats(link).unwrap_or_default();
        let msg: DatalinkReport =
            reporter.lock(|r| r.borrow_mut().report(Instant::now(), &up, &down));
        send(downlink, &msg);
    };
    let uart_errors = || send(downlink, &UartErrors::default());
    let gyro = || {
        let v = v();
        send(
            downlink,
            &ImuGyroRaw {
                id: 1,
                temp: 36.5,
                gp: (v.phi * 4000.0) as i32,
                gq: (v.theta * 4000.0) as i32,
                gr: (SPEED / RADIUS * 4000.0) as i32,
            },
        );
    };
    let accel = || {
        let v = v();
        send(
            downlink,
            &ImuAccelRaw {
                id: 1,
                temp: 36.5,
                ax: (v.phi * 900.0) as i32,
                ay: 0,
                az: -9000,
            },
        );
    };
    let mag = || {
        send(
            downlink,
            &ImuMagRaw {
                id: 1,
                mx: 2100,
                my: -300,
                mz: 4000,
            },
        )
    };

    // Cycle through the settings, as the reference firmware's periodic DL_VALUE does.
    let dl_value_index: Mutex<M, Cell<u8>> = Mutex::new(Cell::new(0));
    let dl_value = || {
        let index = dl_value_index.lock(|c| {
            let i = c.get();
            c.set((i + 1) % (services.settings().len() as u8).max(1));
            i
        });
        if let Some(value) = services.settings().get(index) {
            send(downlink, &DlValue { index, value });
        }
    };

    let scheduler: Scheduler<'_, M, 1, 24> = Scheduler::new(&SCHEDULE);
    let _ = scheduler.register_message::<Alive>(&alive);
    let _ = scheduler.register_message::<AutopilotVersion>(&version);
    let _ = scheduler.register_message::<Attitude>(&attitude);
    let _ = scheduler.register_message::<GpsInt>(&gps_int);
    let _ = scheduler.register_message::<RotorcraftFp>(&fp);
    let _ = scheduler.register_message::<Ins>(&ins);
    let _ = scheduler.register_message::<Energy>(&energy);
    let _ = scheduler.register_message::<RotorcraftStatus>(&status);
    let _ = scheduler.register_message::<DlValue>(&dl_value);
    let _ = scheduler.register_message::<DatalinkReport>(&report);
    let _ = scheduler.register_message::<UartErrors>(&uart_errors);
    let _ = scheduler.register_message::<ImuGyroRaw>(&gyro);
    let _ = scheduler.register_message::<ImuAccelRaw>(&accel);
    let _ = scheduler.register_message::<ImuMagRaw>(&mag);

    let dynamics = async {
        let mut ticker = Ticker::every(Duration::from_millis(20));
        loop {
            ticker.next().await;
            vehicle.lock(|v| v.borrow_mut().step(0.02));
        }
    };
    let flood = async {
        // PAYLOAD frames of 120 bytes of fields, as often as the configured rate needs.
        let bytes = [0xA5u8; 120];
        let per_frame = bytes.len() as u32 + 1 + 8;
        let rate = config.flood_bytes_per_s.max(1);
        let period_us = (u64::from(per_frame) * 1_000_000 / u64::from(rate)).max(100);
        let mut ticker = Ticker::every(Duration::from_micros(period_us));
        loop {
            ticker.next().await;
            if config.flood_bytes_per_s > 0 && flood_on.lock(Cell::get) {
                send(
                    downlink,
                    &Payload {
                        values: VarArray::new(&bytes),
                    },
                );
            }
        }
    };
    let mut reader = Reader::<R, PprzV2>::new(radio_rx, PprzV2::new(), link);
    let modes = async {
        loop {
            let mode = mode_request.wait().await;
            let _ = scheduler.set_mode(0, mode);
        }
    };
    join5(
        scheduler.run(),
        reader.run(&datalink),
        dynamics,
        flood,
        modes,
    )
    .await;
    unreachable_forever().await
}

/// `join5` of never-ending futures never completes; this keeps the `!` return type
/// without a panic path.
async fn unreachable_forever() -> ! {
    loop {
        core::future::pending::<()>().await;
    }
}
