//! The one progress reporter of the long commands (`train`, `diagnose`, `simulate`,
//! `experiment`): on a terminal an indicatif bar; anywhere else (a pipe, a log file, a batch
//! job) plain lines on stderr, so that a job of hours shows life in its log too.
//!
//! Off a terminal a stage prints one line when it starts, then, while it runs, one line
//! every [`LINE_INTERVAL`] with where it is (done of total, the latest message, elapsed
//! time and what is left): a line per interval, never one per item. A background thread
//! writes those lines, so a single slow item (one fit of an hour) still shows life. A stage
//! started [`Announce::IfSlow`] stays silent, bar and lines alike, until it has run for one
//! interval: a quick run prints nothing.

use std::io::IsTerminal;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// The longest time without a line off a terminal while a stage runs.
pub const LINE_INTERVAL: Duration = Duration::from_secs(5);

/// What a stage counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Count {
    /// Items of the named unit ("epochs", "fits", "samples").
    Items(&'static str),
    /// Units of work shown as a share done (the total means nothing to a user).
    Percent,
    /// Nothing countable: the lines give the time.
    Time,
}

/// When a stage shows itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Announce {
    /// At once.
    Now,
    /// Once it has run for one interval.
    IfSlow,
}

/// Progress on stderr, a bar or lines (see the module documentation). Its methods take
/// `&self`: threads may report at once.
pub struct Reporter {
    shared: Arc<Shared>,
    heartbeat: Option<JoinHandle<()>>,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    terminal: bool,
    interval: Duration,
}

#[derive(Default)]
struct State {
    stage: Option<Stage>,
    bar: Option<ProgressBar>,
    last_line: Option<Instant>,
    stopped: bool,
    /// Lines kept instead of printed (tests).
    captured: Option<Vec<String>>,
}

struct Stage {
    name: String,
    total: u64,
    count: Count,
    position: u64,
    message: String,
    started: Instant,
    shown: bool,
}

impl Reporter {
    /// A bar when stderr is a terminal, else lines every [`LINE_INTERVAL`].
    pub fn new() -> Self {
        Reporter::start(std::io::stderr().is_terminal(), LINE_INTERVAL, false)
    }

    fn start(terminal: bool, interval: Duration, capture: bool) -> Self {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                captured: capture.then(Vec::new),
                ..State::default()
            }),
            wake: Condvar::new(),
            terminal,
            interval,
        });
        let beating = Arc::clone(&shared);
        let heartbeat = std::thread::Builder::new()
            .name("progress".into())
            .spawn(move || beating.beat())
            .ok();
        Reporter { shared, heartbeat }
    }

    /// Starts a stage of `total` (ending the one before).
    pub fn stage(&self, name: &str, total: u64, count: Count, announce: Announce) {
        let mut state = self.shared.lock();
        if let Some(bar) = state.bar.take() {
            bar.finish_and_clear();
        }
        state.stage = Some(Stage {
            name: name.to_string(),
            total,
            count,
            position: 0,
            message: String::new(),
            started: Instant::now(),
            shown: false,
        });
        if announce == Announce::Now {
            self.shared.show(&mut state);
        }
    }

    /// Sets the current stage's position and message.
    pub fn update(&self, position: u64, message: String) {
        let mut state = self.shared.lock();
        if let Some(bar) = &state.bar {
            bar.set_position(position);
            bar.set_message(message.clone());
        }
        if let Some(stage) = state.stage.as_mut() {
            (stage.position, stage.message) = (position, message);
        }
    }

    /// Sets the current stage's message, its position unchanged (news within an item).
    pub fn message(&self, message: String) {
        let mut state = self.shared.lock();
        if let Some(bar) = &state.bar {
            bar.set_message(message.clone());
        }
        if let Some(stage) = state.stage.as_mut() {
            stage.message = message;
        }
    }

    /// Sets the current stage's total (known only once it runs).
    pub fn set_total(&self, total: u64) {
        let mut state = self.shared.lock();
        if let Some(bar) = &state.bar {
            bar.set_length(total);
        }
        if let Some(stage) = state.stage.as_mut() {
            stage.total = total;
        }
    }

    /// Advances the current stage by `step` with a new message.
    pub fn advance(&self, step: u64, message: String) {
        let mut state = self.shared.lock();
        let Some(stage) = state.stage.as_mut() else {
            return;
        };
        stage.position += step;
        stage.message = message;
        let (position, message) = (stage.position, stage.message.clone());
        if let Some(bar) = &state.bar {
            bar.set_position(position);
            bar.set_message(message);
        }
    }

    /// Prints a line now (above the bar on a terminal).
    pub fn println(&self, text: &str) {
        let mut state = self.shared.lock();
        match &state.bar {
            Some(bar) => bar.println(text),
            None => emit(&mut state, text.to_string()),
        }
    }

    /// Prints the current stage's progress line now (off a terminal; a bar shows it anyway).
    pub fn report_now(&self) {
        if !self.shared.terminal {
            let mut state = self.shared.lock();
            self.shared.progress_line(&mut state);
        }
    }

    /// Ends the current stage, clearing its bar.
    pub fn finish(&self) {
        let mut state = self.shared.lock();
        if let Some(bar) = state.bar.take() {
            bar.finish_and_clear();
        }
        state.stage = None;
    }
}

