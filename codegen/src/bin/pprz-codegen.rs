//! `pprz-codegen`: generate Rust message types from a Paparazzi `messages.xml`, or check
//! and list one; with `--telemetry`, the same for the periodic telemetry schedule of a
//! `telemetry.xml` resolved against it; with `--settings`, the same for the settings
//! table of `settings.xml` files (no `messages.xml` then).
//!
//! Everything printed that comes from the inputs (names, types, file names) has its
//! control characters escaped: the diagnostics by their own `Display`, the rest with
//! [`pprz_codegen::escape::text`].
//!
//! Exit status: 0 on success, 1 when an input has errors or the output cannot be
//! written, 2 for invalid options.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use pprz_codegen::{Generator, Schedule, SettingsSet, escape, is_rust_path};

/// Generate Rust message types from a Paparazzi messages.xml (or, with --telemetry, the
/// periodic telemetry schedule tables of a telemetry.xml; with --settings, the settings
/// table of settings.xml files).
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// The messages.xml to read (not with --settings).
    #[arg(required_unless_present = "settings", conflicts_with = "settings")]
    messages: Option<PathBuf>,
    /// Settings files (settings.xml), numbered in this order: generate (or check, list)
    /// their settings table instead of message types.
    #[arg(long, num_args = 1.., value_name = "SETTINGS_XML", conflicts_with_all = [
        "classes", "messages_sel", "default_priority", "telemetry", "skip_unknown_telemetry",
        "telemetry_class", "tick_frequency", "stagger",
    ])]
    settings: Vec<PathBuf>,
    /// Path of the pprz-telemetry crate in the generated settings code (with --settings):
    /// a Rust path such as `::pprz_telemetry` or `crate::tm`.
    #[arg(long, default_value = "::pprz_telemetry", conflicts_with = "messages")]
    telemetry_crate: String,
    /// Path of the embassy-sync crate in the generated settings code (with --settings):
    /// a Rust path.
    #[arg(long, default_value = "::embassy_sync", conflicts_with = "messages")]
    embassy_sync_crate: String,
    /// Only these classes (name or id); repeatable.
    #[arg(long = "class", value_name = "CLASS")]
    classes: Vec<String>,
    /// Only these messages (NAME or class.NAME); repeatable.
    #[arg(long = "message", value_name = "NAME")]
    messages_sel: Vec<String>,
    /// A units.xml giving default alt_unit coefficients.
    #[arg(long)]
    units: Option<PathBuf>,
    /// Path of the pprz-messages crate in the generated code (message types and, with
    /// --telemetry, schedule tables; with --settings, setting descriptions): a Rust path
    /// such as `::pprz_messages` or `crate`.
    #[arg(long, default_value = "::pprz_messages")]
    runtime_crate: String,
    /// Priority of messages without a `priority` attribute.
    #[arg(long, default_value_t = pprz_messages::priority::DEFAULT)]
    default_priority: u8,
    /// Write the code here instead of standard output.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Only validate; print a summary.
    #[arg(long, conflicts_with = "list")]
    check: bool,
    /// Only validate; list every selected message (class, id, name, priority, size),
    /// with --telemetry every scheduled message (process, mode, period, phase), or with
    /// --settings every setting.
    #[arg(long)]
    list: bool,
    /// A telemetry.xml: generate (or check, list) its schedule tables instead of the
    /// message types; its message names are resolved against the selected messages.
    #[arg(long, value_name = "TELEMETRY_XML")]
    telemetry: Option<PathBuf>,
    /// Leave the messages of the telemetry.xml that are not in the messages.xml out of
    /// the schedule, with a warning, instead of failing.
    #[arg(long, requires = "telemetry")]
    skip_unknown_telemetry: bool,
    /// Class of the periodic messages.
    #[arg(long, default_value = "telemetry", requires = "telemetry")]
    telemetry_class: String,
    /// Tick frequency of the scheduler, in Hz.
    #[arg(long, default_value_t = 60, requires = "telemetry", value_parser = clap::value_parser!(u32).range(1..))]
    tick_frequency: u32,
    /// Interval between automatic phases, in seconds.
    #[arg(long, default_value_t = 0.1, requires = "telemetry")]
    stagger: f64,
}

