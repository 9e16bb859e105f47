//! MAP and samplers of every inference stage of one level ([`infer_level`]): per model, the
//! posterior ([`super::posterior::build_posterior`]), the multistart MAP with its Laplace
//! approximation (starts: the study's initial values, a space-filling design and the
//! deterministic RFM's end point), with the measurement bias linearised and re-linearised at
//! the optimum until it stops moving (then the exact MAP), the channels' correlation as a
//! fixed point of the MAP's residuals, the samplers ([`super::sample`]), the linearisation
//! check and exact evidence ([`super::linearisation`]), the comparison criteria
//! ([`super::compare`]) and the redundancy ([`super::redundancy`]). Orchestration only: the
//! numerics are in [`crate::forward`] and [`crate::inference`]. Checked by the suite's
//! `bayes_run`, `model_comparison` and `inference_samplers` tests.

use super::posterior::{build_posterior, initial_x, level_hash, SamplerResult};
use super::{fail, InferenceParams, RunContext};
use crate::frf::FrfEngine;
use crate::inference::likelihood::ChannelCorrelation;
use crate::inference::likelihood::NoiseModel;
use crate::inference::map::{find_map, MapParams, MapResult};
use crate::inference::prior::Prior;
use crate::inference::refine::{
    correlation_fixed_point, relinearise_to_map, CorrelationKind, LEAKAGE_EPS_MIN,
};
use crate::inference::Posterior;
use crate::inference::Sampler;
use crate::rfm::RfmResult;
use crate::stage::{Event, LevelData, RunError};
use std::time::Instant;

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
    /// With the measurement bias linearised at the MAP: the exact operator against it on
    /// posterior draws, and the evidence correction it gives.
    pub linearisation_check: Option<super::linearisation::LinearisationCheck>,
    /// Sentences for the report about the noise model as fitted (e.g. the channels'
    /// estimated correlation).
    pub notes: Vec<String>,
    /// Evidence, predictive criteria and checks for model comparison ([`super::compare`]).
    pub compare: super::compare::Comparison,
    /// Parameter redundancy at the MAP; the error says why it is missing.
    pub redundancy: Result<super::redundancy::Redundancy, super::redundancy::RedundancyError>,
    /// The basin study (`[inference.basins]`), filled in after the level's inference.
    pub basins: Option<super::basins::BasinStudy>,
    /// Wall time of each step (the MAP search, each sampler, the linearisation check, the
    /// comparison with its evidence estimators and predictive criteria, the redundancy), s:
    /// the run's manifest lists them under the level's inference.
    pub step_seconds: Vec<(String, f64)>,
}

/// The support of a prior (physical values; ends may be infinite).
fn support(prior: &Prior) -> (f64, f64) {
    match *prior {
        Prior::LogUniform { lo, hi }
        | Prior::Uniform { lo, hi }
        | Prior::TruncatedNormal { lo, hi, .. } => (lo, hi),
        Prior::LogNormal { .. } => (0.0, f64::INFINITY),
    }
}

/// Whether the MAP of `p` is a result ([`crate::rfm::status`]): every value finite, none on
/// the edge of its prior's support, a modulus (Pa) inside its physical range, and a search
/// that did not give up.
pub fn map_status(p: &PosteriorResult) -> crate::rfm::FitStatus {
    use crate::rfm::status::{parameter_flags, ParamCheck};
    let values = &p.map.map_physical;
    let checks: Vec<ParamCheck<'_>> = values
        .iter()
        .enumerate()
        .map(|(k, &value)| ParamCheck {
            name: p.names.get(k).map(String::as_str).unwrap_or("?"),
            unit: p.units.get(k).map(String::as_str).unwrap_or(""),
            value,
            range: p
                .priors
                .get(k)
                .map(support)
                .unwrap_or((f64::NEG_INFINITY, f64::INFINITY)),
        })
        .collect();
    let mut reasons = parameter_flags(&checks);
    if p.map.gave_up() {
        reasons.push(crate::rfm::FlagReason::Diverged);
    }
    crate::rfm::FitStatus::from_reasons(reasons)
}

impl PosteriorResult {
    /// [`map_status`] of this posterior.
    pub fn map_status(&self) -> crate::rfm::FitStatus {
        map_status(self)
    }
    /// The draws the figures show: NUTS's when it ran, else the first sampler's.
    pub fn figure_sampler(&self) -> Option<&SamplerResult> {
        self.samplers
            .iter()
            .find(|s| s.sampler == Sampler::Nuts)
            .or(self.samplers.first())
    }
}

/// MAP and samplers of the inference stages `stages` of `level` (one per model, in order: a
/// model's streams derive from its place there), with the deterministic fits `rfm` of the
/// level as extra MAP starts.
pub fn infer_level(
    run: &RunContext<'_>,
    stages: &[&InferenceParams],
    engine: &dyn FrfEngine,
    level: &LevelData,
    rfm: &[&RfmResult],
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<PosteriorResult>, RunError> {
    let mut out = Vec::new();
    for (mi, stage) in stages.iter().enumerate() {
        let name = &stage.model;
        let inf = &stage.samplers;
        let Some((spec, law)) = run.model(name) else {
            continue;
        };
        let mut post = build_posterior(&run.posterior, stage, engine, level, law)?;
        let x0 = initial_x(&post, &spec.initial);
        // The deterministic fit's end point is a natural extra start.
        let rfm_x = rfm
            .iter()
            .find(|g| g.model_name.eq_ignore_ascii_case(name))
            .filter(|g| {
                post.priors
                    .iter()
                    .zip(&g.params)
                    .all(|(p, v)| p.contains(*v))
            })
            .map(|g| initial_x(&post, &g.params));
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
        let seed = run.seed ^ ((mi as u64 + 1) << 32) ^ level_hash(&level.name);
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
            correlation_fixed_point(
                &mut post,
                &mut map,
                &params,
                kind,
                window,
                &level.freq_hz,
                linearised,
            )
            .map_err(|e| {
                fail(
                    format!("channel correlation of {name} at {}", level.name),
                    e,
                )
            })?;
            if let Some(c) = post.likelihood.channel_correlation() {
                notes.push(correlation_note(c, &level.freq_hz, kind, window));
            }
        }
        progress(Event::Finish);
        let map_seconds = t0.elapsed().as_secs_f64();
        let at = super::At {
            level,
            model: name,
            seed,
        };
        let mut step_seconds = vec![("MAP".to_string(), map_seconds)];
        let mut samplers =
            super::sample::run_samplers(&run.checkpoints, inf, &post, &map, &at, progress)?;
        step_seconds.extend(samplers.iter().map(|s| (s.sampler.to_string(), s.seconds)));
        let t_step = Instant::now();
        let linearisation_check = super::linearisation::to_exact(&mut post, &mut samplers, nl);
        step_seconds.push(("linearisation check".into(), t_step.elapsed().as_secs_f64()));
        let t_step = Instant::now();
        let lin_shift = linearisation_check.map_or((0.0, 0.0), |r| (r.shift, r.shift_se));
        let compare = super::compare::compare(
            &run.checkpoints,
            inf,
            &post,
            &map,
            &samplers,
            lin_shift,
            &at,
            progress,
        )?;
        step_seconds.push(("comparison".into(), t_step.elapsed().as_secs_f64()));
        let t_step = Instant::now();
        let redundancy = super::redundancy::analyse(&post, &map, &samplers);
        step_seconds.push(("redundancy".into(), t_step.elapsed().as_secs_f64()));
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
            step_seconds,
        });
    }
    Ok(out)
}

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
