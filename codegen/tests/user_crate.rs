//! Generated code included in a user's binary crate that uses only some of its messages
//! compiles without a warning: the crate denies warnings, and a message set, a class, a
//! `values` enum or a schedule it leaves unused is no `dead_code`.

mod scratch;

use std::path::{Path, PathBuf};

use pprz_codegen::Generator;
use scratch::ScratchCrate;

fn repo_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(name)
}

/// A firmware-like binary: it sends one message of the default set and uses nothing else
/// of it, of the small fixture set, or of the default schedule.
const MAIN: &str = r#"#![deny(warnings)]

mod messages {
    include!("messages.rs");
}

mod small {
    include!("small.rs");
}

mod periodic {
    include!("periodic.rs");
}

fn main() {
    use pprz_messages::Message;
    let mut buf = [0u8; 4];
    let n = messages::telemetry::Pong.encode(&mut buf).unwrap();
    assert_eq!(n, 0);
}
"#;

#[test]
fn generated_code_in_a_binary_using_some_messages_has_no_warning() {
    let generator = Generator::new(repo_file("messages.xml"));
    let messages = generator.generate().unwrap();
    let periodic = generator
        .clone()
        .telemetry(repo_file("telemetry.xml"))
        .generate_telemetry()
        .unwrap()
        .code;
    let small = Generator::new(repo_file("codegen/tests/fixtures/small.xml"))
        .generate()
        .unwrap();
    let result = ScratchCrate::new("user-binary")
        .write("messages.rs", &messages)
        .write("small.rs", &small)
        .write("periodic.rs", &periodic)
        .write("main.rs", MAIN)
        .check();
    if let Err(stderr) = result {
        panic!("the generated code gives warnings in a binary crate:\n{stderr}");
    }
}

/// A class without messages is legal in a messages.xml: its uninhabited `AnyMessage` still
/// compiles, with no warning, beside a class that has messages.
#[test]
fn a_class_without_messages_compiles_without_warning() {
    let code = Generator::new(repo_file("codegen/tests/fixtures/empty_class.xml"))
        .generate()
        .unwrap();
    let main = r#"#![deny(warnings)]

mod messages {
    include!("messages.rs");
}

fn main() {
    use pprz_messages::Message;
    let mut buf = [0u8; 4];
    assert_eq!(messages::telemetry::Pong.encode(&mut buf).unwrap(), 0);
    assert!(messages::datalink::AnyMessage::decode(1, &[]).is_err());
}
"#;
    let result = ScratchCrate::new("empty-class")
        .write("messages.rs", &code)
        .write("main.rs", main)
        .check();
    if let Err(stderr) = result {
        panic!("a class without messages does not compile warning-free:\n{stderr}");
    }
}
