//! `gbc train --ensemble N`: the members' progress on stderr, the ensemble's report page,
//! `--json`, and the summary on stdout (the band's noise and calibration, its coverage of
//! the held-out experiments, the median's and the members' errors). The work is
//! `gbc::ensemble`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use super::{ResampleArg, TrainArgs};
use crate::api::REPORT_FILE;
use crate::cli::{CommandError, CommandResult};
use crate::ensemble::{self, EnsembleInfo, MemberEvent, Plan, Resample};
use crate::ir::Model;
use crate::plot::tick_label;
use crate::train::{Recipe, TrainOptions, TrainingData};

/// Seconds between progress lines of the members' epochs.
const HEARTBEAT: f64 = 5.0;

/// Trains the ensemble of `members` into `directory` and reports.
pub(super) fn run(
    args: &TrainArgs,
    (model, (model_file, source)): (&Model, (&PathBuf, &str)),
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
    (members, directory): (usize, &Path),
) -> CommandResult {
    let plan = Plan {
        members,
        resample: match args.resample.unwrap_or(ResampleArg::Experiments) {
            ResampleArg::Experiments => Resample::Experiments,
            ResampleArg::None => Resample::None,
        },
        jobs: args
            .jobs
            .unwrap_or_else(crate::cli::experiment::default_jobs)
            .max(1),
        level: args.band,
    };
    let model_path = model_file.display().to_string();
    let data_path = (args.data.iter())
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" ");
    let keep = ensemble::Keep {
        directory: directory.to_path_buf(),
        model: (&model_path, source),
        data: &data_path,
        recoveries: args.recoveries,
    };
    let started = Instant::now();
    let progress = MemberProgress::new(members);
    let trained =
        ensemble::train_ensemble(model, data, (options, recipe), &plan, &keep, &|event| {
            progress.observe(event)
        })
        .map_err(CommandError::user)?;
    let title = (model_file.file_stem()).map_or(model.name.clone(), |s| s.to_string_lossy().into());
    let page = ensemble::page::ensemble_page(
        model,
        &trained,
        (data.train, data.validation),
        plan.level,
        &title,
    );
    crate::io::write_atomic(&directory.join(REPORT_FILE), page.as_bytes())
        .map_err(CommandError::user)?;
    let json_to_stdout = (args.json.as_ref()).is_some_and(|p| p.as_os_str() == crate::io::STDOUT);
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&trained.info).map_err(|error| {
            CommandError::Internal(format!("cannot encode the ensemble: {error}"))
        })?;
        crate::io::write_atomic(path, json.as_bytes()).map_err(CommandError::user)?;
    }
    let text = summary(
        model,
        &trained.info,
        started.elapsed().as_secs_f64(),
        directory,
    );
    if json_to_stdout {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    Ok(())
}

/// The members' progress: a line when one starts or finishes, and every [`HEARTBEAT`]
/// seconds the epoch each running member has reached.
struct MemberProgress {
    /// When the last heartbeat was printed, and each running member's `(epoch, epochs)`.
    state: Mutex<(Instant, Vec<Running>)>,
}

/// A running member's epoch and planned epochs (`None`: not running).
type Running = Option<(usize, usize)>;

impl MemberProgress {
    fn new(members: usize) -> Self {
        MemberProgress {
            state: Mutex::new((Instant::now(), vec![None; members])),
        }
    }

    fn observe(&self, event: MemberEvent) {
        let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let members = state.1.len();
        match event {
            MemberEvent::Started {
                member,
                seed,
                trained_on,
                ..
            } => eprintln!(
                "member {member}/{members}: seed {seed}, training on {}",
                trained_on.join(" ")
            ),
            MemberEvent::Phase { member, phase } if phase != crate::train::TRAINING => {
                eprintln!("member {member}/{members}: {phase}");
            }
            MemberEvent::Phase { .. } => {}
            MemberEvent::Epoch {
                member,
                epoch,
                epochs,
            } => {
                state.1[member - 1] = Some((epoch, epochs));
                if state.0.elapsed().as_secs_f64() >= HEARTBEAT {
                    state.0 = Instant::now();
                    let running: Vec<String> = (state.1.iter().enumerate())
                        .filter_map(|(k, e)| {
                            e.map(|(e, n)| format!("member {} epoch {e}/{n}", k + 1))
                        })
                        .collect();
                    eprintln!("training: {}", running.join(", "));
                }
            }
            MemberEvent::Finished {
                member,
                status,
                seconds,
            } => {
                state.1[member - 1] = None;
                eprintln!("member {member}/{members}: {status} in {seconds:.0} s");
            }
        }
    }
}

