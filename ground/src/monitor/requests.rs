//! Request tracking: the PINGs, SETTINGs and GET_SETTINGs the ground sent, to an
//! aircraft or to none in particular, and the PONGs and DL_VALUEs that answer them.

use pprz_messages::BaseType;

use super::decode::scalar_type;
use super::{Event, Monitor, Notice};
use crate::ping::PingTracker;
use crate::settings::{Answer, SettingTracker};

impl Monitor {
    /// Records that a PING was sent at `now`, to aircraft `dest` (its v2 destination) or
    /// to no particular aircraft (`None`, the single-aircraft form). PONGs answer the
    /// PINGs outstanding in order, oldest first.
    ///
    /// A PING to aircraft N is answered only by a PONG whose source is N; the aircraft
    /// is tracked from now on, whatever [`MAX_AIRCRAFT`](super::MAX_AIRCRAFT) says, its statistics are in
    /// [`aircraft_state`](Self::aircraft_state), and the [`Event::Pong`] it produces is
    /// tagged with N in [`events_with_aircraft`](Self::events_with_aircraft). A PING to
    /// no particular aircraft is answered by a PONG from any aircraft that has no PING
    /// of its own outstanding; its statistics are [`pings`](Self::pings).
    ///
    /// ```
    /// # use pprz_ground::{monitor::Monitor, set::RuntimeSet};
    /// # use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};
    /// # let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="telemetry" id="1">
    /// #     <message name="PONG" id="3"/></msg_class></protocol>"#).unwrap();
    /// let mut monitor = Monitor::new(set, PprzV2::new().into());
    /// monitor.ping_sent(Some(7), 1.0);
    /// monitor.ping_sent(Some(8), 1.0);
    /// // A PONG from aircraft 8 to the ground (source 8, destination 0).
    /// let mut pong = [0u8; 16];
    /// let n = PprzV2::new().encode(&TxMeta::new(MsgHeader::new(8, 0, 1, 3)), &[], &mut pong).unwrap();
    /// monitor.feed(1.25, &pong[..n], |_| {});
    /// let (a7, a8) = (monitor.aircraft_state(7).unwrap(), monitor.aircraft_state(8).unwrap());
    /// assert_eq!(a8.last_rtt(), Some(0.25));
    /// assert_eq!(a7.last_rtt(), None);
    /// assert_eq!(a7.pings().outstanding(), 1);
    /// assert_eq!(monitor.aircraft(), [7, 8]);
    /// ```
    pub fn ping_sent(&mut self, dest: Option<u8>, now: f64) {
        let lost = match dest {
            Some(ac_id) => self.addressed(ac_id).pings.sent(now),
            None => self.pings.sent(now),
        };
        if lost > 0 {
            self.notice(now, dest, Notice::PingsLost { count: lost });
        }
    }

    /// Records that a SETTING of `index` to `value` was sent at `now`, to aircraft `dest`
    /// or to no particular aircraft (`None`, the single-aircraft form).
    ///
    /// Only a DL_VALUE carrying that value (compared as the type of the `value` fields
    /// of SETTING and DL_VALUE) acknowledges it; another value is reported as not
    /// applied. A SETTING to aircraft N is answered only by a DL_VALUE whose source is N,
    /// and N is tracked from now on. A SETTING to no particular aircraft is answered by
    /// a DL_VALUE from any aircraft that has no request of its own pending on `index`.
    pub fn setting_sent(&mut self, dest: Option<u8>, now: f64, index: u8, value: f64) {
        let base = self.setting_type();
        self.setting_tracker(dest)
            .setting_sent(now, index, value, base);
    }

    /// Records that a GET_SETTING of `index` was sent at `now`, to aircraft `dest` or to
    /// no particular aircraft (`None`): the next DL_VALUE of that index (from `dest`,
    /// when given) answers it. An aircraft `dest` is tracked from now on.
    pub fn get_setting_sent(&mut self, dest: Option<u8>, now: f64, index: u8) {
        self.setting_tracker(dest).get_setting_sent(now, index);
    }

    /// The request tracker of the requests to `dest`, or to no particular aircraft.
    fn setting_tracker(&mut self, dest: Option<u8>) -> &mut SettingTracker {
        match dest {
            Some(ac_id) => &mut self.addressed(ac_id).settings,
            None => &mut self.settings,
        }
    }

