//! Statistical validation of the Bayesian layer on rfmlab's own frequency-domain simulation:
//! simulation-based calibration, interval coverage, model selection by evidence, and evidence
//! against brute-force quadrature; every independent unit (a prior draw, a replicate, a
//! generating model's replicate) may run in its own shard.
//!
//! Data: the virtual experiment of the validation file's experiment ([`simulate_level`] in
//! frequency-domain mode: block spectra drawn from their exact Gaussian law, with the
//! experiment's chain: window, averages, sensor noise, shaker), at the force of its chosen level.
//! By default ([`DataSource::NoiseModel`]) its H1 is replaced by a draw from the likelihood's
//! own law at the same noise level, as SBC requires (Talts et al. 2018: data from the model
//! that is inferred, so that a failure points at the computation); `data =
//! "virtual_experiment"` keeps the experiment's H1 and so also checks the noise model.
//! Simulation and inference share one certified ROM (an inverse crime on purpose: these checks
//! calibrate the statistics, not the ROM; the ROM's own error is certified elsewhere).
//!
//! Inference: the forward model with the estimator's measurement model (window leakage and
//! shaker colour, exact kernel), the coherence likelihood with the simulation's equivalent
//! number of averages, log-normal priors of width `sigma_ln` centred on the generating
//! model's truth; the MAP by [`find_map`] from the prior median, and its Laplace
//! approximation. Posterior draws for SBC and intervals for coverage are the Laplace
//! Gaussian's in the unconstrained (log) coordinates, mapped to the physical parameters (cheap
//! enough for hundreds of data sets; NUTS at 3-5 s per posterior is not); evidence for model
//! selection is the Laplace evidence. The quadrature part checks the Laplace (and, when asked,
//! the stepping-stone) evidence against a tensor-grid quadrature of the posterior density.
//!
//! Determinism: unit `k` draws everything (prior draw, simulation seed, MAP design seed,
//! posterior draws) from `unit_rng(seed, k)`; units are computed in parallel and collected in
//! order, so tables do not depend on the thread count or on the sharding.
//!
//! Units, in order: SBC draws, coverage replicates, selection (generating model major,
//! replicate minor), quadrature (model major, replicate minor).

pub mod spec;
pub mod stats;
pub mod summary;
pub mod write;

use crate::experiment::plant::EnginePlant;
use crate::experiment::{simulate_level, ChainParams, Mode};
use crate::forward::{EstimatorSpec, ForwardModel, MeasurementModel, MeasurementParams};
use crate::inference::likelihood::{
    ErrorLaw, FrfData, FrfLikelihood, FrfPosterior, NoiseModel, Scale, DEFAULT_COHERENCE_FLOOR,
};
use crate::inference::map::{find_map, MapParams, MapResult};
use crate::inference::prior::{normal_quantile, Prior};
use crate::inference::refine::relinearise_to_map;
use crate::inference::{unit_rng, Posterior, SteppingStoneParams};
use crate::linalg::dense::cholesky;
use crate::material::ConstitutiveModel;
use crate::output::shards::Shard;
use crate::output::Table;
use crate::rom::{build_rom, ModulusRange, RomParams};
use crate::stage::rom_engine::RomEngine;
use rand::RngExt;
use rayon::prelude::*;
pub use spec::{load_validation, DataSource, ValidationSpec};
use std::time::Instant;

/// Errors of a validation run.
#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    #[error(transparent)]
    Spec(#[from] crate::study::StudyError),
    #[error("setting up the validation: {0}")]
    Setup(String),
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    #[error("figure: {0}")]
    Plot(String),
}

