//! `gbc demo`: the paper's two studies (chemostat, bioreactor), scaled down to finish in a
//! couple of minutes, with the shipped models and data ([`Study::demo_studies`]); each
//! study's CSV/JSON under `OUT/<study>/` and one report page, `OUT/report.html`, with every
//! figure inline and the tables. A re-run reuses finished runs. The full-scale commands are
//! in docs/reproduction.md.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::experiment::{StudyResults, StudyRun};
use super::ApiError;
use crate::experiment::merge::{Published, REPORT_FILE};
use crate::experiment::{report, ExperimentError, Prepared, Progress, Shard, Study};

/// The demo's studies, loaded and checked, and where they are written.
pub struct Demo {
    /// Each study with its whole grid.
    pub studies: Vec<StudyRun>,
    /// The output directory.
    pub out: PathBuf,
}

/// What the demo gave.
pub struct DemoResults {
    /// Each study's results and what was published of them.
    pub studies: Vec<(StudyResults, Published)>,
    /// The report page.
    pub report: PathBuf,
    /// Wall time of the trainings, seconds.
    pub seconds: f64,
}

impl Demo {
    /// Checks that the shipped models and data are there (run from the repository root)
    /// and loads both studies, to be written under `out`.
    pub fn prepare(out: &Path) -> Result<Demo, ApiError> {
        let studies = Study::demo_studies();
        for path in studies.iter().flat_map(Study::files) {
            if !path.is_file() {
                return Err(ApiError::user(ExperimentError::MissingShippedFile {
                    path: path.display().to_string(),
                }));
            }
        }
        let studies = (studies.iter())
            .map(|study| StudyRun::prepare(study, Shard::ALL))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Demo {
            studies,
            out: out.to_path_buf(),
        })
    }

    /// The directory of `study`.
    pub fn directory(&self, study: &StudyRun) -> PathBuf {
        self.out.join(&study.prepared.study.name)
    }

    /// Trains every study on `jobs` threads (`on_progress` hears each run, with its
    /// study), publishes each and writes the report page.
    pub fn execute(
        &self,
        jobs: usize,
        on_progress: &(dyn Fn(&Prepared, Progress) + Sync),
    ) -> Result<DemoResults, ApiError> {
        let started = Instant::now();
        let mut executed = Vec::with_capacity(self.studies.len());
        for study in &self.studies {
            let directory = self.directory(study);
            let tell = |progress: Progress| on_progress(&study.prepared, progress);
            executed.push(study.execute(&directory, jobs, &tell)?);
        }
        let seconds = started.elapsed().as_secs_f64();
        let mut studies = Vec::with_capacity(executed.len());
        for (study, results) in self.studies.iter().zip(executed) {
            let published = results.publish(study)?;
            studies.push((results, published));
        }
        let sections: Vec<_> = studies.iter().map(|(_, p)| p.section.clone()).collect();
        let intro = introduction(jobs, seconds, &self.out);
        let page = report::page(
            "gbc demo: the paper's two studies, scaled down",
            &intro,
            &sections,
        );
        let path = self.out.join(REPORT_FILE);
        crate::io::write_atomic(&path, page.as_bytes()).map_err(ApiError::user)?;
        Ok(DemoResults {
            studies,
            report: path,
            seconds,
        })
    }
}

/// The report page's opening paragraph.
fn introduction(jobs: usize, seconds: f64, out: &Path) -> String {
    format!(
        "<p>Both studies of Lovelett, Avalos &amp; Kevrekidis (2020), scaled down (3 \
         replicates instead of 20 and 10, and 300 instead of 1000 epochs for the bioreactor), \
         trained with {jobs} parallel {} in {seconds:.0} s. The first half trains with \
         gbc's default recipe (one-step epochs, then free-run rollouts of growing length, \
         the params polished); the second half, labelled <i>paper's recipe</i>, with the \
         paper's (the one-step loss every epoch). Each study's runs, tables \
         (<code>results.csv</code>, <code>results.json</code>, <code>summary.csv</code>) and \
         SVG figures are in <code>{}/&lt;study&gt;/</code>. Errors are MSEs of states z-scored \
         with the validation window's statistics. The full-scale studies and their results \
         are in <code>docs/reproduction.md</code>.</p>",
        if jobs == 1 { "job" } else { "jobs" },
        crate::plot::escape(&out.display().to_string())
    )
}
