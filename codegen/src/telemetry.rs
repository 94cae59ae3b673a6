//! Periodic telemetry configurations (Paparazzi `telemetry.xml`): parser, resolution
//! against a message set into tick-based schedule tables, and the emitter of those tables.
//!
//! ```text
//! <telemetry>
//!   <process name="Main">
//!     <mode name="default" key_press="d">
//!       <message name="GPS_INT" period="0.25" phase="0.1"/>
//! ```
//!
//! Pipeline: [`TelemetryConfig::parse`] (syntax and per-file checks) ->
//! [`TelemetryConfig::resolve`] (message names to class and id, seconds to ticks, automatic
//! phases) -> [`Schedule`] -> Rust source with a static table of the types of
//! `pprz_messages::schedule`, which the runtime's scheduler runs.
//!
//! # Ticks
//! The scheduler ticks at a fixed frequency `f` (default 60 Hz, as the reference
//! firmware). A duration of `s` seconds becomes `round(s * f)` ticks, to the nearest tick
//! with halves rounded up (after removing floating-point noise below 1e-6 tick, so
//! `4.1 s * 60 Hz` is 246 ticks, not 245). A period is at least one tick: a shorter period
//! is sent on every tick, with a warning. An explicit phase is taken modulo the period
//! after rounding. A message is due on tick `t` (counted from 0 since the scheduler
//! started) when `t % period_ticks == phase_ticks`.
//!
//! # Automatic phases (staggering)
//! Within one mode, messages with a `phase` keep it. The others get one in file order:
//! the `i`-th message without a phase (counting from 0) starts from the candidate phase
//! `i * stagger mod period`, where `stagger = round(0.1 s * f)` ticks (at least 1; the
//! interval is [`ScheduleOptions::stagger_s`]), so consecutive messages are about 100 ms
//! apart as in the reference firmware. If another message of the same mode with the same
//! period already uses that phase, the next free phase (`+1`, `+2`, ... modulo the
//! period) is taken; only when all `period` phases are used is the least used one taken.
//!
//! Hence, in one mode, messages with automatic phases never share a tick with another
//! message of the same period as long as there are no more of them than the period has
//! ticks; beyond that, at most `ceil(n / period)` of `n` such messages share a tick.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use roxmltree::Node;

use crate::emit::ALLOW_DEAD_CODE;
use crate::error::{Diagnostic, Error, ErrorKind};
use crate::model::{Class, Protocol};
use crate::names;
use crate::xml::{self, Ctx, Seen};

/// A parsed and validated telemetry configuration (before message names are resolved).
#[derive(Debug, Clone, PartialEq)]
pub struct TelemetryConfig {
    /// Name of the file it was read from (for diagnostics).
    pub file: String,
    /// Processes in file order.
    pub processes: Vec<ProcessDef>,
}

/// A `<process>`: a set of modes, one of which is active at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessDef {
    /// Process name (`Main`).
    pub name: String,
    /// Line of the element.
    pub line: u32,
    /// Modes in file order; the first is active at start-up.
    pub modes: Vec<ModeDef>,
}

/// A `<mode>`: the periodic messages sent while it is the active mode of its process.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeDef {
    /// Mode name (`default`).
    pub name: String,
    /// Line of the element.
    pub line: u32,
    /// The `key_press` attribute (a ground-station shortcut), if given.
    pub key_press: Option<String>,
    /// Messages in file order.
    pub messages: Vec<PeriodicDef>,
}

/// A `<message>` of a mode.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicDef {
    /// Message name (`GPS_INT`).
    pub name: String,
    /// Line of the element.
    pub line: u32,
    /// Column of the element.
    pub column: u32,
    /// Period in seconds (finite, > 0).
    pub period: f64,
    /// Phase in seconds (finite, >= 0, less than the period), if given.
    pub phase: Option<f64>,
}

