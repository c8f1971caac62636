//! Keep or withdraw a fitted effect, as a typed decision
//! ([`super::Decision`]; [`super::report`] puts it into words).
//!
//! An effect is kept when, fitted, it removes at least
//! [`ScreenSettings::min_improvement`] of the squared multiple-shooting
//! error (a candidate the screen did not propose:
//! [`ScreenSettings::companion_improvement`] of the squared error above
//! the noise measured on the record, [`super::noise`]). A candidate below the
//! screen may only have let the effects found be refitted, so it is also
//! switched off in the fitted model (the others as fitted) and must itself
//! remove the same share; when it does not, the effects found as refitted
//! beside it are kept if they alone lower the error by the screen's share
//! (the joint refit left the earlier fit's local minimum).

use super::outcome::{BelowScreen, Decision, WithdrawReason};
use super::state::{Context, Scored, State, Trial};
use super::{effects, ScreenSettings};
use crate::model::Model;

/// The decision on a fitted trial, and the model the loop goes on with
/// when the effect is withdrawn but the effects refitted beside it are
/// kept (with its multiple shooting).
pub(super) struct Judged {
    pub decision: Decision,
    pub refit: Option<(Model, Scored)>,
}

/// Judge `trial` (module docs); `below` when it came in below the screen.
pub(super) fn judge(
    ctx: &Context<'_>,
    st: &mut State,
    trial: &Trial,
    below: Option<BelowScreen>,
) -> Judged {
    let s: &ScreenSettings = &ctx.settings.screen;
    let need = if below.is_none() {
        s.min_improvement
    } else {
        s.companion_improvement
    };
    let mut off = None;
    let mut without = None;
    if below.is_some() {
        let m = effects::remove(&trial.fit.model, &trial.effect);
        let (scored, n) = ctx.shoot(&m, trial.sim);
        st.simulations += n;
        without = scored.error;
        off = Some((m, scored));
    }
    let (before, after) = (st.error, trial.scored.error);
    // below the screen, the share is of the error above the noise
    // measured on the record: near the noise half of the whole error
    // cannot be removed by any effect
    let noise = below
        .as_ref()
        .and(ctx.measured_noise)
        .map_or(0.0, |n| n * n);
    let negligible = match (without, after) {
        (Some(w), Some(b)) => w * w - b * b <= need * (w * w - noise),
        _ => false,
    };
    let pays = !negligible
        && match (before, after) {
            (Some(a), Some(b)) => a * a - b * b > need * (a * a - noise),
            (None, Some(_)) => true,
            _ => false,
        };
    if pays {
        let decision = Decision::Kept {
            before,
            after,
            below,
        };
        return Judged {
            decision,
            refit: None,
        };
    }
    let reason = if negligible {
        WithdrawReason::NotItself {
            without,
            with: after,
            need,
        }
    } else {
        WithdrawReason::TooLittle {
            need,
            before,
            after,
        }
    };
    let better = match (negligible, without, before) {
        (true, Some(w), Some(a)) => w * w < a * a * (1.0 - s.min_improvement),
        _ => false,
    };
    let refit = off.filter(|_| better);
    let decision = Decision::Withdrawn {
        reason,
        below,
        refit_kept: refit.as_ref().map(|_| (before, without)),
    };
    Judged { decision, refit }
}
