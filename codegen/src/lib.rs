//! Generates Rust message types from a Paparazzi `messages.xml`, periodic telemetry
//! schedule tables from a `telemetry.xml`, and settings tables from `settings.xml` files.
//!
//! Pipeline: XML parser -> typed, validated [`Protocol`] model -> emitter -> one Rust
//! source file that a crate `include!`s. The generated code is `no_std`, allocation-free
//! and builds on the [`pprz_messages`] runtime crate: per message a struct with typed
//! fields implementing [`pprz_messages::Message`] and [`pprz_messages::Decode`], per
//! class an `AnyMessage` enum that decodes by id, enums for `values` attributes, a
//! `MESSAGES` descriptor table for generic tools, and a `Set` type naming the set for the
//! runtime (see [below](#the-set-type-and-its-roles)).
//!
//! The runtime that sends and receives these messages is `pprz_telemetry` (its page is
//! beside this one in the crate list; `cargo doc -p pprz-telemetry --open` opens it).
//!
//! # From a `build.rs` (as prost-build or mavlink-bindgen are used)
//!
//! ```toml
//! [dependencies]
//! pprz-messages = "0.1"
//! [build-dependencies]
//! pprz-codegen = { version = "0.1", default-features = false }
//! ```
//!
//! ```no_run
//! // build.rs (body of `fn main`)
//! if let Err(e) = pprz_codegen::Generator::new("messages.xml")
//!     .classes(["telemetry", "datalink"])   // optional: only what the firmware uses
//!     .write_to_out_dir("pprz_messages.rs")
//! {
//!     eprintln!("{e}");
//!     std::process::exit(1);
//! }
//! ```
//!
//! ```ignore
//! // src/lib.rs or main.rs
//! pub mod messages {
//!     include!(concat!(env!("OUT_DIR"), "/pprz_messages.rs"));
//! }
//! ```
//!
//! Generating to a string, e.g. for a test:
//!
//! ```
//! let xml = r#"<protocol><msg_class name="telemetry" id="1">
//!   <message name="DL_VALUE" id="31" priority="192">
//!     <field name="index" type="uint8"/><field name="value" type="float"/>
//!   </message></msg_class></protocol>"#;
//! let code = pprz_codegen::Generator::from_str("inline.xml", xml).generate().unwrap();
//! assert!(code.contains("pub struct DlValue"));
//! ```
//!
//! Errors name the file, line, message and field:
//!
//! ```
//! let xml = r#"<protocol><msg_class name="telemetry" id="1">
//!   <message name="BAD" id="1"><field name="x" type="uint9"/></message>
//! </msg_class></protocol>"#;
//! let err = pprz_codegen::Generator::from_str("bad.xml", xml).generate().unwrap_err();
//! assert!(err.to_string().starts_with("error: bad.xml:2:30: message BAD, field x: unknown type `uint9`"));
//! ```
//!
//! # The `Set` type and its roles
//!
//! The runtime's services are generic over the message set: they ask a type for the
//! messages they speak through the traits of [`pprz_messages::roles`]. Every generated
//! file has a `pub struct Set;` implementing those the set fills:
//!
//! - `ServiceSet` when the set has `PING`, `SETTING` and `GET_SETTING` in class
//!   `datalink`, and `PONG` and `DL_VALUE` in class `telemetry`;
//! - `LinkReportSet` when it has `DATALINK_REPORT` in class `telemetry`;
//!
//! each with exactly the fields of the table in [`pprz_messages::roles`] (names and types,
//! in order, no extra field; ids and priorities are the set's own). Classes are matched by
//! name. A message that fits implements its own role trait (`roles::Ping`,
//! `roles::SettingValue`, ...) even when the rest of its set role is missing. The doc
//! comment of `Set` lists the roles filled and, for each one that is not, why (a message
//! missing or left out by the selection, in another class, or with other fields):
//!
//! ```
//! let xml = r#"<protocol><msg_class name="telemetry" id="1">
//!   <message name="DATALINK_REPORT" id="30">
//!     <field name="uplink_lost_time" type="uint16"/><field name="uplink_nb_msgs" type="uint16"/>
//!     <field name="downlink_nb_msgs" type="uint16"/><field name="downlink_rate" type="uint16"/>
//!     <field name="uplink_rate" type="uint16"/><field name="downlink_ovrn" type="uint8"/>
//!   </message></msg_class></protocol>"#;
//! let code = pprz_codegen::Generator::from_str("inline.xml", xml).generate().unwrap();
//! assert!(code.contains("impl ::pprz_messages::roles::LinkReportSet for Set {"));
//! assert!(!code.contains("roles::ServiceSet for Set"));
//! assert!(code.contains(
//!     "no `ServiceSet`: `PING`, `PONG`, `SETTING`, `GET_SETTING` and `DL_VALUE` missing."
//! ));
//! ```
//!
//! # Periodic telemetry (`telemetry.xml`)
//!
//! The same generator reads a Paparazzi telemetry configuration (processes, modes, message
//! periods and phases), resolves its message names against the message set above (class
//! `telemetry` by default) and emits static schedule tables, into a second file. The
//! tables are values of the plain data types of [`pprz_messages::schedule`] (`Schedule`,
//! `Process`, `Mode`, `Periodic`), which the runtime's scheduler runs: like the message
//! types, they need only the `pprz-messages` crate, found at the path given by
//! [`runtime_crate`](Generator::runtime_crate). See [`telemetry`] for the tick rounding
//! and the automatic phase staggering.
//!
//! ```no_run
//! // build.rs (body of `fn main`), after generating the messages:
//! match pprz_codegen::Generator::new("messages.xml")
//!     .telemetry("telemetry.xml")
//!     .tick_frequency(60)                  // Hz, the default
//!     .skip_unknown_telemetry(false)       // true: leave unknown messages out, warn
//!     .write_telemetry_to_out_dir("periodic.rs")
//! {
//!     Ok(_warnings) => {} // already printed as `cargo:warning=`
//!     Err(e) => {
//!         eprintln!("{e}");
//!         std::process::exit(1);
//!     }
//! }
//! ```
//!
//! ```ignore
//! pub mod periodic {
//!     include!(concat!(env!("OUT_DIR"), "/periodic.rs"));
//! }
//! // periodic::SCHEDULE, periodic::FREQUENCY_HZ, periodic::PROCESSES,
//! // periodic::main::PROCESS, periodic::main::MODE_DEFAULT, ...
//! ```
//!
//! A message the configuration names but the message set lacks is an error naming it with
//! file and line, unless [`skip_unknown_telemetry`](Generator::skip_unknown_telemetry)
//! is set:
//!
//! ```
//! let messages = r#"<protocol><msg_class name="telemetry" id="1">
//!   <message name="ALIVE" id="2"/></msg_class></protocol>"#;
//! let telemetry = r#"<telemetry><process name="Main"><mode name="default">
//!   <message name="ALIVE" period="2.1"/>
//!   <message name="ROTORCRAFT_FOO" period="1"/>
//! </mode></process></telemetry>"#;
//! let g = pprz_codegen::Generator::from_str("messages.xml", messages)
//!     .telemetry_from_str("telemetry.xml", telemetry);
//! let err = g.generate_telemetry().unwrap_err();
//! assert!(err.to_string().starts_with(
//!     "error: telemetry.xml:3:3: message ROTORCRAFT_FOO: not in class `telemetry` of `messages.xml` (mode `default`, process `Main`)"
//! ));
//! let out = g.skip_unknown_telemetry(true).generate_telemetry().unwrap();
//! assert_eq!(out.warnings.len(), 1);
//! assert!(out.code.contains("name: \"ALIVE\", class_id: 1, msg_id: 2, period_ticks: 126"));
//! ```
//!
//! # Settings (`settings.xml`)
//!
//! The generator also reads Paparazzi settings files, numbers their settings as Paparazzi
//! does (every `<dl_setting>` in document order, files in the order given) and emits a
//! table the aircraft registers in one call: `COUNT`, `SETTINGS` (one
//! [`pprz_messages::settings::SettingDesc`] per setting, bounds in the aircraft's units),
//! `index` (a constant per variable), `Bindings` (one field per variable: a forgotten
//! binding does not compile) and `register`. The code needs the `pprz-messages`,
//! `pprz-telemetry` and `embassy-sync` crates (paths set by
//! [`runtime_crate`](Generator::runtime_crate), [`telemetry_crate`](Generator::telemetry_crate)
//! and [`embassy_sync_crate`](Generator::embassy_sync_crate)). See [`settings`] for what is
//! read, accepted and refused.
//!
//! ```no_run
//! // build.rs (body of `fn main`)
//! match pprz_codegen::Generator::for_settings(["settings/basic.xml", "settings/tuning.xml"])
//!     .write_settings_to_out_dir("settings.rs")
//! {
//!     Ok(_warnings) => {} // already printed as `cargo:warning=`
//!     Err(e) => {
//!         eprintln!("{e}");
//!         std::process::exit(1);
//!     }
//! }
//! ```
//!
//! ```ignore
//! pub mod settings {
//!     include!(concat!(env!("OUT_DIR"), "/settings.rs"));
//! }
//! static TABLE: Settings<'static, CriticalSectionRawMutex, { settings::COUNT }> = Settings::new();
//! settings::register(&TABLE, &settings::Bindings {
//!     gain: Binding::Fns(&get_gain, &set_gain),
//!     // ... one field per variable
//! })?;
//! ```
//!
//! ```
//! let xml = r#"<settings><dl_settings><dl_settings name="ins">
//!   <dl_setting var="ins.roll_neutral" min="-15" max="15" step="0.5"
//!               unit="rad" alt_unit="deg" persistent="true"/>
//! </dl_settings></dl_settings></settings>"#;
//! let g = pprz_codegen::Generator::for_settings(Vec::<String>::new())
//!     .settings_from_str("ins.xml", xml);
//! let set = g.settings_set().unwrap();
//! let roll = &set.settings[0];
//! assert_eq!((roll.index, roll.group.as_str()), (0, "ins"));
//! assert_eq!(roll.max, 15f64.to_radians() as f32); // degrees shown, radians aboard
//! let code = g.generate_settings().unwrap().code;
//! assert!(code.contains("pub const INS_ROLL_NEUTRAL: u8 = 0;"));
//! assert!(code.contains("pub ins_roll_neutral: ::pprz_telemetry::settings::Binding<'a>,"));
//! ```
//!
//! # What is refused
//!
//! Besides malformed XML and wrong types, sizes or ids, the generator refuses, each with
//! file and line:
//!
//! - class ids above [`model::MAX_CLASS_ID`] (15): a PPRZ v2 frame carries the class in
//!   4 bits, next to the component id, so such a message could never be sent;
//! - names that make no usable Rust name ([`ErrorKind::UnusableName`]): no letter or
//!   digit (`_`), a type name starting with a digit (`_1ST` -> `1St`) or equal to `Self`,
//!   a message named like its class's `AnyMessage`; names that make the same Rust name
//!   (`FOO_BAR`, `FOO__BAR`, `fooBar`) are duplicates. Keywords are escaped (`type` ->
//!   `type_`), as are class modules that would shadow a primitive type or a crate
//!   (`u8` -> `u8_`, `core` -> `core_`); any other name (`RESULT`, `OPTION`, `SOME`,
//!   `SET`...) is fine, as the generated code names standard items by their full path;
//! - elements inside `<field>` (its text is its description), and a second
//!   `<description>` in a message;
//! - inputs beyond the [`limits`]: size, attributes per element, entity declarations
//!   and expansion, nodes.
//!
//! A command-line front end, `pprz-codegen`, is built with the `cli` feature (default),
//! which also provides the `cli` module: clap parsing with escaped error messages,
//! shared by the project's tools.

