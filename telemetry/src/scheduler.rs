//! Periodic telemetry scheduler (work in progress).
