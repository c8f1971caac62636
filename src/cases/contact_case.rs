//! The multiple-shooting check of the updating issue (docs/theory.md, facts
//! R4–R6): the gap and the stiffness of the 5→6 bumper of
//! `data/lanl8dof-contact.toml` (the model file holds the truth) from a
//! 4096-sample record with 1 % noise — accelerations at DOFs 1, 5, 6, seed
//! 7, simulated at [`SUBSTEPS`] sub-steps — fitted on the whole record
//! open loop, or over [`SEGMENT`]-sample segments (0.1 s) started from the
//! true states. Shared by the example `update_contact_shooting`, the
//! benchmark `update` and the tests.

use crate::error::Result;
use crate::integrate::{SimSettings, Simulation};
use crate::model::Model;
use crate::record::{Quantity, Record};
use crate::simulate::{simulate_record, RecordSpec};
use crate::update::param::{Parameter, Target};
use crate::update::problem::Problem;
use crate::update::shooting;

/// The model file, compiled in.
pub const MODEL_TOML: &str = include_str!("../../data/lanl8dof-contact.toml");

/// Sub-steps per sample of the record and of the fits.
pub const SUBSTEPS: usize = 40;

/// Samples per segment (0.1 s at 512 Hz).
pub const SEGMENT: usize = 51;

/// The case.
#[derive(Debug, Clone)]
pub struct ContactCase {
    /// The true model.
    pub truth: Model,
    /// The simulated record.
    pub record: Record,
    /// The simulation behind it (noise-free).
    pub simulation: Simulation,
    /// Gap and stiffness free, over the whole record from rest.
    pub whole: Problem,
    /// The same over segments from the true states.
    pub shooting: Problem,
}

/// Build the case, the gap and the stiffness started at the given
/// relative changes from the truth.
pub fn case(start: [f64; 2]) -> Result<ContactCase> {
    let truth = Model::from_toml_str(MODEL_TOML, "data/lanl8dof-contact.toml")?;
    let spec = RecordSpec {
        samples: 4096,
        sensors: vec![1, 5, 6],
        kinds: vec![Quantity::Accel],
        noise: 0.01,
        seed: 7,
        settings: SimSettings {
            substeps: SUBSTEPS,
            ..Default::default()
        },
        ..Default::default()
    };
    let (record, simulation) = simulate_record(&truth, &spec)?;
    let params = vec![
        Parameter::relative(&truth, Target::ContactGap(0))?.with_relative_start(start[0]),
        Parameter::relative(&truth, Target::ContactStiffness(0))?.with_relative_start(start[1]),
    ];
    let n = truth.ndof();
    let mut whole = Problem::from_record(
        &truth,
        &record,
        &[Quantity::Accel],
        None,
        params,
        vec![0.0; n],
        vec![0.0; n],
    )?;
    whole.sim.substeps = SUBSTEPS;
    let mut shooting = whole.clone();
    shooting.segments = shooting::from_truth(&record, SEGMENT)?;
    Ok(ContactCase {
        truth,
        record,
        simulation,
        whole,
        shooting,
    })
}
