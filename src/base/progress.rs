//! Progress of long loops, reported without a parameter: work loops deep in the library
//! (sampling a grid slice by slice, extracting a mesh) call [`advance`] a few times per
//! z-slice or chunk, never per sample, and whoever shows progress (the command line's bar)
//! installs a [`Sink`] for as long as it shows it. While no sink is installed, [`advance`]
//! is a relaxed atomic load and a return.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// What receives the units of work the library reports (the command line implements it
/// with its progress bar).
pub trait Sink: Send + Sync {
    /// `n` more units of the current stage's work are done.
    fn advance(&self, n: u64);
}

/// Whether a sink is installed (checked before taking the lock).
static ACTIVE: AtomicBool = AtomicBool::new(false);
/// The installed sink.
static SINK: Mutex<Option<Arc<dyn Sink>>> = Mutex::new(None);

/// Installs `sink` as the receiver of [`advance`], replacing any other, until [`remove`].
pub fn install(sink: Arc<dyn Sink>) {
    if let Ok(mut s) = SINK.lock() {
        *s = Some(sink);
        ACTIVE.store(true, Ordering::Release);
    }
}

/// Removes the installed sink, returning it; [`advance`] is a no-op again.
pub fn remove() -> Option<Arc<dyn Sink>> {
    ACTIVE.store(false, Ordering::Release);
    SINK.lock().ok().and_then(|mut s| s.take())
}

/// Records `n` more units of the current stage's work (no-op when no sink is installed).
#[inline]
pub fn advance(n: u64) {
    if !ACTIVE.load(Ordering::Relaxed) {
        return;
    }
    if let Ok(s) = SINK.lock()
        && let Some(sink) = s.as_ref()
    {
        sink.advance(n);
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicU64;

    use super::*;

    /// Counts the units reported by one thread (other tests may run conversions, which
    /// report progress, in parallel).
    struct Count(AtomicU64, std::thread::ThreadId);

    impl Sink for Count {
        fn advance(&self, n: u64) {
            if std::thread::current().id() == self.1 {
                self.0.fetch_add(n, Ordering::Relaxed);
            }
        }
    }

    #[test]
    fn an_installed_sink_receives_the_units_until_removed() {
        let count = Arc::new(Count(AtomicU64::new(0), std::thread::current().id()));
        install(count.clone());
        advance(3);
        advance(4);
        assert!(remove().is_some());
        advance(100);
        assert_eq!(count.0.load(Ordering::Relaxed), 7);
        assert!(remove().is_none());
    }
}
