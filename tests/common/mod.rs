//! Shared by the tests that run the `tacit` binary: a run from the
//! repository's root and its output as text.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Run `tacit` with `args` from the repository's root.
pub fn tacit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tacit"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

/// Standard output, then standard error, of a run.
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Standard error of a run.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `tacit simulate` of a model from matrices measured at `points` (labels,
/// comma-separated) and driven at `input` by a 5 N RMS random force in
/// `band` (Hz, `low,high`), 1024 Hz, 1 % noise; `extra` adds options (the
/// seed, the sub-steps, the samples). Panics with the run's output when it
/// fails.
pub fn simulate_points(
    model: &str,
    points: &str,
    input: &str,
    band: &str,
    extra: &[&str],
    out: &std::path::Path,
) {
    let mut args = vec![
        "simulate",
        "--model",
        model,
        "--points",
        points,
        "--input-point",
        input,
        "--band",
        band,
        "--rms",
        "5",
        "--fs",
        "1024",
        "--noise",
        "0.01",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", out.to_str().unwrap()]);
    let o = tacit(&args);
    assert!(o.status.success(), "{}", text(&o));
}

/// Run `python3 scripts/SCRIPT OUT ARGS` (a script that writes a model
/// from matrices into OUT); false, with a message, when there is no
/// `python3`. Panics with the script's output when it fails.
pub fn script_model(script: &str, out: &std::path::Path, args: &[&str]) -> bool {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(script);
    match Command::new("python3")
        .arg(path)
        .arg(out)
        .args(args)
        .output()
    {
        Ok(o) => {
            assert!(o.status.success(), "{}", text(&o));
            true
        }
        Err(e) => {
            eprintln!("skipped: python3 is needed to run scripts/{script} ({e})");
            false
        }
    }
}

/// A JSON file, parsed.
pub fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}
