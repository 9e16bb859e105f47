//! The closed loop on measured E'(w), E''(w):
//!
//! 1. fit the start law (the paper's Model 4 by default): MAP by the multistart search
//!    ([`crate::inference::map::find_map`]) and the Laplace evidence there;
//! 2. analyse the residual ([`super::residual`]) of log E' and log E'';
//! 3. propose more relaxation content: one more Maxwell branch at each of the `placements`
//!    relaxation times where the score (Lagrange-multiplier) test of a new branch is largest;
//!    the same without the structural damper `h` (whose constant E'' is not causal); at the
//!    first step also the fractional Zener law instead of the start law; and at every step
//!    the simpler laws with the same content (the fractional branch as a Maxwell branch, its
//!    alpha -> 1 limit; `h` dropped), which are the only proposals once the law is at the
//!    causal floor or the branch limit;
//! 4. keep the candidate of highest evidence if it beats the current law by more than
//!    `min_evidence_gain` nats, and repeat; stop when no candidate does, when the number of
//!    branches reaches `max_branches`, or when the current law's weighted misfit is within
//!    `causal_floor_ratio` of the best causal fit of the data under the same weights
//!    ([`super::kk`]): a remaining systematic residual is then the data's own causal
//!    inconsistency, which no added term can remove.
//!
//! Evidence: Laplace's estimate at the MAP plus `ln n!` for `n` exchangeable Maxwell branches
//! (their identical priors make the posterior `n!`-modal; Laplace sees one mode). It depends on
//! the prior box ([`super::PriorBox`]); the same box is used for every law.

use super::kk::{kk_check, KkCheck};
use super::law::RelaxationLaw;
use super::posterior::{MasterCurve, MaterialPosterior, PriorBox};
use super::residual::{residual_stats, ResidualStats};
use super::MaterialFitError;
use crate::inference::map::{find_map, MapParams};
use crate::inference::Posterior;

/// Settings of the loop.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopParams {
    /// The first law. Default Model 4.
    pub start: RelaxationLaw,
    /// Largest number of Maxwell branches. Default 30.
    pub max_branches: usize,
    /// Evidence gain (nats) a candidate needs to be accepted. Default 2.3 (a Bayes factor of
    /// 10, "strong" on Jeffreys' scale).
    pub min_evidence_gain: f64,
    /// Try the fractional Zener law as an alternative to the start law. Default true.
    pub try_fractional: bool,
    /// Placements tried for a new branch per step (local maxima of the score test). Default 3.
    pub placements: usize,
    /// Relaxation times per decade of the KK check. Default 6 (3 leaves up to 10 % discretisation error in the transforms of a single Maxwell branch, 6 below 2 %).
    pub kk_per_decade: f64,
    /// Flag threshold of the KK check, in point-to-point scatters. Default 3.
    pub kk_threshold: f64,
    /// Stop when the law's weighted misfit is within this factor of the best causal fit's with
    /// the same weights ([`Candidate::causal_floor_ratio`]). Default 1.05.
    pub causal_floor_ratio: f64,
    /// The MAP search (seed, starts, iterations). Default: 4 space-filling starts besides the
    /// warm start, 500 L-BFGS iterations.
    pub map: MapParams,
}

impl Default for LoopParams {
    fn default() -> Self {
        LoopParams {
            start: RelaxationLaw::model4(),
            max_branches: 30,
            min_evidence_gain: 2.3,
            try_fractional: true,
            placements: 3,
            kk_per_decade: 6.0,
            kk_threshold: 3.0,
            causal_floor_ratio: 1.05,
            map: MapParams {
                n_starts: 4,
                max_iters: 500,
                ..MapParams::default()
            },
        }
    }
}

