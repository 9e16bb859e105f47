//! Virtual-experiment files (`rfmlab simulate EXPERIMENT.toml`): the truth (structure,
//! constitutive law per level, sensor masses, shaker, channel gains and delays) and the
//! measurement chain, validated into an [`Experiment`]. Unknown keys are rejected.

use super::ctx::Ctx;
use super::raw::RawStructure;
use super::validate::{structure, toml_error};
use super::{resolve, Structure, StudyError};
use crate::common::C64;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// An experiment file as written (public so that the documentation's key list can be checked
/// against it; fields stay private).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawExperimentFile {
    experiment: RawExperiment,
    structure: RawStructure,
    #[serde(default)]
    chain: RawChain,
    shaker: Option<RawShaker>,
    #[serde(default)]
    sensors: Vec<RawSensor>,
    #[serde(default)]
    resonators: Vec<RawResonator>,
    #[serde(default)]
    channels: Vec<RawChannel>,
    degraded_bond: Option<RawDegradedBond>,
    base_springs: Option<RawBaseSprings>,
    levels: Vec<RawTruthLevel>,
}

/// Springs under the adhesive's lower face instead of a fixed face (N/m^3, per unit area).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBaseSprings {
    normal: f64,
    tangential: f64,
}

/// A region of the adhesive with a reduced modulus: `E* (S - loss S_region)` over
/// `x in [x_start, x_start + width]` (m).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDegradedBond {
    x_start: f64,
    width: Option<f64>,
    loss: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExperiment {
    name: String,
    description: Option<String>,
    /// "time" (default) or "frequency".
    mode: Option<String>,
    seed: Option<u64>,
    /// Output UFF58 file, relative to the experiment file.
    output: String,
    binary: Option<bool>,
    /// "rom" (default) or "full".
    engine: Option<String>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawChain {
    band_hz: Option<Vec<f64>>,
    /// [start, stop, step] in Hz.
    lines_hz: Option<Vec<f64>>,
    fs_hz: Option<f64>,
    block_s: Option<f64>,
    overlap: Option<f64>,
    averages: Option<usize>,
    window: Option<String>,
    force_noise_rms: Option<f64>,
    force_noise_fraction: Option<f64>,
    response_noise_rms: Option<f64>,
    response_noise_fraction: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawShaker {
    armature_mass: f64,
    stinger_stiffness: f64,
    /// Where the force is read: "structure" (default: a force gauge at the structure, H1
    /// estimates the structure's FRF) or "shaker" (the force on the shaker's side of the
    /// stinger: the data carry the shaker's moving mass, `Effect::Shaker`).
    force_gauge: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensor {
    point: u32,
    mass: f64,
    /// "measured" (default: the mass acts in the point's measured direction) or "xyz" (in x, y
    /// and z, as a real accelerometer's inertia does).
    directions: Option<String>,
}

/// A sensor's mass on the structure (undeclared in a study: a closed-loop test case).
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    pub point: u32,
    pub mass_kg: f64,
    /// The mass acts in x, y and z (else in the point's measured direction only).
    pub all_directions: bool,
}

/// A mass on a spring at a point, in the point's direction (the force is read at the
/// structure).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawResonator {
    point: u32,
    mass: f64,
    stiffness: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannel {
    point: u32,
    /// Complex calibration factor [re, im] or a real number.
    gain: Option<toml::Value>,
    delay: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTruthLevel {
    name: String,
    force_rms_n: f64,
    law: String,
    branches: Option<usize>,
    params: BTreeMap<String, f64>,
}

/// The truth of one excitation level.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthLevel {
    pub name: String,
    pub force_rms_n: f64,
    pub law: String,
    pub branches: Option<usize>,
    /// Parameters in the law's order (SI).
    pub params: Vec<f64>,
    pub param_names: Vec<String>,
}

/// A validated virtual experiment.
#[derive(Clone, Debug)]
pub struct Experiment {
    pub file: PathBuf,
    pub name: String,
    pub description: String,
    pub frequency_domain: bool,
    pub seed: u64,
    pub output: PathBuf,
    pub binary: bool,
    pub use_full_model: bool,
    pub structure: Structure,
    /// Chain settings common to all levels (force, seed and mode are set per level).
    pub chain: crate::experiment::spec::ChainParams,
    /// Sensor masses.
    pub sensors: Vec<Sensor>,
    /// Resonators: a mass (kg) on a spring (N/m) at a point, in its direction (point id, kg,
    /// N/m).
    pub resonators: Vec<(u32, f64, f64)>,
    /// Per structure point (in order): complex gain and delay (s).
    pub gains: Vec<C64>,
    pub delays_s: Vec<f64>,
    pub levels: Vec<TruthLevel>,
    /// The shaker when its force is read on the shaker's side of the stinger
    /// (`shaker.force_gauge = "shaker"`): the plant then carries the shaker (and
    /// `chain.shaker` is None).
    pub shaker_side_force: Option<crate::experiment::spec::Shaker>,
    /// A degraded bond region: (x_start, x_end) in m and the loss fraction d in [0, 1), the
    /// adhesive stiffness there scaled by (1 - d) (`degraded_bond` table).
    pub degraded_bond: Option<((f64, f64), f64)>,
    /// Springs under the adhesive's lower face (`base_springs` table), instead of a fixed
    /// face.
    pub base_springs: Option<crate::fe::base::BaseSprings>,
}

/// Default width (m) of a degraded bond strip: 10 mm.
pub const DEFAULT_DEGRADED_WIDTH_M: f64 = 0.010;

/// Read, parse and validate an experiment file.
pub fn load_experiment(path: &Path) -> Result<Experiment, StudyError> {
    let text = std::fs::read_to_string(path).map_err(|e| StudyError {
        file: path.display().to_string(),
        key: "(file)".into(),
        message: format!("cannot read the experiment file: {e}"),
    })?;
    parse_experiment(&text, path)
}

/// Parse and validate experiment text; `path` names the file and anchors relative paths.
pub fn parse_experiment(text: &str, path: &Path) -> Result<Experiment, StudyError> {
    use crate::experiment::spec::{ChainParams, Mode, NoiseLevel, Shaker};
    let raw: RawExperimentFile = toml::from_str(text).map_err(|e| toml_error(path, text, &e))?;
    let ctx = Ctx { file: path };
    let structure = structure(&ctx, &raw.structure)?;
    let e = &raw.experiment;
    let frequency_domain = match e.mode.as_deref().unwrap_or("time") {
        "time" => false,
        "frequency" => true,
        o => return Err(ctx.err("experiment.mode", format!("\"{o}\": use \"time\" (time-domain records, Welch H1) or \"frequency\" (fast: H1 errors drawn from their distribution)"))),
    };
    let use_full_model = match e.engine.as_deref().unwrap_or("rom") {
        "rom" => false,
        "full" => true,
        o => {
            return Err(ctx.err(
                "experiment.engine",
                format!("\"{o}\": use \"rom\" or \"full\""),
            ))
        }
    };
    let mut chain = ChainParams::default();
    let c = &raw.chain;
    if let Some(b) = &c.band_hz {
        if b.len() != 2 || !(b[0] >= 0.0 && b[1] > b[0]) {
            return Err(ctx.err(
                "chain.band_hz",
                "give [f_low, f_high] in Hz with 0 <= f_low < f_high",
            ));
        }
        chain.band_hz = (b[0], b[1]);
    }
    if let Some(l) = &c.lines_hz {
        if l.len() != 3 || !(l[2] > 0.0 && l[1] >= l[0] && l[0] > 0.0) {
            return Err(ctx.err(
                "chain.lines_hz",
                "give [start, stop, step] in Hz with 0 < start <= stop and step > 0",
            ));
        }
        let n = ((l[1] - l[0]) / l[2] + 1e-9).floor() as usize + 1;
        chain.lines_hz = (0..n).map(|k| l[0] + k as f64 * l[2]).collect();
    }
    if let Some(v) = c.fs_hz {
        chain.fs_hz = ctx.positive("chain.fs_hz", v, "Hz")?;
    }
    if let Some(v) = c.block_s {
        chain.block_s = ctx.positive("chain.block_s", v, "s")?;
    }
    if let Some(v) = c.overlap {
        if !(0.0..1.0).contains(&v) {
            return Err(ctx.err(
                "chain.overlap",
                format!("{v}: the overlap is a fraction in [0, 1), e.g. 0.5"),
            ));
        }
        chain.overlap = v;
    }
    if let Some(v) = c.averages {
        if v == 0 {
            return Err(ctx.err("chain.averages", "must be at least 1"));
        }
        chain.n_averages = v;
    }
    if let Some(w) = &c.window {
        chain.window = w
            .parse()
            .map_err(|m: crate::experiment::spec::UnknownWindow| {
                ctx.err("chain.window", m.to_string())
            })?;
    }
    match (c.force_noise_rms, c.force_noise_fraction) {
        (Some(_), Some(_)) => {
            return Err(ctx.err(
                "chain.force_noise_rms",
                "give force_noise_rms or force_noise_fraction, not both",
            ))
        }
        (Some(v), None) => {
            chain.force_noise =
                NoiseLevel::Rms(ctx.non_negative("chain.force_noise_rms", v, "N")?)
        }
        (None, Some(v)) => {
            chain.force_noise = NoiseLevel::FractionOfSignalRms(ctx.non_negative(
                "chain.force_noise_fraction",
                v,
                "-",
            )?)
        }
        (None, None) => {}
    }
    match (c.response_noise_rms, c.response_noise_fraction) {
        (Some(_), Some(_)) => {
            return Err(ctx.err(
                "chain.response_noise_rms",
                "give response_noise_rms or response_noise_fraction, not both",
            ))
        }
        (Some(v), None) => {
            chain.response_noise = vec![NoiseLevel::Rms(ctx.non_negative(
                "chain.response_noise_rms",
                v,
                "m/s^2",
            )?)]
        }
        (None, Some(v)) => {
            chain.response_noise = vec![NoiseLevel::FractionOfSignalRms(ctx.non_negative(
                "chain.response_noise_fraction",
                v,
                "-",
            )?)]
        }
        (None, None) => {}
    }
    let mut shaker_side_force = None;
    if let Some(s) = &raw.shaker {
        let sh = Shaker {
            armature_mass_kg: ctx.positive("shaker.armature_mass", s.armature_mass, "kg")?,
            stinger_stiffness_n_m: ctx.positive(
                "shaker.stinger_stiffness",
                s.stinger_stiffness,
                "N/m",
            )?,
        };
        match s.force_gauge.as_deref().unwrap_or("structure") {
            "structure" => chain.shaker = Some(sh),
            "shaker" => shaker_side_force = Some(sh),
            o => {
                return Err(ctx.err(
                    "shaker.force_gauge",
                    format!("\"{o}\": use \"structure\" (force gauge at the drive point) or \"shaker\" (force read on the shaker's side of the stinger)"),
                ))
            }
        }
    }
    chain.mode = if frequency_domain {
        Mode::FrequencyDomain
    } else {
        Mode::TimeDomain
    };
    let ids: Vec<u32> = structure.points.iter().map(|p| p.id).collect();
    let mut sensors = Vec::new();
    for (i, s) in raw.sensors.iter().enumerate() {
        if !ids.contains(&s.point) {
            return Err(ctx.err(
                format!("sensors[{i}].point"),
                format!("point {} is not among structure.points {ids:?}", s.point),
            ));
        }
        let all_directions = match s.directions.as_deref() {
            None | Some("measured") => false,
            Some("xyz") => true,
            Some(other) => {
                return Err(ctx.err(
                    format!("sensors[{i}].directions"),
                    format!("\"{other}\" is not a choice: \"measured\" (default, the point's measured direction) or \"xyz\" (x, y and z)"),
                ))
            }
        };
        sensors.push(Sensor {
            point: s.point,
            mass_kg: ctx.non_negative(&format!("sensors[{i}].mass"), s.mass, "kg")?,
            all_directions,
        });
    }
    let mut resonators = Vec::new();
    for (i, r) in raw.resonators.iter().enumerate() {
        if !ids.contains(&r.point) {
            return Err(ctx.err(
                format!("resonators[{i}].point"),
                format!("point {} is not among structure.points {ids:?}", r.point),
            ));
        }
        resonators.push((
            r.point,
            ctx.positive(&format!("resonators[{i}].mass"), r.mass, "kg")?,
            ctx.positive(&format!("resonators[{i}].stiffness"), r.stiffness, "N/m")?,
        ));
    }
    let mut gains = vec![C64::new(1.0, 0.0); ids.len()];
    let mut delays_s = vec![0.0; ids.len()];
    for (i, ch) in raw.channels.iter().enumerate() {
        let Some(k) = ids.iter().position(|&id| id == ch.point) else {
            return Err(ctx.err(
                format!("channels[{i}].point"),
                format!("point {} is not among structure.points {ids:?}", ch.point),
            ));
        };
        if let Some(g) = &ch.gain {
            gains[k] = match g {
                toml::Value::Float(v) => C64::new(*v, 0.0),
                toml::Value::Integer(v) => C64::new(*v as f64, 0.0),
                toml::Value::Array(a) if a.len() == 2 => {
                    let f =
                        |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
                    match (f(&a[0]), f(&a[1])) {
                        (Some(re), Some(im)) => C64::new(re, im),
                        _ => {
                            return Err(
                                ctx.err(format!("channels[{i}].gain"), "give a number or [re, im]")
                            )
                        }
                    }
                }
                _ => {
                    return Err(ctx.err(format!("channels[{i}].gain"), "give a number or [re, im]"))
                }
            };
        }
        if let Some(d) = ch.delay {
            if !d.is_finite() {
                return Err(ctx.err(
                    format!("channels[{i}].delay"),
                    "must be a finite number of seconds",
                ));
            }
            delays_s[k] = d;
        }
    }
    if raw.levels.is_empty() {
        return Err(ctx.err(
            "levels",
            "no levels: add [[levels]] with name, force_rms_n, law and params",
        ));
    }
    let mut levels: Vec<TruthLevel> = Vec::new();
    for (i, l) in raw.levels.iter().enumerate() {
        let key = format!("levels[{i}]");
        if levels.iter().any(|o| o.name == l.name) || l.name.is_empty() {
            return Err(ctx.err(
                format!("{key}.name"),
                format!("level name \"{}\" is empty or used twice", l.name),
            ));
        }
        let force = ctx.positive(&format!("{key}.force_rms_n"), l.force_rms_n, "N")?;
        let law = crate::material::model_from_name(&l.law, l.branches)
            .map_err(|e| ctx.err(format!("{key}.law"), e.to_string()))?;
        let names = law.param_names();
        let bounds = law.bounds();
        let mut params = Vec::new();
        for (k, n) in names.iter().enumerate() {
            let v = *l.params.get(n).ok_or_else(|| {
                ctx.err(
                    format!("{key}.params.{n}"),
                    format!(
                        "missing parameter {n} ({}) of {}",
                        law.param_units()[k],
                        l.law
                    ),
                )
            })?;
            if !(v.is_finite() && v > bounds[k].0 && v < bounds[k].1) {
                return Err(ctx.err(
                    format!("{key}.params.{n}"),
                    format!("{v} is outside the admissible range {:?}", bounds[k]),
                ));
            }
            params.push(v);
        }
        for k in l.params.keys() {
            if !names.contains(k) {
                return Err(ctx.err(
                    format!("{key}.params.{k}"),
                    format!(
                        "{} has no parameter {k}; its parameters are {names:?}",
                        l.law
                    ),
                ));
            }
        }
        levels.push(TruthLevel {
            name: l.name.clone(),
            force_rms_n: force,
            law: l.law.clone(),
            branches: l.branches,
            params,
            param_names: names,
        });
    }
    let degraded_bond = match &raw.degraded_bond {
        None => None,
        Some(d) => {
            let super::StructureSource::Mesher(j) = &structure.source else {
                return Err(ctx.err(
                    "degraded_bond",
                    "a degraded bond region needs the mesher's structure (source = \"mesher\"): an imported model has no adhesive geometry",
                ));
            };
            let width = ctx.positive(
                "degraded_bond.width",
                d.width.unwrap_or(DEFAULT_DEGRADED_WIDTH_M),
                "m",
            )?;
            let (a0, a1) = (
                j.adhesive_x_start_m,
                j.adhesive_x_start_m + j.adhesive_length_m,
            );
            let tol = 1e-9 * j.adhesive_length_m;
            if !(d.x_start.is_finite() && d.x_start >= a0 - tol && d.x_start + width <= a1 + tol) {
                return Err(ctx.err(
                    "degraded_bond.x_start",
                    format!(
                        "the region [{}, {}] m is not inside the adhesive block [{a0}, {a1}] m: give x_start in [{a0}, {}] m",
                        d.x_start,
                        d.x_start + width,
                        a1 - width
                    ),
                ));
            }
            if !(d.loss.is_finite() && (0.0..1.0).contains(&d.loss)) {
                return Err(ctx.err(
                    "degraded_bond.loss",
                    format!(
                        "{}: give the fraction of the modulus lost in the region, 0 <= loss < 1 (0.95 leaves 5 %)",
                        d.loss
                    ),
                ));
            }
            Some(((d.x_start, d.x_start + width), d.loss))
        }
    };
    let base_springs = match &raw.base_springs {
        None => None,
        Some(b) => {
            if !matches!(structure.source, super::StructureSource::Mesher(_)) {
                return Err(ctx.err(
                    "base_springs",
                    "base springs need the mesher's structure (source = \"mesher\"): an imported model has no base face to free",
                ));
            }
            let springs = crate::fe::base::BaseSprings {
                normal_n_m3: b.normal,
                tangential_n_m3: b.tangential,
            };
            crate::fe::base::check_springs(&springs, "base_springs")
                .map_err(|e| ctx.err(e.key().to_string(), e.detail()))?;
            Some(springs)
        }
    };
    Ok(Experiment {
        file: path.to_path_buf(),
        name: e.name.clone(),
        description: e.description.clone().unwrap_or_default(),
        frequency_domain,
        seed: e.seed.unwrap_or(0),
        output: resolve(path, &e.output),
        binary: e.binary.unwrap_or(false),
        use_full_model,
        structure,
        chain,
        sensors,
        resonators,
        gains,
        delays_s,
        levels,
        shaker_side_force,
        degraded_bond,
        base_springs,
    })
}
