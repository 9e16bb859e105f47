//! The `[inference]` part of a run: per level and model, the posterior over the law's
//! parameters (and inferred noise scales) through one forward model, the multistart MAP with
//! its Laplace approximation, and the samplers. Orchestration only: the numerics are in
//! [`crate::forward`] and [`crate::inference`].

use super::{Event, LevelData, RunError};
use crate::forward::{EstimatorSpec, ForwardModel, MeasurementModel, MeasurementParams};
use crate::frf::FrfEngine;
use crate::inference::likelihood::{
    ChannelCorrelation, FrfData, FrfLikelihood, FrfPosterior, NoiseModel, Scale,
};
use crate::inference::map::{find_map, MapParams, MapResult};
use crate::inference::prior::Prior;
use crate::inference::Posterior;
use crate::material::ConstitutiveModel;
use crate::study::inference::{CorrelationKind, Inference};
use crate::study::{Estimator, Study};
use std::time::Instant;

/// Draws of one sampler, flattened over chains (physical values, SI).
#[derive(Clone, Debug, Default)]
pub struct Draws {
    pub chain: Vec<usize>,
    pub draw: Vec<usize>,
    /// `values[param][row]`.
    pub values: Vec<Vec<f64>>,
    pub lp: Vec<f64>,
    pub log_lik: Vec<f64>,
    pub log_prior: Vec<f64>,
    /// Sampler statistics per row (name, values).
    pub stats: Vec<(String, Vec<f64>)>,
}

impl Draws {
    /// `[param][chain][draw]` for the diagnostics.
    pub fn by_chain(&self) -> Vec<Vec<Vec<f64>>> {
        let n_chains = self.chain.iter().copied().max().map_or(0, |c| c + 1);
        self.values
            .iter()
            .map(|col| {
                let mut out = vec![Vec::new(); n_chains];
                for (r, v) in col.iter().enumerate() {
                    out[self.chain[r]].push(*v);
                }
                out
            })
            .collect()
    }
}

/// One sampler's result.
#[derive(Clone, Debug)]
pub struct SamplerResult {
    pub sampler: String,
    pub draws: Draws,
    /// Log evidence and its standard error, when the sampler estimates it.
    pub log_evidence: Option<(f64, f64)>,
    /// Likelihood (with gradient for NUTS) evaluations.
    pub evaluations: usize,
    pub seconds: f64,
    /// Per-stage or per-chain statistics for the report (name, value) rows.
    pub notes: Vec<String>,
}

/// The posterior of one model at one level.
#[derive(Clone, Debug)]
pub struct PosteriorResult {
    pub level: String,
    pub model: String,
    pub names: Vec<String>,
    pub units: Vec<String>,
    pub priors: Vec<Prior>,
    pub noise: NoiseModel,
    pub map: MapResult,
    pub map_seconds: f64,
    pub samplers: Vec<SamplerResult>,
    /// Unconstrained coordinates of the study's initial values (start 0 of the search).
    pub initial_x: Vec<f64>,
    /// With the measurement bias linearised at the MAP: (draws checked, sd over them of
    /// log L exact - log L linearised, log mean exp of that difference), in nats.
    pub linearisation_check: Option<(usize, f64, f64)>,
    /// Sentences for the report about the noise model as fitted (e.g. the channels'
    /// estimated correlation).
    pub notes: Vec<String>,
    /// Evidence, predictive criteria and checks for model comparison ([`super::compare`]).
    pub compare: super::compare::Comparison,
    /// Parameter redundancy at the MAP; the error says why it is missing.
    pub redundancy: Result<super::redundancy::Redundancy, String>,
    /// The basin study (`[inference.basins]`), filled in after the level's inference.
    pub basins: Option<super::basins::BasinStudy>,
}

impl PosteriorResult {
    /// The draws the figures show: NUTS's when it ran, else the first sampler's.
    pub fn figure_sampler(&self) -> Option<&SamplerResult> {
        self.samplers
            .iter()
            .find(|s| s.sampler == "nuts")
            .or(self.samplers.first())
    }
}

/// The estimator declared by the study as the forward model's measurement-model settings for
/// a level with lines `freq_hz`.
pub fn estimator_spec(estimator: &Estimator, freq_hz: &[f64]) -> EstimatorSpec {
    let lo = freq_hz.first().copied().unwrap_or(0.0);
    let hi = freq_hz.last().copied().unwrap_or(0.0);
    EstimatorSpec {
        window: estimator.window,
        block_s: estimator.block_s,
        fs_hz: estimator.fs_hz,
        force_band_hz: estimator.force_band((lo, hi)),
        shaker: estimator.shaker,
    }
}