impl Default for Reporter {
    fn default() -> Self {
        Reporter::new()
    }
}

impl Drop for Reporter {
    fn drop(&mut self) {
        self.finish();
        self.shared.lock().stopped = true;
        self.shared.wake.notify_all();
        if let Some(heartbeat) = self.heartbeat.take() {
            let _ = heartbeat.join();
        }
    }
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The heartbeat: shows a slow stage, and off a terminal writes a progress line when
    /// none was written for an interval.
    fn beat(&self) {
        let tick = (self.interval / 5).max(Duration::from_millis(1));
        let mut state = self.lock();
        loop {
            state = match self.wake.wait_timeout(state, tick) {
                Ok((state, _)) => state,
                Err(poisoned) => poisoned.into_inner().0,
            };
            if state.stopped {
                return;
            }
            let Some(stage) = state.stage.as_ref() else {
                continue;
            };
            if !stage.shown {
                if stage.started.elapsed() >= self.interval {
                    self.show(&mut state);
                }
                continue;
            }
            let quiet = state.last_line.is_none_or(|t| t.elapsed() >= self.interval);
            if !self.terminal && quiet {
                self.progress_line(&mut state);
            }
        }
    }

    /// Shows the current stage: its bar on a terminal, else its first line.
    fn show(&self, state: &mut State) {
        let Some(stage) = state.stage.as_mut() else {
            return;
        };
        stage.shown = true;
        if !self.terminal {
            // A stage shown late (it turned out slow) starts with where it is.
            let late = stage.started.elapsed() >= self.interval;
            let line = match stage.count {
                _ if late => progress_line(stage),
                Count::Items(unit) if stage.total > 0 => {
                    format!("{}: {} {unit}", stage.name, stage.total)
                }
                _ => stage.name.clone(),
            };
            emit(state, line);
            return;
        }
        let template = match stage.count {
            Count::Items(unit) => {
                format!("{{prefix}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{msg}} ({{elapsed}}, ETA {{eta}})")
            }
            Count::Percent => {
                "{prefix} [{bar:30}] {percent:>3}% {msg} ({elapsed}, ETA {eta})".to_string()
            }
            Count::Time => "{prefix} {spinner} {msg} ({elapsed})".to_string(),
        };
        let bar = ProgressBar::new(stage.total);
        if let Ok(style) = ProgressStyle::with_template(&template) {
            bar.set_style(style.progress_chars("=> "));
        }
        if stage.count == Count::Time {
            bar.enable_steady_tick(Duration::from_millis(250));
        }
        bar.set_prefix(stage.name.clone());
        bar.set_position(stage.position);
        bar.set_message(stage.message.clone());
        state.bar = Some(bar);
    }

    /// Writes where the current stage is.
    fn progress_line(&self, state: &mut State) {
        if let Some(line) = state.stage.as_ref().filter(|s| s.shown).map(progress_line) {
            emit(state, line);
        }
    }
}

