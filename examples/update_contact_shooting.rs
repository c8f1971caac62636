//! Multiple-shooting fit of the bumper of the LANL 8-DOF testbed (issue 6
//! check; docs/theory.md, facts R4–R6): gap and contact stiffness of
//! `data/lanl8dof-contact.toml` from a 4096-sample record with 1 % noise
//! (accelerations at DOFs 1, 5, 6), started 30 % away from the truth
//! (gap +30 %, stiffness −30 %), with 0.1 s segments started from the true
//! states; then the same fit on the whole record, open loop, for
//! comparison; then multiple shooting from the four ±30 % corners
//! ([`update::fit_multistart`]). The model file holds the truth, so the
//! percentages are errors from the truth. Prints parameters, errors, iterations, simulations, times.
//!
//! Run: `cargo run --release --example update_contact_shooting`

use tacit::cases::contact_case;
use tacit::update::{self, FitSettings};

fn main() -> tacit::Result<()> {
    let case = contact_case::case([0.3, -0.3])?;
    let (rec, sim) = (&case.record, &case.simulation);
    let active = sim.fint.column_iter().filter(|c| c.amax() > 0.0).count();
    println!(
        "record: {} samples, contact active in {:.1} % of them",
        rec.len(),
        100.0 * active as f64 / rec.len() as f64
    );
    let (problem, whole) = (case.shooting, case.whole);
    for (label, p) in [
        ("multiple shooting, 0.1 s segments", &problem),
        ("whole record, open loop", &whole),
    ] {
        let r = update::fit(p, &FitSettings::default())?;
        println!("\n{label}: {} segment(s)", p.segments.len());
        for q in &r.parameters {
            println!(
                "  {:5} start {:+6.1} % -> {:+7.2} % from the truth",
                q.name,
                100.0 * (q.start - q.nominal) / q.nominal,
                q.percent_change
            );
        }
        println!(
            "  error {:.4} -> {:.4}; {:?}; {} iterations, {} simulations ({} segment runs), {:.2} s",
            r.errors_before.as_ref().map_or(f64::NAN, |e| e.overall),
            r.errors_after.as_ref().map_or(f64::NAN, |e| e.overall),
            r.termination,
            r.iterations,
            r.evaluations,
            r.simulations,
            r.elapsed_s
        );
    }
    // several starts: the four corners at ±30 %
    let corners = vec![
        vec![0.3, -0.3],
        vec![-0.3, 0.3],
        vec![0.3, 0.3],
        vec![-0.3, -0.3],
    ];
    let (best, runs) = update::fit_multistart(&problem, &FitSettings::default(), &corners)?;
    println!("\nmultiple shooting from four starts (gap, stiffness at ±30 %):");
    for (i, r) in runs.iter().enumerate() {
        println!(
            "  start {:?}: gap {:+7.2} %, stiffness {:+7.2} %, error {:.4}, {} simulations, {:.1} s, {:?}{}",
            corners[i],
            r.parameters[0].percent_change,
            r.parameters[1].percent_change,
            r.errors_after.as_ref().map_or(f64::NAN, |e| e.overall),
            r.evaluations,
            r.elapsed_s,
            r.termination,
            if Some(i) == best { "  <- best" } else { "" }
        );
    }
    Ok(())
}
