use super::*;
use crate::Resync;

/// Frames are bytes up to `\n`; a frame starting with `!` is damaged.
#[derive(Clone)]
struct Lines;

#[derive(Debug, Clone, PartialEq, Eq)]
struct Damage;

impl Resync for Damage {
    fn drop_len(&self) -> usize {
        1
    }
}

impl Codec for Lines {
    type Frame = Vec<u8>;
    type Error = Damage;
    fn decode(&self, buf: &[u8]) -> Result<Option<(Vec<u8>, usize)>, Damage> {
        if buf.first() == Some(&b'!') {
            return Err(Damage);
        }
        Ok(crate::test_lines::decode_line(buf))
    }
    fn encode(&self, frame: &Vec<u8>, out: &mut Vec<u8>) {
        crate::test_lines::encode_line(frame, out);
    }
}

/// `ok…` answers, `no…` refuses, `noise…` is dropped as noise, anything else is
/// another device's frame, damage retries when the line falls quiet.
struct Asking;

impl Matcher for Asking {
    type Codec = Lines;
    type Answer = Vec<u8>;
    type Refusal = Vec<u8>;
    type Mismatch = String;

    fn judge(&mut self, input: Result<Vec<u8>, Damage>) -> VerdictOf<Self> {
        match input {
            Ok(frame) if frame.starts_with(b"ok") => Verdict::Answer(frame),
            Ok(frame) if frame.starts_with(b"noise") => Verdict::Noise,
            Ok(frame) if frame.starts_with(b"no") => Verdict::Refused(frame),
            Ok(_) => Verdict::Skip,
            Err(e) => Verdict::RetryWhenQuiet(Trouble::Damaged(e)),
        }
    }

    fn device(&self) -> String {
        "device 1".to_owned()
    }
}

const TIMEOUT: Duration = Duration::from_millis(100);

fn exchange(retries: u8) -> Exchange<Asking> {
    Exchange::new(
        Asking,
        Lines,
        b"ask\n".to_vec(),
        Policy::new(retries, TIMEOUT).with_quiet_gap(Duration::from_millis(5)),
    )
}

/// The outcome of an exchange that gave up after `attempts` of [`TIMEOUT`].
fn gave_up(attempts: u8, last: Trouble<Damage, String>) -> Option<Outcome<Asking>> {
    Some(Err(Ended::GaveUp {
        attempts,
        timeout: TIMEOUT,
        last,
    }))
}

/// Sends the next attempt at `now`; its bytes.
fn send(ex: &mut Exchange<Asking>, now: Instant) -> Vec<u8> {
    let bytes = ex.poll_transmit().expect("an attempt is due");
    ex.handle_sent(now);
    bytes
}

#[test]
fn an_answer_ends_the_exchange_and_other_frames_are_skipped() {
    let mut ex = exchange(2);
    let t0 = Instant::now();
    assert_eq!(send(&mut ex, t0), b"ask\n");
    ex.handle_input(b"other device\nok 42\n", t0 + Duration::from_millis(3));
    assert_eq!(ex.poll_outcome(), Some(Ok(b"ok 42".to_vec())));
    assert_eq!(ex.attempts(), 1);
}

#[test]
fn silence_is_retried_after_the_timeout_until_the_attempts_run_out() {
    let mut ex = exchange(1);
    let t0 = Instant::now();
    send(&mut ex, t0);
    assert_eq!(ex.poll_timeout(), Some(t0 + TIMEOUT));
    ex.handle_timeout(t0 + TIMEOUT / 2);
    assert!(ex.poll_outcome().is_none(), "an early call does nothing");
    ex.handle_timeout(t0 + TIMEOUT);
    let t1 = t0 + TIMEOUT;
    send(&mut ex, t1);
    ex.handle_timeout(t1 + TIMEOUT);
    assert_eq!(ex.poll_outcome(), gave_up(2, Trouble::Silence));
    assert!(ex.poll_transmit().is_none(), "no third attempt");
}

#[test]
fn a_refusal_is_the_device_answering_and_is_never_retried() {
    let mut ex = exchange(5);
    let t0 = Instant::now();
    send(&mut ex, t0);
    ex.handle_input(b"no such thing\n", t0);
    assert_eq!(
        ex.poll_outcome(),
        Some(Err(Ended::Refused(b"no such thing".to_vec())))
    );
    assert_eq!(ex.attempts(), 1);
}

