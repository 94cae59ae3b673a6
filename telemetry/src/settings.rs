//! The settings table: what the ground reads and writes by index with SETTING and
//! GET_SETTING (answered by the [services](crate::services)).
//!
//! Each entry is a [`Binding`] (how the value is read and written) and, for settings
//! declared in a `settings.xml`, its [`SettingDesc`] (name, bounds, labels, storage), as
//! the code generator emits them. A setting with a description refuses values outside
//! its bounds: the refused SETTING is answered with the value in force and counted. (It is
//! refused rather than clamped: an operator who typed 100 for 10.0 must not get the
//! maximum.) NaN and infinities are refused by every setting.
//!
//! ```
//! use core::sync::atomic::{AtomicU32, Ordering};
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_messages::settings::SettingDesc;
//! use pprz_telemetry::settings::{Binding, Refusal, Settings};
//!
//! static GAIN: AtomicU32 = AtomicU32::new(0);
//! fn get() -> f32 { f32::from_bits(GAIN.load(Ordering::Relaxed)) }
//! fn set(v: f32) { GAIN.store(v.to_bits(), Ordering::Relaxed) }
//! static DESC: SettingDesc<'static> = SettingDesc::new(0, "gain", 0.0, 10.0);
//!
//! static SETTINGS: Settings<'static, M, 4> = Settings::new();
//! SETTINGS.add_desc(&DESC, Binding::Fns(&get, &set)).unwrap();
//! assert_eq!(SETTINGS.try_set(0, 2.5), Ok(2.5));
//! assert_eq!(SETTINGS.try_set(0, 100.0), Err(Refusal::OutOfBounds(2.5)));
//! ```

use core::cell::RefCell;
use core::fmt;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_messages::settings::SettingDesc;

use crate::scheduler::ModeSetting;

/// How a setting is read and written.
#[derive(Clone, Copy)]
pub enum Binding<'a> {
    /// Application closures or functions: read, and write (the write may refuse a value
    /// or adjust it; what is read back is what the ground is told).
    Fns(&'a (dyn Fn() -> f32 + Sync), &'a (dyn Fn(f32) + Sync)),
    /// The active telemetry mode of a process.
    Mode(ModeSetting<'a>),
}

impl fmt::Debug for Binding<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Binding::Fns(..) => "Binding::Fns",
            Binding::Mode(_) => "Binding::Mode",
        })
    }
}

/// Why a value was not applied; each carries the value in force (what the ground is
/// told).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refusal {
    /// NaN or an infinity.
    NonFinite(f32),
    /// Outside the setting's bounds.
    OutOfBounds(f32),
    /// No setting at this index.
    UnknownIndex,
}

/// One entry of the settings table: a name, its description if it has one, and typed
/// access through `f32`, the type SETTING and DL_VALUE carry.
#[derive(Clone, Copy)]
pub struct SettingEntry<'a> {
    /// Name, for display.
    pub name: &'a str,
    /// The description from a `settings.xml`, if the setting has one.
    pub desc: Option<&'a SettingDesc<'a>>,
    binding: Binding<'a>,
}

impl SettingEntry<'_> {
    /// The current value.
    pub fn get(&self) -> f32 {
        match self.binding {
            Binding::Fns(get, _) => get(),
            Binding::Mode(mode) => mode.get(),
        }
    }

    /// Sets the value and returns the value read back; a refused value leaves the
    /// setting as it is and returns its value too (see [`try_set`](Self::try_set)).
    pub fn set(&self, value: f32) -> f32 {
        match self.try_set(value) {
            Ok(v) | Err(Refusal::NonFinite(v) | Refusal::OutOfBounds(v)) => v,
            Err(Refusal::UnknownIndex) => self.get(),
        }
    }

    /// Sets the value and returns the value read back.
    ///
    /// # Errors
    /// [`Refusal`] with the value in force: a non-finite value (every setting: NaN is
    /// never a setting's value, and `clamp` lets it through), or one outside the
    /// description's bounds. An unknown telemetry mode leaves a mode setting as it is,
    /// which the value read back shows.
    pub fn try_set(&self, value: f32) -> Result<f32, Refusal> {
        if !value.is_finite() {
            return Err(Refusal::NonFinite(self.get()));
        }
        if let Some(desc) = self.desc
            && desc.check(value).is_err()
        {
            return Err(Refusal::OutOfBounds(self.get()));
        }
        match self.binding {
            Binding::Fns(_, set) => set(value),
            Binding::Mode(mode) => {
                // Refused values leave the mode in force, which the read-back reports.
                let _ = mode.set(value);
            }
        }
        Ok(self.get())
    }
}

impl fmt::Debug for SettingEntry<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SettingEntry")
            .field("name", &self.name)
            .field("desc", &self.desc)
            .finish_non_exhaustive()
    }
}

/// A setting could not be added.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingsError {
    /// The table holds `capacity` settings already (or 256, the most an index byte
    /// addresses).
    Full {
        /// Capacity of the table.
        capacity: usize,
    },
    /// A described setting's index is not the next one of the table (descriptions are
    /// added in index order, first).
    OutOfOrder {
        /// The description's index.
        index: u8,
        /// The index the table would give it.
        next: usize,
    },
}

