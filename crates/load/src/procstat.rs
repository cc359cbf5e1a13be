//! The server's resident memory and CPU time, read from `/proc` when it runs
//! on this machine, and the load generator's own CPU time beside it (on a
//! 2-core machine the client's share matters as much as the server's).

use std::net::SocketAddr;
use std::path::Path;

use serde::Serialize;

/// Linux reports CPU times in USER_HZ ticks, which is 100 on every
/// architecture Linux supports for userspace (`sysconf(_SC_CLK_TCK)`).
const TICKS_PER_SEC: f64 = 100.0;

/// One reading of a process.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ProcSample {
    pub rss_bytes: u64,
    /// User + system CPU seconds since the process started.
    pub cpu_secs: f64,
}

/// Reads `/proc/<pid>`; `None` if the process is gone or not Linux.
pub fn sample(pid: u32) -> Option<ProcSample> {
    read(&Path::new("/proc").join(pid.to_string()))
}

/// This process.
pub fn sample_self() -> Option<ProcSample> {
    read(Path::new("/proc/self"))
}

fn read(dir: &Path) -> Option<ProcSample> {
    let stat = std::fs::read_to_string(dir.join("stat")).ok()?;
    let status = std::fs::read_to_string(dir.join("status")).ok()?;
    Some(ProcSample { rss_bytes: parse_rss(&status)?, cpu_secs: parse_cpu(&stat)? })
}

/// utime + stime (fields 14 and 15 of `stat`; the command name, field 2, may
/// hold spaces and parentheses, so fields are counted after its last `)`).
fn parse_cpu(stat: &str) -> Option<f64> {
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11); // field 3 is the first after ')'
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some((utime + stime) as f64 / TICKS_PER_SEC)
}

/// `VmRSS:   12345 kB` of `status`.
fn parse_rss(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The process listening on `addr` on this machine, found through the
/// socket's inode (`/proc/net/tcp{,6}`, then `/proc/*/fd`). `None` if it is
/// not visible (another user's process, another machine, not Linux).
pub fn find_listener(addr: SocketAddr) -> Option<u32> {
    let port = format!(":{:04X}", addr.port());
    let mut inodes = Vec::new();
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let Ok(text) = std::fs::read_to_string(table) else { continue };
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            // local_address, state 0A = LISTEN, inode.
            if f.len() > 9 && f[1].ends_with(&port) && f[3] == "0A" {
                inodes.push(format!("socket:[{}]", f[9]));
            }
        }
    }
    if inodes.is_empty() {
        return None;
    }
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Some(pid) = entry.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else { continue };
        let Ok(fds) = std::fs::read_dir(entry.path().join("fd")) else { continue };
        for fd in fds.flatten() {
            if let Ok(link) = std::fs::read_link(fd.path())
                && inodes.iter().any(|i| link.as_os_str() == i.as_str())
            {
                return Some(pid);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_cpu_after_a_command_name_with_spaces() {
        let stat = "4242 (tokio (rt) 1) S 1 4242 4242 0 -1 4194560 500 0 0 0 250 50 0 0 20 0 9 0 100 0 0";
        assert_eq!(parse_cpu(stat), Some(3.0));
        assert_eq!(parse_rss("Name:\tx\nVmRSS:\t   2048 kB\n"), Some(2 * 1024 * 1024));
        assert_eq!(parse_rss("Name:\tx\n"), None);
    }

    #[test]
    fn reads_this_process_and_finds_its_listener() {
        let me = sample_self().expect("/proc/self on Linux");
        assert!(me.rss_bytes > 1024 * 1024, "{me:?}");
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        assert_eq!(find_listener(listener.local_addr().unwrap()), Some(std::process::id()));
    }
}
