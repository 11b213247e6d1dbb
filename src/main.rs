//! The `gbc` command line: a short dispatch over subcommands (`src/cli/`). It is a module of
//! this binary, not of the library, so it reaches the compiler through `gbc::api` alone.

mod cli;

fn main() {
    std::process::exit(cli::main());
}
