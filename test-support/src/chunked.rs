//! Feeding a decoder its input in chunks of chosen sizes: the one harness of the
//! decoder tests and fuzz targets.
//!
//! A test wraps its decoder in a type that implements [`ChunkFeed`] (what to do with
//! each frame, after each chunk, at the end of the stream), then calls
//! [`feed_in_chunks`]. The harness cuts the stream, feeds each chunk until the decoder
//! has used it up (checking that `feed` returns nothing only then), and flushes.
//!
//! ```
//! use pprz_test_support::chunked::{ChunkFeed, cycled, feed_in_chunks};
//!
//! /// A "decoder" whose frames are the runs of bytes ended by 0xFF.
//! #[derive(Default)]
//! struct Lines { buf: Vec<u8>, frames: Vec<Vec<u8>>, chunks: usize }
//!
//! impl ChunkFeed for Lines {
//!     fn feed(&mut self, input: &mut &[u8]) -> bool {
//!         while let Some((&b, rest)) = input.split_first() {
//!             *input = rest;
//!             if b == 0xFF {
//!                 self.frames.push(std::mem::take(&mut self.buf));
//!                 return true;
//!             }
//!             self.buf.push(b);
//!         }
//!         false
//!     }
//!     fn chunk_done(&mut self) {
//!         self.chunks += 1;
//!     }
//!     fn flush(&mut self) -> bool {
//!         false
//!     }
//! }
//!
//! let mut run = Lines::default();
//! feed_in_chunks(&mut run, &[1, 2, 0xFF, 3, 0xFF], cycled(&[2, 0]));
//! assert_eq!(run.frames, [vec![1, 2], vec![3]]);
//! assert_eq!(run.chunks, 3); // sizes 2, 1 (0 counts as 1), then 2
//! ```

/// A decoder under test, with what the test does with its output.
pub trait ChunkFeed {
    /// Feeds the decoder from `input` (advancing it past the bytes used) until one
    /// frame comes out or `input` is used up; handles that frame. Returns whether a
    /// frame came out: the harness calls it again on the same chunk until it returns
    /// `false`, which must mean the chunk is used up.
    fn feed(&mut self, input: &mut &[u8]) -> bool;

    /// Called after each chunk has been used up.
    fn chunk_done(&mut self) {}

    /// Takes and handles the next frame left in the decoder at the end of the stream;
    /// returns whether there was one.
    fn flush(&mut self) -> bool;
}

/// Feeds `stream` to `run` in chunks whose sizes come from `sizes` (0 counts as 1; a
/// size beyond the end of the stream takes the rest; when `sizes` ends, the rest is
/// one chunk), then flushes it until it returns no frame.
///
/// # Panics
/// If [`ChunkFeed::feed`] returns `false` with bytes of its chunk left.
#[track_caller]
pub fn feed_in_chunks<R: ChunkFeed + ?Sized>(
    run: &mut R,
    stream: &[u8],
    sizes: impl IntoIterator<Item = usize>,
) {
    let mut sizes = sizes.into_iter();
    let mut rest = stream;
    while !rest.is_empty() {
        let size = sizes.next().unwrap_or(rest.len()).max(1);
        let (chunk, tail) = rest.split_at(size.min(rest.len()));
        rest = tail;
        let mut input = chunk;
        while run.feed(&mut input) {}
        assert!(
            input.is_empty(),
            "feed returned no frame with {} bytes of its chunk left",
            input.len()
        );
        run.chunk_done();
    }
    while run.flush() {}
}

/// The chunk sizes `sizes`, repeated without end (a single chunk of the whole stream if
/// `sizes` is empty).
pub fn cycled(sizes: &[usize]) -> impl Iterator<Item = usize> + '_ {
    let whole: &[usize] = &[usize::MAX];
    let sizes = if sizes.is_empty() { whole } else { sizes };
    sizes.iter().copied().cycle()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records the chunks it is given and hands out each byte as a frame when `eager`.
    struct Recorder {
        chunks: Vec<Vec<u8>>,
        eager: bool,
        flushes: usize,
    }

    impl ChunkFeed for Recorder {
        fn feed(&mut self, input: &mut &[u8]) -> bool {
            if input.is_empty() {
                return false;
            }
            if self.eager {
                self.chunks.push(input[..1].to_vec());
                *input = &input[1..];
                return true;
            }
            self.chunks.push(input.to_vec());
            *input = &[];
            false
        }

        fn flush(&mut self) -> bool {
            self.flushes += 1;
            self.flushes < 3
        }
    }

    fn chunks(stream: &[u8], sizes: impl IntoIterator<Item = usize>) -> Vec<Vec<u8>> {
        let mut r = Recorder {
            chunks: Vec::new(),
            eager: false,
            flushes: 0,
        };
        feed_in_chunks(&mut r, stream, sizes);
        assert_eq!(r.flushes, 3, "flushes until no frame");
        r.chunks
    }

    #[test]
    fn sizes_cycle_zero_counts_as_one_and_the_rest_is_one_chunk() {
        let s = [1, 2, 3, 4, 5, 6, 7];
        assert_eq!(
            chunks(&s, cycled(&[2, 0])),
            [&s[..2], &s[2..3], &s[3..5], &s[5..6], &s[6..]]
        );
        assert_eq!(chunks(&s, [3]), [&s[..3], &s[3..]]);
        assert_eq!(chunks(&s, cycled(&[])), [&s[..]]);
        assert_eq!(chunks(&s, cycled(&[100])), [&s[..]]);
        assert!(chunks(&[], cycled(&[1])).is_empty());
    }

    #[test]
    fn feeds_each_chunk_until_no_frame() {
        let mut r = Recorder {
            chunks: Vec::new(),
            eager: true,
            flushes: 0,
        };
        feed_in_chunks(&mut r, &[1, 2, 3], cycled(&[2]));
        assert_eq!(r.chunks, [[1], [2], [3]]);
    }

    #[test]
    #[should_panic(expected = "feed returned no frame with 2 bytes of its chunk left")]
    fn a_chunk_left_unused_fails() {
        struct Lazy;
        impl ChunkFeed for Lazy {
            fn feed(&mut self, _: &mut &[u8]) -> bool {
                false
            }
            fn flush(&mut self) -> bool {
                false
            }
        }
        feed_in_chunks(&mut Lazy, &[1, 2], [5]);
    }
}
