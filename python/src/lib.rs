//! `rfmlab._rfmlab`: the native half of the `rfmlab` Python package. The pure-Python layer
//! (`python/rfmlab/`) turns what these functions return (parquet bytes, columns, plain lists)
//! into polars frames, numpy arrays and ArviZ InferenceData.
//!
//! Long calls (a run, a design, building a posterior's engine, a simulation) release the GIL.
//! Errors become the package's exceptions (`rfmlab.StudyError` with `file`, `key` and
//! `message`, `rfmlab.DataError`, `rfmlab.RunError`), built by `rfmlab._errors`.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rfmlab::data::FrfSet;
use rfmlab::diagnose::prepared::Prepared;
use rfmlab::inference::likelihood::FrfPosterior;
use rfmlab::inference::{DensityError, Posterior as _};
use rfmlab::stage::RunError;
use rfmlab::study::StudyError;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

mod design;
mod run;

/// An instance of the exception class `class` of `rfmlab._errors` made with `args`; if the
/// module cannot be imported, the import error.
fn error<'py, A>(py: Python<'py>, class: &str, args: A) -> PyErr
where
    A: pyo3::call::PyCallArgs<'py>,
{
    match py
        .import("rfmlab._errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1(args))
    {
        Ok(v) => PyErr::from_value(v),
        Err(e) => e,
    }
}

fn study_error(py: Python<'_>, e: &StudyError) -> PyErr {
    error(
        py,
        "StudyError",
        (e.file.clone(), e.key.clone(), e.message.clone()),
    )
}

/// A run error as the package's exception: study errors name the file and key, data errors
/// the file, dataset and line; everything else is a `RunError`.
fn run_error(py: Python<'_>, e: &RunError) -> PyErr {
    match e {
        RunError::Study(s) => study_error(py, s),
        RunError::Data(d) => error(
            py,
            "DataError",
            (d.file.clone(), d.dataset, d.line, d.message.clone()),
        ),
        e => error(py, "RunError", (e.to_string(),)),
    }
}

/// Columns of an FRF set in long form: one row per level, channel and line.
fn frf_columns<'py>(py: Python<'py>, set: &FrfSet) -> PyResult<Bound<'py, PyDict>> {
    let mut level = Vec::new();
    let mut quantity = Vec::new();
    let mut rid = Vec::new();
    let mut rdir = Vec::new();
    let mut fid = Vec::new();
    let mut fdir = Vec::new();
    let mut freq = Vec::new();
    let mut re = Vec::new();
    let mut im = Vec::new();
    let mut coh = Vec::new();
    for lv in &set.levels {
        let q = format!("{:?}", lv.quantity).to_lowercase();
        for ch in &lv.channels {
            for (l, f) in lv.freq_hz.iter().enumerate() {
                level.push(lv.name.clone());
                quantity.push(q.clone());
                rid.push(ch.response_id);
                rdir.push(ch.response_dir.to_string());
                fid.push(ch.reference_id);
                fdir.push(ch.reference_dir.to_string());
                freq.push(*f);
                re.push(ch.values[l].re);
                im.push(ch.values[l].im);
                coh.push(ch.coherence.as_ref().map(|c| c[l]));
            }
        }
    }
    let d = PyDict::new(py);
    d.set_item("level", level)?;
    d.set_item("quantity", quantity)?;
    d.set_item("response_id", rid)?;
    d.set_item("response_dir", rdir)?;
    d.set_item("reference_id", fid)?;
    d.set_item("reference_dir", fdir)?;
    d.set_item("freq_hz", freq)?;
    d.set_item("re", re)?;
    d.set_item("im", im)?;
    d.set_item("coherence", coh)?;
    Ok(d)
}