impl fmt::Display for SettingsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SettingsError::Full { capacity } => {
                write!(f, "settings table full ({capacity} settings)")
            }
            SettingsError::OutOfOrder { index, next } => write!(
                f,
                "setting {index} added out of order: the table's next index is {next}"
            ),
        }
    }
}

impl core::error::Error for SettingsError {}

/// The settings the ground can read and write, by index (the index is the position of
/// registration, as the ground's settings file numbers them). Up to `N` (at most 256)
/// settings, added through `&self`, so the table can be a `static` or part of one.
pub struct Settings<'a, M: RawMutex, const N: usize> {
    inner: Mutex<M, RefCell<Table<'a, N>>>,
}

/// (A plain array: no drop glue, so a setting may borrow the structure holding it.)
struct Table<'a, const N: usize> {
    len: usize,
    entries: [Option<SettingEntry<'a>>; N],
}

impl<'a, M: RawMutex, const N: usize> Settings<'a, M, N> {
    /// An empty table.
    pub const fn new() -> Self {
        Self {
            inner: Mutex::new(RefCell::new(Table {
                len: 0,
                entries: [None; N],
            })),
        }
    }

    fn push(&self, entry: SettingEntry<'a>) -> Result<u8, SettingsError> {
        self.inner.lock(|t| {
            let mut t = t.borrow_mut();
            let len = t.len;
            if let Some(desc) = entry.desc
                && usize::from(desc.index) != len
            {
                return Err(SettingsError::OutOfOrder {
                    index: desc.index,
                    next: len,
                });
            }
            let full = SettingsError::Full { capacity: N };
            let index = u8::try_from(len).map_err(|_| full)?;
            let slot = t.entries.get_mut(len).ok_or(full)?;
            *slot = Some(entry);
            t.len = len + 1;
            Ok(index)
        })
    }

    /// Registers a setting read by `get` and written by `set` (closures or functions),
    /// without bounds; returns its index.
    ///
    /// # Errors
    /// [`SettingsError::Full`] when the table holds `N` settings (or 256).
    pub fn add(
        &self,
        name: &'a str,
        get: &'a (dyn Fn() -> f32 + Sync),
        set: &'a (dyn Fn(f32) + Sync),
    ) -> Result<u8, SettingsError> {
        self.push(SettingEntry {
            name,
            desc: None,
            binding: Binding::Fns(get, set),
        })
    }

    /// Registers the active telemetry mode of a process as a setting (see
    /// [`Modes::setting`](crate::scheduler::Modes::setting)), so the ground switches
    /// telemetry modes with SETTING; returns its index.
    ///
    /// # Errors
    /// [`SettingsError::Full`], as [`add`](Self::add).
    pub fn add_mode(&self, name: &'a str, mode: ModeSetting<'a>) -> Result<u8, SettingsError> {
        self.push(SettingEntry {
            name,
            desc: None,
            binding: Binding::Mode(mode),
        })
    }

    /// Registers the setting `desc` describes (a generated table's entry), bound to
    /// `binding`, at `desc.index`; values outside its bounds are refused.
    ///
    /// # Errors
    /// [`SettingsError::Full`], or [`SettingsError::OutOfOrder`] if `desc.index` is not
    /// the table's next index.
    pub fn add_desc(
        &self,
        desc: &'a SettingDesc<'a>,
        binding: Binding<'a>,
    ) -> Result<u8, SettingsError> {
        self.push(SettingEntry {
            name: desc.name(),
            desc: Some(desc),
            binding,
        })
    }

    /// The entry at `index` (a copy: calling it holds no lock).
    pub fn entry(&self, index: u8) -> Option<SettingEntry<'a>> {
        self.inner.lock(|t| {
            let t = t.borrow();
            t.entries.get(..t.len)?.get(usize::from(index)).copied()?
        })
    }

    /// The value of setting `index`.
    pub fn get(&self, index: u8) -> Option<f32> {
        self.entry(index).map(|e| e.get())
    }

    /// Sets setting `index`, returning the value read back (what the ground is told);
    /// see [`SettingEntry::try_set`] for the values refused.
    pub fn set(&self, index: u8, value: f32) -> Option<f32> {
        self.entry(index).map(|e| e.set(value))
    }

    /// Sets setting `index`, returning the value read back.
    ///
    /// # Errors
    /// [`Refusal`]: no such setting, or a value it refuses.
    pub fn try_set(&self, index: u8, value: f32) -> Result<f32, Refusal> {
        self.entry(index)
            .ok_or(Refusal::UnknownIndex)?
            .try_set(value)
    }

    /// Number of settings.
    pub fn len(&self) -> usize {
        self.inner.lock(|t| t.borrow().len)
    }

    /// Whether the table is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Calls `f` with every entry in index order (copies: `f` may use the table).
    pub fn for_each(&self, mut f: impl FnMut(u8, SettingEntry<'a>)) {
        for i in 0..self.len().min(256) {
            let index = i as u8;
            if let Some(entry) = self.entry(index) {
                f(index, entry);
            }
        }
    }
}

impl<M: RawMutex, const N: usize> Default for Settings<'_, M, N> {
    fn default() -> Self {
        Self::new()
    }
}