/// One fitted law.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// Step of the loop (0: the start law and its alternative).
    pub step: usize,
    /// How it was proposed: "start", "fractional_alternative", "add_branch", "add_branch_drop_h",
    /// "fractional_to_branch", "drop_h".
    pub proposal: String,
    pub law: RelaxationLaw,
    /// MAP law parameters (SI) followed by sigma_storage and sigma_loss.
    pub map: Vec<f64>,
    /// Laplace standard deviations of the same.
    pub sd: Vec<f64>,
    pub names: Vec<String>,
    pub log_likelihood: f64,
    /// Laplace log evidence with the `ln n!` term (`-inf` when the Hessian is not positive
    /// definite: the law is not identifiable on these data).
    pub log_evidence: f64,
    pub positive_definite: bool,
    /// Weighted misfit sum (r'/s')^2 + sum (r''/s'')^2 (ln residuals, the law's own scatters)
    /// over that of the best causal fit with the same weights ([`super::kk::causal_fit`]):
    /// near 1, no law with a non-negative relaxation spectrum fits these data better.
    pub causal_floor_ratio: f64,
    /// Evidence gain over the law current at its step.
    pub evidence_gain: f64,
    pub accepted: bool,
    pub rms_log10_storage: f64,
    pub rms_log10_loss: f64,
    pub stats_storage: ResidualStats,
    pub stats_loss: ResidualStats,
    /// log10 residuals (data - model) per point.
    pub res_log10_storage: Vec<f64>,
    pub res_log10_loss: Vec<f64>,
    /// Model E', E'' (Pa) per point.
    pub model_storage_pa: Vec<f64>,
    pub model_loss_pa: Vec<f64>,
}

impl Candidate {
    pub fn n_params(&self) -> usize {
        self.law.n_params()
    }
    pub fn rms_log10_sum(&self) -> f64 {
        self.rms_log10_storage + self.rms_log10_loss
    }
}

/// Why the loop stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// No candidate gained `min_evidence_gain`.
    NoEvidenceGain,
    /// The law reached the best causal fit: the rest is the data's causal inconsistency.
    CausalFloor,
    /// `max_branches` reached.
    MaxBranches,
}

impl StopReason {
    pub fn as_str(&self) -> &'static str {
        match self {
            StopReason::NoEvidenceGain => "no candidate improves the evidence",
            StopReason::CausalFloor => {
                "the law reached the best causal fit of the data (Kramers-Kronig floor)"
            }
            StopReason::MaxBranches => "maximum number of branches reached",
        }
    }
}

/// The loop's outcome.
#[derive(Clone, Debug)]
pub struct LoopResult {
    /// Every law fitted, in order.
    pub candidates: Vec<Candidate>,
    /// Indices into `candidates` of the accepted laws, in order (first: the start law or its
    /// alternative).
    pub path: Vec<usize>,
    pub stop: StopReason,
    pub kk: KkCheck,
    pub prior_box: PriorBox,
}

impl LoopResult {
    /// The final law.
    pub fn final_candidate(&self) -> &Candidate {
        &self.candidates[self.path[self.path.len() - 1]]
    }
    /// The first accepted law.
    pub fn first_candidate(&self) -> &Candidate {
        &self.candidates[self.path[0]]
    }
}

fn ln_factorial(n: usize) -> f64 {
    (2..=n).map(|k| (k as f64).ln()).sum()
}

