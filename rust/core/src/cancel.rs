//! Cooperative cancellation. Long drivers call [`check`] at coarse points (between
//! iterations, levels, phases) and parallel loops skip their remaining rows once [`cancelled`]
//! is true, so a caller can stop a run within a fraction of a second.
//!
//! Whoever runs the work binds a [`Token`] to the threads that run it (phloem's Python layer
//! binds one to every worker of a pool when the pool starts); on a thread without a token
//! nothing is ever cancelled, so plain Rust callers see no difference.

use std::cell::OnceCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::{Error, Result};

/// A shared cancellation flag; clones share it.
#[derive(Clone, Debug, Default)]
pub struct Token(Arc<AtomicBool>);

impl Token {
    /// A token that is not cancelled.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks every thread bound to this token to stop at its next check point.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Clears the request, for reusing the token once the cancelled work has stopped.
    pub fn reset(&self) {
        self.0.store(false, Ordering::Relaxed);
    }

    /// Whether [`Token::cancel`] was called since the last [`Token::reset`].
    #[must_use]
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// Binds the token to the current thread for the thread's lifetime; a thread keeps the
    /// first token bound to it.
    pub fn bind(&self) {
        CURRENT.with(|c| {
            let _ = c.set(self.clone());
        });
    }
}

thread_local! {
    static CURRENT: OnceCell<Token> = const { OnceCell::new() };
}

/// Whether the current thread's work was asked to stop (never, on a thread without a token).
#[must_use]
pub fn cancelled() -> bool {
    CURRENT.with(|c| c.get().is_some_and(Token::is_cancelled))
}

/// `Err(Error::Cancelled)` once the current thread's work was asked to stop.
pub fn check() -> Result<()> {
    if cancelled() {
        Err(Error::Cancelled)
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_bound_threads_see_a_cancelled_token() {
        let token = Token::new();
        token.cancel();
        assert!(check().is_ok(), "no token bound here");
        let t = token.clone();
        let r = std::thread::spawn(move || {
            t.bind();
            let first = check();
            t.reset();
            (first, check())
        })
        .join()
        .unwrap();
        assert_eq!(r, (Err(Error::Cancelled), Ok(())));
        assert!(!token.is_cancelled(), "clones share the flag");
    }
}