/// `writeln!` into a `String` (which cannot fail).
macro_rules! line {
    ($out:expr, $($arg:tt)*) => {{
        let _ = writeln!($out, $($arg)*);
    }};
}

/// The text printed when the ensemble is done.
fn summary(model: &Model, info: &EnsembleInfo, seconds: f64, directory: &Path) -> String {
    let mut out = String::new();
    let used = info.used().count();
    line!(
        out,
        "trained an ensemble of {used} members of `{}` ({} of {} finished) in {seconds:.1} s, {}",
        model.name,
        used,
        info.members.len(),
        match info.resample {
            Resample::Experiments => "each on a bootstrap of whole training experiments",
            Resample::None => "each on every training experiment",
        }
    );
    for member in &info.members {
        line!(
            out,
            "  member {} (seed {}): trained on {}; {}{}",
            member.index,
            member.seed,
            member.trained_on.join(" "),
            member.status,
            member.validation_error.map_or(String::new(), |e| format!(
                ", held-out error {}",
                tick_label(e)
            ))
        );
    }
    band_lines(&mut out, info);
    coverage_lines(&mut out, info);
    line!(
        out,
        "ensemble written to {} (ensemble.json, members/, report.html)",
        directory.display()
    );
    out
}

/// The noise and calibration of each state.
fn band_lines(out: &mut String, info: &EnsembleInfo) {
    let level = info
        .coverage
        .as_ref()
        .map_or(ensemble::DEFAULT_LEVEL, |c| c.level);
    let calibration = &info.calibration;
    if let Some(reason) = &calibration.reason {
        line!(out, "band: not calibrated ({reason}); none is claimed");
        return;
    }
    let experiments: Vec<String> = (calibration.experiments.iter())
        .map(|(name, members)| match members.is_empty() {
            true => format!("{name} (no member left it out)"),
            false => format!(
                "{name} (members {})",
                members
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })
        .collect();
    line!(
        out,
        "band calibrated out of bag on {}:",
        experiments.join(", ")
    );
    line!(
        out,
        "  {:<12} {:<44} {:>9} {:>10}",
        "state",
        "noise",
        "oob cells",
        "factor"
    );
    for (state, (noise, scores)) in (info.band.noise.iter().zip(&calibration.states)).enumerate() {
        let factor = calibration
            .factor(state, level)
            .map_or("-".into(), tick_label);
        let cells = if scores.pooled {
            format!("{} (pooled)", scores.cells)
        } else {
            scores.cells.to_string()
        };
        line!(
            out,
            "  {:<12} {:<44} {:>9} {:>10}",
            noise.state,
            noise.describe(),
            cells,
            factor
        );
    }
}

/// The coverage of the held-out experiments and the errors.
fn coverage_lines(out: &mut String, info: &EnsembleInfo) {
    let Some(coverage) = &info.coverage else {
        line!(out, "coverage: no held-out measured cell to count");
        return;
    };
    let share = |inside: usize, cells: usize| {
        format!(
            "{inside} of {cells} ({:.1} %)",
            100.0 * inside as f64 / cells.max(1) as f64
        )
    };
    line!(
        out,
        "coverage of the {} % band on held-out {}: {} measured cells inside",
        tick_label(100.0 * coverage.level),
        coverage.experiments.join(" "),
        share(coverage.overall.inside, coverage.overall.cells)
    );
    for count in &coverage.states {
        line!(
            out,
            "  {:<12} {}",
            count.state,
            share(count.inside, count.cells)
        );
    }
    let base = &coverage.uncalibrated;
    line!(
        out,
        "  (not calibrated, the members' spread with the noise at {} %: {})",
        tick_label(100.0 * info.band.base_level),
        share(base.inside, base.cells)
    );
    if let Some(errors) = &info.errors {
        let members: Vec<String> = errors.members.iter().map(|e| tick_label(*e)).collect();
        line!(
            out,
            "held-out error of the members' median {} (members: {})",
            tick_label(errors.median),
            members.join(", ")
        );
    }
}