/// Fit `law` from the warm start `init` (law parameters; the noise scales are set from the
/// residual there).
fn fit(
    curve: &MasterCurve,
    bounds: &PriorBox,
    law: RelaxationLaw,
    init: &[f64],
    step: usize,
    proposal: &str,
    params: &MapParams,
) -> Result<Candidate, MaterialFitError> {
    let post = MaterialPosterior::new(law, curve, bounds);
    let kinds = law.param_kinds();
    let mut x0: Vec<f64> = init
        .iter()
        .zip(&kinds)
        .map(|(v, k)| bounds.clamp(*k, *v))
        .collect();
    let (rs, rl) = post.log_residuals(&x0);
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let ok = |v: f64| {
        if v.is_finite() {
            v.clamp(2e-4, 0.5)
        } else {
            0.1
        }
    };
    x0.push(ok(rms(&rs)));
    x0.push(ok(rms(&rl)));
    let x0 = post.unconstrained(&x0);
    let mp = MapParams {
        seed: params.seed ^ (step as u64).wrapping_mul(0x9E37_79B9) ^ proposal.len() as u64,
        ..params.clone()
    };
    let r = find_map(&post, Some(&x0), &mp, &|| {}).map_err(|e| MaterialFitError::Fit {
        law: law.label(),
        message: e.to_string(),
    })?;
    let la = &r.laplace;
    let phys = r.map_physical.clone();
    let np = law.n_params();
    let (rs, rl) = post.log_residuals(&phys[..np]);
    let to10 =
        |v: Vec<f64>| -> Vec<f64> { v.into_iter().map(|x| x / std::f64::consts::LN_10).collect() };
    let (rs, rl) = (to10(rs), to10(rl));
    let omega = curve.omega();
    let (ms, ml): (Vec<f64>, Vec<f64>) = omega
        .iter()
        .map(|&w| {
            let e = law.modulus(&phys[..np], w);
            (e.re, e.im)
        })
        .unzip();
    let log_evidence = if la.positive_definite && la.log_evidence.is_finite() {
        la.log_evidence + ln_factorial(law.n_branches)
    } else {
        f64::NEG_INFINITY
    };
    Ok(Candidate {
        step,
        proposal: proposal.to_string(),
        law,
        sd: la.sd_physical(),
        map: phys,
        names: post.names(),
        log_likelihood: la.log_likelihood,
        log_evidence,
        positive_definite: la.positive_definite,
        evidence_gain: f64::NAN,
        causal_floor_ratio: f64::NAN,
        accepted: false,
        rms_log10_storage: rms(&rs),
        rms_log10_loss: rms(&rl),
        stats_storage: residual_stats(&rs),
        stats_loss: residual_stats(&rl),
        res_log10_storage: rs,
        res_log10_loss: rl,
        model_storage_pa: ms,
        model_loss_pa: ml,
    })
}

/// [`Candidate::causal_floor_ratio`] of `c`.
fn floor_ratio(curve: &MasterCurve, tau: &[f64], c: &Candidate) -> f64 {
    let k = c.map.len();
    let (ss, sl) = (c.map[k - 2], c.map[k - 1]);
    let (fs, fl) = super::kk::causal_fit(curve, tau, ss, sl);
    let ln10 = std::f64::consts::LN_10;
    let chi = |rs: &mut dyn Iterator<Item = f64>, rl: &mut dyn Iterator<Item = f64>| -> f64 {
        rs.map(|r| (r / ss).powi(2)).sum::<f64>() + rl.map(|r| (r / sl).powi(2)).sum::<f64>()
    };
    let law = chi(
        &mut c.res_log10_storage.iter().map(|r| r * ln10),
        &mut c.res_log10_loss.iter().map(|r| r * ln10),
    );
    let floor = chi(
        &mut curve
            .storage_pa
            .iter()
            .zip(&fs)
            .map(|(d, m)| (d / m.max(1e-300)).ln()),
        &mut curve
            .loss_pa
            .iter()
            .zip(&fl)
            .map(|(d, m)| (d / m.max(1e-300)).ln()),
    );
    law / floor
}

/// Starting values of a law from the data alone: E0 the lowest E', the relaxation strength the
/// rise of E' across the window, the time at the peak of E'', h the smallest E''.
fn initial_from_data(curve: &MasterCurve, law: RelaxationLaw) -> Vec<f64> {
    let n = curve.len();
    let omega = curve.omega();
    let e_lo = curve.storage_pa[0];
    let e_hi = curve.storage_pa[n - 1].max(1.01 * e_lo);
    let ipk = (0..n)
        .max_by(|&a, &b| curve.loss_pa[a].total_cmp(&curve.loss_pa[b]))
        .unwrap_or(0);
    let tau_pk = 1.0 / omega[ipk];
    let min_l = curve.loss_pa.iter().cloned().fold(f64::INFINITY, f64::min);
    let mut p = vec![e_lo];
    if law.structural_damper {
        p.push(min_l);
    }
    let nb = law.n_branches;
    for k in 0..nb {
        // Spread the branches over the window around the loss peak.
        let t = if nb == 1 {
            tau_pk
        } else {
            let lo = (1.0 / omega[n - 1]).ln();
            let hi = (1.0 / omega[0]).ln();
            (lo + (hi - lo) * (k as f64 + 0.5) / nb as f64).exp()
        };
        p.push((e_hi - e_lo) / nb as f64);
        p.push(t);
    }
    if law.fractional {
        p.extend([e_hi - e_lo, tau_pk, 0.3]);
    }
    p
}

