//! The F-16 ground vibration test files (Noël & Schoukens 2017) read as
//! they are, a modal model identified from the Level-1 record, its
//! open-loop error over the steady-state periods, and the command line.
//! Reads the shared data set beside the checkout; skips with a message
//! when it is absent.

use std::path::PathBuf;
use std::process::Command;
use tacit::cases::f16;
use tacit::diagnose::interface;

fn level(n: u32) -> Option<PathBuf> {
    tacit::record::shared_data(&format!("f16/F16Data_FullMSine_Level{n}.mat"))
}

/// RMS of each output channel over the samples after `warm_up`.
fn steady_rms(rec: &tacit::record::Record, warm_up: usize) -> Vec<f64> {
    rec.outputs
        .iter()
        .map(|c| tacit::signal::rms_of(&c.data[warm_up..]))
        .collect()
}

const MAP: &str =
    "Force=force:exc,Acceleration[1]=accel:exc,Acceleration[2]=accel:wing,Acceleration[3]=accel:payload";

#[test]
fn level1_modal_model_has_the_benchmark_modes_and_simulates_the_record() {
    let (Some(l1), Some(l7)) = (level(1), level(7)) else {
        return;
    };
    let s = f16::Settings::default();
    let rec = f16::read(&l1).unwrap();
    let (fit, text) = f16::linear_model(&rec, &s).unwrap();
    let modes: Vec<f64> = fit
        .section
        .modes
        .iter()
        .filter(|m| !m.residual)
        .map(|m| m.frequency_hz)
        .collect();
    // wing bending near 5.2 Hz and wing torsion near 7.3 Hz (SOURCE of the
    // benchmark), both inside the band
    assert!(modes.iter().any(|f| (f - 5.19).abs() < 0.05), "{modes:?}");
    assert!(modes.iter().any(|f| (f - 7.32).abs() < 0.05), "{modes:?}");
    assert!(modes.len() >= 6, "{modes:?}");
    for e in &fit.fit_error {
        assert!(*e < 0.16, "FRF fit error {:?}", fit.fit_error);
    }
    // the model simulates its own record: open loop from rest, steady
    // periods, each channel's error well below its RMS
    let model = tacit::model::modal::from_toml_str(&text, "l1").unwrap();
    let mut rec = rec;
    model.resolve_channels(&mut rec).unwrap();
    let err = f16::rms_per_channel(&model, &rec, s.warm_up, s.substeps).unwrap();
    let rms = steady_rms(&rec, s.warm_up);
    for c in 0..3 {
        assert!(
            err[c] < 0.3 * rms[c],
            "channel {c}: error {err:?} vs RMS {rms:?}"
        );
    }
    // at Level 7 the nonlinear interface moves the torsion mode: the same
    // model leaves a far larger error relative to the response
    let mut r7 = f16::read(&l7).unwrap();
    model.resolve_channels(&mut r7).unwrap();
    let err7 = f16::rms_per_channel(&model, &r7, s.warm_up, s.substeps).unwrap();
    let rms7 = steady_rms(&r7, s.warm_up);
    for c in 1..3 {
        assert!(
            err7[c] / rms7[c] > 2.0 * err[c] / rms[c],
            "channel {c}: Level 7 {err7:?} / {rms7:?}, Level 1 {err:?} / {rms:?}"
        );
    }
}

#[test]
fn cli_writes_a_modal_model_that_commands_accept() {
    let Some(l1) = level(1) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("f16-linear.toml");
    let tacit = || Command::new(env!("CARGO_BIN_EXE_tacit"));
    let out = tacit()
        .args(["modal", "--record"])
        .arg(&l1)
        .args(["--mat-map", MAP, "--mat-fs", "Fs", "--warm-up", "20.48s"])
        .args([
            "--window",
            "rectangular",
            "--segment",
            "8192",
            "--band",
            "2,15",
        ])
        .args(["--orders", "10,100", "--write-model"])
        .arg(&model)
        .output()
        .unwrap();
    let so = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{so}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        so.contains("exc, wing, payload") && so.contains("residual"),
        "{so}"
    );
    let text = std::fs::read_to_string(&model).unwrap();
    assert!(
        text.contains("[modal]") && text.contains("driving_point = \"exc\""),
        "{text}"
    );
    // the model file is accepted where a model is: its modes printed
    let out = tacit()
        .args(["modal", "--model"])
        .arg(&model)
        .output()
        .unwrap();
    let so = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(so.contains("7.3"), "{so}");
    // a row the file does not have is named with the variable and the file
    let out = tacit()
        .args(["modal", "--record"])
        .arg(&l1)
        .args(["--mat-map", "Force=force:exc,Acceleration[4]=accel:exc"])
        .args(["--mat-fs", "Fs", "--band", "2,15", "--write-model"])
        .arg(dir.path().join("bad.toml"))
        .output()
        .unwrap();
    let se = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        se.contains("Acceleration row 4") && se.contains("Level1"),
        "{se}"
    );
    assert!(!dir.path().join("bad.toml").exists());
}