/// How a configuration is turned into a [`Schedule`].
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduleOptions {
    /// Class whose messages the configuration names (default `telemetry`).
    pub class: String,
    /// Tick frequency of the scheduler in Hz (default 60, at least 1).
    pub frequency_hz: u32,
    /// Interval between the automatic phases of consecutive messages of a mode, in
    /// seconds (default 0.1; 0 keeps only the separation of equal periods).
    pub stagger_s: f64,
    /// Leave messages absent from the message set out with a warning instead of failing.
    pub skip_unknown: bool,
}

impl Default for ScheduleOptions {
    fn default() -> Self {
        Self {
            class: "telemetry".to_owned(),
            frequency_hz: 60,
            stagger_s: 0.1,
            skip_unknown: false,
        }
    }
}

/// A configuration resolved against a message set: the tables the scheduler runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    /// The telemetry configuration file.
    pub file: String,
    /// The messages file the names were resolved against.
    pub messages_file: String,
    /// Class of the messages.
    pub class: String,
    /// Tick frequency in Hz.
    pub frequency_hz: u32,
    /// Interval between automatic phases, in ticks.
    pub stagger_ticks: u32,
    /// Processes in file order.
    pub processes: Vec<ScheduledProcess>,
    /// What was accepted with a warning: messages left out (with
    /// [`ScheduleOptions::skip_unknown`]) and periods shorter than a tick. Each is a
    /// [`Diagnostic`] with file and line; print them as `warning: {diagnostic}`.
    pub warnings: Vec<Diagnostic>,
}

/// A process of a [`Schedule`].
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduledProcess {
    /// Process name.
    pub name: String,
    /// Modes in file order.
    pub modes: Vec<ScheduledMode>,
}

/// A mode of a [`ScheduledProcess`].
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduledMode {
    /// Mode name.
    pub name: String,
    /// The `key_press` attribute, if given.
    pub key_press: Option<String>,
    /// Messages in file order (without those left out).
    pub messages: Vec<ScheduledMessage>,
}

/// A message of a [`ScheduledMode`], with its timing in ticks.
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduledMessage {
    /// Message name.
    pub name: String,
    /// Line in the configuration.
    pub line: u32,
    /// Class id.
    pub class_id: u8,
    /// Message id within the class.
    pub msg_id: u8,
    /// Period in seconds, as configured.
    pub period_s: f64,
    /// Phase in seconds, if configured.
    pub phase_s: Option<f64>,
    /// Period in ticks (>= 1).
    pub period_ticks: u32,
    /// Phase in ticks (< `period_ticks`), configured or automatic.
    pub phase_ticks: u32,
}

impl Schedule {
    /// Number of modes of all processes.
    pub fn mode_count(&self) -> usize {
        self.processes.iter().map(|p| p.modes.len()).sum()
    }

    /// Number of periodic message entries of all modes.
    pub fn entry_count(&self) -> usize {
        self.processes
            .iter()
            .flat_map(|p| &p.modes)
            .map(|m| m.messages.len())
            .sum()
    }
}

