//! Link health: whether the ground is still there, per device and for the aircraft.
//!
//! A [`LinkHealth`] keeps, for each device, when a frame from the ground was last heard.
//! The state is computed from the time since then whenever it is read, so nothing has to
//! run to keep it current:
//!
//! | time since the ground was last heard | [`Health`] |
//! |---|---|
//! | less than `degraded_after` (default 2 s) | [`Up`](Health::Up) |
//! | from `degraded_after` to `lost_after` (default 5 s) | [`Degraded`](Health::Degraded) |
//! | `lost_after` or more, or never heard | [`Lost`](Health::Lost) |
//!
//! **What counts as heard** ([`Heard`]): by default, a valid frame addressed to this
//! aircraft (or broadcast) whose source is the ground. Frames for other aircraft, frames
//! with a bad checksum and garbage never count. Behind a [link layer](crate::layer) that
//! authenticates (the secure link), only frames it authenticated count: forged, replayed
//! and plaintext frames cannot hold a lost link Up.
//!
//! **The way back.** A frame heard on a Degraded device makes it Up at once. A Lost device
//! needs [`recover_frames`](HealthConfig::recover_frames) frames (default 1), each within
//! the given gap of the one before, so a lucky frame on a dying link can be ignored.
//!
//! **The aircraft** is in the best state of the devices marked as ground links
//! ([`ground_links`](LinkHealth::ground_links), default all): it is Lost only when every
//! ground link is Lost.
//!
//! A failsafe task awaits changes; nothing polls:
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use embassy_time::Duration;
//! use pprz_telemetry::health::{Health, HealthConfig, LinkHealth};
//!
//! static HEALTH: LinkHealth<M> =
//!     LinkHealth::new(HealthConfig::new().lost_after(Duration::from_secs(5)));
//!
//! async fn failsafe() {
//!     let mut state = HEALTH.state();
//!     loop {
//!         state = HEALTH.changed(state).await;
//!         if state == Health::Lost {
//!             // go home
//!         }
//!     }
//! }
//! assert_eq!(HEALTH.state(), Health::Lost); // nothing heard yet
//! ```
//!
//! The [`Link`](crate::Link) facade has one ([`Link::health`](crate::Link::health)); with
//! the lower-level runtime, give it to the [`Datalink`](crate::reader::Datalink)
//! ([`Datalink::with_health`](crate::reader::Datalink::with_health)), and every reader
//! delivering there drives it.

use core::cell::RefCell;
use core::future::poll_fn;
use core::task::Poll;

use embassy_futures::select::select;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::waitqueue::MultiWakerRegistration;
use embassy_time::{Duration, Instant, Timer};
use pprz_transports::GROUND_ID;

use crate::registry::{Received, Trust};
use crate::route::Targets;

/// The state of a link (ordered: `Lost < Degraded < Up`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Health {
    /// Not heard for `lost_after` or more (or never, or still recovering).
    Lost,
    /// Not heard for `degraded_after` or more.
    Degraded,
    /// Heard recently.
    Up,
}

impl Health {
    /// The state's name in lower case (`"up"`, `"degraded"`, `"lost"`).
    pub const fn name(self) -> &'static str {
        match self {
            Health::Lost => "lost",
            Health::Degraded => "degraded",
            Health::Up => "up",
        }
    }
}

/// Which received frames count as hearing the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Heard {
    /// Frames for us (or broadcast) whose source is the ground ([`GROUND_ID`]); the
    /// default.
    FromGround,
    /// Every frame for us (or broadcast), whoever sent it (another aircraft too).
    AnySource,
    /// No frame: the application calls [`LinkHealth::heard`] itself (e.g. on a message
    /// of its choice).
    Manual,
}

/// The timeouts and rules of a [`LinkHealth`]; `const`, built by named steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HealthConfig {
    degraded_after: Duration,
    lost_after: Duration,
    recover_frames: u8,
    recover_gap: Duration,
    heard: Heard,
}

impl HealthConfig {
    /// Degraded after 2 s of silence, Lost after 5 s (Paparazzi's default
    /// `DATALINK_LOST_TIME`), back Up on one frame, ground frames only.
    pub const fn new() -> Self {
        Self {
            degraded_after: Duration::from_secs(2),
            lost_after: Duration::from_secs(5),
            recover_frames: 1,
            recover_gap: Duration::from_secs(1),
            heard: Heard::FromGround,
        }
    }

