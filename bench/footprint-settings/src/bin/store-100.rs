//! A firmware with 100 generated persistent settings, loaded at boot and stored by the
//! store task (see the crate).

#![no_std]
#![no_main]

pprz_footprint_settings::firmware!(100, store);
