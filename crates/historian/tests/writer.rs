//! The writer task against a real PostgreSQL (testkit's throwaway cluster).

use std::sync::Arc;
use std::time::{Duration, SystemTime};

use historian::metrics::{Health, Metrics};
use historian::writer::{DbState, Limits, Writer};
use historian::{Batch, Quality, SampleRow};
use testkit::Postgres;
use tokio::sync::{mpsc, watch};
use tokio_postgres::NoTls;

/// Generous: a loaded 2-core machine.
const LIMIT: Duration = Duration::from_secs(60);

fn samples(n: usize) -> Batch {
    let now = SystemTime::now();
    Batch {
        samples: (0..n)
            .map(|i| SampleRow {
                group: "plant".into(),
                node: "cell1".into(),
                device: "jbc1".into(),
                point: format!("p{i}"),
                t: now,
                value: Some(i as f64),
                text: None,
                quality: Quality::Good,
            })
            .collect(),
        ..Batch::default()
    }
}

async fn wait_for(
    state: &mut watch::Receiver<DbState>,
    what: &str,
    f: impl FnMut(&DbState) -> bool,
) -> DbState {
    let found = tokio::time::timeout(LIMIT, state.wait_for(f))
        .await
        .map(|r| r.expect("the writer runs").clone());
    found.unwrap_or_else(|_| panic!("{what} within {LIMIT:?}: {:?}", *state.borrow()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_commit_that_hangs_takes_the_historian_offline_until_it_ends_and_loses_nothing() {
    let pg = Postgres::start();
    let url = pg.create_database("plant");
    let (rows, rx) = mpsc::channel(16);
    let (state_tx, mut state) = watch::channel(DbState::Failing("not connected yet".into()));
    let health = Arc::new(Health::new());
    let limits = Limits {
        slow_commit: Duration::from_secs(1),
        ..Limits::default()
    };
    let writer = Writer::new(
        url.clone(),
        rx,
        state_tx,
        Arc::clone(&health),
        Arc::new(Metrics::new()),
        limits,
    );
    let task = tokio::spawn(writer.run());
    wait_for(&mut state, "connected", |s| *s == DbState::Ok).await;
    rows.send(samples(10)).await.unwrap();
    let deadline = tokio::time::Instant::now() + LIMIT;
    while pg.psql("plant", "SELECT count(*) FROM samples").trim() != "10" {
        assert!(tokio::time::Instant::now() < deadline, "the first rows");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    // Another session holds every lock on samples, as a long maintenance job would.
    let (mut locker, connection) = tokio_postgres::connect(&url, NoTls).await.unwrap();
    tokio::spawn(connection);
    let lock = locker.transaction().await.unwrap();
    lock.batch_execute("LOCK TABLE samples IN ACCESS EXCLUSIVE MODE")
        .await
        .unwrap();
    rows.send(samples(20)).await.unwrap();
    let failing = wait_for(&mut state, "offline while the commit hangs", |s| {
        *s != DbState::Ok
    })
    .await;
    let DbState::Failing(why) = failing else {
        unreachable!()
    };
    assert!(why.contains("a commit has taken more than 1s"), "{why}");
    assert_eq!(health.database().as_deref(), Some(why.as_str()));

    // The lock goes: the commit ends, the historian is back, nothing was lost.
    lock.rollback().await.unwrap();
    wait_for(&mut state, "online once the commit ended", |s| {
        *s == DbState::Ok
    })
    .await;
    assert_eq!(health.database(), None);
    assert_eq!(
        pg.psql("plant", "SELECT count(*) FROM samples").trim(),
        "30",
        "the first 10 rows and the 20 that waited for the lock"
    );
    drop(rows);
    tokio::time::timeout(LIMIT, task)
        .await
        .expect("the writer ends when its channel closes")
        .unwrap()
        .unwrap();
}
