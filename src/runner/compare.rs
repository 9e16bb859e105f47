//! Model comparison at one level and model, computed while the posterior is alive (called
//! from [`super::bayes::infer_level`] after the samplers): the stepping-stone evidence (by
//! default from a reference fitted to the posterior draws, [`crate::inference::reference`],
//! built in `runner/evidence_ref.rs`), TMCMC's final importance reweighting (`tmcmc_is`, with
//! the stepping-stone only), the evidence under priors widened ten-fold, the pointwise log
//! likelihood per line with PSIS-LOO
//! and WAIC, and posterior predictive criteria (FRAC per FRF, SCC(w), ACC(w) over thinned
//! draws; standardised residuals and a chi-square test per channel at the MAP). Across models
//! (Bayes factors, model probabilities) it is done when writing, in the report's
//! model-comparison table (`report/tables/comparison.rs`).
//!
//! # Priors widened ten-fold
//! Each law parameter's prior keeps its centre and family and gets ten times its width in its
//! natural scale: log-uniform `[lo, hi]` becomes log-uniform about the geometric centre
//! `c = sqrt(lo hi)` with `ln(hi'/c) = 10 ln(hi/c)`; uniform and truncated normal get ten
//! times their half-width (and sd) about the centre (mean); log-normal ten times `sigma_ln`.
//! Noise priors are unchanged. The widened evidence is
//! `Z_w = Z E_post[p_w(theta) / p(theta)]` (importance reweighting of posterior draws), exact
//! when the likelihood is negligible outside the declared support; `inside_sd`, the smallest
//! distance of any law parameter's posterior mean to a bound of its declared support in
//! posterior sds (in the prior's own coordinate: log for log priors), says whether that holds
//! (it does beyond about 5). For log-uniform priors the ratio is constant inside the support
//! and the shift is exactly `-d ln 10` for `d` parameters.

use super::posterior::SamplerResult;
use super::sample::checkpoint_dir;
use super::{Event, LevelData, RunError};
use crate::common::C64;
use crate::correlation::{acc_curve, frac_per_frf, scc_curve};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::loo::{self, Loo, Waic};
use crate::inference::prior::Prior;
use crate::inference::special::chi2_sf;
use crate::inference::Sampler;
use crate::inference::{
    combine_replicas, reference_stepping_stone_replica, stepping_stone_replica, Posterior,
    Progress, SteppingStoneParams, SteppingStoneReplica,
};
use crate::study::inference::Inference;
use crate::study::Study;
use std::time::Instant;

/// Most posterior draws the pointwise log likelihood and the predictive criteria use (thinned
/// evenly within each chain).
pub const MAX_DRAWS: usize = 400;

/// One evidence estimate.
#[derive(Clone, Debug)]
pub struct EvidenceRow {
    /// "laplace", "tmcmc" or "stepping_stone".
    pub estimator: String,
    /// "declared" or "widened_10x".
    pub prior: String,
    pub log_evidence: f64,
    pub se: f64,
    pub n_loglik: u64,
    pub seconds: f64,
}

/// Median and 95 % band of a quantity over posterior draws, with its value at the MAP.
#[derive(Clone, Debug)]
pub struct Band {
    pub map: f64,
    pub median: f64,
    pub lo: f64,
    pub hi: f64,
}

/// Posterior predictive check of one channel at the MAP.
#[derive(Clone, Debug)]
pub struct ChannelCheck {
    pub response_id: u32,
    /// Standardised complex residuals `(E[H1] - X) / sqrt(v)` per line.
    pub residuals: Vec<C64>,
    /// `sum |r|^2` (each of re, im has unit variance under the noise model).
    pub chi2: f64,
    /// Degrees of freedom, `2 n_lines`.
    pub dof: usize,
    /// Upper-tail probability of `chi2` under chi-square(`dof`).
    pub p_value: f64,
}