#![warn(missing_docs)]
#![deny(unsafe_code)]

#[cfg(feature = "cli")]
pub mod cli;
mod emit;
mod error;
pub mod escape;
pub mod limits;
pub mod model;
mod names;
mod roles;
pub mod settings;
pub mod telemetry;
mod xml;

use std::path::{Path, PathBuf};

pub use error::{Diagnostic, Error, ErrorKind, SettingProblem};
pub use model::{Class, FieldDef, MessageDef, Protocol, Units};
pub use names::is_rust_path;
pub use settings::{SettingDef, SettingsSet};
pub use telemetry::{Schedule, ScheduleOptions, TelemetryConfig};

/// Writes generated `code` to `path`.
///
/// # Errors
/// The file cannot be written: [`ErrorKind::Write`] naming `path`, with the OS error.
fn write_output(path: &Path, code: &str) -> Result<(), Error> {
    std::fs::write(path, code)
        .map_err(|e| Error::single(&path.display().to_string(), ErrorKind::Write(e.to_string())))
}

/// Where the messages come from.
#[derive(Debug, Clone)]
enum Source {
    File(PathBuf),
    Text { name: String, xml: String },
}

/// Configures and runs the generator.
#[derive(Debug, Clone)]
pub struct Generator {
    /// The `messages.xml` (none for a generator of settings only).
    source: Option<Source>,
    units: Option<PathBuf>,
    classes: Vec<String>,
    messages: Vec<String>,
    runtime: String,
    default_priority: u8,
    telemetry: Option<Source>,
    schedule: ScheduleOptions,
    settings: Vec<Source>,
    telemetry_crate: String,
    embassy_sync_crate: String,
}

