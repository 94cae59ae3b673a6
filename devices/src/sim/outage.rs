//! Outages: windows of time in which a direction of the link delivers nothing.

use core::fmt;

/// Most outage windows a direction of a [`SimLink`](super::SimLink) holds.
pub const MAX_OUTAGES: usize = 8;

/// Why [`SimLink::add_outage`](super::SimLink::add_outage) refused a window.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OutageError {
    /// The window ends at or before its start.
    Empty,
    /// The direction already has [`MAX_OUTAGES`] windows.
    Full,
}

impl fmt::Display for OutageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Empty => f.write_str("an outage must end after it starts"),
            Self::Full => write!(f, "at most {MAX_OUTAGES} outages per direction"),
        }
    }
}

impl core::error::Error for OutageError {}

/// The outage windows of one direction, in ticks, each `[from, until)`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Outages {
    windows: [(u64, u64); MAX_OUTAGES],
    len: usize,
}

impl Outages {
    pub(super) const NONE: Self = Self {
        windows: [(0, 0); MAX_OUTAGES],
        len: 0,
    };

    /// Adds the window `[from, until)` (ticks).
    pub(super) fn add(&mut self, from: u64, until: u64) -> Result<(), OutageError> {
        if until <= from {
            return Err(OutageError::Empty);
        }
        let slot = self.windows.get_mut(self.len).ok_or(OutageError::Full)?;
        *slot = (from, until);
        self.len += 1;
        Ok(())
    }

    /// Whether the time `at` (in the link's units, `scale` per tick) is in a window.
    pub(super) fn cover(&self, at: u128, scale: u128) -> bool {
        self.windows[..self.len]
            .iter()
            .any(|&(from, until)| u128::from(from) * scale <= at && at < u128::from(until) * scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_are_half_open_and_bounded() {
        let mut o = Outages::NONE;
        assert!(!o.cover(0, 1));
        assert_eq!(o.add(10, 10), Err(OutageError::Empty));
        assert_eq!(o.add(10, 5), Err(OutageError::Empty));
        o.add(10, 20).unwrap();
        assert!(!o.cover(9, 1) && o.cover(10, 1) && o.cover(19, 1) && !o.cover(20, 1));
        // In units of 1/3 tick: 29 units is 9.67 ticks, 30 is 10.
        assert!(!o.cover(29, 3) && o.cover(30, 3));
        for i in 1..MAX_OUTAGES as u64 {
            o.add(100 * i, 100 * i + 1).unwrap();
        }
        assert_eq!(o.add(5000, 6000), Err(OutageError::Full));
    }
}