    /// Lost after `timeout` of silence (at least one tick: with 0 the link would never
    /// be anything but Lost). If `degraded_after` is not shorter, the link goes from Up
    /// to Lost directly.
    pub const fn lost_after(mut self, timeout: Duration) -> Self {
        self.lost_after = at_least_a_tick(timeout);
        self
    }

    /// Degraded after `timeout` of silence (at least one tick: with 0 the link would
    /// never be Up).
    pub const fn degraded_after(mut self, timeout: Duration) -> Self {
        self.degraded_after = at_least_a_tick(timeout);
        self
    }

    /// A Lost device is Up again after `frames` frames (at least 1), each heard at most
    /// `gap` after the one before.
    pub const fn recover_frames(mut self, frames: u8, gap: Duration) -> Self {
        self.recover_frames = if frames == 0 { 1 } else { frames };
        self.recover_gap = gap;
        self
    }

    /// Which frames count as hearing the ground.
    pub const fn heard(mut self, heard: Heard) -> Self {
        self.heard = heard;
        self
    }

    /// The silence after which a link is Lost.
    pub const fn lost_timeout(&self) -> Duration {
        self.lost_after
    }

    /// The silence after which a link is Degraded.
    pub const fn degraded_timeout(&self) -> Duration {
        self.degraded_after
    }

    /// The state after `silence` without a frame (`None`: never heard).
    fn state_after(&self, silence: Option<Duration>) -> Health {
        match silence {
            Some(s) if s < self.degraded_after && s < self.lost_after => Health::Up,
            Some(s) if s < self.lost_after => Health::Degraded,
            _ => Health::Lost,
        }
    }
}

/// `timeout`, or one tick if it is zero.
const fn at_least_a_tick(timeout: Duration) -> Duration {
    if timeout.as_ticks() == 0 {
        Duration::from_ticks(1)
    } else {
        timeout
    }
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self::new()
    }
}

/// What one device has heard (a snapshot; see [`LinkHealth::device`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceHealth {
    /// The device's state when the snapshot was taken.
    pub state: Health,
    /// When the ground was last heard on it.
    pub last_heard: Option<Instant>,
    /// Frames heard on it (wrapping).
    pub heard: u32,
    /// Times it became Lost (wrapping).
    pub losses: u32,
    /// The signal strength of the last frame heard that carried one (XBee: `n` = `-n`
    /// dBm).
    pub rssi: Option<u8>,
}

/// What one device has heard, as kept.
#[derive(Debug, Clone, Copy)]
struct Kept {
    last: Option<Instant>,
    heard: u32,
    losses: u32,
    /// Frames in the current run (each within the recovery gap of the one before).
    streak: u8,
    /// Lost, and not yet recovered: stays Lost whatever the time since the last frame.
    recovering: bool,
    rssi: Option<u8>,
}

impl Kept {
    const NEW: Kept = Kept {
        last: None,
        heard: 0,
        losses: 0,
        streak: 0,
        recovering: false,
        rssi: None,
    };

    fn state(&self, config: &HealthConfig, now: Instant) -> Health {
        if self.recovering {
            return Health::Lost;
        }
        config.state_after(self.last.map(|l| now.saturating_duration_since(l)))
    }

    /// When the state would change next without a frame (`None`: it cannot).
    fn deadline(&self, config: &HealthConfig, now: Instant) -> Option<Instant> {
        let last = self.last?;
        if self.recovering {
            return None;
        }
        [config.degraded_after, config.lost_after]
            .into_iter()
            // An instant past the clock's end is never reached: no deadline.
            .filter_map(|t| last.checked_add(t))
            .filter(|&at| at > now)
            .min()
    }

