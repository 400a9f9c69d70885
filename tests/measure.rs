//! Running the CLI under bounds: the child's CPU time and peak resident set,
//! and a wall-clock deadline that kills a child that hangs (a FIFO must not
//! block a test for ever).
//!
//! The kernel's count comes from `wait4`'s rusage, but a child's `ru_maxrss`
//! starts at the resident set of the process that forked it (Linux records the
//! old image's high-water mark at exec): run straight from this test binary,
//! every child "peaked" at the test binary's 41 MB or more. So the command runs
//! under GNU time (`/usr/bin/time`, package `time`, which scripts/test.sh
//! installs), a 2 MB process whose child's count is the child's own; without
//! it, the count from `wait4` is used, which can only overstate.
//!
//! Bounds are on CPU time, not wall time: four agents share two cores on the
//! build machine, which stretches wall time threefold while CPU time stays
//! within a few percent. Each case's bound is ten times what it measured, so
//! that it never flakes but a quadratic or leaking path still fails it.

use std::io::Read;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

/// What a run cost.
#[derive(Clone, Copy, Debug)]
pub struct Cost {
    /// Wall-clock time.
    pub wall: Duration,
    /// User plus system CPU time of the child.
    pub cpu: Duration,
    /// Peak resident set of the child, in KB.
    pub rss_kb: u64,
}

/// Bounds a run must stay within.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// CPU time.
    pub cpu: Duration,
    /// Peak resident set, in MB.
    pub rss_mb: u64,
}

impl Limits {
    /// `cpu_ms` milliseconds of CPU and `rss_mb` MB.
    pub const fn new(cpu_ms: u64, rss_mb: u64) -> Limits {
        Limits { cpu: Duration::from_millis(cpu_ms), rss_mb }
    }
}

/// Runs `cmd` to completion and returns its output and cost; kills it and
/// panics if it runs past `deadline` of wall time.
pub fn run_measured(cmd: Command, deadline: Duration) -> (Output, Cost) {
    let time = std::path::Path::new("/usr/bin/time");
    if !time.exists() {
        return run_rusage(cmd, deadline);
    }
    let log = std::env::temp_dir().join(format!("rothray-time-{}-{}", std::process::id(), next_id()));
    let mut wrapped = Command::new(time);
    wrapped.arg("-o").arg(&log).args(["-f", "%M %U %S"]).arg(cmd.get_program()).args(cmd.get_args());
    if let Some(d) = cmd.get_current_dir() {
        wrapped.current_dir(d);
    }
    for (k, v) in cmd.get_envs() {
        match v {
            Some(v) => wrapped.env(k, v),
            None => wrapped.env_remove(k),
        };
    }
    let (out, mut cost) = run_rusage(wrapped, deadline);
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let _ = std::fs::remove_file(&log);
    // The last line (GNU time puts "Command exited with non-zero status" first).
    let f: Vec<f64> = text.lines().last().unwrap_or("").split_whitespace().filter_map(|w| w.parse().ok()).collect();
    if let [kb, user, sys] = f[..] {
        cost.rss_kb = kb as u64;
        cost.cpu = Duration::from_secs_f64(user + sys);
    }
    (out, cost)
}

fn next_id() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

/// [`run_measured`] by `wait4` alone.
fn run_rusage(mut cmd: Command, deadline: Duration) -> (Output, Cost) {
    // Its own process group, so that a kill reaches what it started (time's or strace's child).
    cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()).process_group(0);
    let mut child = cmd.spawn().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    let pid = child.id() as libc::pid_t;
    // Drain both pipes while waiting: a child that fills one would block.
    let drain = |r: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            if let Some(mut r) = r {
                let _ = r.read_to_end(&mut v);
            }
            v
        })
    };
    let out = drain(child.stdout.take().map(|r| Box::new(r) as Box<dyn Read + Send>));
    let err = drain(child.stderr.take().map(|r| Box::new(r) as Box<dyn Read + Send>));
    let t0 = Instant::now();
    let mut status = 0;
    // SAFETY: rusage is plain data, filled in by wait4.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: a valid pid of our own child and valid out-pointers.
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut ru) };
        if r == pid {
            break;
        }
        assert!(r == 0, "wait4 on {cmd:?}: {}", std::io::Error::last_os_error());
        if t0.elapsed() > deadline {
            // SAFETY: signalling our own child's process group, then reaping it.
            unsafe {
                libc::kill(-pid, libc::SIGKILL);
                libc::wait4(pid, &mut status, 0, &mut ru);
            }
            panic!("{cmd:?} did not finish within {deadline:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let wall = t0.elapsed();
    // The child is reaped; `Child` must not wait for it again.
    drop(child);
    let tv = |t: libc::timeval| Duration::from_secs(t.tv_sec as u64) + Duration::from_micros(t.tv_usec as u64);
    let cost = Cost { wall, cpu: tv(ru.ru_utime) + tv(ru.ru_stime), rss_kb: ru.ru_maxrss as u64 };
    let output = Output { status: ExitStatus::from_raw(status), stdout: out.join().unwrap(), stderr: err.join().unwrap() };
    (output, cost)
}

/// Runs `cmd` and asserts that it stays within `limits` (with a wall-clock
/// deadline of 30 times the CPU bound plus a minute, as a hang guard only).
pub fn run_within_limits(cmd: Command, limits: Limits, what: &str) -> Output {
    let (out, cost) = run_measured(cmd, limits.cpu * 30 + Duration::from_secs(60));
    println!("{what}: {:.3} s CPU, {:.3} s wall, {} MB peak RSS", cost.cpu.as_secs_f64(), cost.wall.as_secs_f64(), cost.rss_kb / 1024);
    assert!(cost.cpu <= limits.cpu, "{what}: {:?} of CPU, bound {:?}", cost.cpu, limits.cpu);
    assert!(cost.rss_kb <= limits.rss_mb * 1024, "{what}: {} KB peak RSS, bound {} MB", cost.rss_kb, limits.rss_mb);
    out
}
