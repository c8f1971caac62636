//! Bad and awkward input through the `tacit` binary: every numeric option
//! refused up front with a message naming it, quiet ends on a closed pipe,
//! outputs whole or not at all, record checks (units, dead, clipped,
//! spiky, offset channels, missing force), messages without internals.
//! Each test holds one row of docs/reliability.md.

mod common;

use common::{stderr, tacit};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use tacit::record::{self, Channel, Record};

const MODEL: &str = "data/lanl8dof.toml";
const CONTACT: &str = "data/lanl8dof-contact.toml";
const BUMPER: &str = "data/lanl8dof-bumper.h5";

/// Exit 1, the message holds every `needle`, no panic, no Rust debug text.
fn fails_with(o: &Output, needles: &[&str]) -> String {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(1), "exit {:?}: {e}", o.status);
    for n in needles {
        assert!(e.contains(n), "missing {n:?} in: {e}");
    }
    assert!(!e.contains("panicked") && !e.contains("{ "), "{e}");
    e
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn bumper() -> Record {
    record::read(&Path::new(env!("CARGO_MANIFEST_DIR")).join(BUMPER)).unwrap()
}

/// Write `rec` to `dir/name` (HDF5 keeps the channel units).
fn save(rec: &Record, dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    record::write(rec, &path).unwrap();
    path
}

fn output_mut<'a>(rec: &'a mut Record, name: &str) -> &'a mut Channel {
    rec.outputs.iter_mut().find(|c| c.name() == name).unwrap()
}

/// `identify` on a record (fast; runs the record checks first).
fn identify(rec: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "identify",
        "--model",
        MODEL,
        "--record",
        p(rec),
        "--sensors",
        "1,5,6",
        "--no-figures",
        "-o",
        p(out),
    ];
    args.extend_from_slice(extra);
    tacit(&args)
}

/// `diagnose` of a record against the declared model.
fn diagnose(rec: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "diagnose",
        "--model",
        MODEL,
        "--record",
        p(rec),
        "-o",
        p(out),
    ];
    args.extend_from_slice(extra);
    tacit(&args)
}

fn hidden_entries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

// ---- options -------------------------------------------------------------

#[test]
fn huge_substeps_are_refused_by_every_command() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o");
    let o = tacit(&[
        "simulate",
        "--model",
        CONTACT,
        "--substeps",
        "1000000000",
        "--samples",
        "16",
        "-o",
        p(&d.path().join("r.h5")),
    ]);
    fails_with(&o, &["--substeps 1000000000", "1..=1000"]);
    let o = diagnose(Path::new(BUMPER), &out, &["--substeps", "1000000000"]);
    fails_with(&o, &["--substeps 1000000000"]);
    let o = identify(Path::new(BUMPER), &out, &["--substeps", "1000000000"]);
    fails_with(&o, &["--substeps 1000000000"]);
    assert!(!out.exists());
}

#[test]
fn memory_estimate_refuses_a_run_larger_than_the_machine() {
    let avail = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| {
            let l = t
                .lines()
                .find(|l| l.starts_with("MemAvailable:"))?
                .to_string();
            l.split_whitespace().nth(1)?.parse::<f64>().ok()
        })
        .map(|kb| kb * 1024.0);
    // 1e8 samples of 8 DOFs: about 70 GB of states
    match avail {
        Some(b) if b < 6e10 => {}
        _ => {
            eprintln!("skipped: this machine has more than 60 GB available");
            return;
        }
    }
    let d = tempfile::tempdir().unwrap();
    let o = tacit(&[
        "simulate",
        "--model",
        MODEL,
        "--samples",
        "100000000",
        "-o",
        p(&d.path().join("r.h5")),
    ]);
    fails_with(&o, &["needs about", "GB of memory", "available"]);
}

