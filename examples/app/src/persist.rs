//! The application's persistent settings: loaded from flash at start, stored when the
//! ground sets the store flag (`settings_store_flag`, index 4 of `settings.xml`), or
//! nothing of the kind on a firmware without flash for settings.
//!
//! A type per case (as for the readers), so a firmware without a store carries no store
//! code: [`NoStore`] (what [`run_aircraft`](crate::run_aircraft) uses) and [`WithStore`]
//! (what [`run_aircraft_with_store`](crate::run_aircraft_with_store) uses).

use core::convert::Infallible;

use embassy_futures::join::join;
use pprz_default::messages::telemetry::DlValue;
use pprz_settings::embedded_storage_async::nor_flash::NorFlash;
use pprz_settings::sequential_storage::cache::CacheImpl;
use pprz_settings::{ErrorKind, PersistentStore, Request, SnapshotKey, StoreControl};
use pprz_telemetry::settings::Settings;

use crate::{M, Out, settings};

/// The settings store of the application, or none. `'c` is the lifetime of the store
/// control the store flag's setting is bound to.
pub(crate) trait Persistence<'c> {
    /// The control the store flag is bound to (none: the flag reads 0).
    fn control(&self) -> Option<&'c StoreControl<M>>;

    /// Loads the stored values into `table`. The application runs it to completion after
    /// the table is registered and before the services answer, so the values loaded are
    /// those the ground reads first.
    async fn load<const N: usize>(&mut self, table: &Settings<'_, M, N>);

    /// Stores on request, forever, and tells the ground the store flag's value after
    /// each store (an unsolicited DL_VALUE through `out`).
    async fn run<const N: usize>(self, table: &Settings<'_, M, N>, out: &Out<'_>) -> Infallible;
}

/// No flash for settings: nothing is loaded, and the store flag reads 0 (Paparazzi's
/// `settings_store()` fails the same way without persistent settings).
pub(crate) struct NoStore;

impl Persistence<'static> for NoStore {
    fn control(&self) -> Option<&'static StoreControl<M>> {
        None
    }

    async fn load<const N: usize>(&mut self, _table: &Settings<'_, M, N>) {}

    async fn run<const N: usize>(self, _table: &Settings<'_, M, N>, _out: &Out<'_>) -> Infallible {
        core::future::pending().await
    }
}

/// A store in flash and the control its store flag is bound to.
pub(crate) struct WithStore<'c, S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize> {
    pub(crate) store: &'c mut PersistentStore<S, C, BUF>,
    pub(crate) control: &'c StoreControl<M>,
}

impl<'c, S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize> Persistence<'c>
    for WithStore<'c, S, C, BUF>
{
    fn control(&self) -> Option<&'c StoreControl<M>> {
        Some(self.control)
    }

    async fn load<const N: usize>(&mut self, table: &Settings<'_, M, N>) {
        // A failed load is counted by the control (`StoreStats::load_failures`); every
        // setting keeps its default. A flash error may pass; a map the store cannot
        // read (corrupted beyond repair, or written by a firmware with a larger buffer)
        // would fail every store, so it is cleared (erased if need be) for the next one.
        if let Err(e) = self.control.load(self.store, table).await
            && e.kind() != ErrorKind::Flash
        {
            let _ = self.store.clear().await;
        }
    }

    async fn run<const N: usize>(self, table: &Settings<'_, M, N>, out: &Out<'_>) -> Infallible {
        let control = self.control;
        let report = async {
            loop {
                let outcome = control.outcome().await;
                if outcome.request == Request::Store {
                    out.send(&DlValue {
                        index: settings::index::SETTINGS_STORE_FLAG,
                        value: outcome.state.value(),
                    });
                }
            }
        };
        // Both run forever: the store task is never dropped mid-way by this join.
        let (never, _) = join(pprz_settings::run(self.store, control, table), report).await;
        never
    }
}