impl TelemetryConfig {
    /// Reads and validates a telemetry configuration file.
    ///
    /// # Errors
    /// Every problem found, each with file and line.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, Error> {
        xml::parse_file(path.as_ref(), Self::parse)
    }

    /// Parses and validates telemetry configuration text; `file` names it in diagnostics.
    ///
    /// Checks: the element structure, required attributes (`name` of processes, modes and
    /// messages, `period` of messages), names usable as identifiers, periods finite and
    /// above 0, phases finite, at least 0 and less than the period, no duplicate process names,
    /// mode names within a process or message names within a mode, and at least one mode
    /// per process.
    ///
    /// # Errors
    /// Every problem found, each with file and line.
    pub fn parse(file: &str, text: &str) -> Result<Self, Error> {
        xml::parse(file, text, parse_config)
    }

    /// Resolves the message names against class `options.class` of `protocol` and
    /// computes periods and phases in ticks (see the [module docs](self)).
    ///
    /// # Errors
    /// A message absent from the class (each one listed with file and line; unless
    /// `options.skip_unknown`, which turns them into [`Schedule::warnings`]), an absent
    /// class, a tick frequency of 0, a negative or non-finite stagger interval, or a
    /// period longer than `u32::MAX` ticks.
    pub fn resolve(
        &self,
        protocol: &Protocol,
        options: &ScheduleOptions,
    ) -> Result<Schedule, Error> {
        let class = self.checked_class(protocol, options)?;
        let freq = f64::from(options.frequency_hz);
        let stagger = match ticks(options.stagger_s, freq) {
            0 if options.stagger_s > 0.0 => 1,
            t => u32::try_from(t).unwrap_or(u32::MAX),
        };
        let mut r = Resolver {
            file: &self.file,
            messages_file: &protocol.file,
            class,
            options,
            freq,
            errors: Vec::new(),
            warnings: Vec::new(),
        };
        let mut processes = Vec::new();
        for process in &self.processes {
            let mut modes = Vec::new();
            for mode in &process.modes {
                modes.push(r.mode(process, mode, stagger));
            }
            processes.push(ScheduledProcess {
                name: process.name.clone(),
                modes,
            });
        }
        if !r.errors.is_empty() {
            return Err(Error::new(r.errors));
        }
        Ok(Schedule {
            file: self.file.clone(),
            messages_file: protocol.file.clone(),
            class: class.name.clone(),
            frequency_hz: options.frequency_hz,
            stagger_ticks: stagger,
            processes,
            warnings: r.warnings,
        })
    }

    /// The class periodic messages are looked up in, once the options are checked: a
    /// tick frequency of at least 1 Hz, a finite stagger interval >= 0, a class present
    /// in `protocol`.
    fn checked_class<'p>(
        &self,
        protocol: &'p Protocol,
        options: &ScheduleOptions,
    ) -> Result<&'p Class, Error> {
        let file = &self.file;
        if options.frequency_hz == 0 {
            return Err(Error::single(
                file,
                ErrorKind::Telemetry("the tick frequency must be at least 1 Hz".into()),
            ));
        }
        if !(options.stagger_s.is_finite() && options.stagger_s >= 0.0) {
            return Err(Error::single(
                file,
                ErrorKind::Telemetry(format!(
                    "the stagger interval must be a finite number of seconds >= 0, not {}",
                    options.stagger_s
                )),
            ));
        }
        protocol.class(&options.class).ok_or_else(|| {
            Error::single(
                file,
                ErrorKind::Telemetry(format!(
                    "class `{}` (where periodic messages are looked up) is not in `{}`",
                    options.class, protocol.file
                )),
            )
        })
    }
}

/// Resolving a configuration's messages against a class: what it reads, and the errors
/// and warnings it collects.
struct Resolver<'a> {
    /// The telemetry configuration's file.
    file: &'a str,
    /// The `messages.xml` the class comes from.
    messages_file: &'a str,
    class: &'a Class,
    options: &'a ScheduleOptions,
    /// The tick frequency, in Hz.
    freq: f64,
    errors: Vec<Diagnostic>,
    warnings: Vec<Diagnostic>,
}

