//! Ground tools (work in progress).