/// Read a UFF58 file (FRFs and coherences): columns in long form, and per level its RMS force
/// and number of averages when the file states them.
#[pyfunction]
fn read_uff<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyTuple>> {
    let files = [(path, String::new())];
    let opts = rfmlab::data::UffImportOptions::default();
    let set = py
        .detach(|| rfmlab::data::frf_set_from_uff(&files, &opts))
        .map_err(|d| {
            error(
                py,
                "DataError",
                (d.file.clone(), d.dataset, d.line, d.message.clone()),
            )
        })?;
    let meta = PyDict::new(py);
    for lv in &set.levels {
        meta.set_item(&lv.name, (lv.force_rms_n, lv.n_averages))?;
    }
    (frf_columns(py, &set)?, meta).into_pyobject(py)
}

/// Simulate the virtual experiment of an experiment file: columns of the simulated FRFs (long
/// form), the truth (JSON text) and the files written (when `out` is given).
#[pyfunction]
#[pyo3(signature = (experiment, out=None))]
fn simulate<'py>(
    py: Python<'py>,
    experiment: PathBuf,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyTuple>> {
    use rfmlab::simulate::SimulateError;
    let result = py.detach(|| -> Result<_, SimulateError> {
        let ex = rfmlab::study::experiment::load_experiment(&experiment)?;
        let sim = rfmlab::simulate::simulate(&ex, &|| ())?;
        let files = match &out {
            Some(o) => {
                let (mut w, s) = sim.write(o)?;
                w.push(s);
                w
            }
            None => Vec::new(),
        };
        Ok((sim, files))
    });
    let (sim, files) = result.map_err(|e| match e {
        SimulateError::Study(s) => study_error(py, &s),
        e => error(py, "RunError", (e.to_string(),)),
    })?;
    let mut truth = sim.truth.clone();
    if let Some(o) = truth.as_object_mut() {
        o.insert("notes".into(), serde_json::json!(sim.notes));
    }
    let files: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
    (frf_columns(py, &sim.set)?, truth.to_string(), files).into_pyobject(py)
}

/// E*(w) = E'(w) + j E''(w) (Pa) of a constitutive law at `freq_hz`: (storage, loss).
#[pyfunction]
#[pyo3(signature = (model, params, freq_hz, branches=None))]
fn modulus(
    py: Python<'_>,
    model: &str,
    params: Vec<f64>,
    freq_hz: Vec<f64>,
    branches: Option<usize>,
) -> PyResult<(Vec<f64>, Vec<f64>)> {
    let law = rfmlab::material::model_from_name(model, branches)
        .map_err(|e| error(py, "RunError", (e.to_string(),)))?;
    if params.len() != law.n_params() {
        return Err(error(
            py,
            "RunError",
            (format!(
                "{model} has {} parameters {:?}; {} given",
                law.n_params(),
                law.param_names(),
                params.len()
            ),),
        ));
    }
    let e: Vec<_> = freq_hz
        .iter()
        .map(|f| law.modulus(&params, 2.0 * std::f64::consts::PI * f))
        .collect();
    Ok((
        e.iter().map(|z| z.re).collect(),
        e.iter().map(|z| z.im).collect(),
    ))
}

/// Parameter names and SI units of a constitutive law.
#[pyfunction]
#[pyo3(signature = (model, branches=None))]
fn law_parameters(
    py: Python<'_>,
    model: &str,
    branches: Option<usize>,
) -> PyResult<(Vec<String>, Vec<String>)> {
    let law = rfmlab::material::model_from_name(model, branches)
        .map_err(|e| error(py, "RunError", (e.to_string(),)))?;
    Ok((law.param_names(), law.param_units()))
}

/// A validated study file.
#[pyclass(frozen, module = "rfmlab._rfmlab")]
struct Study {
    study: rfmlab::study::Study,
    /// Built on the first posterior asked for and kept: the model, data and engines.
    prepared: Mutex<Option<Arc<Prepared>>>,
}

/// Load and validate a study file.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<Study> {
    let study = py
        .detach(|| rfmlab::study::load(&path))
        .map_err(|e| study_error(py, &e))?;
    Ok(Study {
        study,
        prepared: Mutex::new(None),
    })
}

