//! Async convenience: write one whole frame to any [`embedded_io_async::Write`].

use core::fmt;

use embedded_io_async::{ErrorKind, Write};

use crate::transport::{EncodeError, Encoder, TxMeta};

/// Why [`write_frame`] failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum WriteFrameError<E> {
    /// The frame could not be encoded; nothing was written.
    Encode(EncodeError),
    /// The writer failed; part of the frame may have been written.
    Io(E),
    /// The writer accepted no byte (`Ok(0)`); part of the frame may have been written.
    WriteZero,
    /// The writer reported more bytes written than it was given (it breaks the `Write`
    /// contract); part of the frame may have been written.
    Overrun,
}

impl<E: fmt::Debug> fmt::Display for WriteFrameError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Encode(e) => write!(f, "cannot encode frame: {e}"),
            Self::Io(e) => write!(f, "write error: {e:?}"),
            Self::WriteZero => f.write_str("writer accepted no byte"),
            Self::Overrun => f.write_str("writer reported more bytes than it was given"),
        }
    }
}

impl<E: fmt::Debug> core::error::Error for WriteFrameError<E> {}

impl<E: embedded_io_async::Error> embedded_io_async::Error for WriteFrameError<E> {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Encode(_) => ErrorKind::InvalidInput,
            Self::Io(e) => e.kind(),
            Self::WriteZero => ErrorKind::WriteZero,
            Self::Overrun => ErrorKind::InvalidData,
        }
    }
}

impl<E> From<EncodeError> for WriteFrameError<E> {
    fn from(e: EncodeError) -> Self {
        Self::Encode(e)
    }
}

/// Encodes `payload` (the message fields) with `transport` into a stack buffer of
/// [`MAX_FRAME_LEN`](crate::MAX_FRAME_LEN) bytes and writes the whole frame to `w`.
/// Returns the frame length. Does not flush `w`.
///
/// ```
/// # embassy_futures::block_on(async {
/// use pprz_transports::{write_frame, MsgHeader, PprzV2, TxMeta};
/// let mut out = [0u8; 16];
/// let mut w = &mut out[..];
/// let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
/// let n = write_frame(&mut w, &PprzV2::new(), &meta, &[3, 0, 1, 2]).await.unwrap();
/// assert_eq!(&out[..n], &[0x99, 0x0C, 7, 0, 1, 2, 3, 0, 1, 2, 0x1C, 0xC4]);
/// # });
/// ```
pub async fn write_frame<W, T>(
    w: &mut W,
    transport: &T,
    meta: &TxMeta,
    payload: &[u8],
) -> Result<usize, WriteFrameError<W::Error>>
where
    W: Write + ?Sized,
    T: Encoder + ?Sized,
{
    let mut buf = [0u8; crate::MAX_FRAME_LEN];
    let len = transport.encode(meta, payload, &mut buf)?;
    let mut rest = buf.get(..len).unwrap_or_default();
    while !rest.is_empty() {
        match w.write(rest).await {
            Ok(0) => return Err(WriteFrameError::WriteZero),
            Ok(n) => rest = rest.get(n..).ok_or(WriteFrameError::Overrun)?,
            Err(e) => return Err(WriteFrameError::Io(e)),
        }
    }
    Ok(len)
}