/// A generated settings table (see [`Generator::generate_settings`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedSettings {
    /// The Rust source.
    pub code: String,
    /// What was accepted with a warning (see [`SettingsSet::warnings`]).
    pub warnings: Vec<Diagnostic>,
}

/// Generated schedule tables (see [`Generator::generate_telemetry`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedTelemetry {
    /// The Rust source.
    pub code: String,
    /// What was accepted with a warning (see [`Schedule::warnings`]).
    pub warnings: Vec<Diagnostic>,
}

impl Generator {
    /// A generator for a `messages.xml` file.
    pub fn new(messages_xml: impl Into<PathBuf>) -> Self {
        Self::with_source(Some(Source::File(messages_xml.into())))
    }

    /// A generator for `messages.xml` text; `name` names it in diagnostics.
    pub fn from_str(name: &str, xml: &str) -> Self {
        Self::with_source(Some(Source::Text {
            name: name.to_owned(),
            xml: xml.to_owned(),
        }))
    }

    /// A generator for settings files only (no `messages.xml`), read in the order given
    /// (see [`settings`](Self::settings)).
    pub fn for_settings<P: Into<PathBuf>>(files: impl IntoIterator<Item = P>) -> Self {
        Self::with_source(None).settings(files)
    }

    fn with_source(source: Option<Source>) -> Self {
        Self {
            source,
            units: None,
            classes: Vec::new(),
            messages: Vec::new(),
            runtime: "::pprz_messages".to_owned(),
            default_priority: pprz_messages::priority::DEFAULT,
            telemetry: None,
            schedule: ScheduleOptions::default(),
            settings: Vec::new(),
            telemetry_crate: "::pprz_telemetry".to_owned(),
            embassy_sync_crate: "::embassy_sync".to_owned(),
        }
    }

