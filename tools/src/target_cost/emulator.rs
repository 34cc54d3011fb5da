//! Stage 2: run the emulator binary in QEMU and take what it prints.

use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};

/// QEMU running the emulator binary: mps2-an386 (Cortex-M4F), semihosting, one
/// nanosecond of virtual time per instruction (`-icount shift=0`).
pub fn qemu_command(qemu: &str, elf: &Path) -> Command {
    let mut cmd = Command::new(qemu);
    cmd.args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
        .args(["-nographic", "-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0"])
        .arg("-kernel")
        .arg(elf);
    cmd
}

/// Runs the emulator binary in QEMU and returns its standard output. Fails if QEMU is
/// missing, exits with failure (the target's own checks failed) or takes longer than
/// `timeout`.
pub fn run_emulator(qemu: &str, elf: &Path, timeout: Duration) -> Result<String> {
    let mut child = qemu_command(qemu, elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| {
            format!("cannot start {qemu} (Debian/Ubuntu: `apt-get install qemu-system-arm`)")
        })?;
    let mut stdout = child.stdout.take().ok_or_else(|| anyhow!("no stdout"))?;
    let mut stderr = child.stderr.take().ok_or_else(|| anyhow!("no stderr"))?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        stdout.read_to_string(&mut s).map(|_| s)
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if started.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            bail!("the emulator did not finish within {} s", timeout.as_secs());
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let text = reader
        .join()
        .map_err(|_| anyhow!("reader thread failed"))??;
    let errors = err_reader.join().unwrap_or_default();
    if !status.success() {
        let last = text.lines().rfind(|l| !l.starts_with('R')).unwrap_or("");
        bail!(
            "the emulator exited with {status}; last line: {last}; stderr: {}",
            errors.trim()
        );
    }
    Ok(text)
}