/// The measurement model of a level, when the study declares its estimator.
pub fn measurement_model(
    study: &Study,
    level: &LevelData,
) -> Result<Option<MeasurementModel>, RunError> {
    let Some(est) = study
        .measurements
        .as_ref()
        .and_then(|m| m.estimator.as_ref())
    else {
        return Ok(None);
    };
    if let Some((m, _)) = &level.measurement {
        return Ok(Some(m.clone()));
    }
    MeasurementModel::new(
        estimator_spec(est, &level.freq_hz),
        &level.freq_hz,
        &MeasurementParams::default(),
    )
    .map(Some)
    .map_err(|e| super::study_err(study, "measurements.estimator", e.to_string()))
}

fn fail(what: String, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: what,
        message: e.to_string(),
    }
}

/// Equivalent number of independent averages of a level's H1: the study's value, else the
/// file's block count corrected for the declared estimator's overlap (Welch 1967; Hann at
/// 50 %: n / 1.056), else an error naming the key.
fn n_averages(study: &Study, inf: &Inference, level: &LevelData) -> Result<f64, RunError> {
    if let Some(n) = inf.noise.n_averages {
        return Ok(n);
    }
    if !inf.noise.uses_coherence() {
        return Ok(1.0);
    }
    let Some(n) = level.n_averages else {
        return Err(super::study_err(
            study,
            "inference.noise.n_averages",
            format!("the files of level {} do not say how many averages H1 has: give n_averages (equivalent independent averages, e.g. 189.5 for 200 Hann blocks at 50 % overlap)", level.name),
        ));
    };
    Ok(
        match study
            .measurements
            .as_ref()
            .and_then(|m| m.estimator.as_ref())
        {
            Some(e) => {
                let nb = (e.fs_hz * e.block_s).round() as usize;
                crate::experiment::estimator::effective_averages(e.window, nb, nb / 2, n as usize)
            }
            None => n as f64,
        },
    )
}

/// Build the posterior of `law` at `level` (the caller keeps it alive while sampling).
pub fn build_posterior<'a>(
    study: &Study,
    inf: &Inference,
    engine: &'a dyn FrfEngine,
    level: &LevelData,
    law: &'a dyn ConstitutiveModel,
    model_name: &str,
) -> Result<FrfPosterior<'a>, RunError> {
    let col = &level.column;
    let forward = ForwardModel::new(
        engine,
        law,
        &col.omega_rad_s,
        col.input,
        &col.outputs,
        measurement_model(study, level)?,
    )
    .map_err(|e| {
        fail(
            format!("forward model of {model_name} at {}", level.name),
            e,
        )
    })?;
    // Declared effects (`[[structure.effects]]`): fixed ones change the model, free ones are
    // parameters after the law's.
    let mut forward = forward;
    let ids: Vec<u32> = study.structure.points.iter().map(|p| p.id).collect();
    let (effects, effect_priors) = super::declared::level_effects(study, &ids, level)?;
    if !effects.is_empty() {
        forward
            .set_effects(effects)
            .map_err(|e| fail(format!("declared effects at {}", level.name), e))?;
    }
    let noise = inf.noise.resolve(n_averages(study, inf, level)?);
    let data = FrfData {
        freq_hz: level.freq_hz.clone(),
        n_out: col.outputs.len(),
        values: col.accelerance.clone(),
        coherence: level.coherence.clone(),
    };
    let lik = FrfLikelihood::new(forward, data, noise, &level.response_ids).map_err(|e| {
        super::study_err(
            study,
            "inference.noise",
            format!("level {}: {e}", level.name),
        )
    })?;
    let mut priors = inf.priors.get(model_name).cloned().unwrap_or_default();
    priors.extend(effect_priors);
    for _ in 0..lik.n_tau() {
        priors.push(inf.noise_scale_prior.clone());
    }
    if lik.n_noise() > lik.n_tau() {
        priors.push(inf.nu_prior.clone());
    }
    FrfPosterior::new(lik, priors).map_err(|e| fail(format!("posterior of {model_name}"), e))
}