/// Everything of the comparison for one model at one level.
#[derive(Clone, Debug, Default)]
pub struct Comparison {
    pub evidence: Vec<EvidenceRow>,
    /// Smallest distance of a law parameter's posterior mean to its declared bounds, in
    /// posterior sds (infinite for unbounded priors).
    pub inside_sd: f64,
    /// Which sampler's draws the predictive criteria use.
    pub draws_from: String,
    /// (chain, draw) of the thinned draws, numbered as in the `draws` table.
    pub draw_index: Vec<(usize, usize)>,
    /// `pointwise[draw][line]`: log likelihood per line, summed over channels.
    pub pointwise: Vec<Vec<f64>>,
    pub loo: Option<Loo>,
    pub waic: Option<Waic>,
    /// FRAC per channel (order of the level's response ids).
    pub frac: Vec<Band>,
    /// SCC and ACC per line.
    pub scc: Vec<Band>,
    pub acc: Vec<Band>,
    pub ppc: Vec<ChannelCheck>,
    /// The level's lines (Hz).
    pub freq_hz: Vec<f64>,
    /// Notes for the report (stepping-stone replicas, failures of a criterion).
    pub notes: Vec<String>,
}

fn fail(what: String, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: what,
        message: e.to_string(),
    }
}

/// The prior widened ten-fold about its centre (see the module documentation).
pub fn widened(p: &Prior) -> Prior {
    match *p {
        Prior::LogUniform { lo, hi } => {
            let c = (lo.ln() + hi.ln()) / 2.0;
            let h = (hi.ln() - lo.ln()) / 2.0;
            Prior::LogUniform {
                lo: (c - 10.0 * h).exp(),
                hi: (c + 10.0 * h).exp(),
            }
        }
        Prior::Uniform { lo, hi } => {
            let (c, h) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
            Prior::Uniform {
                lo: c - 10.0 * h,
                hi: c + 10.0 * h,
            }
        }
        Prior::LogNormal { median, sigma_ln } => Prior::LogNormal {
            median,
            sigma_ln: 10.0 * sigma_ln,
        },
        Prior::TruncatedNormal { mean, sd, lo, hi } => Prior::TruncatedNormal {
            mean,
            sd: 10.0 * sd,
            lo: mean - 10.0 * (mean - lo),
            hi: mean + 10.0 * (hi - mean),
        },
    }
}

fn log_mean_exp(v: &[f64]) -> f64 {
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !m.is_finite() {
        return m;
    }
    m + (v.iter().map(|x| (x - m).exp()).sum::<f64>() / v.len() as f64).ln()
}

/// `ln E_post[p_w / p]` over posterior draws `values[param][row]` of the law's `nl`
/// parameters, with its delta-method standard error (independent draws assumed).
pub fn widening_shift(priors: &[Prior], values: &[Vec<f64>], nl: usize) -> (f64, f64) {
    let n = values.first().map_or(0, |c| c.len());
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let lr: Vec<f64> = (0..n)
        .map(|r| {
            (0..nl)
                .map(|k| {
                    let v = values[k][r];
                    widened(&priors[k]).log_density_physical(v) - priors[k].log_density_physical(v)
                })
                .sum()
        })
        .collect();
    let lme = log_mean_exp(&lr);
    let w: Vec<f64> = lr.iter().map(|l| (l - lme).exp()).collect();
    let var = w.iter().map(|x| (x - 1.0).powi(2)).sum::<f64>() / n as f64;
    (lme, (var / n as f64).sqrt())
}

/// Distance of each posterior mean to the declared bounds in posterior sds, minimum over
/// the law's parameters (in log coordinates for log-uniform priors).
fn inside_sd(priors: &[Prior], values: &[Vec<f64>], nl: usize) -> f64 {
    let mut out = f64::INFINITY;
    for (prior, values) in priors.iter().zip(values).take(nl) {
        let (bounds, log) = match *prior {
            Prior::LogUniform { lo, hi } => ((lo, hi), true),
            Prior::Uniform { lo, hi } | Prior::TruncatedNormal { lo, hi, .. } => ((lo, hi), false),
            Prior::LogNormal { .. } => continue,
        };
        let f = |v: f64| if log { v.ln() } else { v };
        let col: Vec<f64> = values.iter().map(|v| f(*v)).collect();
        let n = col.len() as f64;
        let m = col.iter().sum::<f64>() / n;
        let sd = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let d = (m - f(bounds.0)).min(f(bounds.1) - m) / sd;
        out = out.min(d);
    }
    out
}