    /// Fills missing `alt_unit_coef` from a Paparazzi `units.xml` (its entries take
    /// precedence over the built-in conversions of [`Units::builtin`], which are always
    /// applied).
    pub fn units(mut self, units_xml: impl Into<PathBuf>) -> Self {
        self.units = Some(units_xml.into());
        self
    }

    /// Generates only these classes (by name or id), plus any [`messages`](Self::messages).
    pub fn classes<S: Into<String>>(mut self, classes: impl IntoIterator<Item = S>) -> Self {
        self.classes.extend(classes.into_iter().map(Into::into));
        self
    }

    /// Generates only these messages (`NAME`, or `class.NAME` where names repeat across
    /// classes), plus any [`classes`](Self::classes).
    pub fn messages<S: Into<String>>(mut self, messages: impl IntoIterator<Item = S>) -> Self {
        self.messages.extend(messages.into_iter().map(Into::into));
        self
    }

    /// Path of the `pprz-messages` crate as seen from the generated code, for the message
    /// types and the schedule tables alike (default `::pprz_messages`; e.g. `crate` inside
    /// that crate, or a re-export such as `::my_runtime::pprz_messages`).
    pub fn runtime_crate(mut self, path: impl Into<String>) -> Self {
        self.runtime = path.into();
        self
    }

