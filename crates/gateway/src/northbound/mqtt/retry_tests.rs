use super::*;

#[test]
fn only_a_session_that_lasted_resets_the_wait_so_short_ones_back_off_like_failures() {
    let waited = Duration::from_secs(8);
    assert_eq!(first_wait(waited, true, STABLE_SESSION), RETRY_FIRST);
    assert_eq!(first_wait(waited, true, Duration::from_millis(400)), waited);
    assert_eq!(first_wait(waited, false, Duration::from_secs(3600)), waited);
    // Sessions taken over at once, one after the other: 0.5, 1, 2, 4 … 30 s apart.
    let mut retry = RETRY_FIRST;
    let mut waits = Vec::new();
    for _ in 0..8 {
        retry = first_wait(retry, true, Duration::from_millis(100));
        waits.push(retry.as_secs_f64());
        retry = (retry * 2).min(RETRY_CAP);
    }
    assert_eq!(waits, [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0]);
}