impl Args {
    /// Checks the crate path options, which are pasted into the generated code: each
    /// must be a Rust path ([`is_rust_path`]).
    ///
    /// # Errors
    /// The message for the user, naming the option and its value (escaped).
    fn check_crate_paths(&self) -> Result<(), String> {
        for (option, value) in [
            ("--runtime-crate", &self.runtime_crate),
            ("--telemetry-crate", &self.telemetry_crate),
            ("--embassy-sync-crate", &self.embassy_sync_crate),
        ] {
            if !is_rust_path(value) {
                return Err(format!(
                    "error: {option} `{}` is not a Rust path: give identifiers (letters, digits and `_`, not starting with a digit) separated by `::`, optionally after a leading `::` or starting with `crate`, `self` or `super` (e.g. `::pprz_messages`, `crate::rt`)",
                    escape::text(value)
                ));
            }
        }
        Ok(())
    }
}

/// A file name given on the command line, for a message: control characters escaped.
fn shown(path: &Path) -> String {
    escape::text(&path.display().to_string())
}

fn list_schedule(s: &Schedule) {
    println!(
        "{:<10} {:<16} {:<28} {:>4} {:>4} {:>8} {:>7}  phase",
        "process", "mode", "message", "class", "id", "period s", "ticks"
    );
    for p in &s.processes {
        for m in &p.modes {
            for msg in &m.messages {
                let phase = match msg.phase_s {
                    Some(ph) => format!("{} ({ph} s)", msg.phase_ticks),
                    None => format!("{} (auto)", msg.phase_ticks),
                };
                println!(
                    "{:<10} {:<16} {:<28} {:>4} {:>4} {:>8} {:>7}  {phase}",
                    escape::text(&p.name),
                    escape::text(&m.name),
                    escape::text(&msg.name),
                    msg.class_id,
                    msg.msg_id,
                    msg.period_s,
                    msg.period_ticks
                );
            }
        }
    }
}

