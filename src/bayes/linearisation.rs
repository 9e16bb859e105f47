//! The linearised measurement bias checked on the posterior draws: with the H1 estimator's
//! bias linearised at the MAP (the default, `linearised_measurement`), the samplers see a
//! linearised likelihood. On up to 200 draws spread evenly over the first sampler's,
//! `d = log L_exact - log L_linearised`; the sd of `d` says whether the posterior's shape
//! changes (a constant `d` does not change it), and `log mean exp d` turns the linearised
//! evidence into the exact one (`Z = Z_lin E_post_lin[exp d]`, importance sampling from the
//! linearised posterior). Checked by the suite's `measurement_model` and `bayes_run` tests.

use super::posterior::SamplerResult;
use crate::inference::likelihood::FrfPosterior;

/// When `post` carries a linearised measurement bias: the check on the draws of `samplers`
/// (draws checked, sd of `d`, `log mean exp d`, in nats), with every sampler's evidence
/// corrected to the exact measurement model by `log mean exp d`; `None` (nothing changed)
/// otherwise. `post` is left as it was.
pub fn to_exact(
    post: &mut FrfPosterior<'_>,
    samplers: &mut [SamplerResult],
    nl: usize,
) -> Option<(usize, f64, f64)> {
    let lb = post.likelihood.forward.linear_bias.take()?;
    let r = linearisation_error(post, samplers, nl);
    post.likelihood.forward.linear_bias = Some(lb);
    // The evidence of the exact likelihood, by importance sampling (see above).
    for smp in samplers.iter_mut() {
        if let Some((lz, se)) = smp.log_evidence {
            smp.log_evidence = Some((lz + r.2, se));
            smp.notes.push(format!(
                "log evidence corrected from the linearised to the exact measurement model by {:+.3} nats (importance weights on {} posterior draws)",
                r.2, r.0
            ));
        }
    }
    Some(r)
}

/// The linearised measurement bias checked on posterior draws: `post` must carry the exact
/// operator; the draws' `log_lik` are the linearised model's. On up to 200 draws spread evenly
/// over the first sampler's, `d = log L_exact - log L_linearised`: returns (draws, sd of `d`,
/// `log mean exp d`). The sd says whether the posterior's shape changes (a constant `d` does
/// not change it); `log mean exp d` turns the linearised evidence into the exact one
/// (`Z = Z_lin E_post_lin[exp d]`, importance sampling from the linearised posterior).
fn linearisation_error(
    post: &FrfPosterior<'_>,
    samplers: &[SamplerResult],
    nl: usize,
) -> (usize, f64, f64) {
    let Some(s) = samplers.first() else {
        return (0, 0.0, 0.0);
    };
    let draws = &s.draws;
    let n = draws.lp.len();
    let step = (n / 200).max(1);
    let d: Vec<f64> = (0..n)
        .step_by(step)
        .take(200)
        .filter_map(|r| {
            let phys: Vec<f64> = draws.values.iter().map(|col| col[r]).collect();
            post.likelihood
                .eval(&phys[..nl], &phys[nl..], false)
                .ok()
                .map(|e| e.value - draws.log_lik[r])
        })
        .collect();
    if d.is_empty() {
        return (0, 0.0, 0.0);
    }
    let m = d.iter().sum::<f64>() / d.len() as f64;
    let sd = (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
    let mx = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let lme = mx + (d.iter().map(|x| (x - mx).exp()).sum::<f64>() / d.len() as f64).ln();
    (d.len(), sd, lme)
}
