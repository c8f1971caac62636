//! The added element laws against closed forms: a cubic spring to ground
//! (static deflection, energy), a quadratic spring (asymmetric static
//! deflections, energy), quadratic and cubic dampers (free-decay
//! envelopes), a clearance (the linear frequency inside the gap, the
//! static force beyond it, both sides) and friction between two DOFs
//! (stick below the limit, the limit force when sliding).

use super::*;
use crate::model::{
    Clearance, CubicDamper, Damping, Model, Quadratic, QuadraticDamper, RelativeFriction,
};

/// A model of `masses` with springs `(dofs, k)` and no damping.
fn chain(masses: &[f64], springs: &[(&[usize], f64)]) -> Model {
    let mut text = format!("masses = {masses:?}\n");
    for (d, k) in springs {
        text += &format!("[[spring]]\ndofs = {d:?}\nstiffness = {k}\n");
    }
    Model::from_toml_str(&text, "test").unwrap()
}

/// Run `model` at `fs` with `substeps` under a constant force `f` (one
/// value per DOF) for `ns` samples from `(u0, v0)`.
fn run(
    model: &Model,
    fs: f64,
    substeps: usize,
    f: &[f64],
    ns: usize,
    u0: &[f64],
    v0: &[f64],
) -> Simulation {
    let settings = SimSettings {
        substeps,
        ..Default::default()
    };
    run_with(model, fs, settings, f, ns, u0, v0)
}

/// [`run`] with the integrator settings given.
fn run_with(
    model: &Model,
    fs: f64,
    settings: SimSettings,
    f: &[f64],
    ns: usize,
    u0: &[f64],
    v0: &[f64],
) -> Simulation {
    let force = DMatrix::from_fn(f.len(), ns, |i, _| f[i]);
    let sim = Integrator::new(model, fs, settings)
        .unwrap()
        .run(force.as_view(), u0, v0);
    assert!(sim.completed(), "{:?}", sim.status);
    sim
}

/// Peaks of `x` (local maxima above 0) as (sample, value).
fn peaks(x: &[f64]) -> Vec<(usize, f64)> {
    (1..x.len() - 1)
        .filter(|&k| x[k] > 0.0 && x[k] >= x[k - 1] && x[k] > x[k + 1])
        .map(|k| (k, x[k]))
        .collect()
}

#[test]
fn cubic_spring_to_ground_static_deflection_and_energy() {
    // m = 0.5 kg, k = 5e4 N/m, k3 = 2e11 N/m³ to ground at DOF 1
    let (m, k, k3) = (0.5, 5e4, 2e11);
    let mut model = chain(&[m], &[(&[1], k)]);
    model.cubics = vec![crate::model::Cubic { dofs: vec![1], k3 }];
    // undamped free vibration from 1 mm: E = m v²/2 + k u²/2 + k3 u⁴/4
    let sim = run(&model, 2000.0, 20, &[0.0], 2000, &[1e-3], &[0.0]);
    let energy = |i: usize| {
        let (u, v) = (sim.u[(0, i)], sim.v[(0, i)]);
        0.5 * m * v * v + 0.5 * k * u * u + 0.25 * k3 * u.powi(4)
    };
    let e0 = energy(0);
    let drift = (0..sim.len())
        .map(|i| (energy(i) / e0 - 1.0).abs())
        .fold(0.0, f64::max);
    assert!(drift < 1e-4, "energy drift {drift}");
    // statically loaded (Rayleigh damping to settle): k u + k3 u³ = F
    let u_star: f64 = 1.2e-3;
    let f = k * u_star + k3 * u_star.powi(3);
    model.damping = Damping::Rayleigh {
        alpha: 400.0,
        beta: 0.0,
    };
    let sim = run(&model, 1000.0, 10, &[f], 1000, &[0.0], &[0.0]);
    let u_end = sim.u[(0, sim.len() - 1)];
    assert!((u_end / u_star - 1.0).abs() < 1e-6, "{u_end} vs {u_star}");
    // (a check of the case, not of the integrator: the load is in the
    // hardening range, the linear spring alone would deflect F/k = 6.76 u*)
    assert!(f / k > 3.0 * u_star);
}

