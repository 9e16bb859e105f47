//! The `[inference]` section of a study: noise model, priors, multistart search and samplers.
//!
//! ```toml
//! [inference]
//! models = ["model3", "model4", "model5"]   # default: those of [[models]] among Models 3-5
//! levels = ["L1", "L2"]                     # default: every level
//! samplers = ["nuts", "stepping_stone"]     # default: NUTS, and the evidence by the stepping-stone
//!                                           # and importance sampling from NUTS's draws; add "tmcmc"
//!                                           # for a sampler that needs no gradient (multimodal posteriors)
//!
//! [inference.noise]
//! model = "coherence"          # "coherence" (default), "inferred" or "student_t"
//! n_averages = 189.5           # equivalent independent averages; default: from the file (Welch-corrected)
//! coherence_floor = 1e-4       # floor on 1 - g^2
//! model_error = 0.0            # relative model-error floor, added in quadrature
//! scale = "coherence"          # student_t only: "coherence" or "inferred"
//! nu = 4.0                     # student_t only: a number, or "infer"
//! bands_hz = [1, 100, 500]     # inferred scales per channel and band (default: one per channel)
//! channel_correlation = "leakage"  # "none" (default), "leakage" (the Welch H1 error as a common
//!                              # frequency jitter along dE[H1]/df, its off-direction share from the
//!                              # MAP residuals) or "estimated" (a sample correlation of the MAP
//!                              # residuals, shrunk to the identity); Gaussian errors only
//! correlation_window_lines = 21  # lines in the window of each line's estimate
//!
//! [inference.priors.model4]    # default per parameter: log-uniform over a decade either side of the initial value
//! E0 = { family = "log_normal", median = 7e6, sigma_ln = 0.5 }
//! eta1 = { family = "log_uniform", lo = 1e3, hi = 1e5 }
//!
//! [inference.map]
//! starts = 16                  # space-filling starts besides the initial values and the RFM result
//!
//! [inference.nuts]
//! chains = 4
//! tune = 1000
//! draws = 1000
//! max_tree_depth = 10
//! target_accept = 0.8
//!
//! [inference.tmcmc]
//! particles = 2000
//!
//! [inference.stepping_stone]   # with samplers = [..., "stepping_stone"]: evidence only
//! particles = 250              # per replica
//! replicas = 8                 # the standard error comes from their spread
//! path = "reference"           # from a Student-t fitted to the posterior draws (default) or "prior"
//! widen = 1.5                  # reference sd over the draws' sd
//! nu = 5.0                     # reference degrees of freedom ("inf" not allowed: use 1e9 for a Gaussian)
//! ```