    /// Priority of messages without a `priority` attribute (default
    /// [`pprz_messages::priority::DEFAULT`]).
    pub fn default_priority(mut self, priority: u8) -> Self {
        self.default_priority = priority;
        self
    }

    /// Reads, validates and selects the message set without generating code.
    ///
    /// # Errors
    /// Every problem of the inputs, with file, line, message and field.
    pub fn protocol(&self) -> Result<Protocol, Error> {
        let mut protocol = match &self.source {
            Some(Source::File(path)) => Protocol::from_file(path)?,
            Some(Source::Text { name, xml }) => Protocol::parse(name, xml)?,
            None => {
                return Err(Error::single(
                    "messages.xml",
                    ErrorKind::NoInput("no messages.xml given (see `Generator::new`)"),
                ));
            }
        };
        protocol.apply_units(&self.unit_conversions()?);
        protocol.select(&self.classes, &self.messages)
    }

    /// The built-in unit conversions, with those of the [`units`](Self::units) file.
    fn unit_conversions(&self) -> Result<Units, Error> {
        let mut units = Units::builtin();
        if let Some(file) = &self.units {
            units.extend(&Units::from_file(file)?);
        }
        Ok(units)
    }

    /// Generates the Rust source.
    ///
    /// # Errors
    /// As [`protocol`](Self::protocol).
    pub fn generate(&self) -> Result<String, Error> {
        let protocol = self.protocol()?;
        Ok(emit::emit(
            &protocol,
            &emit::Options {
                runtime: self.runtime.clone(),
                default_priority: self.default_priority,
            },
        ))
    }

    /// Generates the Rust source into `path`.
    ///
    /// # Errors
    /// As [`protocol`](Self::protocol), or the file cannot be written.
    pub fn write_to(&self, path: impl AsRef<Path>) -> Result<(), Error> {
        let path = path.as_ref();
        let code = self.generate()?;
        write_output(path, &code)
    }

    /// `$OUT_DIR/<file_name>`, after telling Cargo to rerun the build script when an
    /// input file changes.
    fn out_dir_file(&self, file_name: &str) -> Result<PathBuf, Error> {
        for source in [self.source.as_ref(), self.telemetry.as_ref()]
            .into_iter()
            .flatten()
            .chain(&self.settings)
        {
            if let Source::File(path) = source {
                println!("cargo:rerun-if-changed={}", path.display());
            }
        }
        if let Some(units) = &self.units {
            println!("cargo:rerun-if-changed={}", units.display());
        }
        let out_dir = std::env::var_os("OUT_DIR").ok_or_else(|| {
            Error::single(
                file_name,
                ErrorKind::Write("OUT_DIR is not set: call this from a build script".into()),
            )
        })?;
        Ok(PathBuf::from(out_dir).join(file_name))
    }

    /// For a `build.rs`: generates into `$OUT_DIR/<file_name>` and tells Cargo to rerun
    /// when an input changes.
    ///
    /// # Errors
    /// As [`write_to`](Self::write_to), or `OUT_DIR` is not set (not run by Cargo).
    pub fn write_to_out_dir(&self, file_name: &str) -> Result<PathBuf, Error> {
        let path = self.out_dir_file(file_name)?;
        self.write_to(&path)?;
        Ok(path)
    }

