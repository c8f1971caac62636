//! The `tacit` command line. Parses arguments (clap), calls the library,
//! writes files; all numerics live in the library.

// `!(x > 0.0)` also rejects NaN; used on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod cli;

use clap::Parser;

fn main() {
    let args = cli::Cli::parse();
    cli::output::install_signal_cleanup();
    match cli::run(args) {
        Ok(()) => {}
        Err(e) if cli::out::is_pipe_closed(&e) => {
            // the reader of stdout has gone (`| head`): a quiet end
            cli::output::remove_registered();
        }
        Err(e) => {
            cli::output::remove_registered();
            eprintln!("tacit: error: {}", cli::out::error_message(&e));
            std::process::exit(1);
        }
    }
}
