//! Atomic file output, and the guard that keeps a command from overwriting its own input.
//!
//! Every file gbc writes goes through [`write_atomic`]: the bytes go to a temporary file in
//! the target's directory, are flushed to disk, and the temporary file is renamed over the
//! target. A reader therefore sees either the old file or the complete new one, never a
//! half-written file, even if gbc is interrupted.

use miette::Diagnostic;
use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use thiserror::Error;

/// A failure to write an output file.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq, Eq)]
pub enum IoError {
    /// The file (or its temporary sibling) could not be written or renamed into place.
    #[error("cannot write `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0250),
        help("check that the directory is writable and the disk is not full")
    )]
    Write {
        /// The output file.
        path: String,
        /// What the operating system said.
        reason: String,
    },
    /// The directory of the output could not be created.
    #[error("cannot create directory `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0251),
        help("check the path and the permissions of its existing parent directories")
    )]
    CreateDirectory {
        /// The directory.
        path: String,
        /// What the operating system said.
        reason: String,
    },
    /// The output would overwrite a file the same command reads.
    #[error("expected an output path apart from the inputs, found `{output}`, which is the input `{input}`")]
    #[diagnostic(
        code(gbm::E0252),
        help("choose another output path; writing it would destroy the input while it is read")
    )]
    OutputIsInput {
        /// The output path as given.
        output: String,
        /// The input path as given.
        input: String,
    },
    /// A value to be written that is not finite: gbc writes no NaN or infinite number as a
    /// weight, a param or a predicted value ([`crate::finite`]).
    #[error("expected finite values to write to `{path}`, found {what}")]
    #[diagnostic(code(gbm::E0253), help("nothing was written: {help}"))]
    NotFinite {
        /// The output file.
        path: String,
        /// Which value and where, e.g. "`S` = NaN at t = 3.5 (row 12)".
        what: String,
        /// What to do about it.
        help: String,
    },
    /// A table whose columns do not match its header or each other.
    #[error(transparent)]
    #[diagnostic(transparent)]
    MalformedTable(#[from] crate::error::Bug),
}

/// The path that means standard output wherever gbc writes a file.
pub const STDOUT: &str = "-";

/// Writes `bytes` to `path` atomically: into a temporary file in the same directory, flushed
/// to disk, then renamed over `path`. Missing parent directories are created. The path `-`
/// ([`STDOUT`]) writes to standard output instead.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    if path.as_os_str() == STDOUT {
        use std::io::Write;
        let mut stdout = std::io::stdout().lock();
        return (stdout.write_all(bytes).and_then(|()| stdout.flush())).map_err(|error| {
            IoError::Write {
                path: "standard output".into(),
                reason: describe(&error),
            }
        });
    }
    let write_error = |reason: String| IoError::Write {
        path: path.display().to_string(),
        reason,
    };
    let Some(file_name) = path.file_name() else {
        return Err(write_error("expected a file name, found none".to_string()));
    };
    let directory = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&directory).map_err(|error| IoError::CreateDirectory {
        path: directory.display().to_string(),
        reason: describe(&error),
    })?;
    let (temporary_path, file) = create_temporary(&directory, &file_name.to_string_lossy())
        .map_err(|error| write_error(describe(&error)))?;
    let written = fill_and_sync(file, bytes).and_then(|()| fs::rename(&temporary_path, path));
    if let Err(error) = written {
        // Best effort: the temporary file is garbage now; the original error is what matters.
        let _ = fs::remove_file(&temporary_path);
        return Err(write_error(describe(&error)));
    }
    sync_directory(&directory);
    Ok(())
}

/// Refuses an `output` path that names the same file as one of `inputs` (compared after
/// resolving `.`/`..` and symbolic links where the paths exist, and by file identity on
/// Unix, so hard links are caught too).
pub fn ensure_not_input(output: &Path, inputs: &[&Path]) -> Result<(), IoError> {
    if output.as_os_str() == STDOUT {
        return Ok(());
    }
    let resolved_output = resolve(output);
    for input in inputs {
        if resolve(input) == resolved_output || same_file(output, input) {
            return Err(IoError::OutputIsInput {
                output: output.display().to_string(),
                input: input.display().to_string(),
            });
        }
    }
    Ok(())
}