/// Initial unconstrained point: law parameters from `p_law`, noise scales at the RMS relative
/// residual of the fit per channel (so a start is never absurd), nu at 10.
pub(crate) fn initial_x(post: &FrfPosterior<'_>, p_law: &[f64]) -> Vec<f64> {
    let mut phys = p_law.to_vec();
    let lik = &post.likelihood;
    // Declared free effects start at their declared values.
    if phys.len() < lik.forward.n_params() {
        phys.extend(
            lik.forward
                .effects
                .terms
                .iter()
                .filter(|t| t.free)
                .map(|t| t.value),
        );
    }
    if lik.n_tau() > 0 {
        let pred = lik.forward.predict(&phys, false).ok();
        let n = lik.data.n_out;
        let groups = lik.n_tau();
        let mut num = vec![0.0; groups];
        let mut cnt = vec![0.0; groups];
        if let Some(pred) = pred {
            // Relative residuals per channel (bands share the channel's value at the start).
            for (o, (h, x)) in pred.values.iter().zip(&lik.data.values).enumerate() {
                let k = o % n;
                let per = groups / n;
                for b in 0..per {
                    num[k * per + b] += ((h - x).norm() / x.norm()).powi(2);
                    cnt[k * per + b] += 1.0;
                }
            }
        }
        for g in 0..groups {
            let v = if cnt[g] > 0.0 {
                (num[g] / cnt[g]).sqrt()
            } else {
                0.01
            };
            phys.push(v.clamp(2e-4, 0.5));
        }
    }
    if lik.n_noise() > lik.n_tau() {
        phys.push(10.0);
    }
    post.unconstrained(&phys)
}

