//! `gbc train --ensemble N`: the members' progress on stderr, the ensemble's report page,
//! `--json`, and the summary on stdout (the band's noise and calibration, its coverage of
//! the held-out experiments, the median's and the members' errors). The work is
//! `api::train_ensemble`.

use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

use crate::cli::{CommandError, CommandResult};
use gbc::api::flags::TrainArgs;
use gbc::api::{self, EnsemblePlan as Plan, MemberEvent, Record};

/// Seconds between progress lines of the members' epochs.
const HEARTBEAT: f64 = 5.0;

/// Trains the ensemble of `plan` into `directory` and reports.
pub(super) fn run(
    args: &TrainArgs,
    model: &api::Model,
    (records, val): (Vec<Record>, Vec<Record>),
    (spec, plan): (&api::TrainSpec, &Plan),
    directory: &Path,
) -> CommandResult {
    let progress = MemberProgress::new(plan.members);
    let data = (records, val);
    let trained = api::train_ensemble(model, data, (spec, plan), directory, &|event| {
        progress.observe(event)
    })?;
    if let Some(note) = &trained.note {
        eprintln!("{note}");
    }
    let json_to_stdout = (args.json.as_ref()).is_some_and(|p| p.as_os_str() == api::STDOUT);
    if let Some(path) = &args.json {
        api::write_atomic(path, trained.json()?.as_bytes()).map_err(CommandError::user)?;
    }
    let text = trained.summary_text(model);
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
            MemberEvent::Phase { member, phase } if phase != api::TRAINING_PHASE => {
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
