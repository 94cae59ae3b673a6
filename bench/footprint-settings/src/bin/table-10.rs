//! A firmware with 10 generated settings, without persistence (see the crate).

#![no_std]
#![no_main]

pprz_footprint_settings::firmware!(10);