#[test]
fn alpha_grid_count_is_bounded() {
    let d = tempfile::tempdir().unwrap();
    let o = identify(
        Path::new(BUMPER),
        &d.path().join("o"),
        &["--alpha-select", "gcv", "--alpha-grid", "1e-3,1,1000000000"],
    );
    fails_with(&o, &["--alpha-grid 1000000000", "2..=200"]);
    let o = identify(
        Path::new(BUMPER),
        &d.path().join("o"),
        &["--alpha-grid", "1,1e-3,10"],
    );
    fails_with(&o, &["--alpha-grid", "0 < lowest < highest"]);
}

#[test]
fn segment_inf_tiny_and_max_effects_zero_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o");
    let run = |extra: &[&str]| diagnose(Path::new(BUMPER), &out, extra);
    fails_with(&run(&["--segment", "inf"]), &["--segment inf"]);
    let e = fails_with(&run(&["--segment", "1e-9"]), &["--segment 0.000000001 s"]);
    assert!(e.contains("0.015625 to 4.000000 s"), "{e}");
    assert!(!e.contains("18446744073709551615"), "{e}");
    fails_with(
        &run(&["--max-effects", "0"]),
        &["--max-effects 0", "search for nothing"],
    );
    assert!(!out.exists());
}

#[test]
fn fs_zero_is_blamed_on_fs_and_band_on_nyquist() {
    let d = tempfile::tempdir().unwrap();
    let r = d.path().join("r.h5");
    let o = tacit(&["simulate", "--model", MODEL, "--fs", "0", "-o", p(&r)]);
    let e = fails_with(&o, &["--fs 0"]);
    assert!(!e.contains("band"), "{e}");
    let o = tacit(&["simulate", "--model", MODEL, "--fs", "256", "-o", p(&r)]);
    fails_with(&o, &["--band 5,200", "Nyquist frequency 128 Hz"]);
    let o = tacit(&["simulate", "--model", MODEL, "--rms=-1", "-o", p(&r)]);
    fails_with(&o, &["--rms -1"]);
    let o = tacit(&["simulate", "--model", MODEL, "--noise", "nan", "-o", p(&r)]);
    fails_with(&o, &["--noise NaN"]);
    assert!(!r.exists());
}

#[test]
fn window_longer_than_the_record_is_blamed_on_window() {
    let d = tempfile::tempdir().unwrap();
    let o = identify(
        Path::new(BUMPER),
        &d.path().join("o"),
        &["--window", "5000"],
    );
    let e = fails_with(&o, &["--window 5000", "1..=4096"]);
    assert!(!e.contains("--horizon"), "{e}");
    let o = identify(
        Path::new(BUMPER),
        &d.path().join("o"),
        &["--method", "mhe", "--window", "30", "--horizon", "10"],
    );
    fails_with(&o, &["--horizon 10", "30..=4096"]);
}

// ---- pipes and messages ----------------------------------------------------

/// Run with stdout closed before the first write (as `| head -1` does
/// after its line): exit 0, nothing on stderr about the pipe.
fn closed_pipe(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_tacit"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let status = child.wait().unwrap();
    Output {
        status,
        stdout: vec![],
        stderr: err.into_bytes(),
    }
}

