//! Code generator (work in progress).