    fn hear(&mut self, config: &HealthConfig, now: Instant, rssi: Option<u8>) {
        let lost = self.state(config, now) == Health::Lost;
        // A silence long enough to lose the link ends the run, even within the recovery
        // gap: frames from before the loss do not count towards recovering from it.
        let timed_out = lost && !self.recovering;
        let in_run = !timed_out
            && self
                .last
                .is_some_and(|l| now.saturating_duration_since(l) <= config.recover_gap);
        self.streak = if in_run {
            self.streak.saturating_add(1)
        } else {
            1
        };
        if lost {
            if !self.recovering && self.last.is_some() {
                // Silent for `lost_after` since the last frame: a loss, counted once.
                self.losses = self.losses.wrapping_add(1);
            }
            self.recovering = self.streak < config.recover_frames;
        }
        self.last = Some(now);
        self.heard = self.heard.wrapping_add(1);
        if rssi.is_some() {
            self.rssi = rssi;
        }
    }
}

/// How many tasks may wait on one [`LinkHealth`] at once. A change is never missed, but
/// with more waiters than this they keep waking each other (each registration beyond
/// the room wakes the others), so keep to this many: one failsafe and a few reporters.
pub const WAITERS: usize = 4;

/// The state kept under the mutex.
struct State<const D: usize> {
    devices: [Kept; D],
    waiters: MultiWakerRegistration<WAITERS>,
    /// Bumped whenever a heard frame changes the aircraft's state.
    epoch: u32,
}

/// The health of the links of an aircraft with `D` devices; see the
/// [module documentation](self). `const`, so it can be a `static`.
pub struct LinkHealth<M: RawMutex, const D: usize = 1> {
    config: HealthConfig,
    ground: Targets,
    state: Mutex<M, RefCell<State<D>>>,
}

impl<M: RawMutex, const D: usize> LinkHealth<M, D> {
    /// Nothing heard yet on any of the `D` devices, every device a ground link.
    pub const fn new(config: HealthConfig) -> Self {
        Self {
            config,
            ground: Targets::ALL,
            state: Mutex::new(RefCell::new(State {
                devices: [Kept::NEW; D],
                waiters: MultiWakerRegistration::new(),
                epoch: 0,
            })),
        }
    }

    /// Only the devices in `links` lead to the ground (a log or a link to other aircraft
    /// does not): the aircraft is Lost when all of them are.
    pub const fn ground_links(mut self, links: Targets) -> Self {
        self.ground = links;
        self
    }

    /// Replaces the configuration (for a `const` owner such as [`Link`](crate::Link)).
    pub(crate) const fn set_config(&mut self, config: HealthConfig) {
        self.config = config;
    }

    /// The configuration.
    pub const fn config(&self) -> &HealthConfig {
        &self.config
    }

    /// The aircraft's state now.
    pub fn state(&self) -> Health {
        self.state_at(Instant::now())
    }

    /// The aircraft's state at `now`: the best of its ground links'.
    pub fn state_at(&self, now: Instant) -> Health {
        self.state.lock(|s| self.aircraft(&s.borrow(), now))
    }

    /// The state of device `index` now (`None` if there is no such device).
    pub fn device_state(&self, index: usize) -> Option<Health> {
        self.device(index).map(|d| d.state)
    }

    /// A snapshot of device `index` now (`None` if there is no such device).
    pub fn device(&self, index: usize) -> Option<DeviceHealth> {
        self.device_at(index, Instant::now())
    }

    /// A snapshot of device `index` at `now`.
    pub fn device_at(&self, index: usize, now: Instant) -> Option<DeviceHealth> {
        self.state.lock(|s| {
            let s = s.borrow();
            let d = s.devices.get(index)?;
            let state = d.state(&self.config, now);
            // A loss in progress is counted when the next frame ends it; show it now.
            let losses = if state == Health::Lost && !d.recovering && d.last.is_some() {
                d.losses.wrapping_add(1)
            } else {
                d.losses
            };
            Some(DeviceHealth {
                state,
                last_heard: d.last,
                heard: d.heard,
                losses,
                rssi: d.rssi,
            })
        })
    }

    /// How long since the ground was last heard on any ground link (`None`: never).
    pub fn since_heard(&self) -> Option<Duration> {
        let now = Instant::now();
        self.last_heard().map(|l| now.saturating_duration_since(l))
    }

    /// When the ground was last heard on any ground link.
    pub fn last_heard(&self) -> Option<Instant> {
        self.state.lock(|s| {
            self.ground_devices(&s.borrow())
                .filter_map(|d| d.last)
                .max()
        })
    }

