//! Link outages and the failsafe: the `--outage` windows cut the radio to the ground,
//! each aircraft has a link health with the `--lost-timeout` of the options (its
//! failsafe flies home when it is Lost), a task per aircraft records the health's
//! changes, and the summary puts them beside what the ground saw: the `ap_mode` of the
//! ROTORCRAFT_STATUS messages and the times it heard nothing.

use embassy_time::{Duration, Instant};
use pprz_default::messages::telemetry::values::RotorcraftStatusApMode as ApMode;
use pprz_devices::sim::{Direction, MAX_OUTAGES, SimStats};
use pprz_example_app::M;
use pprz_telemetry::health::{Health, HealthConfig, LinkHealth};

use crate::aircraft::Aircraft;
use crate::options::{Args, Outage};
use crate::radio::Radio;
use crate::record::{self, SILENCE_US};
use crate::summary::{
    AircraftLink, Failsafe, LinkFigures, ModeChange, Silence, Transition, Window,
};

/// The example application's `ap_mode` setting: index 3.
pub const AP_MODE_SETTING: u8 = 3;

/// `ap_mode` NAV (13), which `--resume-nav` sets.
pub const NAV: u8 = ApMode::Nav.raw();

/// `ap_mode` HOME (2), the failsafe's.
const HOME: u8 = ApMode::Home.raw();

/// The checks of the link options together and with the others (each was checked alone
/// when parsed); the message of a usage error.
pub fn check(args: &Args) -> Result<(), String> {
    for (name, cuts) in [("up", true), ("down", false)] {
        let count = args
            .outage
            .iter()
            .filter(|o| if cuts { o.cut.up() } else { o.cut.down() })
            .count();
        if count > MAX_OUTAGES {
            return Err(format!(
                "--outage: {count} windows cut {name}, at most {MAX_OUTAGES} per direction"
            ));
        }
    }
    if args.resume_nav.is_some() && args.headless {
        return Err(
            "--resume-nav is sent by the in-process ground: drop --headless (or set ap_mode from your ground)"
                .to_owned(),
        );
    }
    Ok(())
}

/// What the link options ask for after the end of the run (it will not happen): one
/// message per option, for standard error.
pub fn after_the_end(args: &Args) -> Vec<String> {
    let end = args.duration;
    let mut late: Vec<String> = args
        .outage
        .iter()
        .filter(|o| o.from_s >= end)
        .map(|o| {
            format!(
                "--outage {}:{}..{} starts at or after the end of the run (--duration {end}): it has no effect",
                o.cut.name(),
                o.from_s,
                o.until_s
            )
        })
        .collect();
    if let Some(t) = args.resume_nav.filter(|&t| t >= end) {
        late.push(format!(
            "--resume-nav {t} is at or after the end of the run (--duration {end}): it has no effect"
        ));
    }
    late
}

/// A time in the run as an instant of the simulation's clock.
fn instant(seconds: f64) -> Instant {
    Instant::from_micros((seconds * 1e6).round() as u64)
}

/// Seconds of an instant of the simulation's clock.
fn seconds(micros: u64) -> f64 {
    micros as f64 / 1e6
}

/// The link health of each aircraft: Lost after `--lost-timeout`, the other rules the
/// defaults (Degraded after 2 s, back Up on one frame from the ground).
pub fn health(args: &Args) -> LinkHealth<M> {
    let lost = Duration::from_micros((args.lost_timeout * 1e6).round() as u64);
    LinkHealth::new(HealthConfig::new().lost_after(lost))
}

/// Cuts `radio` (a radio to the ground: every one is cut alike) in the windows of
/// `outages`.
pub fn cut(radio: &Radio, outages: &[Outage]) -> Result<(), String> {
    for o in outages {
        let (from, until) = (instant(o.from_s), instant(o.until_s));
        let directions = [
            (o.cut.up(), Direction::BToA),
            (o.cut.down(), Direction::AToB),
        ];
        for (_, direction) in directions.into_iter().filter(|(cut, _)| *cut) {
            radio.add_outage(direction, from, until).map_err(|e| {
                format!("--outage {}:{}..{}: {e}", o.cut.name(), o.from_s, o.until_s)
            })?;
        }
    }
    Ok(())
}

