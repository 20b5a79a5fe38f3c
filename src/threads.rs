//! How many worker threads a caller may ask for: the command line's `--threads` and the Python module's
//! `threads=` share this one bound.
//!
//! More threads than cores only add switching (thousands make a run many times slower, or fail to start); a few
//! per core are allowed for machines that under-report their cores.

use crate::error::{Error, Result};

/// The cap is 4 threads per core, but never below this.
pub const MIN_THREAD_CAP: usize = 16;

/// The largest thread count allowed on this machine: 4 per core, at least [`MIN_THREAD_CAP`].
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    (4 * cores).max(MIN_THREAD_CAP)
}

/// `n` if it is a thread count this machine allows (1 to [`max_threads`]).
///
/// # Errors
/// [`Error::InvalidParam`] naming `name` (`--threads`, `threads`) and the range.
pub fn check_threads(name: &str, n: u64) -> Result<usize> {
    let max = max_threads();
    match usize::try_from(n) {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(Error::param(name, n, format!("1 to {max} (4 per core on this machine, at least {MIN_THREAD_CAP})"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_counts_are_held_to_a_few_per_core() {
        let max = max_threads();
        assert!(max >= MIN_THREAD_CAP);
        assert_eq!(check_threads("threads", 1).unwrap(), 1);
        assert_eq!(check_threads("threads", max as u64).unwrap(), max);
        for bad in [0, max as u64 + 1, u64::MAX] {
            let e = check_threads("threads", bad).unwrap_err().to_string();
            assert!(e.contains("threads") && e.contains(&format!("1 to {max}")), "{e}");
        }
    }
}
