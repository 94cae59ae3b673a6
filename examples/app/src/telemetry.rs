//! The vehicle's telemetry messages, built from a snapshot of its state: one pure
//! function per message of the periodic schedule, so the periodic callbacks are one line
//! each and the messages can be checked without a link.

use pprz_default::messages::telemetry::{
    Alive, Attitude, AutopilotVersion, Energy, GpsInt, ImuAccelRaw, ImuGyroRaw, ImuMagRaw, Ins,
    RotorcraftFp, RotorcraftStatus, values,
};
use pprz_messages::VarArray;

use crate::vehicle::{ALTITUDE, Mode, RADIUS, SPEED, Vehicle};

/// Fixed-point scales of ROTORCRAFT_FP / INS (Paparazzi's BFP formats).
const POS_FRAC: f32 = 256.0; // 2^8
const SPEED_FRAC: f32 = 524_288.0; // 2^19
const ACCEL_FRAC: f32 = 1024.0; // 2^10
const ANGLE_FRAC: f32 = 4096.0; // 2^12

/// The firmware's build hash, as ALIVE carries it.
const MD5: [u8; 8] = [0x5E, 0x1F, 0x0B, 0x77, 0x21, 0x9D, 0xC4, 0x02];

/// ALIVE.
pub fn alive() -> Alive<'static> {
    Alive {
        md5sum: VarArray::new(&MD5),
    }
}

/// AUTOPILOT_VERSION.
pub fn version() -> AutopilotVersion<'static> {
    AutopilotVersion {
        version: 10_000,
        desc: "pprz-embassy example".into(),
    }
}

/// ATTITUDE.
pub fn attitude(v: &Vehicle) -> Attitude {
    Attitude {
        phi: v.phi,
        psi: v.psi,
        theta: v.theta,
    }
}

/// GPS_INT; `tow_ms` is the GPS time of week.
pub fn gps_int(v: &Vehicle, tow_ms: u32) -> GpsInt {
    let (lat, lon) = v.lat_lon();
    GpsInt {
        lat: (lat * 1e7) as i32,
        lon: (lon * 1e7) as i32,
        alt: (v.up * 1000.0) as i32 + 197_000,
        hmsl: (v.up * 1000.0) as i32 + 147_000,
        pacc: 150,
        sacc: 40,
        tow: tow_ms,
        pdop: 120,
        numsv: 11,
        fix: values::GpsIntFix::V3D.raw(),
        comp_id: values::GpsIntCompId::Sim.raw(),
        ..GpsInt::default()
    }
}

/// ROTORCRAFT_FP.
pub fn rotorcraft_fp(v: &Vehicle) -> RotorcraftFp {
    RotorcraftFp {
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
    }
}

/// INS.
pub fn ins(v: &Vehicle) -> Ins {
    let w2 = (SPEED / RADIUS) * (SPEED / RADIUS);
    Ins {
        ins_x: (v.north * POS_FRAC) as i32,
        ins_y: (v.east * POS_FRAC) as i32,
        ins_z: (-v.up * POS_FRAC) as i32,
        ins_xd: (v.vnorth * SPEED_FRAC) as i32,
        ins_yd: (v.veast * SPEED_FRAC) as i32,
        ins_zd: 0,
        ins_xdd: (-v.north * w2 * ACCEL_FRAC) as i32,
        ins_ydd: (-v.east * w2 * ACCEL_FRAC) as i32,
        ins_zdd: 0,
    }
}

/// ENERGY.
pub fn energy(v: &Vehicle) -> Energy {
    Energy {
        throttle: 55,
        voltage: v.voltage,
        current: v.current,
        power: v.voltage * v.current,
        avg_power: v.voltage * 12.0,
        charge: v.charge_ah,
        energy: v.energy_wh,
    }
}

/// ROTORCRAFT_STATUS.
pub fn status(v: &Vehicle) -> RotorcraftStatus {
    RotorcraftStatus {
        frame_rate: 50,
        gps_status: values::RotorcraftStatusGpsStatus::V3D.raw(),
        ap_mode: match v.mode {
            Mode::Nav => values::RotorcraftStatusApMode::Nav.raw(),
            Mode::Home => values::RotorcraftStatusApMode::Home.raw(),
        },
        ap_in_flight: u8::from(v.up > 1.0),
        ap_motors_on: 1,
        arming_status: values::RotorcraftStatusArmingStatus::Armed.raw(),
        ap_h_mode: values::RotorcraftStatusApHMode::Nav.raw(),
        ap_v_mode: values::RotorcraftStatusApVMode::Nav.raw(),
        cpu_time: v.t as u16,
        vsupply: v.voltage,
        vboard: 5.0,
        ..RotorcraftStatus::default()
    }
}

/// IMU_GYRO_RAW.
pub fn gyro(v: &Vehicle) -> ImuGyroRaw {
    ImuGyroRaw {
        id: 1,
        temp: 36.5,
        gp: (v.phi * 4000.0) as i32,
        gq: (v.theta * 4000.0) as i32,
        gr: (SPEED / RADIUS * 4000.0) as i32,
    }
}

/// IMU_ACCEL_RAW.
pub fn accel(v: &Vehicle) -> ImuAccelRaw {
    ImuAccelRaw {
        id: 1,
        temp: 36.5,
        ax: (v.phi * 900.0) as i32,
        ay: 0,
        az: -9000,
    }
}

/// IMU_MAG_RAW.
pub fn mag() -> ImuMagRaw {
    ImuMagRaw {
        id: 1,
        mx: 2100,
        my: -300,
        mz: 4000,
    }
}
