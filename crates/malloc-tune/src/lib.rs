//! Safe calls to glibc's malloc tuning, for a long-running process with a few threads (the
//! gateway, `cellbus serve`).
//!
//! glibc gives each thread that allocates while another holds the lock an arena of its
//! own, up to eight per core; each keeps its own free memory, so a process whose threads
//! take turns building and freeing (a poller, a history writer, the runtime's workers)
//! holds several partly empty heaps. [`set_arena_max`] limits them;
//! [`set_mmap_threshold`] keeps large blocks out of the heap.
//!
//! Elsewhere than glibc on Linux (musl, macOS) the calls do nothing and say so.
//!
//! The workspace forbids `unsafe`; this crate denies it and allows it only for these two
//! FFI calls, each with the reason it is sound.

/// Limits the number of malloc arenas to `arenas` (glibc's `M_ARENA_MAX`); `false` when
/// malloc refused it or this is not glibc.
///
/// Call it before the process starts threads: a thread keeps the arena it was given.
pub fn set_arena_max(arenas: u16) -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt takes two integers, reads no memory of ours and is thread-safe
        // (it takes the arena locks); M_ARENA_MAX with any positive value is documented.
        #[allow(unsafe_code)]
        let done = unsafe { libc::mallopt(libc::M_ARENA_MAX, i32::from(arenas.max(1))) };
        done == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        let _ = arenas;
        false
    }
}

/// Serves every block of `bytes` or more with its own `mmap`, returned to the kernel when
/// freed (glibc's `M_MMAP_THRESHOLD`); `false` when malloc refused it, `bytes` is beyond
/// a C `int`, or this is not glibc.
///
/// Setting it also turns off glibc's moving threshold, which otherwise rises to the size of
/// each large block freed, so that later large blocks (a growing vector, a hash table's
/// next size) come from the heap and leave holes in it when they move on.
pub fn set_mmap_threshold(bytes: u32) -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let Ok(bytes) = i32::try_from(bytes) else {
            return false;
        };
        // SAFETY: as in `set_arena_max`: two integers, no memory of ours; glibc checks the
        // value against its maximum.
        #[allow(unsafe_code)]
        let done = unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, bytes) };
        done == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        let _ = bytes;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_accepts_an_arena_limit() {
        assert!(set_arena_max(1), "mallopt(M_ARENA_MAX, 1) refused");
        assert!(set_arena_max(0), "0 is taken as 1, which glibc accepts");
    }

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_takes_an_mmap_threshold_that_fits_an_int() {
        assert!(
            set_mmap_threshold(128 << 10),
            "mallopt(M_MMAP_THRESHOLD, 128 KiB) refused"
        );
        assert!(!set_mmap_threshold(u32::MAX), "not an int");
        let block = vec![7u8; 256 << 10];
        assert!(block.iter().all(|b| *b == 7));
    }

    #[test]
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    fn elsewhere_the_calls_say_they_did_nothing() {
        assert!(!set_arena_max(1));
        assert!(!set_mmap_threshold(128 << 10));
    }
}