    /// A Paparazzi telemetry configuration (`telemetry.xml`) to generate schedule tables
    /// from, with [`generate_telemetry`](Self::generate_telemetry) and friends.
    pub fn telemetry(mut self, telemetry_xml: impl Into<PathBuf>) -> Self {
        self.telemetry = Some(Source::File(telemetry_xml.into()));
        self
    }

    /// A telemetry configuration as text; `name` names it in diagnostics.
    pub fn telemetry_from_str(mut self, name: &str, xml: &str) -> Self {
        self.telemetry = Some(Source::Text {
            name: name.to_owned(),
            xml: xml.to_owned(),
        });
        self
    }

    /// Class whose messages the telemetry configuration names (default `telemetry`).
    pub fn telemetry_class(mut self, class: impl Into<String>) -> Self {
        self.schedule.class = class.into();
        self
    }

    /// Tick frequency of the scheduler, in Hz (default 60, as the reference firmware):
    /// periods and phases become whole numbers of ticks (see [`telemetry`]).
    pub fn tick_frequency(mut self, hz: u32) -> Self {
        self.schedule.frequency_hz = hz;
        self
    }

    /// Interval between the automatic phases of consecutive messages of a mode, in
    /// seconds (default 0.1).
    pub fn stagger_interval(mut self, seconds: f64) -> Self {
        self.schedule.stagger_s = seconds;
        self
    }

    /// Leave messages of the telemetry configuration that the message set lacks out of
    /// the schedule, with a warning, instead of failing (default `false`).
    pub fn skip_unknown_telemetry(mut self, skip: bool) -> Self {
        self.schedule.skip_unknown = skip;
        self
    }

    /// Reads and validates the telemetry configuration and resolves it against the
    /// selected message set, without generating code.
    ///
    /// # Errors
    /// No configuration was given, any problem of the message set (as
    /// [`protocol`](Self::protocol)) or of the configuration (see
    /// [`TelemetryConfig::parse`] and [`TelemetryConfig::resolve`]), each with file and
    /// line.
    pub fn schedule(&self) -> Result<Schedule, Error> {
        let config = match &self.telemetry {
            Some(Source::File(path)) => TelemetryConfig::from_file(path)?,
            Some(Source::Text { name, xml }) => TelemetryConfig::parse(name, xml)?,
            None => {
                return Err(Error::single(
                    "telemetry.xml",
                    ErrorKind::Telemetry(
                        "no telemetry configuration given (see `Generator::telemetry`)".into(),
                    ),
                ));
            }
        };
        let protocol = self.protocol()?;
        config.resolve(&protocol, &self.schedule)
    }

    /// Generates the Rust source of the schedule tables.
    ///
    /// # Errors
    /// As [`schedule`](Self::schedule).
    pub fn generate_telemetry(&self) -> Result<GeneratedTelemetry, Error> {
        let schedule = self.schedule()?;
        Ok(GeneratedTelemetry {
            code: telemetry::emit(&schedule, &self.runtime),
            warnings: schedule.warnings,
        })
    }

    /// Generates the schedule tables into `path`, returning the warnings.
    ///
    /// # Errors
    /// As [`schedule`](Self::schedule), or the file cannot be written.
    pub fn write_telemetry_to(&self, path: impl AsRef<Path>) -> Result<Vec<Diagnostic>, Error> {
        let path = path.as_ref();
        let generated = self.generate_telemetry()?;
        write_output(path, &generated.code)?;
        Ok(generated.warnings)
    }

    /// For a `build.rs`: generates the schedule tables into `$OUT_DIR/<file_name>`, tells
    /// Cargo to rerun when an input changes, prints each warning as `cargo:warning=`, and
    /// returns the warnings.
    ///
    /// # Errors
    /// As [`write_telemetry_to`](Self::write_telemetry_to), or `OUT_DIR` is not set.
    pub fn write_telemetry_to_out_dir(&self, file_name: &str) -> Result<Vec<Diagnostic>, Error> {
        let warnings = self.write_telemetry_to(self.out_dir_file(file_name)?)?;
        for w in &warnings {
            println!("cargo:warning={w}");
        }
        Ok(warnings)
    }