#[test]
fn quadratic_spring_deflects_asymmetrically_and_conserves_energy() {
    let (m, k, k2) = (0.5, 5e4, 1e7);
    let mut model = chain(&[m], &[(&[1], k)]);
    model.quadratics = vec![Quadratic { dofs: vec![1], k2 }];
    model.damping = Damping::Rayleigh {
        alpha: 400.0,
        beta: 0.0,
    };
    // k u + k2 u² = F at u = ±1 mm: F+ = 60 N, F− = −40 N
    for u_star in [1e-3, -1e-3] {
        let f = k * u_star + k2 * u_star * u_star;
        let sim = run(&model, 1000.0, 10, &[f], 1000, &[0.0], &[0.0]);
        let u_end = sim.u[(0, sim.len() - 1)];
        assert!(
            (u_end / u_star - 1.0).abs() < 1e-6,
            "{u_end} vs {u_star} under {f} N"
        );
    }
    // undamped: E = m v²/2 + k u²/2 + k2 u³/3 (u stays above −k/k2 = −5 mm)
    model.damping = Damping::None;
    let sim = run(&model, 2000.0, 20, &[0.0], 2000, &[2e-3], &[0.0]);
    let energy = |i: usize| {
        let (u, v) = (sim.u[(0, i)], sim.v[(0, i)]);
        0.5 * m * v * v + 0.5 * k * u * u + k2 * u.powi(3) / 3.0
    };
    let e0 = energy(0);
    let drift = (0..sim.len())
        .map(|i| (energy(i) / e0 - 1.0).abs())
        .fold(0.0, f64::max);
    assert!(drift < 1e-4, "energy drift {drift}");
    // the swing is asymmetric: the stiffer side (u > 0) is reached less far
    let u: Vec<f64> = sim.u.row(0).iter().copied().collect();
    let lo = u.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(lo < -2.1e-3, "the softer side swings further: {lo}");
}

#[test]
fn quadratic_damping_decays_as_one_over_one_plus_a_t() {
    // m ü + k u + c2 u̇|u̇| = 0: averaging over a cycle,
    // A(t) = A0 / (1 + a t), a = 4 c2 ω A0 / (3π m)
    let (m, k, c2, a0) = (0.5, 5e4, 2.0, 2e-3);
    let mut model = chain(&[m], &[(&[1], k)]);
    model.quadratic_dampers = vec![QuadraticDamper { dofs: vec![1], c2 }];
    let fs = 4000.0;
    let sim = run(&model, fs, 10, &[0.0], 8000, &[a0], &[0.0]);
    let w = (k / m).sqrt();
    let a = 4.0 * c2 * w * a0 / (3.0 * std::f64::consts::PI * m);
    let u: Vec<f64> = sim.u.row(0).iter().copied().collect();
    let pk = peaks(&u);
    assert!(pk.len() > 50);
    let last = pk[pk.len() - 1];
    let t = last.0 as f64 / fs;
    assert!(a * t > 1.0, "the test must decay: a t = {}", a * t);
    for &(i, p) in pk.iter().skip(5) {
        let law = a0 / (1.0 + a * i as f64 / fs);
        assert!((p / law - 1.0).abs() < 0.02, "peak {p} at {i} vs {law}");
    }
}

#[test]
fn cubic_damping_decays_as_the_averaged_law() {
    // m ü + k u + c3 u̇³ = 0: 1/A² = 1/A0² + (3 c3 ω² / (4 m)) t
    let (m, k, c3, a0) = (0.5, 5e4, 100.0, 2e-3);
    let mut model = chain(&[m], &[(&[1], k)]);
    model.cubic_dampers = vec![CubicDamper { dofs: vec![1], c3 }];
    let fs = 4000.0;
    let sim = run(&model, fs, 10, &[0.0], 8000, &[a0], &[0.0]);
    let w2 = k / m;
    let b = 3.0 * c3 * w2 / (4.0 * m);
    let u: Vec<f64> = sim.u.row(0).iter().copied().collect();
    let pk = peaks(&u);
    let t_end = pk[pk.len() - 1].0 as f64 / fs;
    assert!(b * a0 * a0 * t_end > 1.0, "the test must decay");
    for &(i, p) in pk.iter().skip(5) {
        let law = 1.0 / (1.0 / (a0 * a0) + b * i as f64 / fs).sqrt();
        assert!((p / law - 1.0).abs() < 0.02, "peak {p} at {i} vs {law}");
    }
}