impl Resolver<'_> {
    /// A mode's messages, those whose phase is not given staggered by `stagger` ticks.
    fn mode(&mut self, process: &ProcessDef, mode: &ModeDef, stagger: u32) -> ScheduledMode {
        let mut messages = Vec::new();
        for m in &mode.messages {
            if let Some(resolved) = self.message(process, mode, m) {
                messages.push(resolved);
            }
        }
        stagger_phases(&mut messages, stagger);
        ScheduledMode {
            name: mode.name.clone(),
            key_press: mode.key_press.clone(),
            messages: messages.into_iter().map(|(m, _)| m).collect(),
        }
    }

    /// A periodic message in ticks, and whether its phase was given; `None` (with an
    /// error or a warning) for a message absent from the class or a period too long.
    fn message(
        &mut self,
        process: &ProcessDef,
        mode: &ModeDef,
        m: &PeriodicDef,
    ) -> Option<(ScheduledMessage, bool)> {
        let (class, options, freq) = (self.class, self.options, self.freq);
        let Some(def) = class.messages.iter().find(|d| d.name == m.name) else {
            let missing = format!(
                "not in class `{}` of `{}` (mode `{}`, process `{}`)",
                class.name, self.messages_file, mode.name, process.name
            );
            if options.skip_unknown {
                let d = self.diag(m, format!("{missing}; left out of the schedule"));
                self.warnings.push(d);
            } else {
                let d = self.diag(m, format!(
                    "{missing}; `skip_unknown_telemetry(true)` (CLI: `--skip-unknown-telemetry`) leaves such messages out with a warning"
                ));
                self.errors.push(d);
            }
            return None;
        };
        let raw = ticks(m.period, freq);
        let Ok(period_ticks) = u32::try_from(raw.max(1)) else {
            let d = self.diag(
                m,
                format!(
                    "period {} s is {raw} ticks at {} Hz, more than the {} a schedule holds",
                    m.period,
                    options.frequency_hz,
                    u32::MAX
                ),
            );
            self.errors.push(d);
            return None;
        };
        if raw == 0 {
            let d = self.diag(
                m,
                format!(
                    "period {} s is shorter than one tick at {} Hz ({:.3} ms): sent on every tick",
                    m.period,
                    options.frequency_hz,
                    1000.0 / freq
                ),
            );
            self.warnings.push(d);
        }
        let phase_ticks = m.phase.map(|ph| {
            // < period_ticks after the modulo, so it fits a u32.
            u32::try_from(ticks(ph, freq) % u64::from(period_ticks)).unwrap_or(0)
        });
        let resolved = ScheduledMessage {
            name: m.name.clone(),
            line: m.line,
            class_id: class.id,
            msg_id: def.id,
            period_s: m.period,
            phase_s: m.phase,
            period_ticks,
            phase_ticks: phase_ticks.unwrap_or(0),
        };
        Some((resolved, phase_ticks.is_some()))
    }

    /// A diagnostic about periodic message `m`.
    fn diag(&self, m: &PeriodicDef, text: String) -> Diagnostic {
        Diagnostic {
            file: self.file.to_owned(),
            line: m.line,
            column: m.column,
            message: Some(m.name.clone()),
            field: None,
            kind: ErrorKind::Telemetry(text),
        }
    }
}

/// `seconds * freq` to the nearest tick, halves up, ignoring floating-point noise below
/// 1e-6 tick; saturates at `u64::MAX`.
fn ticks(seconds: f64, freq: f64) -> u64 {
    let x = seconds * freq;
    let snapped = (x * 1e6).round() / 1e6;
    // `as` saturates; the value is finite and >= 0 (validated).
    snapped.round() as u64
}

/// Gives the messages of one mode without an explicit phase (`false` in the pair) their
/// automatic phase; see the module docs for the rule.
fn stagger_phases(messages: &mut [(ScheduledMessage, bool)], stagger: u32) {
    // Messages placed so far per (period, phase), and per period.
    let mut load: HashMap<(u32, u32), usize> = HashMap::new();
    let mut placed: HashMap<u32, usize> = HashMap::new();
    for (m, _) in messages.iter().filter(|(_, explicit)| *explicit) {
        *load.entry((m.period_ticks, m.phase_ticks)).or_default() += 1;
        *placed.entry(m.period_ticks).or_default() += 1;
    }
    let automatic = messages.iter_mut().filter(|(_, explicit)| !*explicit);
    for (i, (m, _)) in (0u64..).zip(automatic) {
        let p = m.period_ticks;
        let candidate = (i * u64::from(stagger) % u64::from(p)) as u32;
        let used = |phase: u32| load.get(&(p, phase)).copied().unwrap_or(0);
        let n = placed.get(&p).copied().unwrap_or(0);
        let phase = if (n as u64) < u64::from(p) {
            // A free phase exists; at most `n + 1` candidates are tried.
            let mut phase = candidate;
            while used(phase) > 0 {
                phase = if phase + 1 == p { 0 } else { phase + 1 };
            }
            phase
        } else {
            // Every phase is used (so `p <= n` is small): the least used one, first
            // from the candidate on.
            (0..p)
                .map(|k| ((u64::from(candidate) + u64::from(k)) % u64::from(p)) as u32)
                .min_by_key(|&phase| used(phase))
                .unwrap_or(candidate)
        };
        m.phase_ticks = phase;
        *load.entry((p, phase)).or_default() += 1;
        *placed.entry(p).or_default() += 1;
    }
}

