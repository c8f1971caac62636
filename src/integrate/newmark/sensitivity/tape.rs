//! A primal run's record, for its sensitivities to be propagated later
//! without simulating again.
//!
//! The derivative step of a sub-step ([`Integrator::sensitivity_step`])
//! reads of the primal run only what the sub-step ended with: the element
//! slopes at the accepted point, the slopes of the last Newton matrix and
//! whether a Newton step was taken (the contacts' sides), and — for
//! parameter seeds — the state `(u, v, a)`. A sample taken whole by the
//! sample map leaves nothing to read: its derivatives wait for the powers
//! of the sub-step map. [`Integrator::run_taped`] records exactly that
//! while it runs (the run is [`Integrator::run`], bit for bit), and
//! [`Integrator::sensitivities_from_tape`] replays it: the same derivative
//! steps in the same order, so the same derivatives, bit for bit, as
//! [`Integrator::run_sensitivities`] from the same start — at the cost of
//! the derivative steps alone. A least-squares driver that evaluates a
//! trial point and then linearizes at it when it is accepted (the segment
//! start states, the joint fit) runs the primal once instead of twice.

use super::super::{Integrator, Work};
use super::{flush_all, Prepared, Seeds, SensOutputs, SensWork, Sensitivities};
use crate::error::{Result, TacitError};
use nalgebra::{DMatrix, DMatrixView};

/// What a run recorded for its derivatives ([`Integrator::run_taped`]).
#[derive(Debug, Clone)]
pub struct Tape {
    n: usize,
    elements: usize,
    substeps: usize,
    /// `(u, v, a)` recorded at every sub-step (parameter seeds need them).
    states: bool,
    /// Per sample from the second: taken whole by the sample map.
    whole: Vec<bool>,
    /// Per sub-step taken: slopes, Newton-matrix slopes, 1 when a Newton
    /// step was taken (else 0), and with `states` the state `(u, v, a)`.
    subs: Vec<f64>,
    /// Samples completed.
    done: usize,
}

impl Tape {
    /// An empty tape for `integ`'s runs (`states`: record `(u, v, a)`).
    pub(in crate::integrate::newmark) fn new(integ: &Integrator, states: bool) -> Tape {
        Tape {
            n: integ.n,
            elements: integ.elements.len(),
            substeps: integ.settings.substeps,
            states,
            whole: Vec::new(),
            subs: Vec::new(),
            done: 0,
        }
    }

    /// Values per sub-step.
    fn width(&self) -> usize {
        2 * self.elements + 1 + if self.states { 3 * self.n } else { 0 }
    }

    /// Sample `k ≥ 1` begins: taken whole or sub-stepped.
    pub(in crate::integrate::newmark) fn sample(&mut self, whole: bool) {
        self.whole.push(whole);
    }

    /// A sub-step was accepted with `ws` as it ends.
    pub(in crate::integrate::newmark) fn substep(&mut self, ws: &Work) {
        self.subs.extend_from_slice(&ws.slopes);
        self.subs.extend_from_slice(&ws.dir_slopes);
        self.subs.push(if ws.iterated { 1.0 } else { 0.0 });
        if self.states {
            self.subs.extend_from_slice(&ws.u);
            self.subs.extend_from_slice(&ws.v);
            self.subs.extend_from_slice(&ws.a);
        }
    }

    /// The run ended with `done` samples completed.
    pub(in crate::integrate::newmark) fn finish(&mut self, done: usize) {
        self.done = done;
    }

    /// Samples completed by the run.
    pub fn samples(&self) -> usize {
        self.done
    }

    /// Keep the record of the first `samples` samples only (a run carried
    /// past a segment's end, replayed over the segment): the replay stops
    /// there.
    pub fn truncate(&mut self, samples: usize) {
        self.done = self.done.min(samples);
    }

    /// Samples the run took whole by the sample map (no sub-step recorded).
    pub fn whole_samples(&self) -> usize {
        self.whole.iter().filter(|&&w| w).count()
    }

    /// Sub-step `i`'s record back into `ws`.
    #[inline(always)]
    fn load(&self, i: usize, ws: &mut Work) {
        let (n, e) = (self.n, self.elements);
        let r = &self.subs[i * self.width()..(i + 1) * self.width()];
        ws.slopes.copy_from_slice(&r[..e]);
        ws.dir_slopes.copy_from_slice(&r[e..2 * e]);
        ws.iterated = r[2 * e] != 0.0;
        if self.states {
            let s = &r[2 * e + 1..];
            ws.u.copy_from_slice(&s[..n]);
            ws.v.copy_from_slice(&s[n..2 * n]);
            ws.a.copy_from_slice(&s[2 * n..3 * n]);
        }
    }
}

impl Integrator {
    /// [`Integrator::run`] (the same simulation, bit for bit) and its
    /// [`Tape`], for [`Integrator::sensitivities_from_tape`]; `states`
    /// records the state at every sub-step, which parameter seeds need.
    pub fn run_taped(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        states: bool,
    ) -> (crate::integrate::Simulation, Tape) {
        let mut tape = Tape::new(self, states);
        // room for every sample sub-stepped: no growth while recording
        let samples = force.ncols().saturating_sub(1);
        tape.whole.reserve(samples);
        tape.subs.reserve(tape.width() * samples * tape.substeps);
        let sim = self.run_sized(force, u0, v0, Some(&mut tape));
        (sim, tape)
    }