/// An operating-system error in lowercase words, for messages.
pub(crate) fn describe(error: &std::io::Error) -> String {
    use std::io::ErrorKind;
    match error.kind() {
        ErrorKind::NotFound => "no such file or directory".to_string(),
        ErrorKind::PermissionDenied => "permission denied".to_string(),
        ErrorKind::IsADirectory => "it is a directory".to_string(),
        ErrorKind::NotADirectory => "a parent of the path is not a directory".to_string(),
        _ => {
            let text = error.to_string();
            let mut chars = text.chars();
            match chars.next() {
                Some(first) => first.to_lowercase().chain(chars).collect(),
                None => "unknown error".to_string(),
            }
        }
    }
}

/// Distinguishes temporary files of one process.
static TEMPORARY_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Creates a fresh hidden temporary file next to the target, never reusing an existing one.
fn create_temporary(directory: &Path, file_name: &str) -> std::io::Result<(PathBuf, File)> {
    loop {
        let count = TEMPORARY_COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = format!(".{file_name}.{}.{count}.tmp", std::process::id());
        let candidate = directory.join(name);
        match OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&candidate)
        {
            Ok(file) => return Ok((candidate, file)),
            Err(error) if error.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(error) => return Err(error),
        }
    }
}

/// Writes all bytes and flushes them to the disk.
fn fill_and_sync(mut file: File, bytes: &[u8]) -> std::io::Result<()> {
    file.write_all(bytes)?;
    file.sync_all()
}

/// Flushes the directory entry of the rename where the platform allows it (best effort: the
/// data itself is already on disk, and some platforms cannot open directories).
fn sync_directory(directory: &Path) {
    if let Ok(handle) = File::open(directory) {
        let _ = handle.sync_all();
    }
}

/// The path with symbolic links and `.`/`..` resolved as far as it exists: the whole path,
/// else its parent (for an output not yet written), else the path made absolute.
fn resolve(path: &Path) -> PathBuf {
    if let Ok(canonical) = fs::canonicalize(path) {
        return canonical;
    }
    let parent = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    match (fs::canonicalize(parent), path.file_name()) {
        (Ok(canonical_parent), Some(name)) => canonical_parent.join(name),
        _ => std::env::current_dir()
            .map(|current| current.join(path))
            .unwrap_or_else(|_| path.to_path_buf()),
    }
}