    /// The signal strength of the last frame heard on a ground link that carried one
    /// (XBee: `n` = `-n` dBm).
    pub fn rssi(&self) -> Option<u8> {
        self.state.lock(|s| {
            self.ground_devices(&s.borrow())
                .filter(|d| d.rssi.is_some())
                .max_by_key(|d| d.last)
                .and_then(|d| d.rssi)
        })
    }

    /// Records that the ground was heard on device `index` at `now` (the readers call
    /// this through the datalink; call it yourself with [`Heard::Manual`]).
    pub fn heard(&self, index: usize, now: Instant) {
        self.hear(index, now, None);
    }

    /// Records a received frame if it counts (see [`Heard`]).
    pub fn frame(&self, rx: &Received<'_, '_>, now: Instant) {
        let counts = match self.config.heard {
            Heard::FromGround => rx.frame.source() == GROUND_ID,
            Heard::AnySource => true,
            Heard::Manual => false,
        };
        if counts && rx.trust != Trust::Unauthenticated {
            self.hear(rx.device.index(), now, rx.frame.rssi());
        }
    }

    fn hear(&self, index: usize, now: Instant, rssi: Option<u8>) {
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            let before = self.aircraft(&s, now);
            let Some(d) = s.devices.get_mut(index) else {
                return;
            };
            d.hear(&self.config, now, rssi);
            if self.aircraft(&s, now) != before {
                s.epoch = s.epoch.wrapping_add(1);
                s.waiters.wake();
            }
        });
    }

    /// Waits until the aircraft's state differs from `from`, and returns the new state.
    /// A state that changes with time wakes the task at its deadline (an embassy-time
    /// timer); one changed by a frame wakes it from the reader.
    pub async fn changed(&self, from: Health) -> Health {
        loop {
            let now = Instant::now();
            let (state, epoch, deadline) = self.state.lock(|s| {
                let s = s.borrow();
                let deadline = self
                    .ground_devices(&s)
                    .filter_map(|d| d.deadline(&self.config, now))
                    .min();
                (self.aircraft(&s, now), s.epoch, deadline)
            });
            if state != from {
                return state;
            }
            let heard = self.epoch_after(epoch);
            match deadline {
                Some(at) => {
                    select(heard, Timer::at(at)).await;
                }
                None => heard.await,
            }
        }
    }

    /// Waits until the aircraft is in `state`.
    pub async fn wait_for(&self, state: Health) {
        let mut now = self.state();
        while now != state {
            now = self.changed(now).await;
        }
    }

    /// Resolves once a heard frame has changed the aircraft's state since `epoch`.
    async fn epoch_after(&self, epoch: u32) {
        poll_fn(|cx| {
            self.state.lock(|s| {
                let mut s = s.borrow_mut();
                if s.epoch == epoch {
                    s.waiters.register(cx.waker());
                    Poll::Pending
                } else {
                    Poll::Ready(())
                }
            })
        })
        .await;
    }

    fn ground_devices<'s>(&self, s: &'s State<D>) -> impl Iterator<Item = &'s Kept> {
        let ground = self.ground;
        s.devices
            .iter()
            .enumerate()
            .filter(move |(i, _)| ground.contains(*i))
            .map(|(_, d)| d)
    }

    fn aircraft(&self, s: &State<D>, now: Instant) -> Health {
        self.ground_devices(s)
            .map(|d| d.state(&self.config, now))
            .max()
            .unwrap_or(Health::Lost)
    }
}

impl<M: RawMutex, const D: usize> core::fmt::Debug for LinkHealth<M, D> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LinkHealth")
            .field("config", &self.config)
            .field("ground", &self.ground)
            .field("state", &self.state())
            .finish_non_exhaustive()
    }
}

/// What a [`Datalink`](crate::reader::Datalink) drives: a [`LinkHealth`] of any mutex and
/// device count.
pub trait HealthInput: Sync {
    /// A frame for us was accepted at `now`.
    fn frame(&self, rx: &Received<'_, '_>, now: Instant);
}

impl<M: RawMutex + Sync, const D: usize> HealthInput for LinkHealth<M, D> {
    fn frame(&self, rx: &Received<'_, '_>, now: Instant) {
        LinkHealth::frame(self, rx, now);
    }
}
