//! The validation file (`VALIDATION.toml`) as written (serde, unknown keys denied) and as
//! validated: the experiment that makes the data, and the settings of each part.

use crate::study::experiment::{load_experiment, Experiment};
use crate::study::StudyError;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A validation file as written (public so that the documentation's key list can be checked
/// against it; fields stay private).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawFile {
    validation: RawValidation,
    sbc: Option<RawSbc>,
    coverage: Option<RawCoverage>,
    selection: Option<RawSelection>,
    quadrature: Option<RawQuadrature>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawValidation {
    name: String,
    experiment: PathBuf,
    level: Option<String>,
    seed: Option<u64>,
    map_starts: Option<usize>,
    output_dir: Option<PathBuf>,
    data: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSbc {
    draws: usize,
    posterior_draws: Option<usize>,
    bins: Option<usize>,
    sigma_ln: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCoverage {
    replicates: usize,
    sigma_ln: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSelection {
    replicates: usize,
    models: Option<Vec<String>>,
    sigma_ln: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawQuadrature {
    replicates: usize,
    models: Option<Vec<String>>,
    sigma_ln: Option<f64>,
    grid: Option<usize>,
    half_width_sd: Option<f64>,
    ss_particles: Option<usize>,
    ss_replicas: Option<usize>,
}

/// Simulation-based calibration (Talts et al. 2018) of Model 4.
#[derive(Clone, Debug, PartialEq)]
pub struct SbcSpec {
    /// Prior draws (one simulated data set each).
    pub draws: usize,
    /// Posterior draws `L` per data set: ranks run over `0..=L`.
    pub posterior_draws: usize,
    /// Bins of the rank histogram; must divide `L + 1`.
    pub bins: usize,
    /// Log-normal prior width (natural log) around the default data's truth.
    pub sigma_ln: f64,
}

/// Coverage of central credible intervals at the default data's truth.
#[derive(Clone, Debug, PartialEq)]
pub struct CoverageSpec {
    pub replicates: usize,
    pub sigma_ln: f64,
}

/// Model selection by evidence among `models`, each generating `replicates` data sets.
#[derive(Clone, Debug, PartialEq)]
pub struct SelectionSpec {
    pub replicates: usize,
    pub models: Vec<String>,
    pub sigma_ln: f64,
}

/// Evidence estimators against brute-force quadrature on two-parameter models.
#[derive(Clone, Debug, PartialEq)]
pub struct QuadratureSpec {
    pub replicates: usize,
    pub models: Vec<String>,
    pub sigma_ln: f64,
    /// Nodes per axis of the quadrature grid.
    pub grid: usize,
    /// Half width of the grid in Laplace standard deviations (along its principal axes).
    pub half_width_sd: f64,
    /// Stepping-stone particles and replicas (0 particles: not run).
    pub ss_particles: usize,
    pub ss_replicas: usize,
}

/// Where a unit's data come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataSource {
    /// The likelihood's own generative model: the predicted E[H1] at the drawn parameters plus
    /// complex Gaussian noise with the variances the noise model states (from the coherence of
    /// a virtual-experiment run at the same parameters), inferred with those variances fixed.
    /// What SBC calibrates: the computation (MAP, Laplace, intervals, evidence), with the model
    /// right by construction.
    NoiseModel,
    /// The virtual experiment's H1 and coherence (window leakage, averaging, sensor noise),
    /// inferred with the coherence likelihood: adds the noise model's misspecification (the
    /// channels' correlated leakage error) to what is checked.
    VirtualExperiment,
}

/// A validated validation file.
#[derive(Clone, Debug)]
pub struct ValidationSpec {
    pub file: PathBuf,
    pub name: String,
    pub experiment: Experiment,
    /// Index into `experiment.levels` of the default data's level (its force, its Model 4 truth).
    pub level: usize,
    pub seed: u64,
    /// Space-filling MAP starts besides the prior median.
    pub map_starts: usize,
    pub output_dir: PathBuf,
    /// Where the data come from (`[validation] data`).
    pub data: DataSource,
    pub sbc: Option<SbcSpec>,
    pub coverage: Option<CoverageSpec>,
    pub selection: Option<SelectionSpec>,
    pub quadrature: Option<QuadratureSpec>,
}

/// Read, parse and validate a validation file.
pub fn load_validation(path: &Path) -> Result<ValidationSpec, StudyError> {
    let file = path.display().to_string();
    let err = |key: &str, message: String| StudyError {
        file: file.clone(),
        key: key.to_string(),
        message,
    };
    let text = std::fs::read_to_string(path)
        .map_err(|e| err("(file)", format!("cannot read the validation file: {e}")))?;
    let raw: RawFile =
        toml::from_str(&text).map_err(|e| crate::study::toml_error(path, &text, &e))?;
    let base = path.parent().unwrap_or(Path::new(""));
    let v = raw.validation;
    let ex_path = base.join(&v.experiment);
    let experiment = load_experiment(&ex_path).map_err(|e| {
        err(
            "validation.experiment",
            format!("{e} (the experiment file is resolved relative to this file)"),
        )
    })?;
    let level = match &v.level {
        None => 0,
        Some(name) => experiment
            .levels
            .iter()
            .position(|l| &l.name == name)
            .ok_or_else(|| {
                err(
                    "validation.level",
                    format!(
                        "no level \"{name}\" in {}: choose one of {:?}",
                        ex_path.display(),
                        experiment
                            .levels
                            .iter()
                            .map(|l| &l.name)
                            .collect::<Vec<_>>()
                    ),
                )
            })?,
    };
    if experiment.levels.is_empty() {
        return Err(err(
            "validation.experiment",
            "the experiment has no [[levels]]: give one with law = \"model4\"".into(),
        ));
    }
    if experiment.levels[level].law != "model4" {
        return Err(err(
            "validation.level",
            format!(
                "the level's law is {}, the validation's default data need model4",
                experiment.levels[level].law
            ),
        ));
    }
    let sigma = |key: &str, s: Option<f64>, default: f64| -> Result<f64, StudyError> {
        let s = s.unwrap_or(default);
        if !(s > 0.0 && s <= 2.0) {
            return Err(err(
                key,
                format!("{s} is not a log-normal width in (0, 2] (natural log, e.g. 0.1)"),
            ));
        }
        Ok(s)
    };
    let positive = |key: &str, n: usize| -> Result<usize, StudyError> {
        if n == 0 {
            return Err(err(key, "must be at least 1".into()));
        }
        Ok(n)
    };
    let models = |key: &str, m: Option<Vec<String>>, default: &[&str], n_params: Option<usize>| {
        let m: Vec<String> = m.unwrap_or_else(|| default.iter().map(|s| s.to_string()).collect());
        if m.is_empty() {
            return Err(err(key, "give at least one model".into()));
        }
        for name in &m {
            let law = crate::material::model_from_name(name, None)
                .map_err(|e| err(key, format!("{name}: {e}")))?;
            let k = model_number(name).filter(|k| (1..=5).contains(k));
            if k.is_none() {
                return Err(err(
                    key,
                    format!("{name}: only model1..model5 have a truth (the paper's Table 4)"),
                ));
            }
            if let Some(n) = n_params {
                if law.n_params() != n {
                    return Err(err(
                        key,
                        format!(
                            "{name} has {} parameters; quadrature needs {n} (model1 or model2)",
                            law.n_params()
                        ),
                    ));
                }
            }
        }
        Ok(m)
    };
    let sbc = match raw.sbc {
        None => None,
        Some(s) => {
            let l = s.posterior_draws.unwrap_or(99);
            let bins = s.bins.unwrap_or(10);
            if bins < 2 || (l + 1) % bins != 0 {
                return Err(err(
                    "sbc.bins",
                    format!("{bins} bins do not divide the {} possible ranks (posterior_draws + 1): e.g. posterior_draws = 99 with 10 bins", l + 1),
                ));
            }
            Some(SbcSpec {
                draws: positive("sbc.draws", s.draws)?,
                posterior_draws: positive("sbc.posterior_draws", l)?,
                bins,
                sigma_ln: sigma("sbc.sigma_ln", s.sigma_ln, 0.1)?,
            })
        }
    };
    let coverage = match raw.coverage {
        None => None,
        Some(c) => Some(CoverageSpec {
            replicates: positive("coverage.replicates", c.replicates)?,
            sigma_ln: sigma("coverage.sigma_ln", c.sigma_ln, 0.1)?,
        }),
    };
    let selection = match raw.selection {
        None => None,
        Some(s) => Some(SelectionSpec {
            replicates: positive("selection.replicates", s.replicates)?,
            models: models(
                "selection.models",
                s.models,
                &["model3", "model4", "model5"],
                None,
            )?,
            sigma_ln: sigma("selection.sigma_ln", s.sigma_ln, 0.5)?,
        }),
    };
    let quadrature = match raw.quadrature {
        None => None,
        Some(q) => {
            let grid = q.grid.unwrap_or(81);
            if grid < 11 {
                return Err(err("quadrature.grid", format!("{grid} nodes per axis: give at least 11 (81 is accurate to 1e-6 nats on a Gaussian)")));
            }
            let hw = q.half_width_sd.unwrap_or(8.0);
            if !(hw >= 3.0) {
                return Err(err(
                    "quadrature.half_width_sd",
                    format!("{hw}: give at least 3 standard deviations (8 is the default)"),
                ));
            }
            Some(QuadratureSpec {
                replicates: positive("quadrature.replicates", q.replicates)?,
                models: models(
                    "quadrature.models",
                    q.models,
                    &["model1", "model2"],
                    Some(2),
                )?,
                sigma_ln: sigma("quadrature.sigma_ln", q.sigma_ln, 0.5)?,
                grid,
                half_width_sd: hw,
                ss_particles: q.ss_particles.unwrap_or(0),
                ss_replicas: q.ss_replicas.unwrap_or(4).max(1),
            })
        }
    };
    let data = match v.data.as_deref() {
        None | Some("noise_model") => DataSource::NoiseModel,
        Some("virtual_experiment") => DataSource::VirtualExperiment,
        Some(other) => {
            return Err(err(
                "validation.data",
                format!("\"{other}\" is not a data source: use \"noise_model\" (the likelihood's own generative model, the default) or \"virtual_experiment\""),
            ))
        }
    };
    Ok(ValidationSpec {
        file: path.to_path_buf(),
        data,
        name: v.name,
        experiment,
        level,
        seed: v.seed.unwrap_or(1),
        map_starts: v.map_starts.unwrap_or(0),
        output_dir: base.join(
            v.output_dir
                .unwrap_or_else(|| PathBuf::from("../results/validate")),
        ),
        sbc,
        coverage,
        selection,
        quadrature,
    })
}

/// `modelN` -> N.
pub fn model_number(name: &str) -> Option<usize> {
    name.to_ascii_lowercase()
        .strip_prefix("model")
        .and_then(|s| s.parse().ok())
}