/// Whether two existing paths are the same file (device and inode), e.g. hard links.
#[cfg(unix)]
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (fs::metadata(a), fs::metadata(b)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Whether two existing paths are the same file: on other platforms path comparison is all
/// there is.
#[cfg(not(unix))]
fn same_file(_a: &Path, _b: &Path) -> bool {
    false
}

/// A scratch directory under the system's temporary directory, unique to one test and
/// removed when dropped. Shared by the tests of the data reader and input programs.
#[cfg(test)]
pub(crate) struct ScratchDir {
    /// The directory.
    pub(crate) path: PathBuf,
}

#[cfg(test)]
impl ScratchDir {
    /// Creates `gbc-<label>-<pid>-<count>` in the temporary directory.
    pub(crate) fn new(label: &str) -> std::io::Result<Self> {
        let count = TEMPORARY_COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = format!("gbc-{label}-{}-{count}", std::process::id());
        let path = std::env::temp_dir().join(name);
        fs::create_dir_all(&path)?;
        Ok(ScratchDir { path })
    }
    /// A path inside the directory.
    pub(crate) fn join(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }
}

#[cfg(test)]
impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    #[test]
    fn write_atomic_creates_parents_and_replaces_content() -> TestResult {
        let scratch = ScratchDir::new("io-write")?;
        let target = scratch.join("nested/deeper/out.csv");
        write_atomic(&target, b"first")?;
        assert_eq!(fs::read(&target)?, b"first");
        write_atomic(&target, b"second, longer")?;
        assert_eq!(fs::read(&target)?, b"second, longer");
        let leftovers: Vec<_> = fs::read_dir(scratch.join("nested/deeper"))?
            .filter_map(|entry| entry.ok())
            .map(|entry| entry.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            leftovers,
            vec!["out.csv".to_string()],
            "no temporary file is left"
        );
        Ok(())
    }

    #[test]
    fn write_atomic_onto_a_directory_fails_naming_the_path() -> TestResult {
        let scratch = ScratchDir::new("io-dir")?;
        let target = scratch.join("taken");
        fs::create_dir_all(target.join("inner"))?;
        let error = write_atomic(&target, b"x")
            .err()
            .ok_or("expected an error")?;
        assert!(matches!(error, IoError::Write { .. }), "{error:?}");
        assert!(error.to_string().contains("taken"), "{error}");
        assert_eq!(code(&error), "gbm::E0250");
        let leftovers = fs::read_dir(&scratch.path)?.count();
        assert_eq!(
            leftovers, 1,
            "only the directory remains, no temporary file"
        );
        Ok(())
    }

    #[test]
    fn write_atomic_under_a_file_cannot_create_the_directory() -> TestResult {
        let scratch = ScratchDir::new("io-parent")?;
        let blocker = scratch.join("plain-file");
        fs::write(&blocker, b"not a directory")?;
        let error = write_atomic(&blocker.join("out.csv"), b"x")
            .err()
            .ok_or("expected an error")?;
        assert_eq!(code(&error), "gbm::E0251");
        assert!(error.to_string().contains("plain-file"), "{error}");
        Ok(())
    }

    #[test]
    fn ensure_not_input_catches_the_same_file_under_another_spelling() -> TestResult {
        let scratch = ScratchDir::new("io-guard")?;
        let input = scratch.join("data.csv");
        fs::write(&input, b"t,u\n0,1\n")?;
        let spelled_otherwise = scratch.path.join(".").join("data.csv");
        let error = ensure_not_input(&spelled_otherwise, &[Path::new("model.gbm"), &input])
            .err()
            .ok_or("expected an error")?;
        assert_eq!(code(&error), "gbm::E0252");
        assert!(error.to_string().contains("data.csv"), "{error}");
        let other = scratch.join("out.csv");
        assert_eq!(ensure_not_input(&other, &[&input]), Ok(()));
        Ok(())
    }

    #[cfg(unix)]
    #[test]
    fn ensure_not_input_catches_links() -> TestResult {
        let scratch = ScratchDir::new("io-links")?;
        let input = scratch.join("data.csv");
        fs::write(&input, b"t\n0\n")?;
        let symbolic = scratch.join("alias.csv");
        std::os::unix::fs::symlink(&input, &symbolic)?;
        let hard = scratch.join("hard.csv");
        fs::hard_link(&input, &hard)?;
        assert!(ensure_not_input(&symbolic, &[&input]).is_err());
        assert!(ensure_not_input(&hard, &[&input]).is_err());
        Ok(())
    }

    #[test]
    fn ensure_not_input_compares_paths_that_do_not_exist_yet() {
        let missing = Path::new("no-such-dir-for-gbc/out.csv");
        let result = ensure_not_input(
            missing,
            &[Path::new(
                "no-such-dir-for-gbc/../no-such-dir-for-gbc/out.csv",
            )],
        );
        // Neither exists, so only the spelled paths are compared: different spellings pass.
        assert_eq!(result, Ok(()));
        let same = ensure_not_input(missing, &[missing]);
        assert!(same.is_err());
    }

    #[test]
    fn describe_lowercases_operating_system_messages() {
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(describe(&missing), "no such file or directory");
        let other = std::io::Error::other("Disk Full");
        assert_eq!(describe(&other), "disk Full");
    }

    fn code(error: &IoError) -> String {
        error
            .code()
            .map(|code| code.to_string())
            .unwrap_or_default()
    }
}