/// Branches to try adding to a fitted law, by the score (Lagrange-multiplier) test of a new
/// branch of strength E at E = 0: on a grid of relaxation times (3 per decade, one decade beyond
/// the data), the log-likelihood gradient g(tau) = dlog L / dE and the Fisher information
/// I(tau) give the score statistic S = g^2 / I (g > 0 only: a strength is non-negative). The
/// `n_max` largest local maxima of S at least a decade apart are returned as (E, tau) with the
/// one-step estimate E = g / I.
fn new_branches(curve: &MasterCurve, c: &Candidate, n_max: usize) -> Vec<(f64, f64)> {
    let n = curve.len();
    let omega = curve.omega();
    let k = c.map.len();
    let (ss, sl) = (c.map[k - 2], c.map[k - 1]);
    let ln10 = std::f64::consts::LN_10;
    let (t_lo, t_hi) = (0.1 / omega[n - 1], 10.0 / omega[0]);
    let nt = ((t_hi / t_lo).log10() * 3.0).ceil() as usize + 1;
    let mut grid: Vec<(f64, f64, f64)> = Vec::with_capacity(nt);
    for j in 0..nt {
        let tau = t_lo * (t_hi / t_lo).powf(j as f64 / (nt - 1) as f64);
        let (mut g, mut info) = (0.0, 0.0);
        for i in 0..n {
            let a = omega[i] * tau;
            let d = 1.0 + a * a;
            // dE'/dE and dE''/dE of a branch, relative to the model's moduli.
            let us = a * a / d / c.model_storage_pa[i];
            let ul = a / d / c.model_loss_pa[i];
            // ln residuals r = ln data - ln model; d log L / dE = sum r / s^2 * d ln E / dE.
            g += c.res_log10_storage[i] * ln10 * us / (ss * ss)
                + c.res_log10_loss[i] * ln10 * ul / (sl * sl);
            info += us * us / (ss * ss) + ul * ul / (sl * sl);
        }
        grid.push((tau, g, info));
    }
    let score: Vec<f64> = grid
        .iter()
        .map(|&(_, g, i)| if g > 0.0 && i > 0.0 { g * g / i } else { 0.0 })
        .collect();
    let mut peaks: Vec<usize> = (0..nt)
        .filter(|&j| {
            score[j] > 0.0
                && (j == 0 || score[j] >= score[j - 1])
                && (j + 1 == nt || score[j] >= score[j + 1])
        })
        .collect();
    peaks.sort_by(|&a, &b| score[b].total_cmp(&score[a]));
    let mut chosen: Vec<usize> = Vec::new();
    for j in peaks {
        if chosen.len() == n_max {
            break;
        }
        let lt = grid[j].0.log10();
        if chosen
            .iter()
            .all(|&q| (grid[q].0.log10() - lt).abs() >= 1.0)
        {
            chosen.push(j);
        }
    }
    let e_max = curve.storage_pa.iter().cloned().fold(0.0, f64::max);
    chosen
        .into_iter()
        .map(|j| {
            let (tau, g, info) = grid[j];
            ((g / info).clamp(1e-4 * e_max, e_max), tau)
        })
        .collect()
}

