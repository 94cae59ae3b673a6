//! Property checks shared by the tests of every generated message set (the default set
//! in `pprz-default`, the full reference set in `pprz-reference-check`; both include this
//! file by path).

use pprz_messages::{DecodeError, MessageSet, dynamic};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

/// Decodes `payload` as message `(class, id)` with the generated types and re-encodes it
/// into `out`, returning the encoded length.
pub type Codec = dyn Fn(u8, u8, &[u8], &mut [u8]) -> Result<usize, DecodeError>;

/// For every message of `set`, with random field values and array lengths:
/// * a well-formed payload decodes, and re-encodes to the same bytes;
/// * the payload minus its last byte, or plus one byte, is rejected with a typed error;
/// * random bytes never panic, and decode exactly when the generic decoder accepts them
///   (and then re-encode to themselves).
pub fn check_all(set: &MessageSet<'static>, cases: u32, codec: &Codec) {
    for desc in set.messages() {
        let mut runner = TestRunner::new(Config {
            cases,
            failure_persistence: None,
            ..Config::default()
        });
        let strategy = (prop::collection::vec(any::<u8>(), 1..1500), 0usize..600);
        let result = runner.run(&strategy, |(entropy, cut)| {
            let mut i = 0usize;
            let mut next = || {
                i += 1;
                entropy[i % entropy.len()]
            };
            let mut payload = [0u8; 2048];
            let n = dynamic::synthesize(desc, &mut payload, 40, &mut next)
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            let payload = &payload[..n];
            let mut out = [0u8; 2048];
            let m = codec(desc.class_id, desc.id, payload, &mut out)
                .map_err(|e| TestCaseError::fail(format!("{}: {e}", desc.name)))?;
            prop_assert_eq!(&out[..m], payload, "{} re-encodes differently", desc.name);

            if n > 0 {
                let short = codec(desc.class_id, desc.id, &payload[..n - 1], &mut out);
                prop_assert!(
                    matches!(short, Err(DecodeError::Truncated { .. })),
                    "{}: truncated payload gave {:?}",
                    desc.name,
                    short
                );
            }
            let mut long = payload.to_vec();
            long.push(0xA5);
            let long = codec(desc.class_id, desc.id, &long, &mut out);
            prop_assert!(
                matches!(long, Err(DecodeError::TrailingBytes { .. })),
                "{}: oversized payload gave {:?}",
                desc.name,
                long
            );

            let random = &entropy[..cut.min(entropy.len())];
            let typed = codec(desc.class_id, desc.id, random, &mut out);
            let generic = dynamic::check(desc, random);
            prop_assert_eq!(
                typed.is_ok(),
                generic.is_ok(),
                "{}: typed {:?} vs generic {:?}",
                desc.name,
                typed,
                generic
            );
            if let Ok(m) = typed {
                prop_assert_eq!(&out[..m], random);
            }
            Ok(())
        });
        if let Err(e) = result {
            panic!("message {}.{}: {e}", desc.class_name, desc.name);
        }
    }
}
