//! Memory checks before large allocations: a command that would need more
//! memory than this process may still use fails at once, naming what and
//! which limit, instead of being killed part way.

use anyhow::{Result, bail};

/// Fails if `bytes` exceeds the memory this machine has available.
pub fn check_memory(bytes: u64, what: &str) -> Result<()> {
    let (available, source) = memory_available();
    if bytes > available {
        bail!(
            "{what} would need {:.1} GiB but only {:.1} GiB of memory is available ({source})",
            bytes as f64 / (1u64 << 30) as f64,
            available as f64 / (1u64 << 30) as f64
        );
    }
    Ok(())
}

/// Memory this process may still use, and what limits it: the least of the
/// system's MemAvailable, the cgroup's limit less its usage (v2, then v1), and
/// the address-space rlimit (`ulimit -v`) less the process's current size.
fn memory_available() -> (u64, &'static str) {
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let kib_field = |text: &str, key: &str| {
        text.lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<u64>().ok())
            .map(|kb| kb * 1024)
    };
    let number = |t: Option<String>| t.and_then(|t| t.trim().parse::<u64>().ok());
    let mut limits: Vec<(u64, &'static str)> = vec![];
    if let Some(avail) = read("/proc/meminfo").and_then(|m| kib_field(&m, "MemAvailable:")) {
        limits.push((avail, "MemAvailable"));
    }
    let cgroup = match number(read("/sys/fs/cgroup/memory.max")) {
        Some(max) => Some((max, number(read("/sys/fs/cgroup/memory.current")).unwrap_or(0))),
        None => number(read("/sys/fs/cgroup/memory/memory.limit_in_bytes"))
            .map(|max| (max, number(read("/sys/fs/cgroup/memory/memory.usage_in_bytes")).unwrap_or(0))),
    };
    if let Some((max, used)) = cgroup {
        limits.push((max.saturating_sub(used), "the cgroup's memory limit"));
    }
    let address_space = read("/proc/self/limits").and_then(|l| {
        let line = l.lines().find(|l| l.starts_with("Max address space"))?.to_string();
        line.split_whitespace().nth(3)?.parse::<u64>().ok()
    });
    if let Some(limit) = address_space {
        let size = read("/proc/self/status").and_then(|s| kib_field(&s, "VmSize:")).unwrap_or(0);
        limits.push((limit.saturating_sub(size), "the address-space limit (ulimit -v)"));
    }
    limits.into_iter().min_by_key(|l| l.0).unwrap_or((16 << 30, "assumed: no limit could be read"))
}
