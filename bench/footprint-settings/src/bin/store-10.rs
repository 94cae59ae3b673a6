//! A firmware with 10 generated persistent settings, loaded at boot and stored by the
//! store task (see the crate).

#![no_std]
#![no_main]

pprz_footprint_settings::firmware!(10, store);