/// Median and central 95 % of `v` (linear interpolation between order statistics, numpy's
/// default).
fn band(map: f64, v: &mut [f64]) -> Band {
    v.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let h = p * (v.len() - 1) as f64;
        let (i, f) = (h.floor() as usize, h - h.floor());
        if i + 1 < v.len() {
            v[i] + f * (v[i + 1] - v[i])
        } else {
            v[i]
        }
    };
    Band {
        map,
        median: q(0.5),
        lo: q(0.025),
        hi: q(0.975),
    }
}

/// The stepping-stone evidence with one checkpoint file per finished replica.
#[allow(clippy::too_many_arguments)]
fn stepping_stone_run(
    study: &Study,
    inf: &Inference,
    post: &FrfPosterior<'_>,
    map: &crate::inference::map::MapResult,
    samplers: &[SamplerResult],
    seed: u64,
    level: &LevelData,
    model: &str,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Option<(EvidenceRow, Vec<String>)>, RunError> {
    let Some(ss) = &inf.stepping_stone else {
        return Ok(None);
    };
    let params = SteppingStoneParams {
        particles: ss.particles,
        replicas: ss.replicas,
        seed,
        ..SteppingStoneParams::default()
    };
    let dir = checkpoint_dir(study, level, model, "stepping_stone");
    // The generalized path's reference (None: from the prior), and what it was fitted to.
    let (reference, fallback) = if ss.from_reference {
        match super::evidence_ref::reference_for(post, map, samplers, ss.widen, ss.nu) {
            Ok(r) => (Some(r), None),
            Err(e) => (None, Some(e)),
        }
    } else {
        (None, None)
    };
    let (key, path_note) = match &reference {
        Some((q, from)) => (
            format!(
                "{}x{}-{seed:016x}-ref{:016x}",
                params.particles,
                params.replicas,
                super::evidence_ref::reference_hash(q)
            ),
            format!(
                "from a Student-t reference (nu {}, sd {} x those of the {from})",
                ss.nu, ss.widen
            ),
        ),
        None => (
            format!("{}x{}-{seed:016x}", params.particles, params.replicas),
            match fallback {
                Some(e) => format!("from the prior (no reference: {e})"),
                None => "from the prior".to_string(),
            },
        ),
    };
    progress(Event::Start {
        step: format!(
            "{}: stepping-stone evidence of {model} ({} replicas x {} particles, {path_note})",
            level.name, params.replicas, params.particles
        ),
        total: params.replicas as u64,
    });
    let t0 = Instant::now();
    let mut replicas = Vec::new();
    let mut loaded = 0;
    let mut rungs = Vec::new();
    for r in 0..params.replicas {
        let file = dir.join(format!("replica-{r}-{key}.txt"));
        if let Some(rep) = load_replica(&file) {
            replicas.push(rep);
            loaded += 1;
            progress(Event::Advance);
            continue;
        }
        let rep = match &reference {
            Some((q, _)) => {
                reference_stepping_stone_replica(post, q, &params, r, &|_: Progress| ())
            }
            None => stepping_stone_replica(post, &params, r, &|_: Progress| ()),
        }
        .map_err(|e| fail(format!("stepping-stone of {model} at {}", level.name), e))?;
        rungs.push(rep.rungs.len());
        save_replica(&file, &rep);
        replicas.push(rep);
        progress(Event::Advance);
    }
    progress(Event::Finish);
    let run = combine_replicas(replicas);
    let logs: Vec<String> = run
        .replicas
        .iter()
        .map(|r| format!("{:.2}", r.log_evidence))
        .collect();
    let notes = vec![format!(
        "stepping-stone {path_note}: {} replicas x {} particles ({} loaded from checkpoints; rungs per run replica {:?}), replica log evidences [{}]",
        params.replicas,
        params.particles,
        loaded,
        rungs,
        logs.join(", ")
    )];
    Ok(Some((
        EvidenceRow {
            estimator: "stepping_stone".into(),
            prior: "declared".into(),
            log_evidence: run.log_evidence,
            se: run.log_evidence_se,
            n_loglik: run.n_loglik,
            seconds: t0.elapsed().as_secs_f64(),
        },
        notes,
    )))
}

/// A finished replica's numbers, bit-exact (hex of the f64 bits); `None` when absent or
/// unreadable (then the replica is run again).
fn load_replica(file: &std::path::Path) -> Option<SteppingStoneReplica> {
    let s = std::fs::read_to_string(file).ok()?;
    let v: Vec<u64> = s
        .split_whitespace()
        .map(|t| u64::from_str_radix(t, 16))
        .collect::<Result<_, _>>()
        .ok()?;
    if v.len() != 3 {
        return None;
    }
    Some(SteppingStoneReplica {
        log_evidence: f64::from_bits(v[0]),
        log_evidence_se: f64::from_bits(v[1]),
        rungs: Vec::new(),
        n_loglik: v[2],
    })
}

/// Written to a temporary file and renamed; a failure only costs the resume.
fn save_replica(file: &std::path::Path, r: &SteppingStoneReplica) {
    let Some(dir) = file.parent() else { return };
    if std::fs::create_dir_all(dir).is_err() {
        return;
    }
    let tmp = file.with_extension("tmp");
    let text = format!(
        "{:016x} {:016x} {:016x}\n",
        r.log_evidence.to_bits(),
        r.log_evidence_se.to_bits(),
        r.n_loglik
    );
    if std::fs::write(&tmp, text).is_ok() {
        let _ = std::fs::rename(&tmp, file);
    }
}

/// Per draw: pointwise log likelihood, FRAC per channel, SCC and ACC per line.
type PerDraw = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

/// Thinned (chain, draw, row) triples (the draw number as in the `draws` table): at most [`MAX_DRAWS`] rows, evenly within each chain,
/// the same number per chain.
fn thin(s: &SamplerResult) -> Vec<(usize, usize, usize)> {
    let d = &s.draws;
    let n_chains = d.chain.iter().copied().max().map_or(0, |c| c + 1);
    if n_chains == 0 {
        return Vec::new();
    }
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); n_chains];
    for (r, c) in d.chain.iter().enumerate() {
        rows[*c].push(r);
    }
    let per = rows.iter().map(|r| r.len()).min().unwrap_or(0);
    let keep = (MAX_DRAWS / n_chains).min(per).max(1);
    let step = (per / keep).max(1);
    let mut out = Vec::new();
    for (c, rs) in rows.iter().enumerate() {
        for &r in rs.iter().step_by(step).take(keep) {
            out.push((c, d.draw[r], r));
        }
    }
    out
}

