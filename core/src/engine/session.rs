//! Sequence numbers on the device side: commands are taken strictly in
//! `seq` order (go-back-N), and a retransmitted command is answered again,
//! from memory, without being applied twice.

use crate::wire::NackCode;

/// How many recent answers are remembered for retransmissions (more than
/// any sender's window).
pub const REPLAY: usize = 32;

/// Where a command's `seq` stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Standing {
    /// The next command: apply it.
    Next,
    /// Seen before: answer again as then (`None`: acknowledged).
    Seen(Option<NackCode>),
    /// Seen before, too long ago to remember the answer.
    Stale,
    /// Ahead of the next one: a command in between was lost.
    Gap,
}

/// The receiving side's sequence state.
#[derive(Debug, Clone)]
pub(crate) struct Session {
    /// The `seq` expected next: the one a `Hello` announced; `None` before
    /// any (at power-up, where the board feeds itself its boot volume: any
    /// `seq` starts the session).
    expect: Option<u16>,
    /// Answers to the last [`REPLAY`] commands, by `seq % REPLAY`.
    answers: [Option<(u16, Option<NackCode>)>; REPLAY],
    /// The last `seq` accepted (for status reports).
    last: u16,
}

impl Session {
    pub(crate) const fn new() -> Self {
        Self { expect: None, answers: [None; REPLAY], last: 0 }
    }

    /// Start afresh (after a `Hello`), expecting `first` next.
    pub(crate) fn reset(&mut self, first: u16) {
        *self = Self { expect: Some(first), ..Self::new() };
    }

    /// The `seq` expected next (0 before the first command).
    pub(crate) fn expected(&self) -> u16 {
        self.expect.unwrap_or(0)
    }

    /// The last `seq` accepted.
    pub(crate) fn last(&self) -> u16 {
        self.last
    }

    /// Where `seq` stands.
    pub(crate) fn standing(&self, seq: u16) -> Standing {
        let Some(expect) = self.expect else { return Standing::Next };
        // Serial-number arithmetic: half the space ahead, half behind.
        let ahead = seq.wrapping_sub(expect);
        if ahead == 0 {
            Standing::Next
        } else if ahead < 0x8000 {
            Standing::Gap
        } else {
            match self.answers.get(usize::from(seq) % REPLAY).copied().flatten() {
                Some((s, answer)) if s == seq => Standing::Seen(answer),
                _ => Standing::Stale,
            }
        }
    }

    /// Record the answer to the command `seq` (which stood [`Standing::Next`]).
    pub(crate) fn answered(&mut self, seq: u16, answer: Option<NackCode>) {
        self.expect = Some(seq.wrapping_add(1));
        if answer.is_none() {
            self.last = seq;
        }
        if let Some(slot) = self.answers.get_mut(usize::from(seq) % REPLAY) {
            *slot = Some((seq, answer));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strict_order_replay_and_gaps() {
        let mut s = Session::new();
        assert_eq!(s.standing(500), Standing::Next);
        s.answered(500, None);
        assert_eq!(s.standing(501), Standing::Next);
        assert_eq!(s.standing(503), Standing::Gap);
        assert_eq!(s.standing(500), Standing::Seen(None));
        s.answered(501, Some(NackCode::Invalid));
        assert_eq!(s.standing(501), Standing::Seen(Some(NackCode::Invalid)));
        assert_eq!(s.last(), 500);
        for q in 502..600 {
            s.answered(q, None);
        }
        assert_eq!(s.standing(501), Standing::Stale);
        assert_eq!(s.standing(599), Standing::Seen(None));
        s.reset(7);
        assert_eq!(s.standing(7), Standing::Next);
        assert_eq!(s.standing(8), Standing::Gap);
        assert_eq!(s.standing(6), Standing::Stale);
    }

    #[test]
    fn wraps_around() {
        let mut s = Session::new();
        s.answered(u16::MAX, None);
        assert_eq!(s.expected(), 0);
        assert_eq!(s.standing(0), Standing::Next);
        assert_eq!(s.standing(u16::MAX), Standing::Seen(None));
        assert_eq!(s.standing(1), Standing::Gap);
    }
}
