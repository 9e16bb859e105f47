//! The `[design]` section: how `rfmlab design` plans a test of the study's joint.
//!
//! ```toml
//! [design]
//! sensors = 4                      # response sensors per design (default: the study's measured points)
//! keep = [2]                       # ids of the study's points that stay (mounted already)
//! candidates = "surface"           # a grid on the free faces ("surface") or the study's points ("points")
//! spacing = 0.010                  # m, the grid's pitch along the length (surface candidates)
//! directions = ["x", "y", "z"]     # measured directions tried at every candidate place
//! drives = [2]                     # ids of the study's points where the shaker may act
//! models = ["model4"]              # laws whose parameters the design should pin down
//! draws = 8                        # parameter draws the information is averaged over (0: the initial values)
//! sensor_mass = 0.010              # kg per sensor, acting in x, y and z (0: massless sensors)
//! force_noise = 0.002              # force-sensor noise, fraction of the force's RMS
//! response_noise = 0.002           # accelerometer noise, fraction of each channel's RMS
//! response_noise_rms = 1e-3        # or: accelerometer noise RMS over the analyser's span, m/s^2
//! n_averages = 200                 # blocks per H1 (Welch, the estimator's overlap)
//! posterior = "results/bayes"      # a previous run's results: its per-level Laplace posterior
//! ```
//!
//! The force levels are those of `[[measurements.levels]]` (`force_rms_n`), the band and the
//! analyser those of `[measurements]`; the data files need not exist yet.

use super::ctx::Ctx;
use super::StudyError;
use crate::common::Axis;
use serde::Deserialize;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawDesign {
    pub sensors: Option<usize>,
    #[serde(default)]
    pub keep: Vec<u32>,
    pub candidates: Option<String>,
    pub spacing: Option<f64>,
    pub directions: Option<Vec<String>>,
    pub drives: Option<Vec<u32>>,
    pub models: Option<Vec<String>>,
    pub draws: Option<usize>,
    pub sensor_mass: Option<f64>,
    pub force_noise: Option<f64>,
    pub response_noise: Option<f64>,
    pub response_noise_rms: Option<f64>,
    pub n_averages: Option<usize>,
    pub posterior: Option<String>,
}

/// Where candidate sensor places come from.
#[derive(Clone, Debug, PartialEq)]
pub enum CandidatePlaces {
    /// A grid on the structure's free faces with this pitch (m) along the length.
    Surface { spacing_m: f64 },
    /// The study's own points (an imported model's DOF-map rows).
    Points,
}

/// Accelerometer noise: a fraction of each channel's RMS, or an absolute RMS (m/s^2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ResponseNoise {
    Fraction(f64),
    Rms(f64),
}

/// The validated `[design]` section.
#[derive(Clone, Debug, PartialEq)]
pub struct DesignSettings {
    /// Response sensors per design, kept ones included (`None`: the study's measured points).
    pub sensors: Option<usize>,
    /// Study point ids that stay in every design.
    pub keep: Vec<u32>,
    pub candidates: CandidatePlaces,
    pub directions: Vec<Axis>,
    /// Study point ids where the shaker may act (`None`: the study's excitation).
    pub drives: Option<Vec<u32>>,
    /// Models whose parameters the design targets (`None`: `[inference] models`, else all).
    pub models: Option<Vec<String>>,
    /// Parameter draws from the priors (0: the models' initial values only). Default 8.
    pub draws: usize,
    /// Each sensor's mass (kg), in x, y and z at its place. Default 0.
    pub sensor_mass_kg: f64,
    /// Force-sensor noise, fraction of the force RMS. Default 0.002.
    pub force_noise: f64,
    /// Default: 0.002 of each channel's RMS.
    pub response_noise: ResponseNoise,
    /// Blocks averaged per H1 (the estimator's overlap applies). Default 200.
    pub n_averages: usize,
    /// A previous run's results folder: its Laplace posterior per level (`laplace.parquet`)
    /// replaces the priors as what the parameters are believed to be.
    pub posterior: Option<std::path::PathBuf>,
}

