//! A tour of the message layer on the host: the default message set, typed encoding,
//! and generic decoding with units — what a ground tool does with any `messages.xml`.
//!
//! Run: `cargo run -p pprz-example-std --bin tour`

use pprz_telemetry::messages::{MESSAGES, telemetry};
use pprz_telemetry::pprz_messages::{Message, MessageDescriptor, VarArray, dynamic};

/// Prints one payload decoded generically: `NAME field=value unit ...`.
fn print_decoded(desc: &MessageDescriptor<'_>, payload: &[u8]) {
    print!("  {:<18}", desc.name);
    for item in dynamic::fields(desc, payload) {
        match item {
            Ok((field, value)) => {
                print!(" {}={value}", field.name);
                if let Some(label) = value.as_i64().and_then(|i| field.label(i)) {
                    print!("({label})");
                }
                match (field.alt_unit, field.alt_unit_coef, value.as_f64()) {
                    (Some(alt), Some(_), Some(raw)) => {
                        print!(" [{:.3} {alt}]", field.to_alt_unit(raw))
                    }
                    _ => {
                        if let Some(unit) = field.unit {
                            print!(" {unit}");
                        }
                    }
                }
            }
            Err(e) => print!(" <{e}>"),
        }
    }
    println!();
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn encode_and_show<M: Message>(msg: &M) {
    let mut buf = [0u8; 256];
    match msg.encode(&mut buf) {
        Ok(n) => {
            println!(
                "{} (class {}, id {}, priority {}): {} bytes: {}",
                M::NAME,
                M::CLASS_ID,
                M::ID,
                M::PRIORITY,
                n,
                hex(&buf[..n])
            );
            print_decoded(&M::DESCRIPTOR, &buf[..n]);
        }
        Err(e) => println!("{}: cannot encode: {e}", M::NAME),
    }
}

fn main() {
    println!("Default message set: {} messages", MESSAGES.len());
    println!(
        "{:<10} {:>3}  {:<20} {:>8}  fields",
        "class", "id", "name", "priority"
    );
    for m in MESSAGES.messages() {
        println!(
            "{:<10} {:>3}  {:<20} {:>8}  {}",
            m.class_name,
            m.id,
            m.name,
            m.priority,
            m.fields.len()
        );
    }
    println!();
    encode_and_show(&telemetry::Gps {
        mode: 3,
        utm_east: 37_712_345,
        utm_north: 482_112_000,
        course: 1_234,
        alt: 152_300,
        speed: 1_250,
        climb: -15,
        week: 2_345,
        itow: 345_600_000,
        utm_zone: 31,
        gps_nb_err: 0,
    });
    encode_and_show(&telemetry::Attitude {
        phi: 0.05,
        psi: 1.57,
        theta: -0.02,
    });
    encode_and_show(&telemetry::DlValue {
        index: 4,
        value: 2.5,
    });
    encode_and_show(&telemetry::Alive {
        md5sum: VarArray::new(&[0xDE, 0xAD, 0xBE, 0xEF]),
    });
    encode_and_show(&telemetry::RotorcraftStatus {
        ap_mode: telemetry::values::RotorcraftStatusApMode::Nav.raw(),
        ap_motors_on: 1,
        vsupply: 12.4,
        ..Default::default()
    });
    println!();
    println!("A corrupt payload is an error, never a panic:");
    let gps = MESSAGES.find(1, 8).map(|d| print_decoded(d, &[1, 2, 3]));
    if gps.is_none() {
        println!("  GPS is not in the set");
    }
}