/// Appends formatted text; writing to a `String` cannot fail.
macro_rules! out {
    ($dst:expr, $($arg:tt)*) => {
        let _ = writeln!($dst, $($arg)*);
    };
}

/// Seconds for display: `2.1`, `0.25`, `1.0`.
fn secs(s: f64) -> String {
    format!("{s:?}")
}

/// The constant naming a mode's index: `raw_sensors` -> `MODE_RAW_SENSORS`.
pub(crate) fn mode_const(name: &str) -> String {
    format!(
        "MODE_{}",
        names::snake_case(name)
            .trim_end_matches('_')
            .to_ascii_uppercase()
    )
}

/// Rust source for a resolved schedule; `runtime` is the path of the `pprz-messages`
/// crate (`::pprz_messages`), whose `schedule` module has the table types.
pub(crate) fn emit(s: &Schedule, runtime: &str) -> String {
    let mut out = String::new();
    let rt = format!("{runtime}::schedule");
    out!(
        out,
        "// Generated by pprz-codegen {} from `{}` (messages of class `{}` from `{}`). Do not edit.\n",
        env!("CARGO_PKG_VERSION"),
        s.file,
        s.class,
        s.messages_file
    );
    emit_constants(&mut out, s);
    emit_table(&mut out, s, &rt);
    for (index, p) in s.processes.iter().enumerate() {
        emit_process_module(&mut out, index, p);
    }
    out
}

/// `FREQUENCY_HZ` and `PROCESSES`.
fn emit_constants(out: &mut String, s: &Schedule) {
    out!(out, "/// Tick frequency of [`SCHEDULE`], in Hz.");
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(out, "pub const FREQUENCY_HZ: u32 = {};\n", s.frequency_hz);
    out!(
        out,
        "/// Number of processes of [`SCHEDULE`] (the `P` parameter of a scheduler that runs it)."
    );
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(out, "pub const PROCESSES: usize = {};\n", s.processes.len());
}

