//! The `gbc` command line: a short dispatch over subcommands (see `gbc::cli`).
fn main() {
    std::process::exit(gbc::cli::main());
}
