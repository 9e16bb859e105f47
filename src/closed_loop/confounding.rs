//! Confounding of a candidate effect with the model's own parameters: base springs
//! soften the joint much as a softer adhesive does, so the loop either names such an effect or
//! reports it as confounded with the adhesive's stiffness, never silently.
//!
//! From the score test's Fisher information at the MAP (the law's parameters `p` as nuisance,
//! their columns scaled by `|p|`, so in relative units):
//!
//! ```text
//!   a   = I_pp^-1 I_pe        the change of p (relative) that best mimics a unit effect
//!   R^2 = 1 - I* / I_ee       the share of the effect's information the law can explain
//! ```
//!
//! `R^2` is the squared multiple correlation of the effect's Jacobian column with the law's
//! (in the noise-weighted metric), and `1 / (1 - R^2)` the factor by which freeing the law
//! inflates the effect's variance. Near 1 the data cannot tell the effect from a change of
//! the law's parameters along `a`: an undetected effect of size `delta` shifts them by
//! `a delta` with almost no trace in the residual. The loop then says so, with the size the
//! data still allow (`delta_max`, the one-step size plus two of its sds, within the prior) and
//! the shift that size would cause ([`Confounding::sentence`]).

use crate::forward::Effect;

/// Above this `R^2` (variance inflation 100) a candidate is reported as confounded.
pub const CONFOUNDED_R2: f64 = 0.99;

/// How much of a candidate's effect the model's parameters absorb at the MAP.
#[derive(Clone, Debug, PartialEq)]
pub struct Confounding {
    /// `1 - I* / I_ee` in [0, 1].
    pub r2: f64,
    /// Per unit of the effect's parameter: the relative change of each model parameter
    /// (absolute where the parameter is 0) that mimics it best, with its name.
    pub absorbed: Vec<(String, f64)>,
}

impl Confounding {
    /// Whether the candidate is confounded (`R^2 >= CONFOUNDED_R2`).
    pub fn confounded(&self) -> bool {
        self.r2 >= CONFOUNDED_R2
    }

    /// The largest size the data allow for `effect`: `max(0, one_step) + 2 sd` for a
    /// one-sided effect, `|one_step| + 2 sd` otherwise, capped at the prior's range.
    pub fn size_allowed(effect: &Effect, one_step: f64, sd: f64) -> f64 {
        let raw = if effect.one_sided() {
            one_step.max(0.0) + 2.0 * sd
        } else {
            one_step.abs() + 2.0 * sd
        };
        match effect.default_prior() {
            crate::inference::prior::Prior::Uniform { lo, hi } => raw.min(hi.abs().max(lo.abs())),
            _ => raw,
        }
    }

    /// A sentence for the report: the effect, its `R^2`, the size the data allow and the shift
    /// of each model parameter it would cause.
    pub fn sentence(&self, effect: &Effect, one_step: f64, sd: f64) -> String {
        let allowed = Self::size_allowed(effect, one_step, sd);
        let shifts = self
            .absorbed
            .iter()
            .map(|(n, a)| format!("{n} {:+.1} %", 100.0 * a * allowed))
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "{} is confounded with the model's parameters (R^2 = {:.4}, variance inflation {:.0}): the data allow it up to {allowed:.3e} {} (one-step size {one_step:.3e} +- {sd:.2e}), which the fit would absorb as {shifts}; these parameters carry that much possible bias",
            effect.name(),
            self.r2,
            1.0 / (1.0 - self.r2).max(1e-12),
            effect.unit()
        )
    }
}