/// The states a health went through from `from` to `to`, and when, given when the
/// ground was `last` heard: a frame makes it better at once (at `last`); silence makes
/// it worse at `last` plus the timeout of each state it reaches (Degraded, then Lost).
/// Computed rather than read from the clock, so the times are exact whenever the task
/// that records them runs.
pub fn steps(
    from: Health,
    to: Health,
    last: Option<Instant>,
    config: &HealthConfig,
    now: Instant,
) -> Vec<(Instant, Health)> {
    let Some(last) = last else {
        return vec![(now, to)];
    };
    if to > from {
        return vec![(last, to)];
    }
    let (degraded, lost) = (config.degraded_timeout(), config.lost_timeout());
    let mut steps = Vec::new();
    if from == Health::Up && to == Health::Lost && degraded < lost {
        steps.push((last + degraded, Health::Degraded));
    }
    let timeout = if to == Health::Lost { lost } else { degraded };
    steps.push((last + timeout, to));
    steps
}

/// Records every change of aircraft `ac`'s link `health`.
#[embassy_executor::task(pool_size = crate::fleet::MAX_FLEET as usize)]
pub async fn watch(ac: u8, health: &'static LinkHealth<M>) {
    let mut state = health.state();
    loop {
        let next = health.changed(state).await;
        let now = Instant::now();
        for (at, s) in steps(state, next, health.last_heard(), health.config(), now) {
            record::health(ac, at, s);
        }
        state = next;
    }
}

/// The link figures of the run so far: per aircraft, its health and what the ground saw.
pub fn figures(args: &Args, aircraft: &Aircraft) -> LinkFigures {
    let now_us = Instant::now().as_micros();
    let config = aircraft.health.config();
    // What the outages cut, every radio to the ground together.
    let radios = aircraft.ground_radios();
    let total = |d: Direction, f: fn(&SimStats) -> u32| {
        radios
            .iter()
            .map(|r| f(&r.radio.stats(d)))
            .fold(0u32, u32::saturating_add)
    };
    let outages: Vec<Window> = args
        .outage
        .iter()
        .map(|o| Window {
            direction: o.cut.name(),
            from_s: o.from_s,
            until_s: o.until_s,
        })
        .collect();
    // The healths are read before the record is locked (never one lock inside the
    // other: the application records its submissions from inside its own locks).
    // A health of one device: device 0 is always there.
    let healths: Vec<(u8, u32, Health)> = aircraft
        .healths()
        .into_iter()
        .map(|(ac, health)| {
            let (losses, state) = health
                .device(0)
                .map_or((0, Health::Lost), |d| (d.losses, d.state));
            (ac, losses, state)
        })
        .collect();
    let record = record::lock();
    let each = healths
        .into_iter()
        .map(|(ac, losses, state)| {
            let r = record.aircraft.get(&ac);
            let ap_modes: Vec<ModeChange> = r
                .map(|r| r.ap_modes.iter().map(|&(t, m)| mode_change(t, m)).collect())
                .unwrap_or_default();
            let mut silences: Vec<Silence> = r
                .map(|r| {
                    r.silences
                        .iter()
                        .map(|&(a, b)| silence(a, Some(b)))
                        .collect()
                })
                .unwrap_or_default();
            if let Some(last) = r.and_then(|r| r.last_heard_us)
                && now_us.saturating_sub(last) > SILENCE_US
            {
                silences.push(silence(last, None));
            }
            AircraftLink {
                ac_id: ac,
                outages: outages.clone(),
                transitions: r
                    .map(|r| r.health.iter().map(|&(t, s)| transition(t, s)).collect())
                    .unwrap_or_default(),
                losses,
                state: state.name(),
                failsafes: failsafes(&ap_modes),
                ap_modes,
                silences,
                events_omitted: r.map_or(0, |r| r.omitted),
            }
        })
        .collect();
    LinkFigures {
        lost_timeout_s: config.lost_timeout().as_micros() as f64 / 1e6,
        degraded_timeout_s: config.degraded_timeout().as_micros() as f64 / 1e6,
        resume_nav_s: args.resume_nav,
        lost_bytes_down: total(Direction::AToB, |s| s.outage_bytes),
        lost_bytes_up: total(Direction::BToA, |s| s.outage_bytes),
        failed_attempts_down: total(Direction::AToB, |s| s.outage_attempts),
        failed_attempts_up: total(Direction::BToA, |s| s.outage_attempts),
        aircraft: each,
    }
}