/// MAP and samplers of every `[inference]` model at one level.
pub fn infer_level(
    study: &Study,
    inf: &Inference,
    engine: &dyn FrfEngine,
    level: &LevelData,
    laws: &[Box<dyn ConstitutiveModel>],
    rfm: &[super::GlobalResult],
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<PosteriorResult>, RunError> {
    if !inf.levels.contains(&level.name) {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    for (mi, name) in inf.models.iter().enumerate() {
        let Some((spec, law)) = study
            .models
            .iter()
            .zip(laws)
            .find(|(m, _)| m.name.eq_ignore_ascii_case(name))
        else {
            continue;
        };
        let mut post = build_posterior(study, inf, engine, level, law.as_ref(), name)?;
        let x0 = initial_x(&post, &spec.initial);
        // The deterministic fit's end point is a natural extra start.
        let rfm_x = rfm
            .iter()
            .find(|g| g.result.model_name.eq_ignore_ascii_case(name))
            .filter(|g| {
                post.priors
                    .iter()
                    .zip(&g.result.params)
                    .all(|(p, v)| p.contains(*v))
            })
            .map(|g| initial_x(&post, &g.result.params));
        let t0 = Instant::now();
        let nl = law.n_params();
        // With the measurement bias linearised (the default), the search runs on the bias
        // linearised at the deterministic fit (or the initial values), then re-linearises at
        // its optimum until the optimum stops moving: there the linearised and the exact
        // likelihood have the same value and gradient, so it is the exact MAP.
        let linearised =
            inf.linearised_measurement && post.likelihood.forward.obs.measurement.is_some();
        if linearised {
            let p_lin = rfm_x
                .as_ref()
                .map(|x| post.physical(x))
                .unwrap_or_else(|| spec.initial.clone());
            post.likelihood
                .forward
                .linearise_measurement(&p_lin[..nl])
                .map_err(|e| fail(format!("measurement model of {name} at {}", level.name), e))?;
        }
        let n_starts = inf.map_starts + 1 + rfm_x.is_some() as usize;
        progress(Event::Start {
            step: format!("{}: MAP of {name} ({n_starts} starts)", level.name),
            total: n_starts as u64,
        });
        let seed = study.seed ^ ((mi as u64 + 1) << 32) ^ level_hash(&level.name);
        let params = MapParams {
            n_starts: inf.map_starts,
            max_iters: inf.map_max_iterations,
            seed,
            ..MapParams::default()
        };
        let mut map = find_map(&post, Some(&x0), &params, &|| progress(Event::Advance))
            .map_err(|e| fail(format!("MAP of {name} at level {}", level.name), e))?;
        if let Some(xr) = rfm_x {
            // One more start from the RFM result, searched like the others.
            let extra = find_map(
                &post,
                Some(&xr),
                &MapParams {
                    n_starts: 0,
                    ..params.clone()
                },
                &|| progress(Event::Advance),
            )
            .map_err(|e| fail(format!("MAP of {name} at level {}", level.name), e))?;
            let mut s = extra.starts[0].clone();
            s.kind = "rfm";
            s.index = map.starts.len();
            let better = s.objective < map.starts[map.best].objective - 1e-9;
            map.starts.push(s);
            map.evaluations += extra.evaluations;
            if better {
                map.best = map.starts.len() - 1;
                map.laplace = extra.laplace;
                map.map_x = extra.map_x;
                map.map_physical = extra.map_physical;
                map.polish_steps = extra.polish_steps;
            }
        }
        if linearised {
            relinearise_to_map(&mut post, &mut map, &params, nl)
                .map_err(|e| fail(format!("MAP of {name} at level {}", level.name), e))?;
        }
        let mut notes = Vec::new();
        if let Some((kind, window)) = inf.channel_correlation {
            // Correlated channels: the correlation per line from the MAP's standardised
            // residuals, then the MAP again under it; twice, so the correlation is that of
            // the residuals of the MAP it defines (the second pass moves it little).
            for _ in 0..CORRELATION_PASSES {
                let c = correlation_at(&post, &map.map_physical, kind, window, &level.freq_hz)
                    .map_err(|e| {
                        fail(
                            format!("channel correlation of {name} at {}", level.name),
                            e,
                        )
                    })?;
                post.likelihood
                    .set_channel_correlation(Some(c))
                    .map_err(|e| {
                        super::study_err(
                            study,
                            "inference.noise.channel_correlation",
                            e.to_string(),
                        )
                    })?;
                let again = find_map(
                    &post,
                    Some(&map.map_x),
                    &MapParams {
                        n_starts: 0,
                        ..params.clone()
                    },
                    &|| (),
                )
                .map_err(|e| fail(format!("MAP of {name} at level {}", level.name), e))?;
                adopt(&mut map, again);
                if linearised {
                    relinearise_to_map(&mut post, &mut map, &params, nl)
                        .map_err(|e| fail(format!("MAP of {name} at level {}", level.name), e))?;
                }
            }
            if let Some(c) = post.likelihood.channel_correlation() {
                notes.push(correlation_note(c, &level.freq_hz, kind, window));
            }
        }
        progress(Event::Finish);
        let map_seconds = t0.elapsed().as_secs_f64();
        let mut samplers =
            super::sample::run_samplers(study, inf, &post, &map, seed, level, name, progress)?;
        let linearisation_check = match post.likelihood.forward.linear_bias.take() {
            Some(lb) => {
                let r = linearisation_error(&post, &samplers, nl);
                post.likelihood.forward.linear_bias = Some(lb);
                // The evidence of the exact likelihood, by importance sampling (see above).
                for smp in &mut samplers {
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
            None => None,
        };
        let lin_shift = linearisation_check.map_or(0.0, |r| r.2);
        let compare = super::compare::compare(
            study, inf, &post, &map, &samplers, lin_shift, seed, level, name, progress,
        )?;
        let redundancy = super::redundancy::analyse(&post, &map, &samplers);
        let mut units = law.param_units();
        units.extend(std::iter::repeat_n(
            "1".to_string(),
            post.dim() - units.len(),
        ));
        out.push(PosteriorResult {
            level: level.name.clone(),
            model: name.clone(),
            names: post.names(),
            units,
            priors: post.priors.clone(),
            noise: post.likelihood.noise.clone(),
            map,
            map_seconds,
            samplers,
            initial_x: x0,
            linearisation_check,
            notes,
            compare,
            redundancy,
            basins: None,
        });
    }
    Ok(out)
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

/// Take a polishing search's end point as the MAP (the start list stays the multistart's).
fn adopt(map: &mut MapResult, again: MapResult) {
    map.evaluations += again.evaluations;
    map.polish_steps += again.polish_steps;
    map.map_x = again.map_x;
    map.map_physical = again.map_physical;
    map.laplace = again.laplace;
}

/// Re-linearise the measurement bias at the MAP and search again from it until the MAP stops
/// moving (relative 1e-7 in every law parameter); leaves the bias linearised at the final MAP,
/// where the linearised and the exact likelihood agree in value and gradient.
pub fn relinearise_to_map(
    post: &mut FrfPosterior<'_>,
    map: &mut MapResult,
    params: &MapParams,
    nl: usize,
) -> Result<(), String> {
    for _ in 0..MAX_RELINEARISATIONS {
        let p_lin = map.map_physical[..nl].to_vec();
        post.likelihood
            .forward
            .linearise_measurement(&p_lin)
            .map_err(|e| e.to_string())?;
        let again = find_map(
            &*post,
            Some(&map.map_x),
            &MapParams {
                n_starts: 0,
                ..params.clone()
            },
            &|| (),
        )
        .map_err(|e| e.to_string())?;
        let moved = again.map_physical[..nl]
            .iter()
            .zip(&p_lin)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        adopt(map, again);
        if moved < 1e-7 {
            break;
        }
    }
    post.likelihood
        .forward
        .linearise_measurement(&map.map_physical[..nl])
        .map_err(|e| e.to_string())
}

/// Floor on the leakage structure's isotropic share eps. Below about 1 % the rank-one structure
/// makes the differences between channels near exact, and then a model difference far below the
/// noise reads as information: on the independent frequency-domain virtual data (whose random
/// error also lies along dE[H1]/df) a floor of 1e-4 gave posterior sds of 1e-5 and put the truth
/// 9 sd away, at a 5e-5 relative parameter shift (the two codes' FE discretisations).
pub(crate) const LEAKAGE_EPS_MIN: f64 = 1e-2;

/// The channels' error correlation per line (`inference.noise.channel_correlation`) from the
/// standardised residuals at the physical parameters `physical` (law's, then noise scales):
/// estimated from the residuals over `window` lines, or the Welch H1's leakage structure
/// (rank one along dE[H1]/df plus an isotropic share floored at [`LEAKAGE_EPS_MIN`]). Used by
/// the inference and by the closed loop, so both see the same correlation.
pub(crate) fn correlation_at(
    post: &FrfPosterior<'_>,
    physical: &[f64],
    kind: CorrelationKind,
    window: usize,
    freq_hz: &[f64],
) -> Result<ChannelCorrelation, String> {
    let (pl, pn) = physical.split_at(post.likelihood.forward.n_params());
    let s = post
        .likelihood
        .standardised(pl, pn)
        .map_err(|e| format!("residuals: {e}"))?;
    let n_out = post.likelihood.data.n_out;
    match kind {
        CorrelationKind::Estimated => ChannelCorrelation::estimate(&s, n_out, window),
        CorrelationKind::Leakage => {
            let pred = post
                .likelihood
                .forward
                .predict(pl, false)
                .map_err(|e| format!("prediction: {e}"))?;
            ChannelCorrelation::leakage(&pred.values, freq_hz, &s, n_out, window, LEAKAGE_EPS_MIN)
        }
    }
    .map_err(|e| e.to_string())
}

/// Passes of (estimate the channels' correlation at the MAP, search the MAP again).
const CORRELATION_PASSES: usize = 2;

/// A report sentence on an estimated channel correlation: where it is large and how much
/// shrinkage the estimate needed.
fn correlation_note(
    c: &ChannelCorrelation,
    freq_hz: &[f64],
    kind: CorrelationKind,
    window: usize,
) -> String {
    let median = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s.get(s.len() / 2).copied().unwrap_or(0.0)
    };
    match kind {
        CorrelationKind::Leakage => {
            let (imax, emax) = c
                .shrinkage
                .iter()
                .copied()
                .enumerate()
                .fold((0, 0.0), |a, (i, v)| if v > a.1 { (i, v) } else { a });
            format!(
                "The channels' errors are modelled as the Welch H1's leakage jitter (`channel_correlation = \"leakage\"`): per line, rank one along dE[H1]/df (one common complex error for all channels) plus an isotropic share eps estimated from the MAP's standardised residuals over {window} lines (floor {LEAKAGE_EPS_MIN:.0e}). eps: median {:.2e}, largest {emax:.2e} at {:.1} Hz.",
                median(&c.shrinkage),
                freq_hz.get(imax).copied().unwrap_or(0.0)
            )
        }
        CorrelationKind::Estimated => {
            let (imax, vmax) = c
                .max_correlation
                .iter()
                .copied()
                .enumerate()
                .fold((0, 0.0), |a, (i, v)| if v > a.1 { (i, v) } else { a });
            format!(
                "The channels' errors are modelled as correlated per line (`channel_correlation = \"estimated\"`): each line's correlation matrix is the sample correlation of the MAP's standardised residuals over {window} lines, shrunk towards the identity (Schäfer & Strimmer). Largest |R_ij| per line: median {:.2}, maximum {vmax:.2} at {:.1} Hz.",
                median(&c.max_correlation),
                freq_hz.get(imax).copied().unwrap_or(0.0)
            )
        }
    }
}

/// At most this many re-linearisations of the measurement bias at the MAP (2-3 suffice: the
/// bias moves the optimum by a fraction of a per cent).
const MAX_RELINEARISATIONS: usize = 6;

/// A stable 64-bit hash of a level name (FNV-1a), to give each level its own seed stream.
pub fn level_hash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01B3)
    })
}

/// Whether a noise model needs coherence (for error messages before loading).
pub fn needs_coherence(n: &NoiseModel) -> bool {
    matches!(n.scale, Scale::Coherence { .. })
}
