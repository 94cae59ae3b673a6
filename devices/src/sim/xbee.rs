//! XBee API facts of the simulated modem.
//!
//! Frame layouts, API ids and status codes are those of [`pprz_transports::xbee`],
//! re-exported here under the modem's names; this module adds the option bits the
//! modem reads and writes and [`api_frame`] to frame `FRAME_DATA`.

use pprz_transports::xbee::{HEADER_LEN, Packet};

pub use pprz_transports::checksum::xbee as checksum;
pub use pprz_transports::xbee::status::{
    CCA_FAILURE as STATUS_CCA_FAILURE, DISCOVERY_NONE, NETWORK_ACK_FAILURE as DELIVERY_NO_ACK,
    NO_ACK as STATUS_NO_ACK, PURGED as STATUS_PURGED, RESOURCE_ERROR as DELIVERY_NO_BUFFERS,
    SUCCESS as STATUS_SUCCESS,
};
pub use pprz_transports::xbee::{
    API_RX_868, API_RX16, API_TX_868, API_TX_STATUS, API_TX_STATUS_868, API_TX16,
    BROADCAST_ADDRESS as BROADCAST_16, OVERHEAD as FRAMING, START,
};

/// Transmit option "disable ACK" (both variants).
pub const OPTION_DISABLE_ACK: u8 = 0x01;
/// Receive option "acknowledged" (868).
pub const RX_OPTION_ACKED: u8 = 0x01;
/// Receive option "broadcast" (both variants).
pub const RX_OPTION_BROADCAST: u8 = 0x02;
/// 868 broadcast address: [`BROADCAST_16`] in the low bits.
pub const BROADCAST_64: u64 = pprz_transports::xbee::address64(pprz_transports::BROADCAST_ID);

/// Writes the API frame `7E len frame_data ck` to `out`; returns its length, or
/// `None` if `out` is too short or `frame_data` longer than 65535 bytes.
pub fn api_frame(frame_data: &[u8], out: &mut [u8]) -> Option<usize> {
    let len = frame_data.len();
    u16::try_from(len).ok()?;
    let out = out.get_mut(..len + FRAMING)?;
    out[HEADER_LEN..HEADER_LEN + len].copy_from_slice(frame_data);
    Some(frame_in_place(out, len))
}

/// Frames the `len` bytes of `FRAME_DATA` at `out[HEADER_LEN..]` in place (`len`
/// at most 65535); returns the frame's length.
pub(super) fn frame_in_place(out: &mut [u8], len: usize) -> usize {
    let mut packet = Packet::new_unchecked(out);
    packet.set_start(START);
    packet.set_length(len as u16);
    packet.fill_checksum();
    len + FRAMING
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn api_frame_checksum() {
        // TX16 to 0x0100, frame id 1, no options, RF data "hi".
        let mut out = [0u8; 16];
        let n = api_frame(&[0x01, 0x01, 0x01, 0x00, 0x00, b'h', b'i'], &mut out);
        assert_eq!(n, Some(11));
        let sum: u8 = out[3..11].iter().fold(0, |a, &b| a.wrapping_add(b));
        assert_eq!(sum, 0xFF, "FRAME_DATA plus checksum sums to 0xFF");
        assert_eq!(&out[..3], &[0x7E, 0x00, 0x07]);
        assert_eq!(api_frame(&[1, 2], &mut out[..5]), None);
    }
}
