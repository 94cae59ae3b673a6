//! The simulated rotorcraft: climbs to its altitude, then flies a circle around home,
//! draining its battery. In [`Mode::Home`] (the link-loss failsafe) it flies straight
//! back over home and hovers there; back in [`Mode::Nav`] it returns to its circle.

/// What the autopilot is doing (reported as ROTORCRAFT_STATUS `ap_mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Flying the circle around home.
    Nav,
    /// Flying back over home and hovering there.
    Home,
}

/// The simulated vehicle.
#[derive(Debug, Clone, Copy)]
pub struct Vehicle {
    /// Seconds since start.
    pub t: f32,
    /// Position in metres east of the home point.
    pub east: f32,
    /// North of home (m).
    pub north: f32,
    /// Up from home (m).
    pub up: f32,
    /// Velocity east (m/s).
    pub veast: f32,
    /// Velocity north (m/s).
    pub vnorth: f32,
    /// Roll (rad).
    pub phi: f32,
    /// Pitch (rad).
    pub theta: f32,
    /// Heading (rad).
    pub psi: f32,
    /// Battery voltage (V).
    pub voltage: f32,
    /// Battery current (A).
    pub current: f32,
    /// Charge used (Ah).
    pub charge_ah: f32,
    /// Energy used (Wh).
    pub energy_wh: f32,
    /// The autopilot's mode.
    pub mode: Mode,
    /// Angle on the circle (rad, from east).
    angle: f32,
}

/// Circle radius (m).
pub const RADIUS: f32 = 80.0;
/// Ground speed (m/s).
pub const SPEED: f32 = 6.0;
/// Altitude of the circle (m).
pub const ALTITUDE: f32 = 40.0;
/// Home: Toulouse (lat, lon in degrees; UTM zone 31).
const HOME_LAT: f64 = 43.4622;
const HOME_LON: f64 = 1.2731;

impl Vehicle {
    /// On the ground at the start of the circle, battery full.
    pub const fn new() -> Self {
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
            mode: Mode::Nav,
            angle: 0.0,
        }
    }

    /// Advances the simulation by `dt` seconds: climb to altitude, then circle (or fly
    /// home, in [`Mode::Home`]).
    pub fn step(&mut self, dt: f32) {
        self.t += dt;
        let w = SPEED / RADIUS;
        let distance = libm::hypotf(self.east, self.north);
        let (ve, vn) = match self.mode {
            Mode::Nav if distance >= RADIUS - 0.5 => {
                self.angle = libm::atan2f(self.north, self.east) + w * dt;
                let a = self.angle;
                self.east = RADIUS * libm::cosf(a);
                self.north = RADIUS * libm::sinf(a);
                (-SPEED * libm::sinf(a), SPEED * libm::cosf(a))
            }
            // Inside the circle (back from home): straight out to it.
            Mode::Nav => self.fly_towards(RADIUS, distance, dt),
            Mode::Home => self.fly_towards(0.0, distance, dt),
        };
        (self.veast, self.vnorth) = (ve, vn);
        self.up = (self.up + 2.0 * dt).min(ALTITUDE);
        if ve != 0.0 || vn != 0.0 {
            self.psi = libm::atan2f(ve, vn);
        }
        let turning = self.mode == Mode::Nav && distance >= RADIUS - 0.5;
        self.phi = if turning {
            libm::atanf(SPEED * w / 9.81)
        } else {
            0.0
        };
        self.theta = 0.02 * libm::sinf(3.0 * self.angle);
        self.current = 12.0 + 2.0 * libm::sinf(0.5 * self.t);
        self.charge_ah += self.current * dt / 3600.0;
        self.voltage = 16.8 - 0.6 * self.charge_ah;
        self.energy_wh += self.voltage * self.current * dt / 3600.0;
    }

    /// Flies radially (along the line through home) to `radius` metres from home at
    /// [`SPEED`], stopping there; returns the velocity (east, north).
    fn fly_towards(&mut self, radius: f32, distance: f32, dt: f32) -> (f32, f32) {
        let gap = radius - distance;
        if libm::fabsf(gap) < 0.01 {
            return (0.0, 0.0);
        }
        // The direction out from home (east when over it).
        let (ue, un) = if distance > 0.01 {
            (self.east / distance, self.north / distance)
        } else {
            (1.0, 0.0)
        };
        let move_by = gap.clamp(-SPEED * dt, SPEED * dt);
        self.east += ue * move_by;
        self.north += un * move_by;
        (ue * move_by / dt, un * move_by / dt)
    }

    /// Latitude and longitude in degrees.
    pub fn lat_lon(&self) -> (f64, f64) {
        const R: f64 = 6_371_000.0;
        let lat = HOME_LAT + f64::from(self.north) / R * (180.0 / core::f64::consts::PI);
        let cos_lat = libm::cos(HOME_LAT.to_radians());
        let lon = HOME_LON + f64::from(self.east) / (R * cos_lat) * (180.0 / core::f64::consts::PI);
        (lat, lon)
    }
}

impl Default for Vehicle {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distance(v: &Vehicle) -> f32 {
        libm::hypotf(v.east, v.north)
    }

    #[test]
    fn home_flies_back_and_hovers_then_nav_returns_to_the_circle() {
        let mut v = Vehicle::new();
        for _ in 0..500 {
            v.step(0.02);
        }
        assert!((distance(&v) - RADIUS).abs() < 0.01, "on the circle");
        v.mode = Mode::Home;
        // 80 m at 6 m/s: home within 14 s, then still.
        for _ in 0..700 {
            v.step(0.02);
        }
        assert!(distance(&v) < 0.02, "over home: {}", distance(&v));
        assert_eq!((v.veast, v.vnorth), (0.0, 0.0), "hovering");
        v.mode = Mode::Nav;
        for _ in 0..700 {
            v.step(0.02);
        }
        assert!((distance(&v) - RADIUS).abs() < 0.01, "back on the circle");
        let speed = libm::hypotf(v.veast, v.vnorth);
        assert!((speed - SPEED).abs() < 0.01, "circling at {speed} m/s");
    }
}