#[test]
fn dampers_between_two_dofs_act_on_the_relative_velocity() {
    // two free masses, a damper between them only, no net momentum: the
    // momentum stays 0 and the relative motion decays by the law of the
    // reduced mass μ
    let (m1, m2, c2) = (0.5, 0.3, 5.0);
    let mut model = chain(&[m1, m2], &[]);
    model.quadratic_dampers = vec![QuadraticDamper {
        dofs: vec![1, 2],
        c2,
    }];
    let (va, vb) = (0.6, -1.0);
    // (|J0 u| grows to ~1e6 N here, while the damper's force falls to
    // 7e-3 N: the Newton tolerance is relative to the step's forces)
    let settings = SimSettings {
        substeps: 10,
        ..Default::default()
    };
    let sim = run_with(
        &model,
        1000.0,
        settings,
        &[0.0, 0.0],
        1000,
        &[0.0, 0.0],
        &[va, vb],
    );
    let mu = m1 * m2 / (m1 + m2);
    let nu0 = va - vb;
    for kk in [10, 100, 999] {
        let (v1, v2) = (sim.v[(0, kk)], sim.v[(1, kk)]);
        assert!((m1 * v1 + m2 * v2).abs() < 1e-9, "{}", m1 * v1 + m2 * v2);
        // μ ν̇ = −c2 ν|ν| → ν = ν0 / (1 + c2 ν0 t / μ)
        let law = nu0 / (1.0 + c2 * nu0 * kk as f64 / 1000.0 / mu);
        assert!(((v1 - v2) / law - 1.0).abs() < 1e-3, "{} vs {law}", v1 - v2);
    }
}

/// Two masses on springs to ground joined by a clearance of `gap`.
fn clearance_pair(gap: f64, kc: f64) -> Model {
    let mut model = chain(&[0.4, 0.4], &[(&[1], 4e4), (&[2], 4e4), (&[1, 2], 1e4)]);
    model.clearances = vec![Clearance {
        dofs: vec![1, 2],
        gap,
        stiffness: kc,
    }];
    model
}

#[test]
fn clearance_is_linear_inside_the_gap() {
    // the antisymmetric mode with |u1 − u2| < gap: the frequency of the
    // linear model, ω² = (k0 + 2 k12) / m, and the same motion
    let model = clearance_pair(1e-3, 1e7);
    let (m, k0, k12): (f64, f64, f64) = (0.4, 4e4, 1e4);
    let fs = 2000.0;
    let (u0, v0) = ([2e-4, -2e-4], [0.0, 0.0]);
    let sim = run(&model, fs, 20, &[0.0, 0.0], 2000, &u0, &v0);
    let lin = run(&model.linear_part(), fs, 20, &[0.0, 0.0], 2000, &u0, &v0);
    let w = ((k0 + 2.0 * k12) / m).sqrt();
    for kk in 0..sim.len() {
        let d = sim.u[(0, kk)] - sim.u[(1, kk)];
        assert!(d.abs() < 1e-3);
        assert_eq!(sim.u[(0, kk)], lin.u[(0, kk)]);
        // (the Newmark period error, (ω h)²/12 = 7.8e-6, leaves a phase
        // error of 3e-3 rad at 1 s: at most 1.2e-6 m of the 4e-6 allowed)
        let exact = 4e-4 * (w * kk as f64 / fs).cos();
        assert!((d - exact).abs() < 1e-2 * 4e-4, "{d} vs {exact} at {kk}");
    }
    assert!(sim.fint.iter().all(|&f| f == 0.0));
}

#[test]
fn clearance_static_force_on_both_sides() {
    // F at DOF 1: beyond the gap the clearance carries
    // f_c = k_c (δ − g), δ from the springs; the same with the sign
    // turned (two-sided), and nothing while F/k stays inside the gap
    let (gap, kc) = (2e-4, 2e5);
    let mut model = clearance_pair(gap, kc);
    model.springs.pop(); // no spring 1–2: the clearance alone joins them
    model.damping = Damping::Rayleigh {
        alpha: 300.0,
        beta: 0.0,
    };
    let k0: f64 = 4e4;
    for f in [20.0, -20.0, 5.0] {
        let sim = run(
            &model,
            1000.0,
            10,
            &[f, 0.0],
            1500,
            &[0.0, 0.0],
            &[0.0, 0.0],
        );
        let e = sim.len() - 1;
        let (u1, u2) = (sim.u[(0, e)], sim.u[(1, e)]);
        // f_c (1 + 2 k_c/k0) = k_c (|F|/k0 − g), when positive
        let fc = (kc * (f.abs() / k0 - gap) / (1.0 + 2.0 * kc / k0)).max(0.0) * f.signum();
        assert!((u2 - fc / k0).abs() < 1e-9, "F {f}: u2 {u2} vs {}", fc / k0);
        assert!((u1 - (f - fc) / k0).abs() < 1e-9, "F {f}: u1 {u1}");
        assert!((sim.fint[(1, e)] + fc).abs() < 1e-5 * f.abs(), "F {f}");
    }
}