/// Torsion mode (near 7.3 Hz) of a set of modes: frequency, damping.
fn torsion(modes: &[tacit::model::modal::ModalMode]) -> (f64, f64) {
    let m = modes
        .iter()
        .filter(|m| !m.residual && (m.frequency_hz - 7.25).abs() < 0.3)
        .max_by(|a, b| a.shape[1].abs().total_cmp(&b.shape[1].abs()))
        .expect("a torsion mode near 7.3 Hz");
    (m.frequency_hz, m.damping)
}

/// The case closed end to end with the defaults (the interface candidate:
/// the Jenkins element on the interface coordinate, 150 simulations):
/// the model after is the one ranked first on the estimation records
/// (Levels 1 and 7), and on Level 5 it leaves at most a third of the
/// Level-1 model's error (measured 0.283 / 0.406 / 0.521 m/s² against
/// 0.996 / 2.068 / 1.968).
#[test]
fn closed_loop_level7_validated_on_level5() {
    let (Some(l1), Some(l7), Some(l5)) = (level(1), level(7), level(5)) else {
        return;
    };
    let s = f16::Settings::default();
    let out = f16::run(&l1, &l7, &l5, &s, &|_| {}).unwrap();
    let r = &out.result;
    let v = &r.validation;
    assert_eq!(v.channels, ["accel:exc", "accel:wing", "accel:payload"]);
    // chosen on the estimation records, not on the validation record
    let o = r.interface.as_ref().expect("the interface candidate");
    assert_eq!(r.after_model, o.chosen());
    assert_eq!(r.after_model, interface::JENKINS, "{:?}", o.ranking);
    let cost = |n: &str| o.ranking.iter().find(|x| x.name == n).unwrap().cost;
    assert!(cost(interface::JENKINS) < 0.5 * cost(f16::DIAGNOSED));
    assert!(cost(f16::DIAGNOSED) < cost(f16::LEVEL1));
    for c in 0..3 {
        let (b, a) = (v.before.rms_per_channel[c], v.after.rms_per_channel[c]);
        assert!(b > 0.8 && b < 2.5, "before {c}: {b}");
        assert!(a <= b / 3.0, "channel {c}: after {a} vs before {b}");
        let e = &r.estimation;
        assert!(e.after.rms_per_channel[c] < 0.5 * e.before.rms_per_channel[c]);
    }
    // the effect found: on the interface coordinate, started from the
    // pair the trace located, the coordinate moving with the wing and the
    // payload
    let e = &r.effects_found[0];
    assert_eq!(e.points, [interface::INTERFACE, "ground"]);
    assert_eq!(o.pair.points, ["wing", "payload"]);
    let rf = out.restoring.as_ref().expect("a restoring-force plot");
    assert_eq!(rf.pair, ["wing", "payload"]);
    let first = &rf.follows[0];
    assert!(
        ["wing–ground", "payload–ground"].contains(&first.0.as_str()) && first.1 > 0.9,
        "{:?}",
        rf.follows
    );
    // the element's force never exceeds its slip force, and it slips
    let fmax = rf.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    assert!(
        fmax <= rf.slip_force * (1.0 + 1e-9),
        "{fmax} vs {}",
        rf.slip_force
    );
    assert!(fmax > 0.99 * rf.slip_force, "{fmax} vs {}", rf.slip_force);
    // the interface softens and dissipates more at Level 7
    let (f1, z1) = torsion(&r.linear.section.modes);
    let (f7, z7) = torsion(&r.calibrated_modes);
    assert!(
        f7 < f1 - 0.08,
        "torsion {f1} Hz at Level 1, {f7} Hz at Level 7"
    );
    assert!(
        z7 > 2.0 * z1,
        "torsion damping {z1} at Level 1, {z7} at Level 7"
    );
    // the best localized candidate joins the wing and the payload
    let local = r
        .ranking
        .iter()
        .find(|c| c.2.len() == 2)
        .unwrap_or_else(|| panic!("no candidate between two points: {:?}", r.ranking));
    assert_eq!(local.2, ["wing", "payload"], "{:?}", r.ranking);
}