fn telemetry(args: &Args, generator: Generator) -> Result<(), pprz_codegen::Error> {
    let Some(file) = &args.telemetry else {
        return Ok(());
    };
    let generator = generator
        .telemetry(file)
        .skip_unknown_telemetry(args.skip_unknown_telemetry)
        .telemetry_class(args.telemetry_class.clone())
        .tick_frequency(args.tick_frequency)
        .stagger_interval(args.stagger);
    let warnings = if args.check || args.list {
        let s = generator.schedule()?;
        if args.list {
            list_schedule(&s);
        }
        println!(
            "{}: {} processes, {} modes, {} periodic messages at {} Hz: ok",
            shown(file),
            s.processes.len(),
            s.mode_count(),
            s.entry_count(),
            s.frequency_hz
        );
        s.warnings
    } else if let Some(out) = &args.output {
        generator.write_telemetry_to(out)?
    } else {
        let g = generator.generate_telemetry()?;
        print!("{}", g.code);
        g.warnings
    };
    for w in warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

/// A column of `--list --settings`: the text with control characters escaped (one line
/// per setting), or `-` when empty.
fn or_dash(s: Option<&str>) -> String {
    match s.filter(|s| !s.is_empty()) {
        Some(s) => escape::text(s),
        None => "-".to_owned(),
    }
}

/// A number for reading: `10`, `0.5`, `1e-6`, `3.4e38`.
fn number(x: f32) -> String {
    let debug = format!("{x:?}");
    if debug.contains('e') {
        debug
    } else {
        x.to_string()
    }
}

fn list_settings(set: &SettingsSet) {
    println!(
        "{:>3}  {:<16} {:<32} {:<16} {:<24} {:>6}  {:<6} {:<10} {:<24} {:<10}  handler",
        "idx",
        "group",
        "var",
        "shortname",
        "bounds",
        "step",
        "type",
        "unit",
        "labels",
        "persistent"
    );
    for s in &set.settings {
        let unit = match (&s.unit, &s.alt_unit) {
            (u, Some(a)) => format!(
                "{} ({} x{})",
                or_dash(u.as_deref()),
                or_dash(Some(a)),
                s.alt_unit_coef as f32
            ),
            (u, None) => or_dash(u.as_deref()),
        };
        let handler = match (&s.handler, &s.module) {
            (Some(h), Some(m)) => or_dash(Some(&format!("{m}.{h}"))),
            (h, _) => or_dash(h.as_deref()),
        };
        println!(
            "{:>3}  {:<16} {:<32} {:<16} {:<24} {:>6}  {:<6} {:<10} {:<24} {:<10}  {handler}",
            s.index,
            or_dash(Some(&s.group)),
            or_dash(Some(&s.var)),
            or_dash(s.shortname.as_deref()),
            format!("[{}, {}]", number(s.min), number(s.max)),
            number(s.step),
            s.ty.name(),
            unit,
            or_dash(Some(&s.values.join("|"))),
            if s.persistent { "persistent" } else { "-" },
        );
    }
}

fn settings(args: &Args) -> Result<(), pprz_codegen::Error> {
    let mut generator = Generator::for_settings(&args.settings)
        .runtime_crate(args.runtime_crate.clone())
        .telemetry_crate(args.telemetry_crate.clone())
        .embassy_sync_crate(args.embassy_sync_crate.clone());
    if let Some(units) = &args.units {
        generator = generator.units(units);
    }
    let warnings = if args.check || args.list {
        let set = generator.settings_set()?;
        if args.list {
            list_settings(&set);
        }
        println!(
            "{} settings ({} variables, {} persistent) from {} files: ok",
            set.len(),
            set.variables().len(),
            set.persistent_count(),
            set.files.len()
        );
        set.warnings
    } else if let Some(out) = &args.output {
        generator.write_settings_to(out)?
    } else {
        let g = generator.generate_settings()?;
        print!("{}", g.code);
        g.warnings
    };
    for w in warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

fn main() -> ExitCode {
    let args: Args = pprz_codegen::cli::parse();
    if let Err(e) = args.check_crate_paths() {
        eprintln!("{e}");
        return ExitCode::from(2);
    }
    let Some(messages) = &args.messages else {
        return finish(settings(&args));
    };
    let mut generator = Generator::new(messages)
        .classes(args.classes.clone())
        .messages(args.messages_sel.clone())
        .runtime_crate(args.runtime_crate.clone())
        .default_priority(args.default_priority);
    if let Some(units) = &args.units {
        generator = generator.units(units);
    }
    let result = if args.telemetry.is_some() {
        telemetry(&args, generator)
    } else if args.check || args.list {
        generator.protocol().map(|p| {
            if args.list {
                println!(
                    "{:<10} {:>3}  {:<32} {:>8}  payload",
                    "class", "id", "message", "priority"
                );
                for c in &p.classes {
                    for m in &c.messages {
                        let size = if m.is_fixed_size() {
                            m.min_len().to_string()
                        } else {
                            format!("{}..={}", m.min_len(), m.max_len())
                        };
                        println!(
                            "{:<10} {:>3}  {:<32} {:>8}  {size}",
                            escape::text(&c.name),
                            m.id,
                            escape::text(&m.name),
                            m.priority.unwrap_or(args.default_priority)
                        );
                    }
                }
            }
            println!(
                "{}: {} classes, {} messages: ok",
                shown(messages),
                p.classes.len(),
                p.message_count()
            );
        })
    } else if let Some(out) = &args.output {
        generator.write_to(out)
    } else {
        generator.generate().map(|code| print!("{code}"))
    };
    finish(result)
}

fn finish(result: Result<(), pprz_codegen::Error>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Escaped by the diagnostics' `Display`.
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
