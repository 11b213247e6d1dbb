//! `gbc train --ensemble N`: the members' progress on stderr, the ensemble's report page,
//! `--json`, and the summary on stdout (the band's noise and calibration, its coverage of
//! the held-out experiments, the median's and the members' errors). The work is
//! `gbc::ensemble`.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use super::{ResampleArg, TrainArgs};
use crate::api::REPORT_FILE;
use crate::cli::{CommandError, CommandResult};
use crate::ensemble::{self, MemberEvent, Plan, Resample};
use crate::ir::Model;
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
            .unwrap_or_else(crate::experiment::default_jobs)
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
    let text = crate::api::summary::ensemble_summary(
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
            MemberEvent::Choosing { done, total } => {
                if state.0.elapsed().as_secs_f64() >= HEARTBEAT {
                    state.0 = Instant::now();
                    eprintln!(
                        "toward the mechanism: choosing the stop for every member, \
                         {done}/{total} fold epochs"
                    );
                }
            }
            MemberEvent::Chosen { stop: 0, .. } => eprintln!(
                "toward the mechanism: stopping at 0 epochs: every member is the mechanism"
            ),
            MemberEvent::Chosen { stop, epochs } => {
                eprintln!("toward the mechanism: every member stops after epoch {stop} of {epochs}")
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
