//! The keep-alive: a `C2HB` on Port 1 on its schedule, its echo on Port 2.

use std::sync::Arc;

use tokio::sync::broadcast;
use tokio::time::Instant;

use crate::event::Event;
use crate::keepalive::{KeepAlive, Verdict};
use crate::reply::Reply;

use super::*;

/// Runs the keep-alive for the life of the client.
pub(super) async fn run_keep_alive(
    inner: Arc<Inner>,
    mut schedule: KeepAlive,
    mut echoes: broadcast::Receiver<Notice>,
) {
    let mut backoff = inner.config.backoff.timer();
    let mut probed_generation = 0;
    loop {
        let wake = Instant::from_std(schedule.poll_timeout());
        tokio::select! {
            () = tokio::time::sleep_until(wake) => {}
            notice = echoes.recv() => match notice {
                Ok(notice) => take_echo(&mut schedule, &notice),
                Err(broadcast::error::RecvError::Lagged(_)) => {}
                Err(broadcast::error::RecvError::Closed) => return,
            }
        }
        if Instant::now() >= wake && !schedule.is_checking() {
            // Lock first: the check's time-out starts when Port 1 is ours, not while a
            // long transfer still holds it.
            let mut port1 = inner.port1.lock().await;
            if let Some(command) = schedule.poll_transmit(now_std()) {
                tracing::debug!(command = %command.wire(), "keep-alive");
                let answered = inner.exchange(&mut port1, &command, 1).await;
                probed_generation = port1.generation;
                match answered {
                    Ok(_) => schedule.port1_answered(),
                    // 3.5-2: A4E00 means the command was wrong but the port works.
                    Err(ClientError::Refused(refusal))
                        if refusal.reply == Reply::OPERATION_ERROR =>
                    {
                        schedule.port1_answered();
                    }
                    Err(error) => tracing::warn!(%error, "keep-alive: no answer on Port 1"),
                }
            }
        }
        loop {
            match echoes.try_recv() {
                Ok(notice) => take_echo(&mut schedule, &notice),
                Err(broadcast::error::TryRecvError::Lagged(_)) => {}
                Err(_) => break,
            }
        }
        match schedule.poll_verdict(now_std()) {
            Some(Verdict::Alive { id }) => {
                tracing::trace!(%id, "keep-alive: both ports answered");
                backoff.reset();
            }
            Some(Verdict::Dead { id, port1, port2 }) => {
                tracing::warn!(%id, port1_dead = port1, port2_dead = port2, "keep-alive failed: reconnecting");
                inner.notify(Notice::KeepAliveFailed { id, port1, port2 });
                if port2 {
                    inner.port2_dead.send_modify(|n| *n += 1);
                }
                if port1 {
                    inner.reconnect_port1(probed_generation, &mut backoff).await;
                    schedule.reset(now_std());
                }
            }
            None => {}
        }
    }
}

/// Feeds an `R1HB` to the keep-alive schedule.
pub(super) fn take_echo(schedule: &mut KeepAlive, notice: &Notice) {
    if let Notice::Event(Event::Heartbeat { id }) = notice
        && !schedule.port2_echo(id)
    {
        tracing::debug!(%id, "an R1HB that answers no open keep-alive");
    }
}