/// The doc comment of `SCHEDULE`: its frequency, processes and modes.
fn emit_table_doc(out: &mut String, s: &Schedule) {
    let summary = s
        .processes
        .iter()
        .map(|p| {
            format!(
                "`{}` ({} {})",
                p.name,
                if p.modes.len() == 1 { "mode" } else { "modes" },
                p.modes
                    .iter()
                    .map(|m| format!("`{}`", m.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    out!(
        out,
        "/// The periodic telemetry schedule, ticking at {} Hz: {}.",
        s.frequency_hz,
        match s.processes.len() {
            0 => "no processes".to_owned(),
            1 => format!("process {summary}"),
            _ => format!("processes {summary}"),
        }
    );
    out!(out, "///");
    out!(
        out,
        "/// Periods and phases are in ticks of 1/{} s; phases not given in the configuration",
        s.frequency_hz
    );
    out!(
        out,
        "/// are staggered ({} ticks apart, never equal for equal periods while possible).",
        s.stagger_ticks
    );
}

/// The `SCHEDULE` static: per process, per mode, its periodic messages.
fn emit_table(out: &mut String, s: &Schedule, rt: &str) {
    emit_table_doc(out, s);
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(
        out,
        "pub static SCHEDULE: {rt}::Schedule<'static> = {rt}::Schedule {{"
    );
    out!(out, "    frequency_hz: {},", s.frequency_hz);
    out!(out, "    processes: &[");
    for p in &s.processes {
        out!(out, "        {rt}::Process {{");
        out!(out, "            name: {:?},", p.name);
        out!(out, "            modes: &[");
        for m in &p.modes {
            emit_mode(out, rt, m);
        }
        out!(out, "            ],");
        out!(out, "        }},");
    }
    out!(out, "    ],");
    out!(out, "}};");
}

/// One mode of the `SCHEDULE` table.
fn emit_mode(out: &mut String, rt: &str, m: &ScheduledMode) {
    out!(out, "                {rt}::Mode {{");
    out!(out, "                    name: {:?},", m.name);
    match &m.key_press {
        Some(k) => {
            out!(
                out,
                "                    key_press: ::core::option::Option::Some({k:?}),"
            );
        }
        None => {
            out!(
                out,
                "                    key_press: ::core::option::Option::None,"
            );
        }
    }
    out!(out, "                    messages: &[");
    for msg in &m.messages {
        let phase = match msg.phase_s {
            Some(ph) => format!("phase {} s", secs(ph)),
            None => "automatic phase".to_owned(),
        };
        out!(
            out,
            "                        // {}: every {} s, {phase}",
            msg.name,
            secs(msg.period_s)
        );
        out!(
            out,
            "                        {rt}::Periodic {{ name: {:?}, class_id: {}, msg_id: {}, period_ticks: {}, phase_ticks: {}, period_s: {:?} }},",
            msg.name,
            msg.class_id,
            msg.msg_id,
            msg.period_ticks,
            msg.phase_ticks,
            msg.period_s as f32
        );
    }
    out!(out, "                    ],");
    out!(out, "                }},");
}

/// The module of process `p` (number `index`): its index and the indices of its modes.
fn emit_process_module(out: &mut String, index: usize, p: &ScheduledProcess) {
    out!(out, "");
    out!(
        out,
        "/// Process `{}` of [`SCHEDULE`]: its index and the indices of its modes (values of its mode setting).",
        p.name
    );
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(out, "pub mod {} {{", names::module_name(&p.name));
    out!(
        out,
        "    /// Index of process `{}` in [`SCHEDULE`](super::SCHEDULE).",
        p.name
    );
    out!(out, "    pub const PROCESS: usize = {index};");
    for (i, m) in p.modes.iter().enumerate() {
        let key = m
            .key_press
            .as_ref()
            .map(|k| format!(" (key `{k}`)"))
            .unwrap_or_default();
        let list = if m.messages.is_empty() {
            "no messages".to_owned()
        } else {
            m.messages
                .iter()
                .map(|msg| format!("{} every {} s", msg.name, secs(msg.period_s)))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let text = if i == 0 {
            format!("Mode `{}`{key}, active at start-up: {list}.", m.name)
        } else {
            format!("Mode `{}`{key}: {list}.", m.name)
        };
        out!(out, "    #[doc = {:?}]", format!(" {text}"));
        out!(out, "    pub const {}: usize = {i};", mode_const(&m.name));
    }
    out!(out, "}}");
}

/// The `<telemetry>` root of a telemetry configuration: its processes.
fn parse_config(p: &mut xml::Parser<'_, '_>) -> TelemetryConfig {
    let ctx = Ctx::default();
    let mut seen = Seen::default();
    let processes = match p.root("telemetry", "<telemetry> as the root element") {
        None => Vec::new(),
        Some(root) => p.children(root, "process", &ctx, "<process>", |p, node| {
            let process = parse_process(p, node)?;
            let (name, line) = (&process.name, process.line);
            if seen.check(p, node, &ctx, "process name", name.clone(), line) {
                let module = names::module_name(name);
                seen.check(p, node, &ctx, "module name of process", module, line);
            }
            Some(process)
        }),
    };
    TelemetryConfig {
        file: p.file().to_owned(),
        processes,
    }
}

/// A `<process>` and its modes; `None` if its name is unusable.
fn parse_process(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>) -> Option<ProcessDef> {
    let ctx = Ctx::default();
    let name = p
        .name(node, "process", &ctx)
        .filter(|name| !p.unusable(node, &ctx, "process", name, names::snake_name_problem(name)));
    let mut mode_elements = 0;
    let mut seen = Seen::default();
    let modes = p.children(node, "mode", &ctx, "<mode>", |p, child| {
        mode_elements += 1;
        let mode = parse_mode(p, child)?;
        let (name, line) = (&mode.name, mode.line);
        if seen.check(p, child, &ctx, "mode name", name.clone(), line) {
            let constant = mode_const(name);
            seen.check(p, child, &ctx, "constant name of mode", constant, line);
        }
        Some(mode)
    });
    let name = name?;
    if mode_elements == 0 {
        p.report(
            node,
            &ctx,
            ErrorKind::Telemetry(format!("process `{name}` has no <mode>")),
        );
    }
    let (line, _) = p.line_col(node);
    Some(ProcessDef { name, line, modes })
}

/// A `<mode>` and its messages; `None` if its name is unusable.
fn parse_mode(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>) -> Option<ModeDef> {
    let ctx = Ctx::default();
    let name = p.name(node, "mode", &ctx);
    let mut seen = Seen::default();
    let messages = p.children(node, "message", &ctx, "<message>", |p, child| {
        let m = parse_message(p, child)?;
        let mctx = Ctx::message(&m.name);
        seen.check(p, child, &mctx, "message name", m.name.clone(), m.line);
        Some(m)
    });
    let (line, _) = p.line_col(node);
    Some(ModeDef {
        name: name?,
        line,
        key_press: node.attribute("key_press").map(|k| k.trim().to_owned()),
        messages,
    })
}

/// A `<message>` of a mode; `None` if its name or period is unusable.
fn parse_message(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>) -> Option<PeriodicDef> {
    let name = p.name(node, "message", &Ctx::default())?;
    let ctx = Ctx::message(&name);
    let period = p.required(node, "message", "period", &ctx).and_then(|v| {
        p.number(
            node,
            &ctx,
            "period",
            v,
            |x| x > 0.0,
            "a finite number of seconds > 0",
        )
    });
    let phase = match node.attribute("phase").map(str::trim) {
        None => None,
        Some(v) => Some(p.number(
            node,
            &ctx,
            "phase",
            v,
            |x| x >= 0.0 && period.is_none_or(|period| x < period),
            "a finite number of seconds >= 0 and less than the period",
        )?),
    };
    let (line, column) = p.line_col(node);
    Some(PeriodicDef {
        name,
        line,
        column,
        period: period?,
        phase,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(period_ticks: u32, phase: Option<u32>) -> (ScheduledMessage, bool) {
        (
            ScheduledMessage {
                name: String::new(),
                line: 0,
                class_id: 1,
                msg_id: 1,
                period_s: 0.0,
                phase_s: None,
                period_ticks,
                phase_ticks: phase.unwrap_or(0),
            },
            phase.is_some(),
        )
    }

    fn phases(ms: &[(ScheduledMessage, bool)]) -> Vec<u32> {
        ms.iter().map(|(m, _)| m.phase_ticks).collect()
    }

    #[test]
    fn rounds_to_nearest_tick() {
        assert_eq!(ticks(4.1, 60.0), 246);
        assert_eq!(ticks(0.075, 60.0), 5);
        assert_eq!(ticks(0.03, 60.0), 2);
        assert_eq!(ticks(0.02, 60.0), 1);
        assert_eq!(ticks(0.005, 60.0), 0);
        assert_eq!(ticks(1e300, 60.0), u64::MAX);
    }

    #[test]
    fn staggers_by_interval_and_separates_equal_periods() {
        // 6 messages of 30 ticks: 0, 6, 12, 18, 24, then 30 % 30 = 0 is taken -> 1.
        let mut ms: Vec<_> = (0..6).map(|_| msg(30, None)).collect();
        stagger_phases(&mut ms, 6);
        assert_eq!(phases(&ms), [0, 6, 12, 18, 24, 1]);
        // Explicit phases are kept and avoided.
        let mut ms = vec![msg(15, Some(0)), msg(15, None), msg(15, None), msg(7, None)];
        stagger_phases(&mut ms, 6);
        assert_eq!(phases(&ms), [0, 1, 6, 5]);
        // More messages than phases: balanced.
        let mut ms: Vec<_> = (0..5).map(|_| msg(2, None)).collect();
        stagger_phases(&mut ms, 6);
        assert_eq!(phases(&ms), [0, 1, 0, 1, 0]);
    }
}