/// Why one validation unit failed: the unit's rows say so in their `status` and the run
/// continues with the next unit.
#[derive(Debug, thiserror::Error)]
pub enum UnitError {
    #[error("virtual experiment: {0}")]
    Experiment(#[from] crate::experiment::ExperimentError),
    #[error("forward model: {0}")]
    Forward(#[from] crate::forward::ForwardError),
    #[error("likelihood: {0}")]
    Likelihood(#[from] crate::inference::likelihood::LikelihoodError),
    #[error("MAP: {0}")]
    Map(#[from] crate::inference::map::MapError),
    #[error("re-linearisation at the MAP: {0}")]
    Refine(#[from] crate::inference::refine::RefineError),
    #[error("stepping-stone: {0}")]
    Evidence(#[from] crate::inference::SamplerError),
    #[error(transparent)]
    Setup(#[from] ValidateError),
    /// A numerical condition the unit cannot go on without (a covariance that is not positive
    /// definite, no finite density on a grid).
    #[error("{0}")]
    Numerical(&'static str),
}

/// Central credible levels whose coverage is checked.
pub const LEVELS: [f64; 3] = [0.5, 0.9, 0.95];

/// The structure, the ROM and the measurement chain shared by every unit.
pub struct Setup {
    /// The certified ROM with its pencil prepared on the lines and on the measurement model's
    /// fine grid, the grids every unit's likelihood evaluates (a dense LU of the reduced
    /// system per line per evaluation otherwise).
    pub rom: RomEngine,
    pub excitation: usize,
    pub point_ids: Vec<u32>,
    /// The chain of the default data (frequency-domain mode; seed set per unit).
    pub chain: ChainParams,
    pub measurement: MeasurementModel,
    pub freq_hz: Vec<f64>,
    pub omega_rad_s: Vec<f64>,
    /// The default data's Model 4 truth.
    pub truth4: Vec<f64>,
    /// ROM basis size and certified error.
    pub rom_basis: usize,
    pub rom_error: f64,
    /// Whether the ROM was read from the ROM cache ([`Setup::with_rom_cache`]) rather than
    /// built.
    pub rom_from_cache: bool,
    /// Where the data come from.
    pub data: DataSource,
}

/// One unit's data set: what the likelihood sees, the equivalent number of independent
/// averages, and (for [`DataSource::NoiseModel`]) the variances the data were drawn with,
/// which the likelihood then uses as fixed.
#[derive(Clone, Debug)]
pub struct SimData {
    pub data: FrfData,
    pub n_averages: f64,
    pub variances: Option<Vec<f64>>,
}

/// The law and truth of a model by name: Model 4 at the default data's truth, the others at
/// the paper's Table 4.
pub fn law_and_truth(
    setup: &Setup,
    name: &str,
) -> Result<(Box<dyn ConstitutiveModel>, Vec<f64>), ValidateError> {
    let law = crate::material::model_from_name(name, None)
        .map_err(|e| ValidateError::Setup(format!("{name}: {e}")))?;
    let k = spec::model_number(name).unwrap_or(0);
    let truth = if k == 4 {
        setup.truth4.clone()
    } else {
        crate::material::try_paper_table4(k)
            .map_err(|e| ValidateError::Setup(format!("{name}: {e}")))?
            .0
    };
    Ok((law, truth))
}

impl Setup {
    /// Build the structure, the ROM over the moduli of every truth (and Model 4's SBC prior
    /// to 3 sd) and the estimator's measurement model.
    pub fn new(spec: &ValidationSpec) -> Result<Setup, ValidateError> {
        Setup::with_rom_cache(spec, None)
    }

    /// [`Setup::new`] with the certified ROM read from the cache folder `rom_cache` when it
    /// holds it, else built and saved there ([`crate::rom::cache::certified_rom`]): the
    /// processes of a sharded validation, started together, build it once (the others wait for
    /// the entry and read it), and a run again after an interruption reads it.
    pub fn with_rom_cache(
        spec: &ValidationSpec,
        rom_cache: Option<&std::path::Path>,
    ) -> Result<Setup, ValidateError> {
        let ex = &spec.experiment;
        let file = ex.file.display().to_string();
        let built = crate::study::build::build_model(&ex.structure, &file)?;
        let model = crate::study::build::with_sensor_masses(
            &built.model,
            &ex.structure,
            &ex.sensors,
            &file,
        )?;
        let lv = &ex.levels[spec.level];
        let mut chain = ex.chain.clone();
        chain.mode = Mode::FrequencyDomain;
        chain.force_rms_n = lv.force_rms_n;
        chain.gains = ex.gains.clone();
        chain.delays_s = ex.delays_s.clone();
        let (f0, f1) = chain.band_hz;
        let lo = (f0 - chain.kernel.half_width_hz).max(0.25);
        let hi = f1 + chain.kernel.half_width_hz + 1.0;
        // Moduli the units will ask for: every truth, and Model 4 at the corners of its SBC
        // prior's 3-sd box.
        let mut sets: Vec<(String, Vec<f64>)> = vec![("model4".into(), lv.params.clone())];
        if let Some(s) = &spec.sbc {
            let n = lv.params.len();
            for c in 0..(1usize << n) {
                let p: Vec<f64> = (0..n)
                    .map(|i| {
                        let sgn = if c >> i & 1 == 1 { 3.0 } else { -3.0 };
                        lv.params[i] * (sgn * s.sigma_ln).exp()
                    })
                    .collect();
                sets.push(("model4".into(), p));
            }
        }
        let mut others: Vec<&String> = Vec::new();
        if let Some(s) = &spec.selection {
            others.extend(&s.models);
        }
        if let Some(q) = &spec.quadrature {
            others.extend(&q.models);
        }
        for name in others {
            let k = spec::model_number(name).unwrap_or(0);
            if k != 4 {
                let t = crate::material::try_paper_table4(k)
                    .map_err(|e| ValidateError::Setup(format!("{name}: {e}")))?
                    .0;
                sets.push((name.clone(), t));
            }
        }
        let mut range = ModulusRange {
            e_storage_pa: (f64::INFINITY, 0.0),
            e_loss_pa: (f64::INFINITY, 0.0),
        };
        for (name, p) in &sets {
            let law = crate::material::model_from_name(name, None)
                .map_err(|e| ValidateError::Setup(format!("{name}: {e}")))?;
            for k in 0..=200 {
                let f = lo + (hi - lo) * k as f64 / 200.0;
                let e = law.modulus(p, std::f64::consts::TAU * f);
                range.e_storage_pa.0 = range.e_storage_pa.0.min(e.re / 1.5);
                range.e_storage_pa.1 = range.e_storage_pa.1.max(e.re * 1.5);
                range.e_loss_pa.0 = range.e_loss_pa.0.min((e.im / 1.5).max(0.0));
                range.e_loss_pa.1 = range.e_loss_pa.1.max((e.im * 1.5).max(1e3));
            }
        }
        let inputs = [built.excitation];
        let params = RomParams {
            band_hz: (lo, hi),
            range,
            tolerance: 1e-5,
            ..RomParams::default()
        };
        let build = || {
            build_rom(&model, &inputs, &params)
                .map_err(|e| ValidateError::Setup(format!("ROM: {e}")))
        };
        let ((rom, cert), entry) =
            crate::rom::cache::certified_rom(rom_cache, &model, &inputs, &params, build)?;
        let rom_from_cache = entry.is_some();
        let freq_hz = chain.lines_hz.clone();
        let measurement = MeasurementModel::new(
            EstimatorSpec {
                window: chain.window,
                block_s: chain.block_s,
                fs_hz: chain.fs_hz,
                force_band_hz: chain.band_hz,
                shaker: chain.shaker,
            },
            &freq_hz,
            &MeasurementParams::default(),
        )
        .map_err(|e| ValidateError::Setup(format!("measurement model: {e}")))?;
        let omega_rad_s: Vec<f64> = freq_hz.iter().map(|f| std::f64::consts::TAU * f).collect();
        let rom = RomEngine::prepared(rom, &[omega_rad_s.clone(), measurement.fine_omega()])
            .map_err(|e| ValidateError::Setup(format!("the ROM's pencil: {e}")))?;
        Ok(Setup {
            rom,
            excitation: built.excitation,
            point_ids: model.points.iter().map(|p| p.id).collect(),
            omega_rad_s,
            freq_hz,
            chain,
            measurement,
            truth4: lv.params.clone(),
            rom_basis: cert.basis_size,
            rom_error: cert.max_rel_error,
            rom_from_cache,
            data: spec.data,
        })
    }

    /// One simulated data set of `law` at `params` with chain seed `seed`.
    ///
    /// The virtual experiment runs in either case (its coherence sets the noise level). With
    /// [`DataSource::NoiseModel`] its H1 is then replaced by a draw from the likelihood's own
    /// law: `X = E[H1](params) + e`, `Re e, Im e ~ N(0, v)` independent, with
    /// `v = |E[H1]|^2 (1 - g2) / (2 n g2)` (the coherence scale of
    /// [`Scale::Coherence`], floor included, evaluated at the mean instead of the data), and
    /// the posterior uses these `v` as fixed variances.
    pub fn simulate(
        &self,
        law: &dyn ConstitutiveModel,
        params: &[f64],
        seed: u64,
    ) -> Result<SimData, UnitError> {
        let modulus = |w: f64| law.modulus(params, w);
        let plant = EnginePlant {
            engine: &self.rom,
            modulus: &modulus,
            input_col: 0,
            drive_output: self.excitation,
        };
        let chain = ChainParams {
            seed,
            ..self.chain.clone()
        };
        let sim = simulate_level(&plant, &chain)?;
        let n_out = sim.channels.len();
        let n_lines = sim.freq_hz.len();
        let mut values = Vec::with_capacity(n_lines * n_out);
        let mut coherence = Vec::with_capacity(n_lines * n_out);
        for l in 0..n_lines {
            for c in &sim.channels {
                values.push(c.values[l]);
                coherence.push(c.coherence[l]);
            }
        }
        let n_averages = sim.truth.effective_averages;
        let variances = match self.data {
            DataSource::VirtualExperiment => None,
            DataSource::NoiseModel => {
                let outputs: Vec<usize> = (0..n_out).collect();
                let forward = ForwardModel::new(
                    &self.rom,
                    law,
                    &self.omega_rad_s,
                    self.excitation,
                    &outputs,
                    Some(self.measurement.clone()),
                )?;
                let mean = forward.predict(params, false)?;
                let mut rng = unit_rng(seed, 0x006e_6f69_7365);
                let mut v = Vec::with_capacity(values.len());
                for (o, (x, g2)) in values.iter_mut().zip(&coherence).enumerate() {
                    let m = mean.values[o];
                    let g2 = g2.clamp(f64::MIN_POSITIVE, 1.0);
                    let var = crate::inference::likelihood::coherence_variance(
                        m.norm_sqr(),
                        g2,
                        n_averages,
                        DEFAULT_COHERENCE_FLOOR,
                    );
                    let (a, b): (f64, f64) = (
                        rng.sample(rand_distr::StandardNormal),
                        rng.sample(rand_distr::StandardNormal),
                    );
                    *x = m + crate::common::C64::new(a, b) * var.sqrt();
                    v.push(var);
                }
                Some(v)
            }
        };
        Ok(SimData {
            data: FrfData {
                freq_hz: sim.freq_hz.clone(),
                n_out,
                values,
                coherence: Some(coherence),
            },
            n_averages,
            variances,
        })
    }

    /// The posterior of `law` on `data` under log-normal priors of width `sigma_ln` around
    /// `median`.
    pub fn posterior<'a>(
        &'a self,
        law: &'a dyn ConstitutiveModel,
        sim: &SimData,
        median: &[f64],
        sigma_ln: f64,
    ) -> Result<FrfPosterior<'a>, UnitError> {
        let outputs: Vec<usize> = (0..self.point_ids.len()).collect();
        let forward = ForwardModel::new(
            &self.rom,
            law,
            &self.omega_rad_s,
            self.excitation,
            &outputs,
            Some(self.measurement.clone()),
        )?;
        let noise = NoiseModel {
            scale: match &sim.variances {
                Some(v) => Scale::Fixed {
                    variances: v.clone(),
                },
                None => Scale::Coherence {
                    n_averages: sim.n_averages,
                    floor: DEFAULT_COHERENCE_FLOOR,
                },
            },
            errors: ErrorLaw::Gaussian,
            model_error: 0.0,
        };
        let lik = FrfLikelihood::new(forward, sim.data.clone(), noise, &self.point_ids)?;
        let priors = median
            .iter()
            .map(|&m| Prior::LogNormal {
                median: m,
                sigma_ln,
            })
            .collect();
        Ok(FrfPosterior::new(lik, priors)?)
    }
}

/// One independent unit of the validation.
#[derive(Clone, Debug, PartialEq)]
pub enum Unit {
    Sbc { draw: usize },
    Coverage { replicate: usize },
    Selection { generating: usize, replicate: usize },
    Quadrature { model: usize, replicate: usize },
}

/// All units of a validation, in their global order (unit `k` is the `k`-th).
pub fn units(spec: &ValidationSpec) -> Vec<Unit> {
    let mut u = Vec::new();
    if let Some(s) = &spec.sbc {
        u.extend((0..s.draws).map(|draw| Unit::Sbc { draw }));
    }
    if let Some(c) = &spec.coverage {
        u.extend((0..c.replicates).map(|replicate| Unit::Coverage { replicate }));
    }
    if let Some(s) = &spec.selection {
        for generating in 0..s.models.len() {
            u.extend((0..s.replicates).map(|replicate| Unit::Selection {
                generating,
                replicate,
            }));
        }
    }
    if let Some(q) = &spec.quadrature {
        for model in 0..q.models.len() {
            u.extend((0..q.replicates).map(|replicate| Unit::Quadrature { model, replicate }));
        }
    }
    u
}

/// The rows one unit contributes (a unit that failed contributes rows with its status).
#[derive(Clone, Debug, Default)]
struct Rows {
    sbc: Vec<SbcRow>,
    coverage: Vec<CoverageRow>,
    selection: Vec<SelectionRow>,
    quadrature: Vec<QuadratureRow>,
}

#[derive(Clone, Debug)]
struct SbcRow {
    unit: usize,
    draw: usize,
    parameter: String,
    truth: f64,
    map: f64,
    sd: f64,
    rank: usize,
    n_posterior: usize,
    status: String,
}

#[derive(Clone, Debug)]
struct CoverageRow {
    unit: usize,
    replicate: usize,
    parameter: String,
    truth: f64,
    map: f64,
    sd: f64,
    /// (lo, hi) per entry of [`LEVELS`].
    bounds: [(f64, f64); 3],
    status: String,
}

#[derive(Clone, Debug)]
struct SelectionRow {
    unit: usize,
    replicate: usize,
    generating: String,
    candidate: String,
    log_evidence: f64,
    log_likelihood_map: f64,
    best: bool,
    status: String,
}

#[derive(Clone, Debug)]
struct QuadratureRow {
    unit: usize,
    model: String,
    replicate: usize,
    estimator: String,
    log_evidence: f64,
    se: f64,
    evaluations: usize,
    status: String,
}

/// The tables of one shard (or of the whole run) and what it cost.
pub struct ShardResult {
    pub tables: Vec<Table>,
    pub units: usize,
    pub seconds: f64,
}

/// Names of the tables a validation writes.
pub const TABLES: [&str; 4] = ["sbc", "coverage", "selection", "quadrature"];

/// Run the units of `shard` (in parallel; rows collected in unit order).
pub fn run_shard(
    spec: &ValidationSpec,
    setup: &Setup,
    shard: Shard,
    progress: &(dyn Fn() + Sync),
) -> Result<ShardResult, ValidateError> {
    let t0 = Instant::now();
    let all = units(spec);
    let mine: Vec<(usize, &Unit)> = all
        .iter()
        .enumerate()
        .filter(|(k, _)| shard.owns(*k))
        .collect();
    let rows: Vec<Rows> = mine
        .par_iter()
        .map(|(k, u)| {
            let r = run_unit(spec, setup, *k, u);
            progress();
            r
        })
        .collect();
    let mut all_rows = Rows::default();
    for r in rows {
        all_rows.sbc.extend(r.sbc);
        all_rows.coverage.extend(r.coverage);
        all_rows.selection.extend(r.selection);
        all_rows.quadrature.extend(r.quadrature);
    }
    Ok(ShardResult {
        tables: tables(&all_rows)?,
        units: mine.len(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// A unit's MAP search: the prior median plus `map_starts` space-filling starts, on the
/// measurement bias linearised at the prior median, then re-linearised at the MAP until the
/// MAP stops moving (there the linearised and the exact likelihood have the same value and
/// gradient, as in `bayes::infer_level`); the posterior is left linearised at the MAP, so its
/// Laplace approximation and any later evaluation use the cheap operator.
fn fit(
    post: &mut FrfPosterior<'_>,
    median: &[f64],
    starts: usize,
    seed: u64,
) -> Result<MapResult, UnitError> {
    let nl = median.len();
    post.likelihood.forward.linearise_measurement(median)?;
    let x0 = post.unconstrained(median);
    let params = MapParams {
        n_starts: starts,
        seed,
        ..MapParams::default()
    };
    let mut map = find_map(post, Some(&x0), &params, &|| ())?;
    relinearise_to_map(post, &mut map, &params, nl)?;
    if !map.laplace.positive_definite {
        return Err(UnitError::Numerical(
            "the Hessian at the MAP is not positive definite",
        ));
    }
    Ok(map)
}

/// Central interval of probability `level` of coordinate `i` under the Laplace Gaussian in
/// the unconstrained coordinates, in physical values (the transform is monotone per
/// coordinate).
fn interval(post: &FrfPosterior<'_>, map: &MapResult, i: usize, level: f64) -> (f64, f64) {
    let lap = &map.laplace;
    let d = lap.dim();
    let sd = lap.cov_x[i * d + i].max(0.0).sqrt();
    let z = normal_quantile(0.5 + level / 2.0);
    let at = |v: f64| {
        let mut x = lap.x.clone();
        x[i] = v;
        post.constrained(&x)[i]
    };
    let (a, b) = (at(lap.x[i] - z * sd), at(lap.x[i] + z * sd));
    (a.min(b), a.max(b))
}

fn run_unit(spec: &ValidationSpec, setup: &Setup, k: usize, unit: &Unit) -> Rows {
    let mut rng = unit_rng(spec.seed, k as u64);
    let mut rows = Rows::default();
    match unit {
        Unit::Sbc { draw } => {
            let s = spec.sbc.as_ref().expect("sbc unit without [sbc]");
            let Ok((law, truth)) = law_and_truth(setup, "model4") else {
                return rows;
            };
            let names = law.param_names();
            let theta: Vec<f64> = truth
                .iter()
                .map(|t| {
                    let z: f64 = rng.sample(rand_distr::StandardNormal);
                    t * (s.sigma_ln * z).exp()
                })
                .collect();
            let sim_seed: u64 = rng.random();
            let map_seed: u64 = rng.random();
            let res = (|| {
                let sim = setup.simulate(law.as_ref(), &theta, sim_seed)?;
                let mut post = setup.posterior(law.as_ref(), &sim, &truth, s.sigma_ln)?;
                let map = fit(&mut post, &truth, spec.map_starts, map_seed)?;
                let d = map.laplace.dim();
                let l = cholesky(&map.laplace.cov_x, d)
                    .ok_or(UnitError::Numerical("Laplace covariance"))?;
                let mut ranks = vec![0usize; d];
                for _ in 0..s.posterior_draws {
                    let z: Vec<f64> = (0..d)
                        .map(|_| rng.sample(rand_distr::StandardNormal))
                        .collect();
                    let x: Vec<f64> = (0..d)
                        .map(|i| {
                            map.laplace.x[i] + (0..=i).map(|j| l[i * d + j] * z[j]).sum::<f64>()
                        })
                        .collect();
                    let p = post.constrained(&x);
                    for i in 0..d {
                        ranks[i] += (p[i] < theta[i]) as usize;
                    }
                }
                Ok::<_, UnitError>((map.map_physical.clone(), map.laplace.sd_physical(), ranks))
            })();
            for (i, name) in names.iter().enumerate() {
                let (map, sd, rank, status) = match &res {
                    Ok((m, sd, r)) => (m[i], sd[i], r[i], "ok".to_string()),
                    Err(e) => (f64::NAN, f64::NAN, 0, e.to_string()),
                };
                rows.sbc.push(SbcRow {
                    unit: k,
                    draw: *draw,
                    parameter: name.clone(),
                    truth: theta[i],
                    map,
                    sd,
                    rank,
                    n_posterior: s.posterior_draws,
                    status,
                });
            }
        }
        Unit::Coverage { replicate } => {
            let c = spec
                .coverage
                .as_ref()
                .expect("coverage unit without [coverage]");
            let Ok((law, truth)) = law_and_truth(setup, "model4") else {
                return rows;
            };
            let names = law.param_names();
            let sim_seed: u64 = rng.random();
            let map_seed: u64 = rng.random();
            let res = (|| {
                let sim = setup.simulate(law.as_ref(), &truth, sim_seed)?;
                let mut post = setup.posterior(law.as_ref(), &sim, &truth, c.sigma_ln)?;
                let map = fit(&mut post, &truth, spec.map_starts, map_seed)?;
                let b: Vec<[(f64, f64); 3]> = (0..names.len())
                    .map(|i| LEVELS.map(|lv| interval(&post, &map, i, lv)))
                    .collect();
                Ok::<_, UnitError>((map.map_physical.clone(), map.laplace.sd_physical(), b))
            })();
            for (i, name) in names.iter().enumerate() {
                let nan = (f64::NAN, f64::NAN);
                let (map, sd, bounds, status) = match &res {
                    Ok((m, sd, b)) => (m[i], sd[i], b[i], "ok".to_string()),
                    Err(e) => (f64::NAN, f64::NAN, [nan; 3], e.to_string()),
                };
                rows.coverage.push(CoverageRow {
                    unit: k,
                    replicate: *replicate,
                    parameter: name.clone(),
                    truth: truth[i],
                    map,
                    sd,
                    bounds,
                    status,
                });
            }
        }
        Unit::Selection {
            generating,
            replicate,
        } => {
            let s = spec
                .selection
                .as_ref()
                .expect("selection unit without [selection]");
            let sim_seed: u64 = rng.random();
            let map_seed: u64 = rng.random();
            let gen_name = &s.models[*generating];
            let data = law_and_truth(setup, gen_name)
                .map_err(UnitError::from)
                .and_then(|(law, truth)| setup.simulate(law.as_ref(), &truth, sim_seed));
            let mut cand: Vec<SelectionRow> = Vec::new();
            for (ci, name) in s.models.iter().enumerate() {
                let res = match &data {
                    Err(e) => Err(e.to_string()),
                    Ok(sim) => law_and_truth(setup, name)
                        .map_err(UnitError::from)
                        .and_then(|(law, truth)| {
                            let mut post =
                                setup.posterior(law.as_ref(), sim, &truth, s.sigma_ln)?;
                            let map = fit(
                                &mut post,
                                &truth,
                                spec.map_starts,
                                map_seed ^ (ci as u64 + 1),
                            )?;
                            Ok((map.laplace.log_evidence, map.laplace.log_likelihood))
                        })
                        .map_err(|e| e.to_string()),
                };
                let (le, ll, status) = match res {
                    Ok((le, ll)) => (le, ll, "ok".to_string()),
                    Err(e) => (f64::NAN, f64::NAN, e),
                };
                cand.push(SelectionRow {
                    unit: k,
                    replicate: *replicate,
                    generating: gen_name.clone(),
                    candidate: name.clone(),
                    log_evidence: le,
                    log_likelihood_map: ll,
                    best: false,
                    status,
                });
            }
            if let Some(b) = cand
                .iter()
                .enumerate()
                .filter(|(_, r)| r.log_evidence.is_finite())
                .max_by(|a, b| a.1.log_evidence.total_cmp(&b.1.log_evidence))
                .map(|(i, _)| i)
            {
                cand[b].best = true;
            }
            rows.selection = cand;
        }
        Unit::Quadrature { model, replicate } => {
            let q = spec
                .quadrature
                .as_ref()
                .expect("quadrature unit without [quadrature]");
            let name = &q.models[*model];
            let sim_seed: u64 = rng.random();
            let map_seed: u64 = rng.random();
            let ss_seed: u64 = rng.random();
            let res = (|| {
                let (law, truth) = law_and_truth(setup, name)?;
                let sim = setup.simulate(law.as_ref(), &truth, sim_seed)?;
                let mut post = setup.posterior(law.as_ref(), &sim, &truth, q.sigma_ln)?;
                let map = fit(&mut post, &truth, spec.map_starts, map_seed)?;
                let mut out = vec![(
                    "laplace".to_string(),
                    map.laplace.log_evidence,
                    0.0,
                    map.evaluations,
                )];
                let (lz, n) = quadrature_log_evidence(&post, &map, q.grid, q.half_width_sd)?;
                out.insert(0, ("quadrature".to_string(), lz, 0.0, n));
                if q.ss_particles > 0 {
                    let r = crate::inference::stepping_stone(
                        &post,
                        &SteppingStoneParams {
                            particles: q.ss_particles,
                            replicas: q.ss_replicas,
                            seed: ss_seed,
                            ..SteppingStoneParams::default()
                        },
                        &crate::inference::no_progress,
                    )?;
                    out.push((
                        "stepping_stone".to_string(),
                        r.log_evidence,
                        r.log_evidence_se,
                        r.n_loglik as usize,
                    ));
                }
                Ok::<_, UnitError>(out)
            })();
            match res {
                Ok(v) => {
                    for (est, lz, se, n) in v {
                        rows.quadrature.push(QuadratureRow {
                            unit: k,
                            model: name.clone(),
                            replicate: *replicate,
                            estimator: est,
                            log_evidence: lz,
                            se,
                            evaluations: n,
                            status: "ok".into(),
                        });
                    }
                }
                Err(e) => rows.quadrature.push(QuadratureRow {
                    unit: k,
                    model: name.clone(),
                    replicate: *replicate,
                    estimator: "quadrature".into(),
                    log_evidence: f64::NAN,
                    se: f64::NAN,
                    evaluations: 0,
                    status: e.to_string(),
                }),
            }
        }
    }
    rows
}

/// `log Z = log int exp(log prior + log lik) dx` by the tensor trapezoid rule on
/// `n x ... x n` nodes over the Laplace Gaussian's principal box, `x = m + L z`,
/// `z in [-h, h]^d` (`L` the Cholesky factor of the Laplace covariance, so the integrand is
/// about a standard normal in `z`): `log Z = log sum_j w_j exp(f(x_j)) + log det L`. Returns
/// the estimate and the evaluations spent. Exact to the rule's error for any posterior that
/// decays inside the box (the tails beyond `h` sd are below `exp(-h^2 / 2)` relative).
pub fn quadrature_log_evidence(
    post: &dyn Posterior,
    map: &MapResult,
    n: usize,
    h: f64,
) -> Result<(f64, usize), UnitError> {
    let lap = &map.laplace;
    let d = lap.dim();
    let l = cholesky(&lap.cov_x, d).ok_or(UnitError::Numerical(
        "the Laplace covariance is not positive definite",
    ))?;
    let logdet_l: f64 = (0..d).map(|i| l[i * d + i].ln()).sum();
    let step = 2.0 * h / (n - 1) as f64;
    let total = n.pow(d as u32);
    let vals: Vec<f64> = (0..total)
        .into_par_iter()
        .map(|idx| {
            let mut z = vec![0.0; d];
            let mut r = idx;
            let mut w = 1.0f64;
            for zi in z.iter_mut() {
                let j = r % n;
                r /= n;
                *zi = -h + step * j as f64;
                if j == 0 || j == n - 1 {
                    w *= 0.5;
                }
            }
            let x: Vec<f64> = (0..d)
                .map(|i| lap.x[i] + (0..=i).map(|j| l[i * d + j] * z[j]).sum::<f64>())
                .collect();
            match post.log_posterior(&x, None) {
                Ok(v) if v.is_finite() => v + w.ln(),
                _ => f64::NEG_INFINITY,
            }
        })
        .collect();
    let mx = vals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !mx.is_finite() {
        return Err(UnitError::Numerical(
            "no finite posterior density on the quadrature grid",
        ));
    }
    let s: f64 = vals.iter().map(|v| (v - mx).exp()).sum();
    Ok((mx + s.ln() + d as f64 * step.ln() + logdet_l, total))
}

fn tables(r: &Rows) -> Result<Vec<Table>, ValidateError> {
    let i64s = |v: Vec<usize>| v.into_iter().map(|x| x as i64).collect::<Vec<i64>>();
    let mut sbc = Table::new("sbc");
    sbc.push_i64("unit", "", i64s(r.sbc.iter().map(|x| x.unit).collect()))?;
    sbc.push_i64("draw", "", i64s(r.sbc.iter().map(|x| x.draw).collect()))?;
    sbc.push_str(
        "parameter",
        r.sbc.iter().map(|x| x.parameter.clone()).collect(),
    )?;
    sbc.push_f64("truth", "SI", r.sbc.iter().map(|x| x.truth).collect())?;
    sbc.push_f64("map", "SI", r.sbc.iter().map(|x| x.map).collect())?;
    sbc.push_f64("sd", "SI", r.sbc.iter().map(|x| x.sd).collect())?;
    sbc.push_i64("rank", "", i64s(r.sbc.iter().map(|x| x.rank).collect()))?;
    sbc.push_i64(
        "n_posterior",
        "",
        i64s(r.sbc.iter().map(|x| x.n_posterior).collect()),
    )?;
    sbc.push_str("status", r.sbc.iter().map(|x| x.status.clone()).collect())?;

    let mut cov = Table::new("coverage");
    cov.push_i64(
        "unit",
        "",
        i64s(r.coverage.iter().map(|x| x.unit).collect()),
    )?;
    cov.push_i64(
        "replicate",
        "",
        i64s(r.coverage.iter().map(|x| x.replicate).collect()),
    )?;
    cov.push_str(
        "parameter",
        r.coverage.iter().map(|x| x.parameter.clone()).collect(),
    )?;
    cov.push_f64("truth", "SI", r.coverage.iter().map(|x| x.truth).collect())?;
    cov.push_f64("map", "SI", r.coverage.iter().map(|x| x.map).collect())?;
    cov.push_f64("sd", "SI", r.coverage.iter().map(|x| x.sd).collect())?;
    for (j, lv) in LEVELS.iter().enumerate() {
        let p = (lv * 100.0).round() as u32;
        cov.push_f64(
            format!("lo{p}"),
            "SI",
            r.coverage.iter().map(|x| x.bounds[j].0).collect(),
        )?;
        cov.push_f64(
            format!("hi{p}"),
            "SI",
            r.coverage.iter().map(|x| x.bounds[j].1).collect(),
        )?;
        cov.push_bool(
            format!("in{p}"),
            r.coverage
                .iter()
                .map(|x| x.bounds[j].0 <= x.truth && x.truth <= x.bounds[j].1)
                .collect(),
        )?;
    }
    cov.push_str(
        "status",
        r.coverage.iter().map(|x| x.status.clone()).collect(),
    )?;

    let mut sel = Table::new("selection");
    sel.push_i64(
        "unit",
        "",
        i64s(r.selection.iter().map(|x| x.unit).collect()),
    )?;
    sel.push_i64(
        "replicate",
        "",
        i64s(r.selection.iter().map(|x| x.replicate).collect()),
    )?;
    sel.push_str(
        "generating",
        r.selection.iter().map(|x| x.generating.clone()).collect(),
    )?;
    sel.push_str(
        "candidate",
        r.selection.iter().map(|x| x.candidate.clone()).collect(),
    )?;
    sel.push_f64(
        "log_evidence_laplace",
        "nat",
        r.selection.iter().map(|x| x.log_evidence).collect(),
    )?;
    sel.push_f64(
        "log_likelihood_map",
        "nat",
        r.selection.iter().map(|x| x.log_likelihood_map).collect(),
    )?;
    sel.push_bool("best", r.selection.iter().map(|x| x.best).collect())?;
    sel.push_str(
        "status",
        r.selection.iter().map(|x| x.status.clone()).collect(),
    )?;

    let mut quad = Table::new("quadrature");
    quad.push_i64(
        "unit",
        "",
        i64s(r.quadrature.iter().map(|x| x.unit).collect()),
    )?;
    quad.push_str(
        "model",
        r.quadrature.iter().map(|x| x.model.clone()).collect(),
    )?;
    quad.push_i64(
        "replicate",
        "",
        i64s(r.quadrature.iter().map(|x| x.replicate).collect()),
    )?;
    quad.push_str(
        "estimator",
        r.quadrature.iter().map(|x| x.estimator.clone()).collect(),
    )?;
    quad.push_f64(
        "log_evidence",
        "nat",
        r.quadrature.iter().map(|x| x.log_evidence).collect(),
    )?;
    quad.push_f64("se", "nat", r.quadrature.iter().map(|x| x.se).collect())?;
    quad.push_i64(
        "evaluations",
        "",
        i64s(r.quadrature.iter().map(|x| x.evaluations).collect()),
    )?;
    quad.push_str(
        "status",
        r.quadrature.iter().map(|x| x.status.clone()).collect(),
    )?;
    Ok(vec![sbc, cov, sel, quad])
}
