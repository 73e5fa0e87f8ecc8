//! What the history benches start from: a store in a temporary directory, a runtime to
//! wait on its flushes, and point ids to write to.

use gateway::point::PointId;
use gateway::store::{Store, StoreOptions};
use tempfile::TempDir;
use tokio::runtime::Runtime;

/// A store opened with `options` in a fresh temporary directory (removed when dropped),
/// and a current-thread runtime to block on its flushes.
pub fn temp_store(options: StoreOptions) -> (TempDir, Store, Runtime) {
    let dir = tempfile::tempdir().expect("temp dir");
    let store = Store::open(dir.path(), options).expect("store");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .build()
        .expect("runtime");
    (dir, store, runtime)
}

/// `n` point ids, twenty to a device: `dev0.point0` to `dev0.point19`, `dev1.point0`, …
pub fn device_points(n: usize) -> Vec<PointId> {
    (0..n)
        .map(|i| PointId::parse(&format!("dev{}.point{}", i / 20, i % 20)).expect("valid id"))
        .collect()
}