#[test]
fn damage_ends_the_attempt_when_the_line_falls_quiet_not_at_the_timeout() {
    let mut ex = exchange(1);
    let t0 = Instant::now();
    send(&mut ex, t0);
    ex.handle_input(b"!garbled", t0 + Duration::from_millis(2));
    let quiet = t0 + Duration::from_millis(7);
    assert_eq!(ex.poll_timeout(), Some(quiet));
    ex.handle_timeout(quiet);
    assert!(ex.poll_outcome().is_none());
    // The second attempt starts at once, long before the first one's timeout.
    send(&mut ex, quiet);
    ex.handle_input(b"ok\n", quiet + Duration::from_millis(1));
    assert_eq!(ex.poll_outcome(), Some(Ok(b"ok".to_vec())));
    assert_eq!(ex.attempts(), 2);
}

#[test]
fn input_that_keeps_coming_ends_the_attempt_at_its_deadline() {
    let mut ex = exchange(1);
    let t0 = Instant::now();
    send(&mut ex, t0);
    ex.handle_input(b"other device\n", t0 + TIMEOUT / 2);
    assert!(
        ex.is_waiting(),
        "before the deadline the answer may still come"
    );
    // A caller whose reads never wait (a line that never stops talking) never calls
    // handle_timeout: the input itself ends the attempt.
    ex.handle_input(b"other device\n", t0 + TIMEOUT);
    assert!(!ex.is_waiting());
    let t1 = t0 + TIMEOUT;
    send(&mut ex, t1);
    ex.handle_input(b"other device\n", t1 + TIMEOUT + Duration::from_millis(3));
    assert_eq!(
        ex.poll_outcome(),
        gave_up(
            2,
            Trouble::Others {
                frames: 1,
                from: None
            }
        )
    );
}

#[test]
fn an_answer_in_the_input_that_crosses_the_deadline_still_counts() {
    let mut ex = exchange(0);
    let t0 = Instant::now();
    send(&mut ex, t0);
    ex.handle_input(b"ok late\n", t0 + TIMEOUT + Duration::from_millis(1));
    assert_eq!(ex.poll_outcome(), Some(Ok(b"ok late".to_vec())));
}

/// What a one-attempt exchange that got `input` and then no answer says went wrong.
fn trouble_after_a_timeout(input: &[u8]) -> Trouble<Damage, String> {
    let mut ex = exchange(0);
    let t0 = Instant::now();
    send(&mut ex, t0);
    ex.handle_input(input, t0 + Duration::from_millis(1));
    ex.handle_timeout(t0 + TIMEOUT);
    let Some(Err(Ended::GaveUp { last, .. })) = ex.poll_outcome() else {
        panic!("the attempt should have timed out");
    };
    last
}

#[test]
fn a_timeout_after_line_noise_says_how_many_bytes_of_noise_came() {
    assert_eq!(
        trouble_after_a_timeout(b"noise noise\nnoise\n"),
        Trouble::Noise { bytes: 18 }
    );
    let words = |bytes| Trouble::<String, String>::Noise { bytes }.to_string();
    assert_eq!(words(18), "no reply, only 18 bytes of line noise");
    assert_eq!(words(1), "no reply, only 1 byte of line noise");
}

#[test]
fn a_timeout_after_frames_for_something_else_says_how_many_came() {
    assert_eq!(
        trouble_after_a_timeout(b"other\nnoise\nother\n"),
        Trouble::Others {
            frames: 2,
            from: None
        }
    );
    let words = |frames| Trouble::<String, String>::Others { frames, from: None }.to_string();
    assert_eq!(
        words(2),
        "no reply, only 2 frames that answer something else"
    );
    assert_eq!(
        words(1),
        "no reply, only a frame that answers something else"
    );
}

#[test]
fn a_timeout_beyond_the_clock_waits_the_longest_wait_instead_of_overflowing() {
    let mut ex = Exchange::new(
        Asking,
        Lines,
        b"ask\n".to_vec(),
        Policy::new(0, Duration::MAX).with_quiet_gap(Duration::MAX),
    );
    let t0 = Instant::now();
    send(&mut ex, t0);
    assert_eq!(ex.poll_timeout(), Some(t0 + LONGEST_WAIT));
    ex.handle_input(b"!garbled", t0);
    assert_eq!(ex.poll_timeout(), Some(t0 + LONGEST_WAIT));
    ex.handle_timeout(t0 + LONGEST_WAIT);
    assert!(!ex.is_waiting());
}