/// Run the loop on `curve`.
pub fn run_loop(curve: &MasterCurve, params: &LoopParams) -> Result<LoopResult, MaterialFitError> {
    if params.start.n_params() == 0 || params.max_branches < params.start.n_branches {
        return Err(MaterialFitError::Data(format!(
            "max_branches {} is below the start law's {} branches",
            params.max_branches, params.start.n_branches
        )));
    }
    let bounds = PriorBox::from_data(curve);
    let kk = kk_check(curve, params.kk_per_decade, params.kk_threshold);
    let tau = super::kk::tau_grid(curve, params.kk_per_decade);
    let mut cands: Vec<Candidate> = Vec::new();
    // Step 0: the start law, and the fractional alternative.
    let mut first = fit(
        curve,
        &bounds,
        params.start,
        &initial_from_data(curve, params.start),
        0,
        "start",
        &params.map,
    )?;
    first.evidence_gain = 0.0;
    cands.push(first);
    let mut current = 0usize;
    if params.try_fractional && params.start != RelaxationLaw::fractional_zener() {
        let law = RelaxationLaw::fractional_zener();
        let mut c = fit(
            curve,
            &bounds,
            law,
            &initial_from_data(curve, law),
            0,
            "fractional_alternative",
            &params.map,
        )?;
        c.evidence_gain = c.log_evidence - cands[0].log_evidence;
        cands.push(c);
        if cands[1].log_evidence > cands[0].log_evidence {
            current = 1;
        }
    }
    cands[current].accepted = true;
    let mut path = vec![current];
    let mut step = 0;
    let stop = loop {
        if cands[current].causal_floor_ratio.is_nan() {
            cands[current].causal_floor_ratio = floor_ratio(curve, &tau, &cands[current]);
        }
        let cur = cands[current].clone();
        let at_floor = cur.causal_floor_ratio <= params.causal_floor_ratio;
        let at_max = cur.law.n_branches >= params.max_branches;
        step += 1;
        let np = cur.law.n_params();
        let p = &cur.map[..np];
        let mut proposals: Vec<(&str, RelaxationLaw, Vec<f64>)> = Vec::new();
        // Simpler laws with the same relaxation content: the fractional branch as a Maxwell
        // branch (alpha -> 1), the structural damper dropped.
        if let Some(i) = cur.law.fractional_index() {
            if !at_max {
                let law = RelaxationLaw {
                    n_branches: cur.law.n_branches + 1,
                    fractional: false,
                    ..cur.law
                };
                let mut init = p[..i].to_vec();
                init.extend([p[i], p[i + 1]]);
                proposals.push(("fractional_to_branch", law, init));
            }
        }
        if cur.law.structural_damper && cur.law.n_branches + usize::from(cur.law.fractional) > 0 {
            let law = RelaxationLaw {
                structural_damper: false,
                ..cur.law
            };
            let mut init = p.to_vec();
            init.remove(1);
            proposals.push(("drop_h", law, init));
        }
        // More relaxation content, unless the law is at the causal floor or the branch limit.
        if !at_floor && !at_max {
            let add = RelaxationLaw {
                n_branches: cur.law.n_branches + 1,
                ..cur.law
            };
            let at = cur.law.branch_index(cur.law.n_branches);
            for (e_new, t_new) in new_branches(curve, &cur, params.placements) {
                // Add a branch: insert (E, tau) after the existing branches.
                let mut init = p[..at].to_vec();
                init.extend([e_new, t_new]);
                init.extend_from_slice(&p[at..]);
                if cur.law.structural_damper {
                    let law = RelaxationLaw {
                        structural_damper: false,
                        ..add
                    };
                    let mut init2 = init.clone();
                    init2.remove(1);
                    proposals.push(("add_branch_drop_h", law, init2));
                }
                proposals.push(("add_branch", add, init));
            }
        }
        let stop_now = if at_floor {
            StopReason::CausalFloor
        } else if at_max {
            StopReason::MaxBranches
        } else {
            StopReason::NoEvidenceGain
        };
        if proposals.is_empty() || step > 4 * params.max_branches + 4 {
            break stop_now;
        }
        let mut best: Option<usize> = None;
        for (name, law, init) in proposals {
            let mut c = fit(curve, &bounds, law, &init, step, name, &params.map)?;
            c.evidence_gain = c.log_evidence - cur.log_evidence;
            cands.push(c);
            let i = cands.len() - 1;
            if best.is_none_or(|b| cands[i].log_evidence > cands[b].log_evidence) {
                best = Some(i);
            }
        }
        let b = best.unwrap_or(current);
        if !(cands[b].evidence_gain > params.min_evidence_gain) {
            break stop_now;
        }
        cands[b].accepted = true;
        current = b;
        path.push(b);
    };
    Ok(LoopResult {
        candidates: cands,
        path,
        stop,
        kk,
        prior_box: bounds,
    })
}