fn transition(micros: u64, state: Health) -> Transition {
    Transition {
        t_s: seconds(micros),
        state: state.name(),
    }
}

fn mode_change(micros: u64, raw: u8) -> ModeChange {
    ModeChange {
        t_s: seconds(micros),
        ap_mode: ApMode::LABELS
            .get(usize::from(raw))
            .map_or_else(|| raw.to_string(), |l| (*l).to_owned()),
    }
}

fn silence(from: u64, until: Option<u64>) -> Silence {
    Silence {
        from_s: seconds(from),
        until_s: until.map(seconds),
    }
}

/// Each time the ground saw HOME after another mode (or first), and when it saw NAV
/// after that.
fn failsafes(modes: &[ModeChange]) -> Vec<Failsafe> {
    let home = ApMode::LABELS[usize::from(HOME)];
    let nav = ApMode::LABELS[usize::from(NAV)];
    let mut out: Vec<Failsafe> = Vec::new();
    for m in modes {
        if m.ap_mode == home {
            out.push(Failsafe {
                home_s: m.t_s,
                nav_s: None,
            });
        } else if m.ap_mode == nav
            && let Some(last) = out.last_mut()
            && last.nav_s.is_none()
        {
            last.nav_s = Some(m.t_s);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Instant {
        Instant::from_millis(ms)
    }

    #[test]
    fn silence_steps_through_degraded_to_lost_at_the_timeouts() {
        let config = HealthConfig::new().lost_after(Duration::from_secs(3));
        let last = Some(at(9_004));
        let steps = steps(Health::Up, Health::Lost, last, &config, at(12_010));
        assert_eq!(
            steps,
            [(at(11_004), Health::Degraded), (at(12_004), Health::Lost)]
        );
        let one = super::steps(Health::Degraded, Health::Lost, last, &config, at(12_010));
        assert_eq!(one, [(at(12_004), Health::Lost)]);
        // Lost before Degraded: straight to Lost.
        let short = HealthConfig::new().lost_after(Duration::from_secs(1));
        let direct = super::steps(Health::Up, Health::Lost, last, &short, at(10_010));
        assert_eq!(direct, [(at(10_004), Health::Lost)]);
    }

    #[test]
    fn a_frame_makes_it_up_when_it_was_heard() {
        let config = HealthConfig::new();
        let s = steps(
            Health::Lost,
            Health::Up,
            Some(at(20_003)),
            &config,
            at(20_004),
        );
        assert_eq!(s, [(at(20_003), Health::Up)]);
        let never = steps(Health::Lost, Health::Up, None, &config, at(5));
        assert_eq!(never, [(at(5), Health::Up)]);
    }

    #[test]
    fn failsafes_pair_home_with_the_next_nav() {
        let m = |t: f64, mode: &str| ModeChange {
            t_s: t,
            ap_mode: mode.to_owned(),
        };
        let modes = [
            m(0.5, "NAV"),
            m(12.4, "HOME"),
            m(25.6, "NAV"),
            m(40.0, "HOME"),
        ];
        let f = failsafes(&modes);
        assert_eq!(f.len(), 2);
        assert_eq!((f[0].home_s, f[0].nav_s), (12.4, Some(25.6)));
        assert_eq!((f[1].home_s, f[1].nav_s), (40.0, None));
    }
}