#[test]
fn relative_friction_sticks_below_the_limit_and_slides_at_it() {
    // two free masses, friction F between them, a constant force P on
    // mass 1: they stick while m2 P/(m1 + m2) < F; sliding, mass 2 is
    // dragged by F exactly
    let (m1, m2, level, vreg) = (0.6, 0.4, 1.0, 1e-4);
    let mut model = chain(&[m1, m2], &[]);
    model.relative_frictions = vec![RelativeFriction {
        dofs: vec![1, 2],
        level,
        velocity: vreg,
    }];
    let fs = 1000.0;
    // stick: P = 2 N needs 0.8 N < 1 N
    let sim = run(&model, fs, 10, &[2.0, 0.0], 500, &[0.0, 0.0], &[0.0, 0.0]);
    let e = sim.len() - 1;
    // (the stiff regularised law rings in the accelerations of the
    // trapezoidal rule, ±0.5 % here; the velocities are smooth)
    let v_common = 2.0 / (m1 + m2) * e as f64 / fs;
    assert!((sim.v[(0, e)] / v_common - 1.0).abs() < 1e-3);
    assert!((sim.v[(1, e)] / v_common - 1.0).abs() < 1e-3);
    let creep = sim.v[(0, e)] - sim.v[(1, e)];
    assert!(creep.abs() < 3.0 * vreg, "relative velocity {creep}");
    // slide: P = 5 N needs 2 N > 1 N
    let sim = run(&model, fs, 10, &[5.0, 0.0], 500, &[0.0, 0.0], &[0.0, 0.0]);
    assert!(sim.v[(0, e)] - sim.v[(1, e)] > 100.0 * vreg);
    approx::assert_relative_eq!(sim.fint[(1, e)], -level, max_relative = 1e-9);
    approx::assert_relative_eq!(sim.fint[(0, e)], level, max_relative = 1e-9);
    approx::assert_relative_eq!(sim.a[(1, e)], level / m2, max_relative = 1e-6);
    approx::assert_relative_eq!(sim.a[(0, e)], (5.0 - level) / m1, max_relative = 1e-6);
}

#[test]
fn fine_sub_steps_converge_at_second_order_on_a_drifting_structure() {
    // a free-free pair with a cubic spring between the masses, shaken at
    // 40 Hz at one end with a 1 N bias: the pair drifts 0.1 m while the
    // relative motion stays at a tenth of a millimetre, the case where a
    // Newton tolerance relative to |J0 u| ~ M |u| / h² left an
    // acceleration error growing as 1/h²
    let mut model = chain(&[0.4, 0.4], &[(&[1, 2], 5e4)]);
    model.cubics = vec![crate::model::Cubic {
        dofs: vec![1, 2],
        k3: 2e12,
    }];
    let (fs, ns) = (512.0, 200);
    let force = DMatrix::from_fn(2, ns, |i, k| {
        let t = k as f64 / fs;
        if i == 0 {
            1.0 + 20.0 * (2.0 * std::f64::consts::PI * 40.0 * t).sin()
        } else {
            0.0
        }
    });
    let run_at = |substeps: usize| {
        let settings = SimSettings {
            substeps,
            ..Default::default()
        };
        let sim = Integrator::new(&model, fs, settings).unwrap().run(
            force.as_view(),
            &[0.0; 2],
            &[0.0; 2],
        );
        assert!(sim.completed(), "{:?}", sim.status);
        sim
    };
    let reference = run_at(960);
    let error = |substeps: usize| {
        let sim = run_at(substeps);
        (&sim.a - &reference.a).norm() / reference.a.norm()
    };
    let drift = reference.u[(0, ns - 1)];
    assert!(drift > 0.05, "the pair drifts {drift} m");
    let e: Vec<f64> = [60, 120, 240, 480].iter().map(|&s| error(s)).collect();
    for w in e.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(
            (1.7..=2.6).contains(&order),
            "errors {e:?}: order {order} between successive halvings"
        );
    }
    assert!(e[3] < 1e-4, "errors {e:?}");
}