#[pymethods]
impl Study {
    #[getter]
    fn name(&self) -> String {
        self.study.name.clone()
    }
    #[getter]
    fn description(&self) -> String {
        self.study.description.clone()
    }
    #[getter]
    fn file(&self) -> PathBuf {
        self.study.file.clone()
    }
    #[getter]
    fn output_dir(&self) -> PathBuf {
        self.study.output_dir.clone()
    }
    #[getter]
    fn seed(&self) -> u64 {
        self.study.seed
    }
    /// The models of the study (`[[models]]`), by name.
    #[getter]
    fn models(&self) -> Vec<String> {
        self.study.models.iter().map(|m| m.name.clone()).collect()
    }
    /// The measurement levels (`[[measurements.levels]]`), by name.
    #[getter]
    fn levels(&self) -> Vec<String> {
        self.study
            .measurements
            .as_ref()
            .map(|m| m.levels.iter().map(|l| l.name.clone()).collect())
            .unwrap_or_default()
    }
    /// `[inference]` models and levels, when the study has the section.
    #[getter]
    fn inference(&self) -> Option<(Vec<String>, Vec<String>)> {
        self.study
            .inference
            .as_ref()
            .map(|i| (i.models.clone(), i.levels.clone()))
    }
    /// The folder of certified ROMs reused across runs (`.rom-cache/` beside the output folder).
    #[getter]
    fn rom_cache_dir(&self) -> PathBuf {
        rfmlab::stage::rom_cache_dir(&self.study.output_dir)
    }

    /// Check the study without running it (data, channels, band, initial values): a dict.
    fn check(&self, py: Python<'_>) -> PyResult<String> {
        let s = py
            .detach(|| rfmlab::pipeline::check_study(&self.study))
            .map_err(|e| run_error(py, &e))?;
        serde_json::to_string(&s).map_err(|e| error(py, "RunError", (e.to_string(),)))
    }

    /// Run the study (see `run.rs`): table names, parquet bytes per table, files written.
    #[pyo3(signature = (output=None, callback=None, figures=true, rom_cache=true, closed_loop=None))]
    fn _run<'py>(
        &self,
        py: Python<'py>,
        output: Option<PathBuf>,
        callback: Option<Py<PyAny>>,
        figures: bool,
        rom_cache: bool,
        closed_loop: Option<bool>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let args = run::RunArgs {
            output,
            figures,
            rom_cache,
            closed_loop,
        };
        run::run(py, &self.study, args, callback)
    }

    /// Plan the test (see `design.rs`, as `rfmlab design`): a dict with the best and the
    /// study's own design, the design tables as parquet bytes, the notes and the report.
    #[pyo3(signature = (output=None, sensors=None, force=false, callback=None))]
    fn _design<'py>(
        &self,
        py: Python<'py>,
        output: Option<PathBuf>,
        sensors: Option<usize>,
        force: bool,
        callback: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let args = design::DesignArgs {
            output,
            sensors,
            force,
        };
        design::design(py, &self.study, args, callback)
    }

    /// The closed loop on the study (as `rfmlab diagnose`): its summary as JSON text.
    #[pyo3(signature = (model=None, threshold_nats=None, output=None, figures=false, callback=None))]
    fn _diagnose(
        &self,
        py: Python<'_>,
        model: Option<String>,
        threshold_nats: Option<f64>,
        output: Option<PathBuf>,
        figures: bool,
        callback: Option<Py<PyAny>>,
    ) -> PyResult<String> {
        if let Some(t) = threshold_nats {
            if !(t.is_finite() && t >= 0.0) {
                return Err(error(
                    py,
                    "StudyError",
                    (
                        self.study.file.display().to_string(),
                        "closed_loop.evidence_threshold".to_string(),
                        format!(
                            "threshold_nats {t} must be a non-negative number of nats (default 5)"
                        ),
                    ),
                ));
            }
        }
        run::diagnose(
            py,
            &self.study,
            model,
            threshold_nats,
            output,
            figures,
            callback,
        )
    }

    /// The posterior of `model` at `level`; with `at` (physical values of every coordinate,
    /// e.g. the MAP) the measurement bias is linearised there as the run's samplers see it.
    #[pyo3(signature = (model, level, at=None, rom_cache=true))]
    fn _posterior(
        &self,
        py: Python<'_>,
        model: String,
        level: String,
        at: Option<Vec<f64>>,
        rom_cache: bool,
    ) -> PyResult<Posterior> {
        let prepared = {
            let cached = self
                .prepared
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clone();
            match cached {
                Some(p) => p,
                None => {
                    let cache =
                        rom_cache.then(|| rfmlab::stage::rom_cache_dir(&self.study.output_dir));
                    let p = py
                        .detach(|| Prepared::new(&self.study, cache.as_deref()))
                        .map_err(|e| run_error(py, &e))?;
                    let p = Arc::new(p);
                    *self.prepared.lock().unwrap_or_else(|e| e.into_inner()) = Some(p.clone());
                    p
                }
            }
        };
        let cell = py
            .detach(|| PostCell::try_new(prepared, |p| p.posterior(&model, &level, at.as_deref())))
            .map_err(|e| run_error(py, &e))?;
        Ok(Posterior { cell, model, level })
    }
}

