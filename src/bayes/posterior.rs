//! The posterior of one model at one level: the forward model through the level's
//! measurement model (the H1 estimator's expected value, [`crate::forward::MeasurementModel`]),
//! the declared effects, the likelihood with the stage's noise model
//! ([`crate::inference::likelihood::FrfLikelihood`]) and the priors (law, free effects, noise
//! scales, nu); and the typed results the inference stages return (draws per sampler).
//! Checked by the suite's `bayes_run` and `measurement_model` tests.

use super::{fail, input_err, InferenceParams, PosteriorInputs};
use crate::forward::ForwardModel;
use crate::frf::FrfEngine;
use crate::inference::likelihood::{FrfData, FrfLikelihood, FrfPosterior, NoiseModel, Scale};
use crate::material::ConstitutiveModel;
use crate::stage::{LevelData, RunError};
use crate::study::inference::NoiseSpec;

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
    pub sampler: crate::inference::Sampler,
    pub draws: Draws,
    /// Log evidence and its standard error, when the sampler estimates it.
    pub log_evidence: Option<(f64, f64)>,
    /// Likelihood (with gradient for NUTS) evaluations.
    pub evaluations: usize,
    pub seconds: f64,
    /// Per-stage or per-chain statistics for the report (name, value) rows.
    pub notes: Vec<String>,
}

/// Equivalent number of independent averages of a level's H1: the study's value, else the
/// file's block count corrected for the declared estimator's overlap (Welch 1967; Hann at
/// 50 %: n / 1.056), else an error naming the key.
fn n_averages(
    inputs: &PosteriorInputs<'_>,
    noise: &NoiseSpec,
    level: &LevelData,
) -> Result<f64, RunError> {
    if let Some(n) = noise.n_averages {
        return Ok(n);
    }
    if !noise.uses_coherence() {
        return Ok(1.0);
    }
    let Some(n) = level.n_averages else {
        return Err(input_err(
            inputs.file,
            "inference.noise.n_averages",
            format!("the files of level {} do not say how many averages H1 has: give n_averages (equivalent independent averages, e.g. 189.5 for 200 Hann blocks at 50 % overlap)", level.name),
        ));
    };
    Ok(match inputs.estimator {
        Some(e) => {
            let nb = (e.fs_hz * e.block_s).round() as usize;
            crate::experiment::estimator::effective_averages(e.window, nb, nb / 2, n as usize)
        }
        None => n as f64,
    })
}

/// Build the posterior of stage `stage` (its model's law `law`) at `level` (the caller keeps
/// it alive while sampling).
pub fn build_posterior<'a>(
    inputs: &PosteriorInputs<'_>,
    stage: &InferenceParams,
    engine: &'a dyn FrfEngine,
    level: &LevelData,
    law: &'a dyn ConstitutiveModel,
) -> Result<FrfPosterior<'a>, RunError> {
    let model_name = stage.model.as_str();
    let sp = &stage.samplers;
    let col = &level.column;
    // The inputs first: the declared effects (`[[structure.effects]]`: fixed ones change the
    // model, free ones are parameters after the law's), the noise model, the H1 measurement.
    let (effects, effect_priors) =
        super::declared::level_effects(inputs.declared, inputs.file, inputs.point_ids, level)?;
    let n_d = n_averages(inputs, &sp.noise, level)?;
    let measurement =
        crate::stage::measurement::measurement_model(inputs.estimator, level, inputs.file)?;
    let noise = sp.noise.resolve(n_d);
    let mut forward = ForwardModel::new(
        engine,
        law,
        &col.omega_rad_s,
        col.input,
        &col.outputs,
        measurement,
    )
    .map_err(|e| {
        fail(
            format!("forward model of {model_name} at {}", level.name),
            e,
        )
    })?;
    if !effects.is_empty() {
        forward
            .set_effects(effects)
            .map_err(|e| fail(format!("declared effects at {}", level.name), e))?;
    }
    let data = FrfData {
        freq_hz: level.freq_hz.clone(),
        n_out: col.outputs.len(),
        values: col.accelerance.clone(),
        coherence: level.coherence.clone(),
    };
    let lik = FrfLikelihood::new(forward, data, noise, &level.response_ids).map_err(|e| {
        input_err(
            inputs.file,
            "inference.noise",
            format!("level {}: {e}", level.name),
        )
    })?;
    let mut priors = stage.priors.clone();
    priors.extend(effect_priors);
    for _ in 0..lik.n_tau() {
        priors.push(sp.noise_scale_prior.clone());
    }
    if lik.n_noise() > lik.n_tau() {
        priors.push(sp.nu_prior.clone());
    }
    FrfPosterior::new(lik, priors).map_err(|e| fail(format!("posterior of {model_name}"), e))
}

/// Initial unconstrained point: law parameters from `p_law`, noise scales at the RMS relative
/// residual of the fit per channel (so a start is never absurd), nu at 10.
pub fn initial_x(post: &FrfPosterior<'_>, p_law: &[f64]) -> Vec<f64> {
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