/// `tacit diagnose --interface` refuses a model that is not a modal model
/// before the diagnosis, naming the option and the file, and writes no
/// output.
#[test]
fn cli_interface_needs_a_modal_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = Command::new(env!("CARGO_BIN_EXE_tacit"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["diagnose", "--model", "data/lanl8dof.toml"])
        .args(["--record", "data/lanl8dof-bumper.h5", "--interface", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let se = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        se.contains("--interface")
            && se.contains("lanl8dof.toml")
            && se.contains("not a modal model"),
        "{se}"
    );
    assert!(!out.exists());
}

/// The interface model with the Level-1 linear part held (a softening
/// cubic spring and a cubic damper between wing and payload) fitted on the
/// first three periods of Level 7: the linear part is untouched, the laws
/// are softening and dissipative, and the model is better than the
/// Level-1 model on Level 5 and close to it on Level 1 (measured on the
/// whole Level-7 record: Level 5 0.80 / 0.73 / 0.74 of the Level-1
/// model's error, Level 1 1.14 / 1.15 / 1.08).
#[test]
fn held_interface_fit_keeps_level1_and_improves_level5() {
    let (Some(l1), Some(l5), Some(l7)) = (level(1), level(5), level(7)) else {
        return;
    };
    let s = f16::Settings::default();
    let (_, text) = f16::linear_model(&f16::read(&l1).unwrap(), &s).unwrap();
    let model = tacit::model::modal::from_toml_str(&text, "l1").unwrap();
    let mut est = f16::read(&l7).unwrap().slice(0, 3 * 8192).unwrap();
    model.resolve_channels(&mut est).unwrap();
    let spec = f16::InterfaceSpec {
        pair: [2, 3],
        starts: (-3.0e12, 1.5e5),
        damper: f16::Damper::Cubic,
        linear: f16::LinearPart::Held,
        ratios_near_hz: vec![5.2, 7.3],
    };
    let fit = f16::interface_fit(&model, &est, &spec, s.substeps).unwrap();
    for p in &fit.parameters {
        assert!(!p.at_bound, "{} held at its bound: {}", p.name, p.value);
    }
    let fitted = fit.model;
    assert_eq!(fitted.springs, model.springs);
    assert_eq!(fitted.damping, model.damping);
    let k3 = fitted.cubics.last().unwrap().k3;
    let c3 = fitted.cubic_dampers.last().unwrap().c3;
    assert!(k3 < 0.0 && c3 > 0.0, "k3 {k3}, c3 {c3}");
    let score = |p: &PathBuf, m: &tacit::model::Model| {
        let mut r = f16::read(p).unwrap();
        m.resolve_channels(&mut r).unwrap();
        f16::rms_per_channel(m, &r, s.warm_up, s.substeps).unwrap()
    };
    let (b5, a5) = (score(&l5, &model), score(&l5, &fitted));
    let (b1, a1) = (score(&l1, &model), score(&l1, &fitted));
    for c in 0..3 {
        assert!(a5[c] < 0.9 * b5[c], "Level 5: {a5:?} vs {b5:?}");
        assert!(a1[c] < 1.25 * b1[c], "Level 1: {a1:?} vs {b1:?}");
    }
}

/// The Jenkins interface at its fitted values (docs/f16.md: k_J 2.9985e6
/// N/m of the 5.3412e6 N/m coupling, slip force 78.65 N, residual mode
/// above the band at 30 % damping; fitted on Level 1 and Level 7): stuck
/// it is the Level-1 model, so Level 1 stays near the Level-1 model's
/// error (measured 1.32 / 1.39 / 1.30 of it), and on Level 5 it leaves
/// 0.53 / 0.37 / 0.39 of the Level-1 model's error.
#[test]
fn jenkins_interface_keeps_level1_and_improves_level5() {
    let (Some(l1), Some(l5)) = (level(1), level(5)) else {
        return;
    };
    let s = f16::Settings::default();
    let (fit, text) = f16::linear_model(&f16::read(&l1).unwrap(), &s).unwrap();
    let model = tacit::model::modal::from_toml_str(&text, "l1").unwrap();
    let spec = interface::FitSpec::default();
    let coupling = model.springs.iter().find(|k| k.dofs == [2, 3]).unwrap();
    approx::assert_relative_eq!(coupling.stiffness, 5.3412e6, max_relative = 1e-4);
    let share = 2.9985e6 / coupling.stiffness;
    let jm = interface::model_with(&fit.section, &spec, &[], share, 78.65).unwrap();
    assert_eq!(jm.jenkins.len(), 1);
    let score = |p: &PathBuf, m: &tacit::model::Model| {
        let mut r = f16::read(p).unwrap();
        m.resolve_channels(&mut r).unwrap();
        f16::rms_per_channel(m, &r, s.warm_up, s.substeps).unwrap()
    };
    let (b5, a5) = (score(&l5, &model), score(&l5, &jm));
    let (b1, a1) = (score(&l1, &model), score(&l1, &jm));
    assert!(a5[0] < 0.6 * b5[0], "Level 5: {a5:?} vs {b5:?}");
    for c in 1..3 {
        assert!(a5[c] < 0.42 * b5[c], "Level 5: {a5:?} vs {b5:?}");
    }
    for c in 0..3 {
        assert!(a1[c] < 1.5 * b1[c], "Level 1: {a1:?} vs {b1:?}");
    }
}

/// The interface's participation in the seven in-band modes (2.96, 3.47,
/// 3.96, 5.19, 6.61, 7.32, 9.17 Hz) and the slip force (N), as fitted by
/// the interface fit of `diagnose::interface` on Levels 1 + 7 (docs/f16.md).
const PARTICIPATIONS: [f64; 7] = [
    0.43523, 0.18298, 0.19369, 0.18105, 0.22471, 0.32557, 0.25887,
];
const SLIP_FORCE: f64 = 225.23;

/// The interface as a coordinate of its own at its fitted values
/// (docs/f16.md: `k_J` 2.9985e6 N/m, the interface's participation in the
/// seven in-band modes and the slip force fitted on Level 1 and Level 7):
/// stuck it is the Level-1 model, so Level 1 keeps the Level-1 model's
/// error, and on Level 5 it leaves at most a third of the Level-1 model's
/// error on every channel (measured 0.28 / 0.20 / 0.26), on Level 3 less
/// than half (0.44 / 0.45 / 0.44); with an elastic softening beside the
/// slider, Level 3 within a third as well.
#[test]
fn interface_coordinate_keeps_level1_and_reaches_a_third_on_level5_and_softened_on_level3() {
    let (Some(l1), Some(l3), Some(l5)) = (level(1), level(3), level(5)) else {
        return;
    };
    let s = f16::Settings::default();
    let (fit, text) = f16::linear_model(&f16::read(&l1).unwrap(), &s).unwrap();
    let model = tacit::model::modal::from_toml_str(&text, "l1").unwrap();
    let coupling = model.springs.iter().find(|k| k.dofs == [2, 3]).unwrap();
    let spec = interface::FitSpec {
        direction: interface::Direction::Coordinate,
        share: 2.9985e6 / coupling.stiffness,
        ..Default::default()
    };
    let jm =
        interface::coordinate_model(&fit.section, &spec, &[], &PARTICIPATIONS, SLIP_FORCE).unwrap();
    assert_eq!(jm.points.last().unwrap(), interface::INTERFACE);
    let score = |p: &PathBuf, m: &tacit::model::Model| {
        let mut r = f16::read(p).unwrap();
        m.resolve_channels(&mut r).unwrap();
        f16::rms_per_channel(m, &r, s.warm_up, s.substeps).unwrap()
    };
    let (b5, a5) = (score(&l5, &model), score(&l5, &jm));
    let (b3, a3) = (score(&l3, &model), score(&l3, &jm));
    let (b1, a1) = (score(&l1, &model), score(&l1, &jm));
    for c in 0..3 {
        assert!(a5[c] < b5[c] / 3.0, "Level 5: {a5:?} vs {b5:?}");
        assert!(a3[c] < 0.5 * b3[c], "Level 3: {a3:?} vs {b3:?}");
        assert!(a1[c] < 1.1 * b1[c], "Level 1: {a1:?} vs {b1:?}");
    }
    // the slider with an elastic softening at its fitted values
    // (docs/f16.md: 4 Jenkins elements on the Iwan stage's coordinate, slip
    // forces 116.52 (i/4)^0.5833 N, a saturating spring of 0.15698 k_J
    // bounded at 24.185 N; fitted on Level 1 and Level 7): Level 3 too
    // within a third of the Level-1 model's error (measured 0.31 / 0.30 /
    // 0.30), Level 5 kept (0.28 / 0.18 / 0.26), Level 1 kept
    let soft = interface::FitSpec {
        elements: 4,
        spread: 0.58332,
        softening: Some(interface::Softening {
            share: 0.156975,
            force: 24.185,
        }),
        ..spec.clone()
    };
    let sm = interface::coordinate_model(&fit.section, &soft, &[], &SOFTENED_AT, 116.518).unwrap();
    assert_eq!(sm.saturating.len(), 1);
    let (s5, s3, s1) = (score(&l5, &sm), score(&l3, &sm), score(&l1, &sm));
    for c in 0..3 {
        assert!(s5[c] < b5[c] / 3.0, "Level 5: {s5:?} vs {b5:?}");
        assert!(s3[c] < b3[c] / 3.0, "Level 3: {s3:?} vs {b3:?}");
        assert!(
            s3[c] < a3[c],
            "Level 3: {s3:?} vs the Jenkins element's {a3:?}"
        );
        assert!(s1[c] < 1.1 * b1[c], "Level 1: {s1:?} vs {b1:?}");
    }
}

/// The interface's participations of the Iwan stage (docs/f16.md), held in
/// the softening stage.
const SOFTENED_AT: [f64; 7] = [
    0.48003, 0.21021, 0.18853, 0.20134, 0.25769, 0.35774, 0.28195,
];
