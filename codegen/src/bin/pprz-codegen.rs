//! `pprz-codegen`: generate Rust message types from a Paparazzi `messages.xml`, or check
//! and list one.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use pprz_codegen::Generator;

/// Generate Rust message types from a Paparazzi messages.xml.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// The messages.xml to read.
    messages: PathBuf,
    /// Only these classes (name or id); repeatable.
    #[arg(long = "class", value_name = "CLASS")]
    classes: Vec<String>,
    /// Only these messages (NAME or class.NAME); repeatable.
    #[arg(long = "message", value_name = "NAME")]
    messages_sel: Vec<String>,
    /// A units.xml giving default alt_unit coefficients.
    #[arg(long)]
    units: Option<PathBuf>,
    /// Path of the pprz-messages crate in the generated code.
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
    /// Only validate; list every selected message (class, id, name, priority, size).
    #[arg(long)]
    list: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let mut generator = Generator::new(&args.messages)
        .classes(args.classes)
        .messages(args.messages_sel)
        .runtime_crate(args.runtime_crate)
        .default_priority(args.default_priority);
    if let Some(units) = args.units {
        generator = generator.units(units);
    }
    let result = if args.check || args.list {
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
                            c.name,
                            m.id,
                            m.name,
                            m.priority.unwrap_or(args.default_priority)
                        );
                    }
                }
            }
            println!(
                "{}: {} classes, {} messages: ok",
                args.messages.display(),
                p.classes.len(),
                p.message_count()
            );
        })
    } else if let Some(out) = &args.output {
        generator.write_to(out)
    } else {
        generator.generate().map(|code| print!("{code}"))
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
