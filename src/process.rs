//! What this process and machine are, as Linux's `/proc` tells: the host's name, a process's start time and
//! whether it is still there, this process's peak memory and file-size limit, the machine's memory and CPU. Each answer
//! is `None` (or empty) where `/proc` cannot tell, and callers treat that as "unknown", never as "no".

/// This machine's name (`/proc/sys/kernel/hostname`, kept to letters, digits, `-` and `.`; empty where there is
/// none): temporary trees and results locks carry it, so that a machine never takes another one's in a shared
/// folder.
pub(crate) fn host_name() -> String {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    name.trim().chars().filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.')).collect()
}

/// The PID namespace of this process (`/proc/self/ns/pid`'s link target, `pid:[4026531836]`); `None` where
/// there is none to read. Two processes' pids can be compared only within one namespace: in a container (or
/// `unshare --pid`) a live run may be pid 1, which on the host is another process.
#[cfg(feature = "toolkit")]
pub(crate) fn pid_namespace() -> Option<String> {
    let target = std::fs::read_link("/proc/self/ns/pid").ok()?;
    let text = target.to_str()?;
    (text.starts_with("pid:[") && text.ends_with(']')).then(|| text.to_string())
}

/// Whether `/proc` describes this machine's processes at all (without it nothing here can tell).
#[cfg(feature = "toolkit")]
pub(crate) fn proc_available() -> bool {
    std::path::Path::new("/proc/self").exists()
}

/// Whether a process `pid` exists on this machine; `None` where `/proc` cannot tell.
#[cfg(feature = "toolkit")]
pub(crate) fn pid_exists(pid: u32) -> Option<bool> {
    proc_available().then(|| std::path::Path::new(&format!("/proc/{pid}")).exists())
}

/// The start time (clock ticks after boot, `/proc/PID/stat` field 22) of process `pid` (`self` for this one):
/// with the pid, it names a process even after the pid is reused.
#[cfg(feature = "toolkit")]
pub(crate) fn process_start(pid: &str) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count from the last ')'.
    stat.rsplit_once(')')?.1.split_whitespace().nth(19)?.parse().ok()
}

/// This process's peak resident set size in bytes (`VmHWM` of `/proc/self/status`).
#[cfg(feature = "toolkit")]
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// This process's soft file-size limit in bytes (`ulimit -f`, from `/proc/self/limits`); `None` when unlimited
/// or unknown.
pub(crate) fn file_size_limit() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limits.lines().find(|l| l.starts_with("Max file size"))?;
    line["Max file size".len()..].split_whitespace().next()?.parse().ok()
}

/// The bytes of address space this process may still map under its soft `ulimit -v` (from `/proc/self/limits`
/// and the `VmSize` of `/proc/self/status`); `None` when there is no such limit or it cannot be read.
pub(crate) fn address_space_room() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limits.lines().find(|l| l.starts_with("Max address space"))?;
    let limit: u64 = line["Max address space".len()..].split_whitespace().next()?.parse().ok()?;
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let size_kib: u64 = status.lines().find(|l| l.starts_with("VmSize:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(limit.saturating_sub(size_kib * 1024))
}

/// The machine's physical memory in bytes (`MemTotal` of `/proc/meminfo`).
pub(crate) fn physical_memory_bytes() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The CPU's model name (the first `model name` of `/proc/cpuinfo`, as `Intel(R) Xeon(R) ...`) and the number of
/// processors it lists; the file is read only up to 1 MiB.
#[cfg(feature = "toolkit")]
pub(crate) fn cpu_model() -> Option<(String, usize)> {
    use std::io::Read;
    let mut text = String::new();
    std::fs::File::open("/proc/cpuinfo").ok()?.take(1 << 20).read_to_string(&mut text).ok()?;
    let field = |line: &str, key: &str| {
        let (k, v) = line.split_once(':')?;
        (k.trim() == key).then(|| v.trim().to_string())
    };
    let model = text.lines().find_map(|l| field(l, "model name"))?;
    let processors = text.lines().filter(|l| field(l, "processor").is_some()).count();
    Some((model, processors))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn this_process_is_known_to_proc() {
        if !proc_available() {
            return;
        }
        assert_eq!(pid_exists(std::process::id()), Some(true));
        assert!(process_start("self").is_some());
        assert!(peak_rss_bytes().is_some_and(|b| b > 0));
        assert!(physical_memory_bytes().is_some_and(|b| b > 0));
        let ns = pid_namespace().expect("/proc/self/ns/pid");
        assert!(ns.starts_with("pid:[") && ns.ends_with(']'), "{ns}");
        // A pid above the kernel's pid_max (at most 2^22) names no process.
        assert_eq!(pid_exists(1 << 23), Some(false));
        if let Some((model, processors)) = cpu_model() {
            assert!(!model.is_empty() && processors >= 1, "{model:?} {processors}");
        }
    }
}
