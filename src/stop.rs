//! A request to stop the running job, made by Ctrl-C or SIGTERM (or by a caller of the
//! library) and polled by every long phase: a training between its batches, a fit between
//! its Levenberg–Marquardt trials and its rounds of starts, a diagnosis between its phases.
//! What is done is kept: a training writes the checkpoint of its last whole epoch, a
//! diagnosis the report it has so far, marked partial.
//!
//! The request is one flag for the whole process (a signal is too); a caller that runs
//! several jobs one after the other clears it with [`clear`] between them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, LazyLock};

/// The process's stop request.
static REQUEST: LazyLock<Arc<AtomicBool>> = LazyLock::new(|| Arc::new(AtomicBool::new(false)));

/// Whether a stop was asked for.
pub fn requested() -> bool {
    REQUEST.load(Ordering::Relaxed)
}

/// Asks every running phase to stop.
pub fn request() {
    REQUEST.store(true, Ordering::SeqCst);
}

/// Withdraws the request (a caller about to run another job).
pub fn clear() {
    REQUEST.store(false, Ordering::SeqCst);
}

/// The flag itself, for a [`crate::api::Control`] that checks it.
pub fn flag() -> Arc<AtomicBool> {
    Arc::clone(&REQUEST)
}

/// Installs the handler of Ctrl-C and SIGTERM: the first signal asks to stop and prints
/// `what` happens then on stderr; a second ends the process at once (exit 130). Returns
/// whether the handler could be installed (else the default handling stays).
pub fn on_signal(what: &'static str) -> bool {
    ctrlc::set_handler(move || {
        if REQUEST.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\nstopping: {what} (interrupt again to stop at once)");
    })
    .is_ok()
}