/// "fitting effects: 2/4 fits, `decay` done in 3.1 s (12 s elapsed, about 12 s left)".
fn progress_line(stage: &Stage) -> String {
    let done = match stage.count {
        Count::Items(unit) if stage.total == 0 => format!("{} {unit}", stage.position),
        Count::Items(unit) => format!("{}/{} {unit}", stage.position, stage.total),
        Count::Percent => {
            let share = stage.position as f64 / stage.total.max(1) as f64;
            format!("{:.0}%", 100.0 * share)
        }
        Count::Time => String::new(),
    };
    let message = match (done.as_str(), stage.message.as_str()) {
        ("", "") => String::new(),
        (_, "") => format!(": {done}"),
        ("", text) => format!(": {text}"),
        (_, text) => format!(": {done}, {text}"),
    };
    let elapsed = stage.started.elapsed().as_secs_f64();
    let left = match (stage.position, stage.total) {
        (done, total) if done > 0 && done < total => {
            let rest = elapsed * (total - done) as f64 / done as f64;
            format!(", about {} left", duration(rest))
        }
        _ => String::new(),
    };
    format!(
        "{}{message} ({} elapsed{left})",
        stage.name,
        duration(elapsed)
    )
}

/// Seconds in words: "42 s", "3 min 20 s", "2 h 05 min".
pub fn duration(seconds: f64) -> String {
    let whole = seconds.max(0.0).round() as u64;
    match whole {
        0..60 => format!("{whole} s"),
        60..3600 => format!("{} min {:02} s", whole / 60, whole % 60),
        _ => format!("{} h {:02} min", whole / 3600, whole % 3600 / 60),
    }
}

fn emit(state: &mut State, line: String) {
    state.last_line = Some(Instant::now());
    match &mut state.captured {
        Some(lines) => lines.push(line),
        None => eprintln!("{line}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn captured(reporter: &Reporter) -> Vec<String> {
        (reporter.shared.lock().captured.clone()).unwrap_or_default()
    }

    #[test]
    fn off_a_terminal_a_stage_prints_its_start_then_a_line_per_interval() {
        let interval = Duration::from_millis(60);
        let reporter = Reporter::start(false, interval, true);
        reporter.stage("fitting effects", 4, Count::Items("fits"), Announce::Now);
        for item in 0..200 {
            reporter.advance(u64::from(item == 0), format!("item {item}"));
        }
        assert_eq!(captured(&reporter), ["fitting effects: 4 fits"]);
        std::thread::sleep(Duration::from_millis(400));
        let lines = captured(&reporter);
        // Never a line per item: at most one per interval (and at least one in 400 ms).
        assert!(
            lines.len() >= 2 && lines.len() <= 1 + 400 / 60 + 1,
            "{lines:?}"
        );
        assert!(
            lines[1].starts_with("fitting effects: 1/4 fits, item 199 ("),
            "{lines:?}"
        );
        reporter.println("a warning");
        assert_eq!(
            captured(&reporter).last().map(String::as_str),
            Some("a warning")
        );
    }

    #[test]
    fn a_stage_that_may_be_quick_shows_only_once_it_is_slow() {
        let reporter = Reporter::start(false, Duration::from_millis(60), true);
        reporter.stage("simulating", 10, Count::Items("samples"), Announce::IfSlow);
        reporter.update(10, "done".into());
        reporter.finish();
        std::thread::sleep(Duration::from_millis(200));
        assert!(captured(&reporter).is_empty());
        reporter.stage("simulating", 10, Count::Percent, Announce::IfSlow);
        reporter.update(5, String::new());
        std::thread::sleep(Duration::from_millis(300));
        let lines = captured(&reporter);
        assert!(lines.len() >= 2, "{lines:?}");
        assert!(
            lines.iter().all(|l| l.starts_with("simulating: 50% (")),
            "{lines:?}"
        );
        reporter.stage("evaluating", 0, Count::Time, Announce::Now);
        reporter.report_now();
        let lines = captured(&reporter);
        let last = &lines[lines.len() - 2..];
        assert_eq!(last[0], "evaluating");
        assert!(last[1].starts_with("evaluating (0 s elapsed"), "{lines:?}");
    }

    #[test]
    fn durations_read_as_words() {
        assert_eq!(duration(4.4), "4 s");
        assert_eq!(duration(200.0), "3 min 20 s");
        assert_eq!(duration(7500.0), "2 h 05 min");
    }
}