type FrfPost<'a> = FrfPosterior<'a>;

self_cell::self_cell!(
    /// A posterior with the prepared study it borrows its engine from.
    struct PostCell {
        owner: Arc<Prepared>,
        #[not_covariant]
        dependent: FrfPost,
    }
);

/// A study's posterior over unconstrained coordinates (see `rfmlab.Posterior`).
#[pyclass(frozen, module = "rfmlab._rfmlab")]
struct Posterior {
    cell: PostCell,
    model: String,
    level: String,
}

impl Posterior {
    fn check_dim(&self, py: Python<'_>, x: &[f64]) -> PyResult<()> {
        let d = self.cell.with_dependent(|_, p| p.dim());
        if x.len() != d {
            return Err(error(
                py,
                "RunError",
                (format!(
                    "x has {} values; the posterior of {} at {} has {d} coordinates",
                    x.len(),
                    self.model,
                    self.level
                ),),
            ));
        }
        Ok(())
    }
}

/// A density error: recoverable ones (outside the admissible range) give -inf, fatal ones raise.
fn density(py: Python<'_>, r: Result<f64, DensityError>, bad: f64) -> PyResult<f64> {
    match r {
        // A NaN (coordinates that are not numbers, an overflow) is a point the density
        // cannot be evaluated at, like a recoverable failure.
        Ok(v) if v.is_nan() => Ok(bad),
        Ok(v) => Ok(v),
        Err(DensityError::Recoverable(_)) => Ok(bad),
        Err(DensityError::Fatal(m)) => Err(error(py, "RunError", (m,))),
    }
}