    /// The type of the `value` field of SETTING in the set (`float` without one).
    fn setting_type(&self) -> BaseType {
        scalar_type(self.set.find_by_name("datalink", "SETTING"), "value").unwrap_or(BaseType::F32)
    }

    /// A PONG from `source` at `now`: it answers the oldest PING outstanding to
    /// `source`, else the oldest one sent to no particular aircraft. A replay
    /// ([`replaying`](Self::replaying)) sent no PING: the PONG is only a message.
    pub(super) fn pong(&mut self, now: f64, source: u8) {
        if self.replay {
            return;
        }
        self.expire_pings(now, Some(source));
        self.expire_pings(now, None);
        let rtt = match self.aircraft.get_mut(&source) {
            Some(a) if a.pings.outstanding() > 0 => a.pings.pong(now),
            _ if self.pings.outstanding() > 0 => self.pings.pong(now),
            // Unexpected: counted by the aircraft if PINGs were sent to it.
            Some(a) if a.pings.sent_count() > 0 => a.pings.pong(now),
            _ => self.pings.pong(now),
        };
        match rtt {
            Some(rtt) => {
                if let Some(a) = self.aircraft.get_mut(&source) {
                    a.last_rtt = Some(rtt);
                }
                self.last_rtt = Some(rtt);
                self.event(now, Some(source), Event::Pong { rtt });
            }
            None => self.notice(now, Some(source), Notice::UnexpectedPong),
        }
    }

    /// A DL_VALUE from `source` at `now`: it answers the request pending on `index` for
    /// `source`, else the one sent to no particular aircraft; it is the latest value of
    /// the setting for a tracked `source`, and reads it for its sweep.
    pub(super) fn dl_value(&mut self, now: f64, source: u8, index: u8, value: f64, base: BaseType) {
        let mut ended = false;
        let answer = match self.aircraft.get_mut(&source) {
            Some(a) => {
                a.values.insert(index, value);
                if let Some(sweep) = a.sweep.as_mut() {
                    ended = sweep.answered(now, index) && sweep.done();
                }
                a.settings.dl_value(now, index, value, base)
            }
            None => Answer::Unsolicited,
        };
        let answer = match answer {
            Answer::Unsolicited => self.settings.dl_value(now, index, value, base),
            answer => answer,
        };
        let event = Event::DlValue {
            index,
            value,
            answer,
        };
        self.event(now, Some(source), event);
        if ended {
            self.sweep_ended(now, source);
        }
    }

    /// Counts as lost the PINGs to `aircraft` (or to none) older than their timeout at
    /// `now`, and notes it.
    fn expire_pings(&mut self, now: f64, aircraft: Option<u8>) {
        let lost = match aircraft {
            Some(id) => self
                .aircraft
                .get_mut(&id)
                .map_or(0, |a| a.pings.expire(now)),
            None => self.pings.expire(now),
        };
        if lost > 0 {
            self.notice(now, aircraft, Notice::PingsLost { count: lost });
        }
    }

    /// Notes the aircraft that go stale at `now` ([`Notice::LinkStale`]), and gives up
    /// the PINGs and requests older than their timeouts (counted lost, noted for the
    /// live view), of every aircraft. Call it regularly, whether frames arrive or not;
    /// the other methods taking `now` do it too where it matters.
    pub fn tick(&mut self, now: f64) {
        self.advance(now);
        self.check_links(now);
        self.expire_pings(now, None);
        for e in self.settings.expire(now) {
            self.notice(now, None, Notice::RequestExpired(e));
        }
        let ids: Vec<u8> = self.aircraft.keys().copied().collect();
        for id in ids {
            self.expire_pings(now, Some(id));
            if let Some(a) = self.aircraft.get_mut(&id) {
                for e in a.settings.expire(now) {
                    self.notice(now, Some(id), Notice::RequestExpired(e));
                }
            }
        }
    }

    /// The last round-trip time measured, of any PING and any aircraft.
    pub fn last_rtt(&self) -> Option<f64> {
        self.last_rtt
    }

    /// The PINGs to no particular aircraft and their statistics; those sent to an
    /// aircraft are in its [`aircraft_state`](Self::aircraft_state).
    pub fn pings(&self) -> &PingTracker {
        &self.pings
    }

    /// The SETTING and GET_SETTING requests to no particular aircraft and their
    /// statistics; those sent to an aircraft are in its
    /// [`aircraft_state`](Self::aircraft_state).
    pub fn settings(&self) -> &SettingTracker {
        &self.settings
    }
}