    /// The derivatives along `seeds` of the run recorded in `tape` (made
    /// by [`Integrator::run_taped`] of this integrator from `u0`, `v0`
    /// under `force`): those [`Integrator::run_sensitivities`] gives, bit
    /// for bit, without the simulation. They stop where the run stopped.
    ///
    /// Errors: those of [`Integrator::run_sensitivities`], a tape of
    /// another integrator or force, parameter seeds with a tape made
    /// without the states, and a parameter that moves M, C or K with a
    /// tape that took samples whole (that parameter has a term in every
    /// sub-step; [`Integrator::run_sensitivities`] then sub-steps them).
    pub fn sensitivities_from_tape(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        tape: &Tape,
        seeds: &Seeds,
    ) -> Result<Sensitivities> {
        let prep = self.check_seeds(force, u0, v0, seeds)?;
        self.check_tape(force, tape, &prep)?;
        let st = &seeds.state;
        Ok(self.replay_sized((force, u0, v0), tape, st, &prep))
    }

    fn check_tape(
        &self,
        force: DMatrixView<'_, f64>,
        tape: &Tape,
        prep: &[Prepared],
    ) -> Result<()> {
        let bad = |m: &str| {
            Err(TacitError::Setting(format!(
                "sensitivities from a tape: {m}"
            )))
        };
        let subs = tape.whole.iter().filter(|&&w| !w).count() * tape.substeps;
        let fits = tape.n == self.n
            && tape.elements == self.elements.len()
            && tape.substeps == self.settings.substeps
            && tape.done <= force.ncols()
            && tape.whole.len() + 1 >= tape.done
            && tape.subs.len() >= tape.width() * subs.min(tape.done * tape.substeps);
        if !fits {
            return bad("the tape was not made by this integrator under this force");
        }
        if !prep.is_empty() && !tape.states {
            return bad("parameter seeds need a tape made with the states");
        }
        let matrices = prep
            .iter()
            .any(|p| p.dm.is_some() || p.dc.is_some() || p.dk.is_some());
        let whole = tape
            .whole
            .iter()
            .take(tape.done.saturating_sub(1))
            .any(|&w| w);
        if matrices && whole {
            return bad(
                "a parameter of M, C or K needs every sample sub-stepped; the tape took some whole",
            );
        }
        Ok(())
    }

    /// [`Integrator::sensitivities_from_tape`] with the kernels' size chosen.
    fn replay_sized(
        &self,
        run: (DMatrixView<'_, f64>, &[f64], &[f64]),
        tape: &Tape,
        st: &DMatrix<f64>,
        prep: &[Prepared],
    ) -> Sensitivities {
        match self.n {
            1 => self.replay_n::<1>(run, tape, st, prep),
            2 => self.replay_n::<2>(run, tape, st, prep),
            3 => self.replay_n::<3>(run, tape, st, prep),
            4 => self.replay_n::<4>(run, tape, st, prep),
            5 => self.replay_n::<5>(run, tape, st, prep),
            6 => self.replay_n::<6>(run, tape, st, prep),
            7 => self.replay_n::<7>(run, tape, st, prep),
            8 => self.replay_n::<8>(run, tape, st, prep),
            _ => self.replay_n::<0>(run, tape, st, prep),
        }
    }

    /// The sample loop of [`Integrator::run_sens_n`] with the primal
    /// sub-steps read from the tape.
    fn replay_n<const N: usize>(
        &self,
        (force, u0, v0): (DMatrixView<'_, f64>, &[f64], &[f64]),
        tape: &Tape,
        state: &DMatrix<f64>,
        prep: &[Prepared],
    ) -> Sensitivities {
        let n = self.n;
        let ns = force.ncols();
        let mut sw = SensWork::new(self, state.ncols() + prep.len(), prep.len());
        let mut dout = SensOutputs::new(n, ns, sw.s);
        let mut ws = Work::new(n, self.elements.len());
        ws.u.copy_from_slice(&u0[..n]);
        ws.v.copy_from_slice(&v0[..n]);
        // the start as the run took it (the same bits)
        if tape.done == 0 || !self.initial_acceleration(force, &mut ws) {
            return dout.finish(0, &sw);
        }
        let powers = self.linear_powers();
        let mut pos = 0;
        let s = self.settings.substeps;
        self.initial_sensitivities::<N>(&ws, &mut sw, state, prep);
        dout.store(&sw, 0);
        for k in 1..tape.done {
            if tape.whole[k - 1] {
                sw.pending.iter_mut().for_each(|p| *p += s);
            } else {
                for sub in 0..s {
                    tape.load(pos, &mut ws);
                    pos += 1;
                    if !self.sensitivity_step::<N>(&ws, &mut sw, prep, powers)
                        && sw.singular_at.is_none()
                    {
                        sw.singular_at =
                            Some((k - 1) as f64 / self.fs() + (sub + 1) as f64 * self.h);
                    }
                }
            }
            flush_all(powers, n, &mut sw);
            dout.store(&sw, k);
        }
        dout.finish(tape.done, &sw)
    }
}
