//! Workloads 1 and 2: encoding a fixed message sequence into a PPRZ v2 byte stream, and
//! parsing that stream back. The inputs and the measured loops are in
//! [`pprz_bench_common::stream`] (`no_std`, shared with the Cortex-M4 firmware of
//! `bench/m4`), re-exported here with [`make_stream`].

pub use pprz_bench_common::stream::*;

/// The stream of [`encode_stream`] for `count` messages, in a new vector.
///
/// # Panics
/// Never: the vector is sized with [`stream_len`].
pub fn make_stream(count: usize) -> Vec<u8> {
    let mut out = vec![0; stream_len(count)];
    let len = encode_stream(count, &mut out).expect("stream_len fits the stream");
    out.truncate(len);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use pprz_default::messages::telemetry::{Attitude, Gps};
    use pprz_messages::Message;

    #[test]
    fn frame_lengths_match_the_message_sizes() {
        assert_eq!(GPS_FRAME_LEN, Gps::MAX_LEN + 8);
        assert_eq!(ATTITUDE_FRAME_LEN, Attitude::MAX_LEN + 8);
        assert_eq!(stream_len(3), 2 * GPS_FRAME_LEN + ATTITUDE_FRAME_LEN);
    }

    #[test]
    fn both_parse_paths_give_the_expected_summary() {
        let count = 101;
        let bytes = make_stream(count);
        assert_eq!(parse_stream(&bytes), expected_summary(count));
        assert_eq!(parse_stream_buffered(&bytes), expected_summary(count));
        // Noise before the frames and a frame cut at the end: the same frames both ways.
        let mut noisy = vec![0x99, 0x03, 0x42];
        noisy.extend_from_slice(&bytes[..bytes.len() - 1]);
        let (a, b) = (parse_stream(&noisy), parse_stream_buffered(&noisy));
        assert_eq!(a, b);
        assert_eq!(a.frames as usize, count - 1);
    }

    #[test]
    fn short_buffer_is_an_error_not_a_panic() {
        let mut out = [0u8; 50];
        assert!(encode_stream(2, &mut out).is_err());
    }
}