/// Comparison of one model at one level: see the module documentation. `samplers` carry the
/// evidence already corrected to the exact measurement model by `lin_shift` (nats), which is
/// added to the stepping-stone and Laplace estimates here too.
#[allow(clippy::too_many_arguments)]
pub fn compare(
    study: &Study,
    inf: &Inference,
    post: &FrfPosterior<'_>,
    map: &crate::inference::map::MapResult,
    samplers: &[SamplerResult],
    lin_shift: f64,
    seed: u64,
    level: &LevelData,
    model: &str,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Comparison, RunError> {
    let mut c = Comparison {
        freq_hz: level.freq_hz.clone(),
        ..Comparison::default()
    };
    let nl = post.n_law();
    let lik = &post.likelihood;
    // Evidence per estimator, declared priors.
    c.evidence.push(EvidenceRow {
        estimator: "laplace".into(),
        prior: "declared".into(),
        log_evidence: map.laplace.log_evidence + lin_shift,
        se: f64::NAN,
        n_loglik: map.evaluations as u64,
        seconds: f64::NAN,
    });
    for s in samplers {
        if let Some((lz, se)) = s.log_evidence {
            c.evidence.push(EvidenceRow {
                estimator: s.sampler.to_string(),
                prior: "declared".into(),
                log_evidence: lz,
                se,
                n_loglik: s.evaluations as u64,
                seconds: s.seconds,
            });
        }
    }
    if let Some((mut row, notes)) = stepping_stone_run(
        study, inf, post, map, samplers, seed, level, model, progress,
    )? {
        row.log_evidence += lin_shift;
        c.evidence.push(row);
        c.notes.extend(notes);
    }
    // TMCMC's final importance reweighting, with the comparison part (stepping-stone) only.
    if let Some(ss) = &inf.stepping_stone {
        match super::evidence_ref::tmcmc_reweighted(post, samplers, ss.widen, ss.nu, seed) {
            Some(Ok((lz, se, n, secs, note))) => {
                c.evidence.push(EvidenceRow {
                    estimator: "tmcmc_is".into(),
                    prior: "declared".into(),
                    log_evidence: lz + lin_shift,
                    se,
                    n_loglik: n,
                    seconds: secs,
                });
                c.notes.push(note);
            }
            Some(Err(e)) => c.notes.push(format!("tmcmc_is not computed: {e}")),
            None => {}
        }
    }
    // The posterior draws of the criteria: NUTS's when it ran, else TMCMC's.
    let Some(s) = samplers
        .iter()
        .find(|s| s.sampler == Sampler::Nuts)
        .or(samplers.iter().find(|s| !s.draws.lp.is_empty()))
    else {
        return Ok(c);
    };
    c.draws_from = s.sampler.to_string();
    // Widened priors by importance reweighting of the draws.
    let (shift, shift_se) = widening_shift(&post.priors, &s.draws.values, nl);
    c.inside_sd = inside_sd(&post.priors, &s.draws.values, nl);
    let declared: Vec<EvidenceRow> = c.evidence.clone();
    for e in declared {
        c.evidence.push(EvidenceRow {
            prior: "widened_10x".into(),
            log_evidence: e.log_evidence + shift,
            se: e.se.hypot(shift_se),
            ..e
        });
    }
    // Pointwise log likelihood and predictions on thinned draws.
    let rows = thin(s);
    let n_out = lik.data.n_out;
    let n_lines = lik.data.freq_hz.len();
    let x_rows: Vec<Vec<C64>> = lik.data.values.chunks(n_out).map(|r| r.to_vec()).collect();
    progress(Event::Start {
        step: format!(
            "{}: predictive criteria of {model} ({} draws)",
            level.name,
            rows.len()
        ),
        total: 0,
    });
    use rayon::prelude::*;
    let per_draw: Vec<Option<PerDraw>> = rows
        .par_iter()
        .map(|&(_, _, r)| {
            let phys: Vec<f64> = s.draws.values.iter().map(|col| col[r]).collect();
            let pw = lik.pointwise(&phys[..nl], &phys[nl..]).ok()?;
            let pred = lik.forward.predict(&phys[..nl], false).ok()?;
            let a: Vec<Vec<C64>> = pred.values.chunks(n_out).map(|r| r.to_vec()).collect();
            Some((
                pw,
                frac_per_frf(&x_rows, &a),
                scc_curve(&x_rows, &a),
                acc_curve(&x_rows, &a),
            ))
        })
        .collect();
    let mut fr: Vec<Vec<f64>> = vec![Vec::new(); n_out];
    let mut sc: Vec<Vec<f64>> = vec![Vec::new(); n_lines];
    let mut ac: Vec<Vec<f64>> = vec![Vec::new(); n_lines];
    for (&(ch, dr, _), v) in rows.iter().zip(per_draw) {
        let Some((pw, f, sv, av)) = v else {
            c.notes.push(format!(
                "draw {dr} of chain {ch} could not be evaluated and is left out of the criteria"
            ));
            continue;
        };
        c.draw_index.push((ch, dr));
        c.pointwise.push(pw);
        for (k, v) in f.into_iter().enumerate() {
            fr[k].push(v);
        }
        for (l, v) in sv.into_iter().enumerate() {
            sc[l].push(v);
        }
        for (l, v) in av.into_iter().enumerate() {
            ac[l].push(v);
        }
    }
    progress(Event::Finish);
    // Deterministic values at the MAP.
    let map_p = &map.map_physical;
    let map_pred = lik
        .forward
        .predict(&map_p[..nl], false)
        .map_err(|e| fail(format!("prediction of {model} at the MAP"), e))?;
    let a: Vec<Vec<C64>> = map_pred.values.chunks(n_out).map(|r| r.to_vec()).collect();
    let f_map = frac_per_frf(&x_rows, &a);
    let s_map = scc_curve(&x_rows, &a);
    let a_map = acc_curve(&x_rows, &a);
    if !c.pointwise.is_empty() {
        c.frac = fr
            .iter_mut()
            .zip(&f_map)
            .map(|(v, m)| band(*m, v))
            .collect();
        c.scc = sc
            .iter_mut()
            .zip(&s_map)
            .map(|(v, m)| band(*m, v))
            .collect();
        c.acc = ac
            .iter_mut()
            .zip(&a_map)
            .map(|(v, m)| band(*m, v))
            .collect();
        // LOO and WAIC over [chain][draw][line], ArviZ's relative efficiency from the thinned
        // draws of every coordinate.
        let n_chains = c.draw_index.iter().map(|d| d.0).max().map_or(0, |m| m + 1);
        let mut ll: Vec<Vec<Vec<f64>>> = vec![Vec::new(); n_chains];
        let mut par: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); n_chains]; post.dim()];
        let kept: Vec<usize> = rows
            .iter()
            .filter(|(ch, dr, _)| c.draw_index.contains(&(*ch, *dr)))
            .map(|t| t.2)
            .collect();
        for ((ch, _), (pw, r)) in c.draw_index.iter().zip(c.pointwise.iter().zip(&kept)) {
            ll[*ch].push(pw.clone());
            for (k, p) in par.iter_mut().enumerate() {
                p[*ch].push(s.draws.values[k][*r]);
            }
        }
        let equal = ll.iter().all(|c| c.len() == ll[0].len());
        let r_eff = if equal {
            loo::relative_eff(&par).unwrap_or(1.0)
        } else {
            1.0
        };
        match loo::loo(&ll, r_eff) {
            Ok(l) => c.loo = Some(l),
            Err(e) => c.notes.push(format!("PSIS-LOO not computed: {e}")),
        }
        match loo::waic(&ll) {
            Ok(w) => c.waic = Some(w),
            Err(e) => c.notes.push(format!("WAIC not computed: {e}")),
        }
    }
    // PPC at the MAP: standardised residuals and chi-square per channel.
    let std = lik
        .standardised(&map_p[..nl], &map_p[nl..])
        .map_err(|e| fail(format!("residuals of {model} at the MAP"), e))?;
    for (k, id) in level.response_ids.iter().enumerate().take(n_out) {
        let residuals: Vec<C64> = (0..n_lines).map(|l| std[l * n_out + k]).collect();
        let chi2: f64 = residuals.iter().map(|r| r.norm_sqr()).sum();
        let dof = 2 * n_lines;
        c.ppc.push(ChannelCheck {
            response_id: *id,
            residuals,
            chi2,
            dof,
            p_value: chi2_sf(chi2, dof as f64),
        });
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_a_log_uniform_prior_costs_ln_10_per_parameter() {
        let priors = vec![
            Prior::LogUniform { lo: 1e5, hi: 1e7 },
            Prior::LogUniform { lo: 1.0, hi: 1e2 },
        ];
        let w = widened(&priors[0]);
        match w {
            Prior::LogUniform { lo, hi } => {
                assert!((lo.log10() + 4.0).abs() < 1e-12 && (hi.log10() - 16.0).abs() < 1e-12)
            }
            _ => panic!(),
        }
        let values = vec![vec![1e6, 2e6, 3e6], vec![10.0, 11.0, 12.0]];
        let (s, se) = widening_shift(&priors, &values, 2);
        assert!((s + 2.0 * 10f64.ln()).abs() < 1e-12, "{s}");
        assert!(se.abs() < 1e-12);
    }
}