use super::ctx::Ctx;
use super::{ModelSpec, StudyError};
use crate::inference::likelihood::{ErrorLaw, NoiseModel, Scale, DEFAULT_COHERENCE_FLOOR};
use crate::inference::prior::Prior;
use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawInference {
    pub models: Option<Vec<String>>,
    pub levels: Option<Vec<String>>,
    pub samplers: Option<Vec<String>>,
    pub noise: Option<RawNoise>,
    #[serde(default)]
    pub priors: BTreeMap<String, BTreeMap<String, RawPrior>>,
    pub map: Option<RawMap>,
    pub nuts: Option<RawNuts>,
    pub tmcmc: Option<RawTmcmc>,
    pub stepping_stone: Option<RawSteppingStone>,
    /// "linearised" (default) or "exact": how samplers see `[measurements.estimator]`.
    pub measurement: Option<String>,
    /// `[inference.across_levels]`, see [`super::comparison`].
    pub across_levels: Option<super::comparison::RawLevels>,
    /// `[inference.basins]`, see [`super::comparison`].
    pub basins: Option<super::comparison::RawBasins>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawNoise {
    pub model: Option<String>,
    pub n_averages: Option<f64>,
    pub coherence_floor: Option<f64>,
    pub model_error: Option<f64>,
    pub scale: Option<String>,
    pub nu: Option<toml::Value>,
    pub bands_hz: Option<Vec<f64>>,
    pub channel_correlation: Option<String>,
    pub correlation_window_lines: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPrior {
    pub family: String,
    pub lo: Option<f64>,
    pub hi: Option<f64>,
    pub median: Option<f64>,
    pub sigma_ln: Option<f64>,
    pub mean: Option<f64>,
    pub sd: Option<f64>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawMap {
    pub starts: Option<usize>,
    pub max_iterations: Option<u64>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawNuts {
    pub chains: Option<usize>,
    pub tune: Option<usize>,
    pub draws: Option<usize>,
    pub max_tree_depth: Option<u64>,
    pub target_accept: Option<f64>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawTmcmc {
    pub particles: Option<usize>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawSteppingStone {
    pub particles: Option<usize>,
    pub replicas: Option<usize>,
    pub path: Option<String>,
    pub widen: Option<f64>,
    pub nu: Option<f64>,
}

/// Stepping-stone settings (evidence only; see [`crate::inference::stepping_stone`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SteppingStoneSettings {
    /// Particles per replica.
    pub particles: usize,
    /// Independent replicas (at least 2: the standard error comes from their spread).
    pub replicas: usize,
    /// `true`: generalized stepping-stone from a reference fitted to the posterior draws
    /// ([`crate::inference::reference`]); `false`: from the prior.
    pub from_reference: bool,
    /// The reference's standard deviations over the draws'.
    pub widen: f64,
    /// The reference's degrees of freedom.
    pub nu: f64,
}

/// The noise model as declared (the number of averages may come from the data file).
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseSpec {
    /// `None` for coherence scales: take the data file's number of averages, corrected for
    /// the estimator's overlap.
    pub n_averages: Option<f64>,
    /// The noise model with `n_averages` still to be filled in for coherence scales (0 there).
    pub model: NoiseModel,
}

impl NoiseSpec {
    /// The noise model with the number of averages resolved.
    pub fn resolve(&self, n_d: f64) -> NoiseModel {
        let mut m = self.model.clone();
        if let Scale::Coherence { n_averages, .. } = &mut m.scale {
            *n_averages = self.n_averages.unwrap_or(n_d);
        }
        m
    }
    /// Whether the scales come from the coherence.
    pub fn uses_coherence(&self) -> bool {
        matches!(self.model.scale, Scale::Coherence { .. })
    }
}

/// NUTS settings.
#[derive(Clone, Debug, PartialEq)]
pub struct NutsSettings {
    pub chains: usize,
    pub tune: usize,
    pub draws: usize,
    pub max_tree_depth: u64,
    pub target_accept: f64,
}

pub use crate::inference::refine::CorrelationKind;

/// The validated `[inference]` section.
#[derive(Clone, Debug, PartialEq)]
pub struct Inference {
    pub models: Vec<String>,
    pub levels: Vec<String>,
    pub nuts: Option<NutsSettings>,
    /// TMCMC particles, when TMCMC runs.
    pub tmcmc_particles: Option<usize>,
    /// Stepping-stone settings, when it runs.
    pub stepping_stone: Option<SteppingStoneSettings>,
    pub noise: NoiseSpec,
    /// Priors per model name: one per law parameter (defaults filled in), then noise priors.
    pub priors: BTreeMap<String, Vec<Prior>>,
    /// Prior of each inferred noise scale (relative): log-uniform on [1e-4, 1].
    pub noise_scale_prior: Prior,
    /// Prior of an inferred nu: log-uniform on [1, 100].
    pub nu_prior: Prior,
    pub map_starts: usize,
    pub map_max_iterations: u64,
    /// Samplers see the measurement model's bias linearised at the MAP (`true`, the default:
    /// the likelihood then costs a sweep of the lines) or the exact kernel operator.
    pub linearised_measurement: bool,
    /// Correlated channels: how, and the window (lines) of each line's estimate from the MAP
    /// residuals; `None`: independent channels.
    pub channel_correlation: Option<(CorrelationKind, usize)>,
    /// The comparison across levels (`[inference.across_levels]`).
    pub level_change: super::comparison::LevelSettings,
    /// The basin study (`[inference.basins]`), off unless given.
    pub basins: Option<super::comparison::BasinSettings>,
}

pub(super) fn prior(ctx: &Ctx, key: &str, r: &RawPrior) -> Result<Prior, StudyError> {
    let need = |v: Option<f64>, k: &str| {
        v.ok_or_else(|| {
            ctx.err(
                format!("{key}.{k}"),
                format!("family \"{}\" needs `{k}`", r.family),
            )
        })
    };
    let p = match r.family.as_str() {
        "log_uniform" => Prior::LogUniform {
            lo: need(r.lo, "lo")?,
            hi: need(r.hi, "hi")?,
        },
        "uniform" => Prior::Uniform {
            lo: need(r.lo, "lo")?,
            hi: need(r.hi, "hi")?,
        },
        "log_normal" => Prior::LogNormal {
            median: need(r.median, "median")?,
            sigma_ln: need(r.sigma_ln, "sigma_ln")?,
        },
        "truncated_normal" => Prior::TruncatedNormal {
            mean: need(r.mean, "mean")?,
            sd: need(r.sd, "sd")?,
            lo: need(r.lo, "lo")?,
            hi: need(r.hi, "hi")?,
        },
        o => {
            return Err(ctx.err(
                format!("{key}.family"),
                format!("unknown prior family \"{o}\": use \"log_uniform\", \"uniform\", \"log_normal\" or \"truncated_normal\""),
            ))
        }
    };
    p.validate().map_err(|e| ctx.err(key, e.0))?;
    Ok(p)
}

/// Validate `[inference]` against the study's models and levels.
pub(super) fn inference(
    ctx: &Ctx,
    r: &RawInference,
    models: &[ModelSpec],
    level_names: &[String],
) -> Result<Inference, StudyError> {
    let key = "inference";
    let model_names: Vec<String> = match &r.models {
        Some(m) => {
            for (i, n) in m.iter().enumerate() {
                if !models.iter().any(|s| s.name.eq_ignore_ascii_case(n)) {
                    return Err(ctx.err(
                        format!("{key}.models[{i}]"),
                        format!("\"{n}\" is not among [[models]] ({:?}): add it there with its initial values", models.iter().map(|m| m.name.as_str()).collect::<Vec<_>>()),
                    ));
                }
            }
            m.iter().map(|s| s.to_ascii_lowercase()).collect()
        }
        None => models
            .iter()
            .map(|m| m.name.to_ascii_lowercase())
            .filter(|n| matches!(n.as_str(), "model3" | "model4" | "model5"))
            .collect(),
    };
    if model_names.is_empty() {
        return Err(ctx.err(
            format!("{key}.models"),
            "no model to infer: list models of [[models]] (Models 3-5 by default)",
        ));
    }
    let levels = match &r.levels {
        Some(l) => {
            for (i, n) in l.iter().enumerate() {
                if !level_names.contains(n) {
                    return Err(ctx.err(
                        format!("{key}.levels[{i}]"),
                        format!("level \"{n}\" is not among measurements.levels {level_names:?}"),
                    ));
                }
            }
            l.clone()
        }
        None => level_names.to_vec(),
    };
    let samplers = r
        .samplers
        .clone()
        .unwrap_or_else(|| vec!["nuts".into(), "stepping_stone".into()]);
    for (i, s) in samplers.iter().enumerate() {
        if !matches!(s.as_str(), "nuts" | "tmcmc" | "stepping_stone") {
            return Err(ctx.err(
                format!("{key}.samplers[{i}]"),
                format!("unknown sampler \"{s}\": use \"nuts\", \"tmcmc\" and/or \"stepping_stone\" (evidence)"),
            ));
        }
    }
    let n = r.nuts.as_ref();
    let count =
        |k: &str, v: Option<usize>, default: usize, min: usize| -> Result<usize, StudyError> {
            let v = v.unwrap_or(default);
            if v < min {
                return Err(ctx.err(k, format!("{v} is too small: give at least {min}")));
            }
            Ok(v)
        };
    let nuts = if samplers.iter().any(|s| s == "nuts") {
        let ta = n.and_then(|n| n.target_accept).unwrap_or(0.8);
        if !(ta > 0.0 && ta < 1.0) {
            return Err(ctx.err(
                format!("{key}.nuts.target_accept"),
                format!(
                    "{ta} must be in (0, 1); 0.8 is the usual value, 0.9-0.95 for hard posteriors"
                ),
            ));
        }
        let depth = n.and_then(|n| n.max_tree_depth).unwrap_or(10);
        if !(1..=15).contains(&depth) {
            return Err(ctx.err(
                format!("{key}.nuts.max_tree_depth"),
                format!("{depth} must be between 1 and 15"),
            ));
        }
        Some(NutsSettings {
            chains: count(
                &format!("{key}.nuts.chains"),
                n.and_then(|n| n.chains),
                4,
                1,
            )?,
            tune: count(
                &format!("{key}.nuts.tune"),
                n.and_then(|n| n.tune),
                1000,
                10,
            )?,
            draws: count(
                &format!("{key}.nuts.draws"),
                n.and_then(|n| n.draws),
                1000,
                4,
            )?,
            max_tree_depth: depth,
            target_accept: ta,
        })
    } else {
        None
    };
    let tmcmc_particles = if samplers.iter().any(|s| s == "tmcmc") {
        Some(count(
            &format!("{key}.tmcmc.particles"),
            r.tmcmc.as_ref().and_then(|t| t.particles),
            2000,
            50,
        )?)
    } else {
        None
    };
    let stepping_stone = if samplers.iter().any(|s| s == "stepping_stone") {
        let ss = r.stepping_stone.as_ref();
        Some(SteppingStoneSettings {
            particles: count(
                &format!("{key}.stepping_stone.particles"),
                ss.and_then(|s| s.particles),
                250,
                50,
            )?,
            replicas: count(
                &format!("{key}.stepping_stone.replicas"),
                ss.and_then(|s| s.replicas),
                8,
                2,
            )?,
            from_reference: match ss.and_then(|s| s.path.as_deref()) {
                None | Some("reference") => true,
                Some("prior") => false,
                Some(other) => {
                    return Err(ctx.err(
                        format!("{key}.stepping_stone.path"),
                        format!("unknown path \"{other}\": use \"reference\" (from a density fitted to the posterior draws) or \"prior\""),
                    ))
                }
            },
            widen: match ss.and_then(|s| s.widen) {
                None => 1.5,
                Some(w) if w >= 1.0 && w.is_finite() => w,
                Some(w) => {
                    return Err(ctx.err(
                        format!("{key}.stepping_stone.widen"),
                        format!("{w}: give a factor of at least 1 on the draws' standard deviations, e.g. 1.5"),
                    ))
                }
            },
            nu: match ss.and_then(|s| s.nu) {
                None => 5.0,
                Some(n) if n > 2.0 && n.is_finite() => n,
                Some(n) => {
                    return Err(ctx.err(
                        format!("{key}.stepping_stone.nu"),
                        format!("{n}: give degrees of freedom above 2 (e.g. 5; 1e9 for a Gaussian)"),
                    ))
                }
            },
        })
    } else {
        None
    };
    // Noise model.
    let rn = r.noise.as_ref();
    let nk = format!("{key}.noise");
    let model_error = rn.and_then(|n| n.model_error).unwrap_or(0.0);
    if !(0.0..1.0).contains(&model_error) {
        return Err(ctx.err(
            format!("{nk}.model_error"),
            format!("{model_error} must be in [0, 1): a relative error floor, e.g. 0.01"),
        ));
    }
    let floor = rn
        .and_then(|n| n.coherence_floor)
        .unwrap_or(DEFAULT_COHERENCE_FLOOR);
    if !(floor > 0.0 && floor < 1.0) {
        return Err(ctx.err(
            format!("{nk}.coherence_floor"),
            format!("{floor} must be in (0, 1), e.g. 1e-4"),
        ));
    }
    let n_averages = match rn.and_then(|n| n.n_averages) {
        None => None,
        Some(v) if v > 0.0 && v.is_finite() => Some(v),
        Some(v) => {
            return Err(ctx.err(
                format!("{nk}.n_averages"),
                format!("{v} must be a positive number (the equivalent number of independent averages, e.g. 189.5 for 200 Hann blocks at 50 % overlap)"),
            ))
        }
    };
    let bands = rn.and_then(|n| n.bands_hz.clone()).unwrap_or_default();
    if !bands.is_empty()
        && (bands.len() < 2 || bands.windows(2).any(|w| !(w[1] > w[0])) || bands[0] < 0.0)
    {
        return Err(ctx.err(
            format!("{nk}.bands_hz"),
            format!("{bands:?}: give increasing band edges in Hz, at least two"),
        ));
    }
    let coherence = Scale::Coherence {
        n_averages: 0.0,
        floor,
    };
    let inferred = Scale::Inferred {
        bands_hz: bands.clone(),
    };
    let kind = rn
        .and_then(|n| n.model.clone())
        .unwrap_or_else(|| "coherence".into());
    let (scale, errors) = match kind.as_str() {
        "coherence" => (coherence, ErrorLaw::Gaussian),
        "inferred" => (inferred, ErrorLaw::Gaussian),
        "student_t" => {
            let scale = match rn.and_then(|n| n.scale.as_deref()).unwrap_or("coherence") {
                "coherence" => coherence,
                "inferred" => inferred,
                o => {
                    return Err(ctx.err(
                        format!("{nk}.scale"),
                        format!("\"{o}\": use \"coherence\" or \"inferred\""),
                    ))
                }
            };
            let nu = match rn.and_then(|n| n.nu.as_ref()) {
                None => Some(4.0),
                Some(toml::Value::String(s)) if s == "infer" => None,
                Some(v) => match v.as_float().or_else(|| v.as_integer().map(|i| i as f64)) {
                    Some(x) if x > 0.0 && x.is_finite() => Some(x),
                    _ => {
                        return Err(ctx.err(
                            format!("{nk}.nu"),
                            format!("{v}: give a positive number of degrees of freedom (e.g. 4) or \"infer\""),
                        ))
                    }
                },
            };
            (scale, ErrorLaw::StudentT { nu })
        }
        o => {
            return Err(ctx.err(
                format!("{nk}.model"),
                format!(
                    "unknown noise model \"{o}\": use \"coherence\", \"inferred\" or \"student_t\""
                ),
            ))
        }
    };
    if rn.and_then(|n| n.scale.as_ref()).is_some() && kind != "student_t" {
        return Err(ctx.err(
            format!("{nk}.scale"),
            "only for model = \"student_t\" (the other models name their scale)",
        ));
    }
    let channel_correlation = match rn.and_then(|n| n.channel_correlation.as_deref()) {
        None | Some("none") => {
            if rn.and_then(|n| n.correlation_window_lines).is_some() {
                return Err(ctx.err(
                    format!("{nk}.correlation_window_lines"),
                    "only with channel_correlation = \"leakage\" or \"estimated\"",
                ));
            }
            None
        }
        Some(kind @ ("estimated" | "leakage")) => {
            if !matches!(errors, ErrorLaw::Gaussian) {
                return Err(ctx.err(
                    format!("{nk}.channel_correlation"),
                    "correlated channels need Gaussian errors: use model = \"coherence\" or \"inferred\", or channel_correlation = \"none\"",
                ));
            }
            let w = rn.and_then(|n| n.correlation_window_lines).unwrap_or(21);
            if w < 8 {
                return Err(ctx.err(
                    format!("{nk}.correlation_window_lines"),
                    format!("{w}: give at least 8 lines (the default 21 estimates a 4-channel correlation from 21 residual vectors)"),
                ));
            }
            Some((
                if kind == "leakage" {
                    CorrelationKind::Leakage
                } else {
                    CorrelationKind::Estimated
                },
                w,
            ))
        }
        Some(o) => {
            return Err(ctx.err(
                format!("{nk}.channel_correlation"),
                format!("unknown value \"{o}\": use \"none\", \"leakage\" or \"estimated\""),
            ))
        }
    };
    // Priors.
    for (m, ps) in &r.priors {
        let Some(spec) = models.iter().find(|s| s.name.eq_ignore_ascii_case(m)) else {
            return Err(ctx.err(
                format!("{key}.priors.{m}"),
                format!("\"{m}\" is not among [[models]]"),
            ));
        };
        for p in ps.keys() {
            if !spec.param_names.contains(p) {
                return Err(ctx.err(
                    format!("{key}.priors.{m}.{p}"),
                    format!(
                        "{m} has no parameter {p}; its parameters are {:?}",
                        spec.param_names
                    ),
                ));
            }
        }
    }
    let mut priors = BTreeMap::new();
    for name in &model_names {
        let spec = models
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(name))
            .expect("checked above");
        let law = crate::material::model_from_name(&spec.name, spec.branches)
            .map_err(|e| ctx.err(format!("{key}.models"), e.to_string()))?;
        let bounds = law.bounds();
        let raw = r
            .priors
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v);
        let mut list = Vec::new();
        for (k, pname) in spec.param_names.iter().enumerate() {
            let pk = format!("{key}.priors.{name}.{pname}");
            let p = match raw.and_then(|r| r.get(pname)) {
                Some(rp) => prior(ctx, &pk, rp)?,
                None => Prior::default_for(spec.initial[k], bounds[k]),
            };
            if !p.contains(spec.initial[k]) {
                return Err(ctx.err(
                    pk,
                    format!(
                        "the prior's support excludes the initial value {} of {pname}: widen the bounds or change models.initial",
                        spec.initial[k]
                    ),
                ));
            }
            let (lo, hi) = bounds[k];
            let support_ok = match p {
                Prior::LogUniform { lo: a, hi: b }
                | Prior::Uniform { lo: a, hi: b }
                | Prior::TruncatedNormal { lo: a, hi: b, .. } => a >= lo && b <= hi,
                Prior::LogNormal { .. } => lo <= 0.0 && hi == f64::INFINITY,
            };
            if !support_ok {
                return Err(ctx.err(
                    pk,
                    format!("the prior's support leaves the admissible range ({lo}, {hi}) of {pname}: bound it inside"),
                ));
            }
            list.push(p);
        }
        priors.insert(name.clone(), list);
    }
    let m = r.map.as_ref();
    Ok(Inference {
        level_change: super::comparison::levels(ctx, r.across_levels.as_ref())?,
        basins: super::comparison::basins(ctx, r.basins.as_ref())?,
        models: model_names,
        levels,
        nuts,
        tmcmc_particles,
        stepping_stone,
        noise: NoiseSpec {
            n_averages,
            model: NoiseModel {
                scale,
                errors,
                model_error,
            },
        },
        priors,
        noise_scale_prior: Prior::LogUniform { lo: 1e-4, hi: 1.0 },
        nu_prior: Prior::LogUniform { lo: 1.0, hi: 100.0 },
        linearised_measurement: match r.measurement.as_deref() {
            None | Some("linearised") => true,
            Some("exact") => false,
            Some(o) => {
                return Err(ctx.err(
                    format!("{key}.measurement"),
                    format!("unknown value \"{o}\": use \"linearised\" (the measurement model's bias linearised at the MAP, the default) or \"exact\""),
                ))
            }
        },
        channel_correlation,
        map_starts: m.and_then(|m| m.starts).unwrap_or(16),
        map_max_iterations: count(
            &format!("{key}.map.max_iterations"),
            m.and_then(|m| m.max_iterations).map(|v| v as usize),
            200,
            1,
        )? as u64,
    })
}