    /// Settings files (Paparazzi `settings.xml`) to generate a settings table from, with
    /// [`generate_settings`](Self::generate_settings) and friends; added after those
    /// already given: the files are numbered in this order (see [`settings`]).
    pub fn settings<P: Into<PathBuf>>(mut self, files: impl IntoIterator<Item = P>) -> Self {
        self.settings
            .extend(files.into_iter().map(|f| Source::File(f.into())));
        self
    }

    /// A settings file as text, after those already given; `name` names it in
    /// diagnostics.
    pub fn settings_from_str(mut self, name: &str, xml: &str) -> Self {
        self.settings.push(Source::Text {
            name: name.to_owned(),
            xml: xml.to_owned(),
        });
        self
    }

    /// Path of the `pprz-telemetry` crate as seen from the generated settings code
    /// (default `::pprz_telemetry`).
    pub fn telemetry_crate(mut self, path: impl Into<String>) -> Self {
        self.telemetry_crate = path.into();
        self
    }

    /// Path of the `embassy-sync` crate as seen from the generated settings code (default
    /// `::embassy_sync`): `register` is generic over its `RawMutex`.
    pub fn embassy_sync_crate(mut self, path: impl Into<String>) -> Self {
        self.embassy_sync_crate = path.into();
        self
    }

    /// Reads, numbers and checks the settings files, without generating code. Conversions
    /// from `unit` to `alt_unit` are the built-in ones and those of the
    /// [`units`](Self::units) file.
    ///
    /// # Errors
    /// No settings file was given, or the problems of the files (see [`settings`]), each
    /// with file, line and column.
    pub fn settings_set(&self) -> Result<SettingsSet, Error> {
        if self.settings.is_empty() {
            return Err(Error::single(
                "settings.xml",
                ErrorKind::NoInput("no settings file given (see `Generator::settings`)"),
            ));
        }
        let inputs: Vec<settings::Input<'_>> = self
            .settings
            .iter()
            .map(|s| match s {
                Source::File(path) => settings::Input::File(path),
                Source::Text { name, xml } => settings::Input::Text(name, xml),
            })
            .collect();
        settings::read(&inputs, &self.unit_conversions()?)
    }

    /// Generates the Rust source of the settings table: `SETTINGS`, `index`, `Bindings`
    /// and `register` (see [`settings`]).
    ///
    /// # Errors
    /// As [`settings_set`](Self::settings_set).
    pub fn generate_settings(&self) -> Result<GeneratedSettings, Error> {
        let set = self.settings_set()?;
        let paths = settings::Paths {
            messages: self.runtime.clone(),
            telemetry: self.telemetry_crate.clone(),
            embassy_sync: self.embassy_sync_crate.clone(),
        };
        Ok(GeneratedSettings {
            code: settings::emit(&set, &paths),
            warnings: set.warnings,
        })
    }

    /// Generates the settings table into `path`, returning the warnings.
    ///
    /// # Errors
    /// As [`settings_set`](Self::settings_set), or the file cannot be written.
    pub fn write_settings_to(&self, path: impl AsRef<Path>) -> Result<Vec<Diagnostic>, Error> {
        let generated = self.generate_settings()?;
        write_output(path.as_ref(), &generated.code)?;
        Ok(generated.warnings)
    }

    /// For a `build.rs`: generates the settings table into `$OUT_DIR/<file_name>`, tells
    /// Cargo to rerun when an input changes, prints each warning as `cargo:warning=`, and
    /// returns the warnings.
    ///
    /// # Errors
    /// As [`write_settings_to`](Self::write_settings_to), or `OUT_DIR` is not set.
    pub fn write_settings_to_out_dir(&self, file_name: &str) -> Result<Vec<Diagnostic>, Error> {
        let warnings = self.write_settings_to(self.out_dir_file(file_name)?)?;
        for w in &warnings {
            println!("cargo:warning={w}");
        }
        Ok(warnings)
    }
}