#[test]
fn broken_pipe_ends_quietly() {
    let d = tempfile::tempdir().unwrap();
    for args in [
        vec!["modal", "--model", MODEL],
        vec!["modal", "--model", MODEL, "--json"],
        vec![
            "simulate",
            "--model",
            MODEL,
            "--samples",
            "64",
            "-o",
            p(&d.path().join("r.csv")),
        ],
    ] {
        let o = closed_pipe(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {e}");
        assert!(!e.contains("panicked") && !e.contains("Broken pipe"), "{e}");
    }
    let out = d.path().join("i");
    let o = closed_pipe(&[
        "identify",
        "--model",
        MODEL,
        "--record",
        BUMPER,
        "--sensors",
        "1,5,6",
        "--no-figures",
        "-o",
        p(&out),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        out.join("summary.json").exists(),
        "the outputs are written before the summary"
    );
}

#[test]
fn os_errors_are_printed_once_and_name_the_users_path() {
    let d = tempfile::tempdir().unwrap();
    let file = d.path().join("plain");
    std::fs::write(&file, "x").unwrap();
    let o = tacit(&[
        "simulate",
        "--model",
        MODEL,
        "--samples",
        "64",
        "-o",
        p(&file.join("sub/r.csv")),
    ]);
    let e = fails_with(&o, &["plain"]);
    assert_eq!(e.matches("os error").count(), 1, "{e}");
    assert!(!e.contains("tmp-"), "{e}");
    let o = identify(Path::new(BUMPER), &file, &[]);
    fails_with(&o, &["not a directory"]);
}

#[test]
fn help_has_no_internals_and_says_where_indices_count_from() {
    for cmd in ["modal", "simulate", "identify", "update", "diagnose"] {
        let o = tacit(&[cmd, "--help"]);
        let h = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(o.status.success(), "{cmd}: {h}");
        for bad in [
            "[`",
            "::",
            "Evaluator",
            "JacobianMethod",
            "CentralDifference",
        ] {
            assert!(!h.contains(bad), "{cmd} --help holds {bad:?}:\n{h}");
        }
    }
    let h = String::from_utf8_lossy(&tacit(&["update", "--help"]).stdout).into_owned();
    assert!(
        h.contains("counts the model file's elements of that kind from 1"),
        "{h}"
    );
    let h = String::from_utf8_lossy(&tacit(&["modal", "--help"]).stdout).into_owned();
    assert!(
        h.contains("force|hybrid") && h.contains("serep|dynamic"),
        "{h}"
    );
    let h = String::from_utf8_lossy(&tacit(&["--help"]).stdout).into_owned();
    assert!(!h.contains("sliding windows"), "{h}");
}

#[test]
fn identify_status_in_words_and_divergence_exits_non_zero() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("paper");
    let o = identify(Path::new(BUMPER), &out, &["--method", "paper"]);
    let e = fails_with(&o, &["diverged from sample", "for inspection"]);
    let so = String::from_utf8_lossy(&o.stdout);
    assert!(!so.contains("{\"") && !e.contains("{\""), "{so}{e}");
    assert!(out.join("summary.json").exists());
}

/// A horizon identification whose force weight is too small for double
/// precision (`--lambda 1e-12` on the bumper) gives a NaN force: an error
/// naming the stage, component and sample; nothing written; never "NaN %"
/// with status ok.
#[test]
fn identify_with_a_non_finite_force_is_an_error_naming_the_stage() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("nan");
    // a fixed weight that small (the weight rules never choose it: the
    // discrepancy principle falls back to the L-curve corner)
    let args = [
        "--method",
        "horizon",
        "--weights",
        "fixed",
        "--lambda",
        "1e-16",
    ];
    let o = identify(Path::new(BUMPER), &out, &args);
    let e = fails_with(
        &o,
        &[
            "the identification (horizon) of",
            "gave a non-finite identified force at f_1, sample 0",
            "nothing was written",
        ],
    );
    assert!(!e.contains("NaN %"), "{e}");
    assert!(!String::from_utf8_lossy(&o.stdout).contains("NaN"));
    assert!(!out.exists());
    // the same method with a usable weight runs
    let o = identify(
        Path::new(BUMPER),
        &out,
        &[
            "--method",
            "horizon",
            "--weights",
            "fixed",
            "--lambda",
            "1e-8",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
}

// ---- outputs whole or not at all -----------------------------------------

#[test]
fn existing_report_is_refused_before_work_and_force_replaces_it_whole() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("summary.json"), "{}").unwrap();
    std::fs::write(out.join("stale.png"), "old").unwrap();
    let t = std::time::Instant::now();
    let o = identify(Path::new(BUMPER), &out, &[]);
    fails_with(&o, &["already holds a tacit report", "--force"]);
    assert!(t.elapsed().as_secs_f64() < 5.0);
    assert!(
        out.join("stale.png").exists(),
        "a refused run touches nothing"
    );
    let o = identify(Path::new(BUMPER), &out, &["--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("stale.png").exists(), "stale file left");
    assert!(out.join("forces.csv").exists());
    assert!(
        hidden_entries(d.path()).is_empty(),
        "{:?}",
        hidden_entries(d.path())
    );
    // a directory of someone else's files is never replaced
    let mine = d.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), "keep").unwrap();
    let o = identify(Path::new(BUMPER), &mine, &["--force"]);
    fails_with(&o, &["holds files tacit did not write"]);
    assert!(mine.join("notes.txt").exists());
}