#[pymethods]
impl Posterior {
    #[getter]
    fn model(&self) -> String {
        self.model.clone()
    }
    #[getter]
    fn level(&self) -> String {
        self.level.clone()
    }
    #[getter]
    fn dim(&self) -> usize {
        self.cell.with_dependent(|_, p| p.dim())
    }
    /// Coordinate names: the law's parameters, then declared free effects, then noise.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.cell.with_dependent(|_, p| p.names())
    }
    /// Number of law (and free effect) parameters, before the noise coordinates.
    #[getter]
    fn n_law(&self) -> usize {
        self.cell.with_dependent(|_, p| p.n_law())
    }
    /// Per coordinate: (family, Debug form of the prior with its bounds or moments).
    #[getter]
    fn priors(&self) -> Vec<(String, String)> {
        self.cell.with_dependent(|_, p| {
            p.priors
                .iter()
                .map(|pr| (pr.family().to_string(), format!("{pr:?}")))
                .collect()
        })
    }
    /// Whether the H1 measurement bias is linearised (at the point given when building).
    #[getter]
    fn linearised(&self) -> bool {
        self.cell
            .with_dependent(|_, p| p.likelihood.forward.linear_bias.is_some())
    }
    /// Log posterior density (up to log Z); -inf where the point cannot be evaluated.
    fn logp(&self, py: Python<'_>, x: Vec<f64>) -> PyResult<f64> {
        self.check_dim(py, &x)?;
        let r = self.cell.with_dependent(|_, p| p.log_posterior(&x, None));
        density(py, r, f64::NEG_INFINITY)
    }
    /// Log posterior density and its gradient in the unconstrained coordinates.
    fn logp_and_grad(&self, py: Python<'_>, x: Vec<f64>) -> PyResult<(f64, Vec<f64>)> {
        self.check_dim(py, &x)?;
        let mut g = vec![0.0; x.len()];
        let r = self
            .cell
            .with_dependent(|_, p| p.log_posterior(&x, Some(&mut g)));
        let v = density(py, r, f64::NEG_INFINITY)?;
        if v == f64::NEG_INFINITY {
            g.iter_mut().for_each(|v| *v = f64::NAN);
        }
        Ok((v, g))
    }
    /// Log prior density in the unconstrained coordinates (transform's log-Jacobian included).
    fn log_prior(&self, py: Python<'_>, x: Vec<f64>) -> PyResult<f64> {
        self.check_dim(py, &x)?;
        Ok(self.cell.with_dependent(|_, p| p.log_prior(&x, None)))
    }
    /// Log likelihood of the level's data; -inf where it cannot be evaluated.
    fn log_likelihood(&self, py: Python<'_>, x: Vec<f64>) -> PyResult<f64> {
        self.check_dim(py, &x)?;
        let r = self.cell.with_dependent(|_, p| p.log_likelihood(&x, None));
        density(py, r, f64::NEG_INFINITY)
    }
    /// `ln |det dp/dx|` of the transform.
    fn log_jacobian(&self, py: Python<'_>, x: Vec<f64>) -> PyResult<f64> {
        self.check_dim(py, &x)?;
        Ok(self.cell.with_dependent(|_, p| p.log_jacobian(&x, None)))
    }
    /// Physical values (SI) of unconstrained coordinates.
    fn to_constrained(&self, py: Python<'_>, x: Vec<f64>) -> PyResult<Vec<f64>> {
        self.check_dim(py, &x)?;
        Ok(self.cell.with_dependent(|_, p| p.constrained(&x)))
    }
    /// Unconstrained coordinates of physical values (SI).
    fn to_unconstrained(&self, py: Python<'_>, p: Vec<f64>) -> PyResult<Vec<f64>> {
        self.check_dim(py, &p)?;
        Ok(self.cell.with_dependent(|_, post| post.unconstrained(&p)))
    }
    /// Log likelihood per frequency line (summed over channels) at physical values `p`.
    fn pointwise(&self, py: Python<'_>, p: Vec<f64>) -> PyResult<Vec<f64>> {
        self.check_dim(py, &p)?;
        self.cell
            .with_dependent(|_, post| {
                let nl = post.n_law();
                post.likelihood.pointwise(&p[..nl], &p[nl..])
            })
            .map_err(|e| error(py, "RunError", (e.to_string(),)))
    }
    /// `n` draws from the prior (unconstrained coordinates), reproducible by `seed`.
    #[pyo3(signature = (n, seed=0))]
    fn sample_prior(&self, n: usize, seed: u64) -> Vec<Vec<f64>> {
        self.cell.with_dependent(|_, p| {
            (0..n)
                .map(|i| p.sample_prior(&mut rfmlab::inference::unit_rng(seed, i as u64)))
                .collect()
        })
    }
    /// The level's lines (Hz) the likelihood uses.
    #[getter]
    fn freq_hz(&self) -> Vec<f64> {
        self.cell
            .with_dependent(|_, p| p.likelihood.data.freq_hz.clone())
    }
}

#[pymodule]
fn _rfmlab(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(read_uff, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(modulus, m)?)?;
    m.add_function(wrap_pyfunction!(law_parameters, m)?)?;
    m.add_class::<Study>()?;
    m.add_class::<Posterior>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
