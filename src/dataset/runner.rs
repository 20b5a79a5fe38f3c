//! Who runs this process, beyond its pid, host and PID namespace, as a results lock records it ([`super::lock`]):
//! the Slurm job it is a task of.

/// A Slurm job, as the environment of its task names it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct SlurmJob {
    /// `ARRAYJOB_TASK` for a task of a job array (`SLURM_ARRAY_JOB_ID`, `SLURM_ARRAY_TASK_ID`), else the job id
    /// (`SLURM_JOB_ID`). A requeued job keeps it; a new submission gets a new one.
    pub(super) id: String,
    /// How many times Slurm has started the job again (`SLURM_RESTART_COUNT`: requeued after a node failure, a
    /// preemption or `scontrol requeue`); 0 for its first run.
    pub(super) restart: u32,
}

impl SlurmJob {
    /// The job of this process, from its environment; `None` outside Slurm.
    pub(super) fn from_env() -> Option<SlurmJob> {
        let var = |name: &str| std::env::var(name).ok().filter(|v| is_id(v));
        let id = match (var("SLURM_ARRAY_JOB_ID"), var("SLURM_ARRAY_TASK_ID")) {
            (Some(job), Some(task)) => format!("{job}_{task}"),
            _ => var("SLURM_JOB_ID")?,
        };
        let restart = std::env::var("SLURM_RESTART_COUNT").ok().and_then(|r| r.trim().parse().ok()).unwrap_or(0);
        Some(SlurmJob { id, restart })
    }

    /// The lines a lock holds for it.
    pub(super) fn lines(&self) -> String {
        format!("slurm-job {}\nslurm-restart {}\n", self.id, self.restart)
    }

    /// The job a lock's lines name, if any.
    pub(super) fn parse(field: impl Fn(&str) -> Option<String>) -> Option<SlurmJob> {
        let id = field("slurm-job ").filter(|id| id.split('_').all(is_id))?;
        Some(SlurmJob { id, restart: field("slurm-restart ").and_then(|r| r.parse().ok()).unwrap_or(0) })
    }
}

/// Whether `text` is a Slurm id (digits; one line in a lock either way).
fn is_id(text: &str) -> bool {
    !text.is_empty() && text.len() <= 32 && text.bytes().all(|b| b.is_ascii_digit())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slurm_jobs_read_and_round_trip() {
        let job = SlurmJob { id: "1234_5".into(), restart: 2 };
        let text = job.lines();
        let field = |key: &str| text.lines().find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_string()));
        assert_eq!(SlurmJob::parse(field), Some(job));
        assert_eq!(SlurmJob::parse(|_| Some("12\n34".into())), None);
        assert_eq!(SlurmJob::parse(|_| None), None);
    }
}