#[test]
fn a_locked_directory_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o");
    // the lock of a live process (this test)
    std::fs::write(
        d.path().join(".o.lock"),
        format!("{}\n", std::process::id()),
    )
    .unwrap();
    let o = identify(Path::new(BUMPER), &out, &[]);
    fails_with(&o, &["another tacit run", "is writing there"]);
    assert!(!out.exists());
    // a lock left by a process that is gone is taken over
    std::fs::write(d.path().join(".o.lock"), "4294967\n").unwrap();
    let o = identify(Path::new(BUMPER), &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        hidden_entries(d.path()).is_empty(),
        "{:?}",
        hidden_entries(d.path())
    );
}

#[test]
fn sigterm_removes_the_temporary_directory() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o");
    let mut child = Command::new(env!("CARGO_BIN_EXE_tacit"))
        .args([
            "diagnose",
            "--model",
            MODEL,
            "--record",
            BUMPER,
            "-o",
            p(&out),
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    while hidden_entries(d.path()).len() < 2 && t.elapsed().as_secs() < 20 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert_eq!(
        hidden_entries(d.path()).len(),
        2,
        "lock and temporary directory"
    );
    std::thread::sleep(std::time::Duration::from_millis(300));
    let k = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(k.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{status:?}");
    assert!(
        hidden_entries(d.path()).is_empty(),
        "{:?}",
        hidden_entries(d.path())
    );
    assert!(!out.exists());
}

#[test]
fn simulate_creates_parents_and_keeps_no_record_when_its_truth_fails() {
    let d = tempfile::tempdir().unwrap();
    let rec = d.path().join("a/b/rec.csv");
    let o = tacit(&[
        "simulate",
        "--model",
        MODEL,
        "--samples",
        "64",
        "-o",
        p(&rec),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(rec.exists() && d.path().join("a/b/rec-truth.csv").exists());
    // the truth file cannot be written (a directory is in its place)
    let rec2 = d.path().join("c/rec.csv");
    std::fs::create_dir_all(d.path().join("c/rec-truth.csv")).unwrap();
    let o = tacit(&[
        "simulate",
        "--model",
        MODEL,
        "--samples",
        "64",
        "-o",
        p(&rec2),
    ]);
    fails_with(&o, &["rec-truth.csv"]);
    assert!(!rec2.exists(), "rec.csv kept although its truth failed");
    assert!(hidden_entries(&d.path().join("c")).is_empty());
}

#[test]
fn simulate_refuses_a_non_utf8_hdf5_name() {
    use std::os::unix::ffi::OsStrExt;
    let d = tempfile::tempdir().unwrap();
    let name = std::ffi::OsStr::from_bytes(b"r\xff.h5");
    let path = d.path().join(name);
    let o = Command::new(env!("CARGO_BIN_EXE_tacit"))
        .args(["simulate", "--model", MODEL, "--samples", "64", "-o"])
        .arg(&path)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    fails_with(&o, &["must be valid UTF-8"]);
    assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
}

// ---- records -------------------------------------------------------------

#[test]
fn unit_attribute_g_is_converted_to_si() {
    let d = tempfile::tempdir().unwrap();
    let orig = bumper();
    let mut rec = orig.clone();
    for c in &mut rec.outputs {
        c.unit = "g".into();
        for x in &mut c.data {
            *x /= 9.80665;
        }
    }
    output_mut(&mut rec, "accel_1").unit = "mm/s^2".into();
    for x in &mut output_mut(&mut rec, "accel_1").data {
        *x *= 9.80665e3;
    }
    rec.inputs[0].unit = "kN".into();
    for x in &mut rec.inputs[0].data {
        *x *= 1e-3;
    }
    let path = save(&rec, d.path(), "units.h5");
    let back = record::read(&path).unwrap();
    for (a, b) in back
        .outputs
        .iter()
        .chain(&back.inputs)
        .zip(orig.outputs.iter().chain(&orig.inputs))
    {
        assert_eq!(a.unit, b.unit);
        let err = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        let scale = b.data.iter().fold(0.0f64, |m, y| m.max(y.abs()));
        assert!(err < 1e-12 * scale, "{}: {err}", a.name());
    }
    // an unknown unit is named
    output_mut(&mut rec, "accel_5").unit = "furlong".into();
    let path = save(&rec, d.path(), "bad-unit.h5");
    let e = record::read(&path).unwrap_err().to_string();
    assert!(e.contains("accel_5") && e.contains("furlong"), "{e}");
}

#[test]
fn accelerations_in_g_and_force_in_kn_are_flagged() {
    let d = tempfile::tempdir().unwrap();
    let mut rec = bumper();
    for c in &mut rec.outputs {
        for x in &mut c.data {
            *x /= 9.80665;
        }
    }
    let g = save(&rec, d.path(), "g.h5");
    let o = identify(&g, &d.path().join("o1"), &[]);
    assert!(
        stderr(&o).contains("look like they are in g"),
        "{}",
        stderr(&o)
    );
    let mut rec = bumper();
    for x in &mut rec.inputs[0].data {
        *x *= 1e-3;
    }
    let kn = save(&rec, d.path(), "kn.h5");
    let o = identify(&kn, &d.path().join("o2"), &[]);
    assert!(
        stderr(&o).contains("force looks like it is in kN"),
        "{}",
        stderr(&o)
    );
    let o = identify(Path::new(BUMPER), &d.path().join("o3"), &[]);
    assert!(!stderr(&o).contains("warning: data"), "{}", stderr(&o));
}

#[test]
fn missing_force_and_dead_selected_channel_are_errors_naming_the_channel() {
    let d = tempfile::tempdir().unwrap();
    let mut rec = bumper();
    rec.inputs.clear();
    let nf = save(&rec, d.path(), "noforce.h5");
    let out = d.path().join("o");
    let o = diagnose(&nf, &out, &[]);
    fails_with(&o, &["no force channel", "noforce.h5"]);
    assert!(!out.exists());
    let mut rec = bumper();
    output_mut(&mut rec, "accel_6").data.fill(0.0);
    let dead = save(&rec, d.path(), "dead.h5");
    let o = diagnose(&dead, &out, &[]);
    let e = fails_with(&o, &["channel accel_6 is dead"]);
    assert!(!e.contains("channel 5"), "{e}");
    let o = identify(&dead, &out, &[]);
    fails_with(&o, &["channel accel_6 is dead"]);
    assert!(!out.exists());
    // not selected: a warning, and the run goes on
    let o = tacit(&[
        "identify",
        "--model",
        MODEL,
        "--record",
        p(&dead),
        "--sensors",
        "1,5",
        "--no-figures",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("warning") && stderr(&o).contains("accel_6 is dead"));
}

#[test]
fn spike_clipping_and_offset_are_named() {
    let d = tempfile::tempdir().unwrap();
    let mut rec = bumper();
    output_mut(&mut rec, "accel_5").data[1000] = 1e6;
    let path = save(&rec, d.path(), "spike.h5");
    let o = identify(&path, &d.path().join("o1"), &[]);
    // (the MHE estimate then diverges at the spike: exit 1, also named)
    assert!(
        stderr(&o).contains("accel_5 has 1 isolated spike(s), the first at sample 1000"),
        "{}",
        stderr(&o)
    );

    let mut rec = bumper();
    for x in &mut output_mut(&mut rec, "accel_1").data {
        *x = x.clamp(-10.0, 10.0);
    }
    let path = save(&rec, d.path(), "clip.h5");
    let o = identify(&path, &d.path().join("o2"), &[]);
    fails_with(&o, &["accel_1 looks clipped", "-10 / 10"]);

    let mut rec = bumper();
    for x in &mut output_mut(&mut rec, "accel_6").data {
        *x += 5.0;
    }
    let path = save(&rec, d.path(), "offset.h5");
    let o = identify(&path, &d.path().join("o3"), &[]);
    assert!(
        stderr(&o).contains("accel_6 (mean 2.5424 m/s^2; an offset of 5.0"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn diagnose_report_carries_the_record_warnings() {
    let d = tempfile::tempdir().unwrap();
    let mut rec = bumper();
    output_mut(&mut rec, "accel_2").data[2000] = 1e6;
    let path = save(&rec, d.path(), "spike.h5");
    let out = d.path().join("o");
    let o = diagnose(&path, &out, &["--sensors", "1,5,6"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let w = json["warnings"].as_array().unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0]
        .as_str()
        .unwrap()
        .contains("accel_2 has 1 isolated spike"));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## Warnings about the records") && md.contains("accel_2"));
}

#[test]
fn csv_with_six_decimal_time_stamps_is_read() {
    let d = tempfile::tempdir().unwrap();
    let rec = bumper();
    let mut text = String::from("time,force_1\n");
    for (k, f) in rec.inputs[0].data.iter().enumerate() {
        text.push_str(&format!("{:.6},{f}\n", k as f64 / rec.fs));
    }
    let csv = d.path().join("force.csv");
    std::fs::write(&csv, text).unwrap();
    let out = d.path().join("sim.h5");
    let o = tacit(&[
        "simulate",
        "--model",
        MODEL,
        "--input",
        "record",
        "--from",
        p(&csv),
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let back = record::read(&out).unwrap();
    assert!((back.fs - 512.0).abs() < 1e-3, "{}", back.fs);
    assert_eq!(back.len(), 4096);
}

/// `M` with spring `k5` at `stiffness`, the damping `damping` (a TOML
/// table body), written to `dir/name`.
fn stiff_model(dir: &Path, name: &str, stiffness: &str, damping: &str) -> PathBuf {
    let m = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(MODEL)).unwrap();
    let at = m.find("name = \"k5\"").unwrap();
    let k = at + m[at..].find("56700.0").unwrap();
    let mut s = format!("{}{stiffness}{}", &m[..k], &m[k + 7..]);
    let d = s.find("[damping]").unwrap();
    s.truncate(d);
    s += &format!("[damping]\n{damping}\n");
    let path = dir.join(name);
    std::fs::write(&path, s).unwrap();
    path
}

#[test]
fn stiff_spring_modes_are_an_error_with_the_stiffness_ratio() {
    let d = tempfile::tempdir().unwrap();
    let m = stiff_model(
        d.path(),
        "stiff.toml",
        "1e20",
        "kind = \"modal\"\nratio = 0.01",
    );
    let o = tacit(&["modal", "--model", p(&m)]);
    fails_with(
        &o,
        &[
            "too ill-conditioned",
            "stiffness ratio of 2.352e15",
            "DOF 5",
            "mode(s) 1, 2, 3, 4, 5, 6, 7",
            "without moving as rigid bodies",
        ],
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("rigid"));
    // 1e12 N/m (a ratio of 1.8e7) still resolves: the 22 Hz mode is not rigid
    let m = stiff_model(
        d.path(),
        "firm.toml",
        "1e12",
        "kind = \"modal\"\nratio = 0.01",
    );
    let o = tacit(&["modal", "--model", p(&m), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rigid = j.to_string().matches("\"rigid\":true").count();
    assert_eq!(rigid, 1, "{j}");
}

#[test]
fn stiff_spring_simulation_diverges_with_the_facts() {
    let d = tempfile::tempdir().unwrap();
    let m = stiff_model(d.path(), "stiff.toml", "1e20", "kind = \"none\"");
    let out = d.path().join("s.csv");
    let o = tacit(&[
        "simulate",
        "--model",
        p(&m),
        "--substeps",
        "10",
        "-o",
        p(&out),
    ]);
    fails_with(
        &o,
        &[
            "diverged from sample 65",
            "DOF 5",
            "3.476e9 Hz",
            "42651158 sub-steps per sample, beyond the 1000 allowed",
        ],
    );
    assert!(!out.exists());
    // by default: the most sub-steps allowed, with a warning
    let o = tacit(&["simulate", "--model", p(&m), "-o", p(&out)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("asks for 2132557885 sub-steps per sample")
            && err.contains("at the most allowed, 1000"),
        "{err}"
    );
}

#[test]
fn declared_stiff_contact_is_not_diagnosed() {
    let d = tempfile::tempdir().unwrap();
    let c = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(CONTACT)).unwrap();
    let m = d.path().join("contact20.toml");
    std::fs::write(&m, c.replace("stiffness = 2.0e6", "stiffness = 1e20")).unwrap();
    let out = d.path().join("d");
    let o = tacit(&[
        "diagnose",
        "--model",
        p(&m),
        "--record",
        BUMPER,
        "-o",
        p(&out),
    ]);
    fails_with(
        &o,
        &[
            "the declared model lanl8dof-contact cannot be scored on the record",
            "the Newton iterations did not converge",
            "beyond the 1000 allowed",
        ],
    );
    assert!(!out.exists());
}

#[test]
fn tiny_masses_with_huge_springs_are_an_error_not_nan_shapes() {
    let d = tempfile::tempdir().unwrap();
    let m = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(MODEL)).unwrap();
    let masses = m.lines().find(|l| l.starts_with("masses")).unwrap();
    let tiny = m
        .replace(masses, &format!("masses = [{}]", ["1e-300"; 8].join(", ")))
        .replace("56700.0", "1e300");
    let path = d.path().join("tiny.toml");
    std::fs::write(&path, tiny).unwrap();
    let o = tacit(&["modal", "--model", p(&path)]);
    let e = fails_with(
        &o,
        &["modes are not finite", "DOF 1 is 1.000e300 / 1.000e-300"],
    );
    assert!(!e.contains("NaN") && !String::from_utf8_lossy(&o.stdout).contains("NaN"));
}

#[test]
fn values_beyond_1e100_are_refused_by_every_command() {
    let d = tempfile::tempdir().unwrap();
    let mut rec = bumper();
    for c in rec.inputs.iter_mut().chain(rec.outputs.iter_mut()) {
        c.data.iter_mut().for_each(|x| *x *= 1e300);
    }
    let big = save(&rec, d.path(), "big.h5");
    let want = [
        "cannot be used as it is",
        "beyond 1e100",
        "other channels too",
    ];
    fails_with(&identify(&big, &d.path().join("i"), &[]), &want);
    let o = diagnose(&big, &d.path().join("d"), &[]);
    fails_with(&o, &want);
    let o = tacit(&[
        "update",
        "--model",
        MODEL,
        "--record",
        p(&big),
        "--free",
        "k5",
        "--data",
        "accel",
        "-o",
        p(&d.path().join("u")),
    ]);
    fails_with(&o, &want);
}
