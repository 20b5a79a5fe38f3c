//! The time a batch has left, for its progress line: the mean pipeline time of the pairs finished so far, times
//! the pairs left, shared among the jobs that run at once. Loading and writing are not in the pipeline time, so
//! it errs on the short side; skipped and failed pairs take no time and do not count.

use std::time::Duration;

/// The pipeline times of the pairs finished so far.
#[derive(Clone, Debug, Default)]
pub struct Eta {
    seconds: f64,
    finished: usize,
}

impl Eta {
    /// No pair finished yet.
    pub fn new() -> Self {
        Eta::default()
    }

    /// Counts a finished pair and its pipeline time.
    pub fn record(&mut self, seconds: f64) {
        if seconds.is_finite() && seconds >= 0.0 {
            self.seconds += seconds;
            self.finished += 1;
        }
    }

    /// The time `left` pairs take at the mean so far, `jobs` at a time (`None` before any pair finished).
    pub fn remaining(&self, left: usize, jobs: usize) -> Option<Duration> {
        if self.finished == 0 {
            return None;
        }
        let mean = self.seconds / self.finished as f64;
        let rounds = left.div_ceil(jobs.max(1));
        Some(Duration::from_secs_f64(mean * rounds as f64))
    }
}

/// A duration as a progress line shows it: `45 s`, `3 min 05 s`, `2 h 07 min`.
pub fn format_duration(d: Duration) -> String {
    let s = d.as_secs_f64().round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, s % 3600 / 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_left_is_the_mean_times_the_rounds_of_jobs() {
        let mut eta = Eta::new();
        assert_eq!(eta.remaining(5, 1), None, "nothing finished: no estimate");
        eta.record(2.0);
        eta.record(4.0);
        eta.record(f64::NAN);
        assert_eq!(eta.remaining(5, 1), Some(Duration::from_secs(15)));
        // 5 pairs, 2 at a time: 3 rounds.
        assert_eq!(eta.remaining(5, 2), Some(Duration::from_secs(9)));
        assert_eq!(eta.remaining(0, 2), Some(Duration::ZERO));
    }

    #[test]
    fn durations_read_as_seconds_minutes_or_hours() {
        assert_eq!(format_duration(Duration::from_secs_f64(44.6)), "45 s");
        assert_eq!(format_duration(Duration::from_secs(185)), "3 min 05 s");
        assert_eq!(format_duration(Duration::from_secs(2 * 3600 + 7 * 60 + 50)), "2 h 07 min");
    }
}
