//! The README's CLI tour, run as written: every `sh` block of the "CLI
//! tour" section, in order, in a fresh directory holding the repository's
//! `data/` and `target/release/tacit` (the binary under test), with
//! `bash -euo pipefail`. Lines that build (`cargo …`, `make …`) are
//! skipped: the binary is already built.

use std::path::Path;
use std::process::Command;

/// The `sh` blocks of the section that starts with `## CLI tour`.
fn tour_script(readme: &str) -> String {
    let start = readme.find("## CLI tour").expect("README has a CLI tour");
    let rest = &readme[start + 3..];
    let section = &rest[..rest.find("\n## ").unwrap_or(rest.len())];
    let mut script = String::new();
    let mut inside = false;
    for line in section.lines() {
        match (inside, line.trim_start()) {
            (false, "```sh") => inside = true,
            (true, "```") => inside = false,
            (true, l) if l.starts_with("cargo ") || l.starts_with("make ") => {}
            (true, _) => {
                script.push_str(line);
                script.push('\n');
            }
            _ => {}
        }
    }
    script
}

#[test]
fn readme_tour_runs_as_written() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let script = tour_script(&readme);
    for bad in ["[--", "|mhe", "|qp", "modes.toml --dofs"] {
        assert!(!script.contains(bad), "the tour holds {bad:?}");
    }
    assert!(script.matches("$T ").count() >= 10, "{script}");
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(root.join("data"), dir.path().join("data")).unwrap();
    std::fs::create_dir_all(dir.path().join("target/release")).unwrap();
    std::os::unix::fs::symlink(
        env!("CARGO_BIN_EXE_tacit"),
        dir.path().join("target/release/tacit"),
    )
    .unwrap();
    let t = std::time::Instant::now();
    let o = Command::new("bash")
        .args(["-euo", "pipefail", "-c", &script])
        .current_dir(dir.path())
        .output()
        .unwrap();
    eprintln!("README tour: {:.1} s", t.elapsed().as_secs_f64());
    assert!(
        o.status.success(),
        "the README tour failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let out = dir.path().join("out/tour");
    for f in [
        "diagnose/report.md",
        "diagnose-156/report.json",
        "identify/forces.csv",
        "identify-horizon/summary.json",
        "rec.h5",
        "sweep.csv",
        "sweep-truth.csv",
        "linear.h5",
        "update/summary.json",
        "bumper-modes.toml",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let so = String::from_utf8_lossy(&o.stdout);
    assert!(so.contains("found contact 5→6"), "{so}");
    bumper_report(&out.join("diagnose"));
    // the shipped test modes: force-residue updating finds k5 near -14 %
    let k5 = so
        .lines()
        .find(|l| l.trim_start().starts_with("k5 "))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.trim_end_matches('%').parse::<f64>().ok())
        .expect("a k5 line");
    assert!((k5 + 14.0).abs() < 0.5, "k5 {k5} %");
}

/// The tour's diagnosis of the bumper, as a person reads it: the gap in
/// mm and the stiffness in N/m with both ± (noise, across the record),
/// the open-loop error explained, the FRF and the restoring force drawn.
fn bumper_report(dir: &Path) {
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    let row = |name: &str| {
        md.lines()
            .find(|l| l.contains(&format!("| {name} |")) && l.contains("contact"))
            .or_else(|| {
                md.lines()
                    .find(|l| l.starts_with(&format!("|  | {name} |")))
            })
            .unwrap_or_else(|| panic!("no {name} row: {md}"))
            .to_string()
    };
    let gap = row("gap");
    assert_eq!(gap.matches(" mm").count(), 4, "{gap}");
    let k = row("stiffness");
    assert_eq!(k.matches(" N/m").count(), 4, "{k}");
    assert!(md.contains("**What ± means.**"), "{md}");
    assert!(
        md.contains("**Why the open-loop error stays high**"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    let quarters = json["effects"][0]["group_estimates"]["gap"]
        .as_array()
        .unwrap();
    assert_eq!(quarters.len(), 4, "{json}");
    for q in quarters {
        // the record's truth is 0.381 mm
        let q = q.as_f64().unwrap();
        assert!((q / 0.381e-3 - 1.0).abs() < 0.05, "quarter gap {q}");
    }
    for f in ["frf.png", "restoring_1.png", "responses.png"] {
        let size = std::fs::metadata(dir.join(f)).map_or(0, |m| m.len());
        assert!(size > 50_000, "{f}: {size} bytes");
        assert!(md.contains(&format!("![{f}]({f})")), "{f} not in report.md");
    }
}

#[test]
fn tour_script_skips_builds_and_keeps_continuations() {
    let md = "x\n## CLI tour\n```sh\ncargo build --release\nT=a\n$T b \\\n  c\n```\ntext\n```sh\n$T d\n```\n## Next\n```sh\n$T e\n```\n";
    assert_eq!(tour_script(md), "T=a\n$T b \\\n  c\n$T d\n");
}
