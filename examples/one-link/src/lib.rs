//! What the `minimal` and `usb` firmwares of the board examples share, beside their board:
//! the one-link facade for aircraft 7 (PPRZ v2, the default message set, the ground lost
//! after 5 s of silence), an ATTITUDE every 100 ms, and a failsafe that raises
//! [`GO_HOME`] when the ground is lost. A board firmware brings up its device, runs
//! [`run`] on it in a task of its own and spawns [`attitude`] and [`failsafe`]:
//!
//! ```ignore
//! #[embassy_executor::task]
//! async fn radio(tx: BufferedUartTx<'static>, rx: BufferedUartRx<'static>) {
//!     pprz_example_one_link::run(tx, rx).await
//! }
//!
//! spawner.spawn(radio(tx, rx).unwrap());
//! spawner.spawn(pprz_example_one_link::attitude().unwrap());
//! spawner.spawn(pprz_example_one_link::failsafe().unwrap());
//! ```
//!
//! Any task sends with `LINK.send(&msg)`, which never blocks: a message that cannot be
//! queued (or written) is counted in `LINK.stats()`, by reason.

#![no_std]

use core::sync::atomic::{AtomicBool, Ordering};

use embassy_time::{Duration, Ticker};
use embedded_io_async::{Read, Write};
use pprz_default::messages::{Set, telemetry::Attitude};
use pprz_telemetry::{FrameArena, Health, HealthConfig, Link, LinkMutex};

/// The frame arena of the link: about half a second of a saturated 57600-baud radio.
pub static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
/// Aircraft 7; the ground is lost after 5 s of silence.
pub static LINK: Link<'static, Set> =
    Link::new(&ARENA, 7).health_config(HealthConfig::new().lost_after(Duration::from_secs(5)));
/// Set when the ground has been silent for 5 s: your autopilot flies home. Only loaded
/// and stored (no compare-and-swap: some of the boards' cores have none).
pub static GO_HOME: AtomicBool = AtomicBool::new(false);

/// Runs the link on the board's device: the writer, the reader and the PING / SETTING /
/// GET_SETTING services, forever.
pub async fn run(tx: impl Write, rx: impl Read) -> ! {
    let Err(e) = LINK.run(tx, rx).await;
    panic!("{e}"); // the link runs in one task only
}

/// Sends an ATTITUDE every 100 ms.
#[embassy_executor::task]
pub async fn attitude() {
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        ticker.next().await;
        let _ = LINK.send(&Attitude {
            phi: 0.1,
            psi: 0.0,
            theta: 0.0,
        });
    }
}

/// Raises [`GO_HOME`] each time the ground is lost (lowering it is the autopilot's
/// business); not before the ground was heard once.
#[embassy_executor::task]
pub async fn failsafe() {
    LINK.health().wait_for(Health::Up).await;
    loop {
        LINK.health().wait_for(Health::Lost).await;
        GO_HOME.store(true, Ordering::Relaxed);
        LINK.health().wait_for(Health::Up).await;
    }
}