pub(super) fn design(
    ctx: &Ctx,
    r: &RawDesign,
    point_ids: &[u32],
) -> Result<DesignSettings, StudyError> {
    let known = |key: &str, ids: &[u32]| -> Result<(), StudyError> {
        match ids.iter().find(|i| !point_ids.contains(i)) {
            Some(i) => Err(ctx.err(
                key,
                format!("point {i} is not among [[structure.points]] (ids {point_ids:?}): add it there or remove it here"),
            )),
            None => Ok(()),
        }
    };
    known("design.keep", &r.keep)?;
    if let Some(d) = &r.drives {
        if d.is_empty() {
            return Err(ctx.err(
                "design.drives",
                "give at least one point id, or leave the key out for the study's excitation",
            ));
        }
        known("design.drives", d)?;
    }
    if let Some(s) = r.sensors {
        if s == 0 || s < r.keep.len() {
            return Err(ctx.err(
                "design.sensors",
                format!(
                    "must be at least 1 and at least the {} kept sensors, got {s}",
                    r.keep.len()
                ),
            ));
        }
    }
    let candidates = match r.candidates.as_deref().unwrap_or("surface") {
        "surface" => CandidatePlaces::Surface {
            spacing_m: match r.spacing {
                Some(s) => ctx.positive("design.spacing", s, "m")?,
                None => 0.0,
            },
        },
        "points" => {
            if r.spacing.is_some() {
                return Err(ctx.err("design.spacing", "applies to candidates = \"surface\" only: remove it"));
            }
            CandidatePlaces::Points
        }
        o => {
            return Err(ctx.err(
                "design.candidates",
                format!("unknown candidate places \"{o}\": use \"surface\" (a grid on the free faces) or \"points\" (the study's points)"),
            ))
        }
    };
    let directions = match &r.directions {
        None => vec![Axis::X, Axis::Y, Axis::Z],
        Some(v) if v.is_empty() => {
            return Err(ctx.err(
                "design.directions",
                "give at least one of \"x\", \"y\", \"z\"",
            ))
        }
        Some(v) => {
            let mut out = Vec::new();
            for (i, s) in v.iter().enumerate() {
                let a = match s
                    .trim_start_matches(['+', '-'])
                    .to_ascii_lowercase()
                    .as_str()
                {
                    "x" => Axis::X,
                    "y" => Axis::Y,
                    "z" => Axis::Z,
                    _ => {
                        return Err(ctx.err(
                            format!("design.directions[{i}]"),
                            format!("\"{s}\" is not a direction: use \"x\", \"y\" or \"z\""),
                        ))
                    }
                };
                if !out.contains(&a) {
                    out.push(a);
                }
            }
            out
        }
    };
    if r.response_noise.is_some() && r.response_noise_rms.is_some() {
        return Err(ctx.err(
            "design.response_noise_rms",
            "give either response_noise (a fraction of each channel's RMS) or response_noise_rms (m/s^2), not both",
        ));
    }
    let response_noise = match (r.response_noise, r.response_noise_rms) {
        (_, Some(v)) => {
            ResponseNoise::Rms(ctx.positive("design.response_noise_rms", v, "m/s^2")?)
        }
        (Some(f), None) => {
            ResponseNoise::Fraction(ctx.positive("design.response_noise", f, "-")?)
        }
        (None, None) => ResponseNoise::Fraction(0.002),
    };
    let force_noise = match r.force_noise {
        Some(f) => ctx.non_negative("design.force_noise", f, "-")?,
        None => 0.002,
    };
    let sensor_mass_kg = match r.sensor_mass {
        Some(m) => ctx.non_negative("design.sensor_mass", m, "kg")?,
        None => 0.0,
    };
    let n_averages = r.n_averages.unwrap_or(200);
    if n_averages < 2 {
        return Err(ctx.err(
            "design.n_averages",
            format!("must be at least 2 blocks, got {n_averages}"),
        ));
    }
    if let Some(m) = &r.models {
        if m.is_empty() {
            return Err(ctx.err(
                "design.models",
                "give at least one model name, or leave the key out",
            ));
        }
    }
    Ok(DesignSettings {
        sensors: r.sensors,
        keep: r.keep.clone(),
        candidates,
        directions,
        drives: r.drives.clone(),
        models: r.models.clone(),
        draws: r.draws.unwrap_or(8),
        sensor_mass_kg,
        force_noise,
        response_noise,
        n_averages,
        posterior: r.posterior.as_ref().map(std::path::PathBuf::from),
    })
}
