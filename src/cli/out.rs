//! Standard output that ends quietly when the reader goes away: `tacit
//! modal | head -1` closes the pipe after one line, and the remaining
//! lines are not an error. [`outln!`] and [`out!`] write to stdout and
//! turn a broken pipe into [`PipeClosed`], which `main` answers with a
//! quiet exit.

use std::io::Write;

/// The reader of standard output has gone away (broken pipe).
#[derive(Debug)]
pub struct PipeClosed;

impl std::fmt::Display for PipeClosed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("standard output was closed")
    }
}

impl std::error::Error for PipeClosed {}

/// Write formatted text to stdout; a broken pipe becomes [`PipeClosed`].
pub fn write_stdout(args: std::fmt::Arguments<'_>) -> anyhow::Result<()> {
    let mut lock = std::io::stdout().lock();
    match lock.write_fmt(args).and_then(|()| lock.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(PipeClosed.into()),
        Err(e) => Err(anyhow::anyhow!("cannot write to standard output: {e}")),
    }
}

/// True when the error (or one of its causes) is a closed standard output.
pub fn is_pipe_closed(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<PipeClosed>().is_some()
            || c.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// `print!` to stdout that returns `Err(PipeClosed)` on a broken pipe.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::out::write_stdout(format_args!($($arg)*))?
    };
}

/// `println!` to stdout that returns `Err(PipeClosed)` on a broken pipe.
macro_rules! outln {
    () => {
        $crate::cli::out::write_stdout(format_args!("\n"))?
    };
    ($($arg:tt)*) => {{
        $crate::cli::out::write_stdout(format_args!($($arg)*))?;
        $crate::cli::out::write_stdout(format_args!("\n"))?;
    }};
}

pub(crate) use {out, outln};

/// The message of an error chain, each cause once: a cause whose text the
/// message already holds (an OS error repeated by its wrapper) is skipped.
pub fn error_message(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || msg.contains(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn os_error_is_not_repeated() {
        let io = std::io::Error::from_raw_os_error(17);
        let e = tacit::TacitError::io("out/x", io);
        let msg = error_message(&anyhow::Error::from(e));
        assert_eq!(msg.matches("os error 17").count(), 1, "{msg}");
        assert!(msg.starts_with("out/x: "), "{msg}");
    }

    #[test]
    fn context_and_cause_are_joined() {
        let e = anyhow::anyhow!("inner").context("outer");
        assert_eq!(error_message(&e), "outer: inner");
        let pipe: anyhow::Error = PipeClosed.into();
        assert!(is_pipe_closed(&pipe));
        assert!(!is_pipe_closed(&e));
    }
}
