//! A running `gbc` whose every wait is bounded: a stop that breaks ends the test with a
//! message (and the child killed) instead of hanging CI.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// The longest any wait on a child may take: generous, so that a slow 2-core CI does not
/// flake, yet a hang fails.
pub const BOUND: Duration = Duration::from_secs(120);

/// How often a wait looks again.
const POLL: Duration = Duration::from_millis(20);

/// A child `gbc` with its stderr (and stdout, when piped) read line by line on threads.
/// Dropped, it kills the child if it still runs.
pub struct Running {
    child: Child,
    stderr: Receiver<String>,
    stdout: Option<Receiver<String>>,
    /// What it runs, for the messages.
    what: String,
    /// Lines of stderr read so far.
    seen: Vec<String>,
}

/// What a finished child left.
pub struct Finished {
    /// Its exit status.
    pub status: ExitStatus,
    /// Its stderr lines not read before it ended.
    pub stderr: Vec<String>,
    /// Its stdout (empty unless piped).
    pub stdout: String,
}

/// `gbc` with `args`, from the crate root, without colour.
pub fn gbc_command(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_gbc"));
    command
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("NO_COLOR", "1");
    command
}

/// The lines of `pipe`, sent on as they are read; the channel closes at its end.
fn lines_of(pipe: impl Read + Send + 'static) -> Receiver<String> {
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(pipe).lines().map_while(Result::ok) {
            if sender.send(line).is_err() {
                break;
            }
        }
    });
    receiver
}

impl Running {
    /// Starts `command` with stderr piped; stdout piped too when `stdout`, else dropped.
    pub fn start(command: &mut Command, stdout: bool) -> Running {
        let what = format!("{command:?}");
        let out = if stdout {
            Stdio::piped()
        } else {
            Stdio::null()
        };
        let mut child = (command.stdout(out).stderr(Stdio::piped()))
            .spawn()
            .unwrap_or_else(|e| panic!("{what} does not start: {e}"));
        let stderr = lines_of(child.stderr.take().expect("stderr is piped"));
        let stdout = child.stdout.take().map(lines_of);
        Running {
            child,
            stderr,
            stdout,
            what,
            seen: Vec::new(),
        }
    }

    /// Kills the child and fails the test with `why` and the stderr read so far.
    fn fail(&mut self, why: &str) -> ! {
        let _ = self.child.kill();
        let _ = self.child.wait();
        panic!(
            "{}: {why}; stderr so far:\n{}",
            self.what,
            self.seen.join("\n")
        );
    }

    /// Reads stderr until a line satisfies `wanted` (returned), within [`BOUND`].
    pub fn line(&mut self, wanted: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + BOUND;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.stderr.recv_timeout(left) {
                Ok(line) if wanted(&line) => return line,
                Ok(line) => self.seen.push(line),
                Err(RecvTimeoutError::Timeout) => {
                    self.fail(&format!("no awaited line within {BOUND:?}"))
                }
                Err(RecvTimeoutError::Disconnected) => {
                    self.fail("stderr ended before the awaited line")
                }
            }
        }
    }

    /// Waits within [`BOUND`] until `ready` holds while the child runs (a child that ends
    /// first fails the test).
    pub fn until(&mut self, what: &str, ready: impl Fn() -> bool) {
        let deadline = Instant::now() + BOUND;
        while !ready() {
            if self.child.try_wait().ok().flatten().is_some() {
                self.seen.extend(self.stderr.try_iter());
                self.fail(&format!("it ended before {what}"));
            }
            if Instant::now() > deadline {
                self.fail(&format!("not {what} within {BOUND:?}"));
            }
            std::thread::sleep(POLL);
        }
    }

    /// Sends the signal `name` (`INT`, `TERM`) to the child.
    pub fn signal(&mut self, name: &str) {
        let sent = Command::new("kill")
            .args([format!("-{name}"), self.child.id().to_string()])
            .status();
        if !sent.is_ok_and(|status| status.success()) {
            self.fail(&format!("`kill -{name}` failed"));
        }
    }

    /// Waits within [`BOUND`] for the child to end and for its pipes to close.
    pub fn finish(&mut self) -> Finished {
        let deadline = Instant::now() + BOUND;
        let status = loop {
            match self.child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if Instant::now() > deadline => {
                    self.fail(&format!("still running after {BOUND:?}"))
                }
                Ok(None) => std::thread::sleep(POLL),
                Err(error) => self.fail(&format!("cannot wait: {error}")),
            }
        };
        let stderr =
            drain(&self.stderr, deadline).unwrap_or_else(|| self.fail("stderr stays open"));
        let stdout = match &self.stdout {
            Some(lines) => drain(lines, deadline).unwrap_or_else(|| self.fail("stdout stays open")),
            None => Vec::new(),
        };
        Finished {
            status,
            stderr,
            stdout: stdout.join("\n"),
        }
    }
}

/// Every line left on `lines` until it closes, or `None` past `deadline`.
fn drain(lines: &Receiver<String>, deadline: Instant) -> Option<Vec<String>> {
    let mut out = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) => out.push(line),
            Err(RecvTimeoutError::Disconnected) => return Some(out),
            Err(RecvTimeoutError::Timeout) => return None,
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
