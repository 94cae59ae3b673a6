//! What the application's tests share: the ground's frames, the aircraft's radio output
//! and the mock clock.

use std::cell::RefCell;
use std::convert::Infallible;
use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};

use embassy_time::{Duration, Instant, MockDriver};
use pprz_default::messages::datalink::{GetSetting, Setting};
use pprz_default::messages::telemetry::DlValue;
use pprz_example_app::AC_ID;
use pprz_messages::{Decode, Message};
use pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};

/// `msg` for our aircraft, from the ground, as a PPRZ v2 frame.
pub fn uplink_frame<Msg: Message>(msg: &Msg) -> Vec<u8> {
    let mut fields = [0u8; 16];
    let n = msg.encode(&mut fields).unwrap();
    let meta = TxMeta::new(MsgHeader::new(0, AC_ID, Msg::CLASS_ID, Msg::ID));
    let mut out = [0u8; 64];
    let len = PprzV2::new().encode(&meta, &fields[..n], &mut out).unwrap();
    out[..len].to_vec()
}

/// SETTING(`index`, `value`) for our aircraft, from the ground, as a PPRZ v2 frame.
pub fn setting_frame(index: u8, value: f32) -> Vec<u8> {
    uplink_frame(&Setting {
        index,
        ac_id: AC_ID,
        value,
    })
}

/// GET_SETTING(`index`) for our aircraft, from the ground, as a PPRZ v2 frame.
#[allow(dead_code)]
pub fn get_setting_frame(index: u8) -> Vec<u8> {
    uplink_frame(&GetSetting {
        index,
        ac_id: AC_ID,
    })
}

/// The aircraft's radio output, each write with its time.
pub struct Air<'a>(pub &'a RefCell<Vec<(Instant, Vec<u8>)>>);

impl embedded_io_async::ErrorType for Air<'_> {
    type Error = Infallible;
}

impl embedded_io_async::Write for Air<'_> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.0.borrow_mut().push((Instant::now(), buf.to_vec()));
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// Polls `fut` until it ends, the mock clock advancing 1 ms whenever it is pending.
pub fn run_on_mock_clock<F: Future>(fut: F) -> F::Output {
    let mut fut = pin!(fut);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return v;
        }
        MockDriver::get().advance(Duration::from_millis(1));
    }
}

/// Every DL_VALUE in `written`: time, index, value.
pub fn dl_values(written: &[(Instant, Vec<u8>)]) -> Vec<(Instant, u8, f32)> {
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut found = Vec::new();
    for (at, bytes) in written {
        let mut input = bytes.as_slice();
        while let Some(frame) = decoder.feed(&mut input) {
            if (frame.class(), frame.msg_id()) == (DlValue::CLASS_ID, DlValue::ID) {
                let v = DlValue::decode(frame.payload()).unwrap();
                found.push((*at, v.index, v.value));
            }
        }
    }
    found
}
