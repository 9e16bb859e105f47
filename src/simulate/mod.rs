//! The virtual experiment of an experiment file (`rfmlab simulate EXPERIMENT.toml`, and
//! `rfmlab.simulate` in Python): the structure of the file with its sensor masses, compliant
//! base or degraded bond, driven through the measurement chain of [`crate::experiment`] at each
//! truth level. [`simulate`] returns the data in memory; [`Simulated::write`] writes UFF58 files
//! (H1 and coherence, labelled as simulated, one file per level) and a `<stem>.truth.json`
//! sidecar stating the truth.
//!
//! The plant's engine is the certified ROM over the band the chain evaluates (the band widened
//! by the estimator kernel's half-width, tolerance 1e-5 of each FRF's peak: two orders below
//! the 0.2 % sensor noise of a typical rig) or, with `experiment.engine = "full"`, the full
//! model.

use crate::common::C64;
use crate::data::{FrfSet, Quantity};
use crate::experiment::plant::{EnginePlant, ShakerSidePlant};
use crate::experiment::{simulate_level, ChannelLabel};
use crate::fe::StructuralModel;
use crate::frf::full::{FullModel, FullParams};
use crate::frf::FrfEngine;
use crate::rom::{build_rom, ModulusRange, RomParams};
use crate::study::experiment::Experiment;
use crate::study::StudyError;
use serde_json::json;

mod write;
pub use write::{is_simulated_file, planned_files};

/// Why a simulation failed.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// The experiment file (exit code 2 in the CLI).
    #[error(transparent)]
    Study(#[from] StudyError),
    /// Building the model or engine, simulating or writing failed.
    #[error("{0}")]
    Failed(String),
}

fn failed(what: &str, e: impl std::fmt::Display) -> SimulateError {
    SimulateError::Failed(format!("{what}: {e}"))
}

/// The simulated data of every truth level, with the truth.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// One level per truth level of the file (accelerance H1 with coherence).
    pub set: FrfSet,
    /// The sidecar document (`simulated`, `experiment`, `seed`, effects, `levels` with each
    /// level's law, parameters and the chain's truth); `files` is filled by [`Simulated::write`].
    pub truth: serde_json::Value,
    /// Sentences on the engine and the structural effects (what the CLI prints).
    pub notes: Vec<String>,
    name: String,
    seed: u64,
    binary: bool,
}

/// The smallest modulus box containing every E*(w) of `moduli`, widened by a factor 1.5 each way
/// (and at least 1 kPa of loss modulus).
pub fn modulus_box(moduli: &[C64]) -> ModulusRange {
    let (mut a, mut b, mut c, mut d) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for e in moduli {
        a = a.min(e.re);
        b = b.max(e.re);
        c = c.min(e.im);
        d = d.max(e.im);
    }
    ModulusRange {
        e_storage_pa: (a / 1.5, b * 1.5),
        e_loss_pa: ((c / 1.5).max(0.0), (d * 1.5).max(1e3)),
    }
}

/// The engine that drives a virtual experiment (all points as outputs, the drive point as
/// input): the certified ROM over the band the experiment evaluates, or the full model on
/// request. The note describes the ROM.
pub fn plant_engine(
    model: &StructuralModel,
    excitation: usize,
    ex: &Experiment,
) -> Result<(Box<dyn FrfEngine>, Option<String>), SimulateError> {
    if ex.use_full_model {
        let full = FullModel::new(model, &[excitation], FullParams::default())
            .map_err(|e| failed("full model", e))?;
        return Ok((Box::new(full), None));
    }
    let (f0, f1) = ex.chain.band_hz;
    let lo = (f0 - ex.chain.kernel.half_width_hz).max(0.25);
    let hi = f1 + ex.chain.kernel.half_width_hz + 1.0;
    let mut moduli = Vec::new();
    for lv in &ex.levels {
        let law = crate::material::model_from_name(&lv.law, lv.branches)
            .map_err(|e| failed(&format!("level {}", lv.name), e))?;
        for k in 0..=200 {
            let f = lo + (hi - lo) * k as f64 / 200.0;
            moduli.push(law.modulus(&lv.params, 2.0 * std::f64::consts::PI * f));
        }
    }
    let params = RomParams {
        band_hz: (lo, hi),
        range: modulus_box(&moduli),
        tolerance: 1e-5,
        ..RomParams::default()
    };
    let (rom, cert) = build_rom(model, &[excitation], &params).map_err(|e| failed("ROM", e))?;
    let note = format!(
        "ROM: {} basis vectors, certified error {:.2e} (tolerance {:.0e}) over {:.1}-{:.1} Hz, E' {:.2}-{:.2} MPa, E'' {:.3}-{:.3} MPa",
        cert.basis_size,
        cert.max_rel_error,
        params.tolerance,
        lo,
        hi,
        params.range.e_storage_pa.0 / 1e6,
        params.range.e_storage_pa.1 / 1e6,
        params.range.e_loss_pa.0 / 1e6,
        params.range.e_loss_pa.1 / 1e6
    );
    Ok((Box::new(rom), Some(note)))
}

/// Simulate every truth level of `ex`; `progress` is called once per finished level.
pub fn simulate(ex: &Experiment, progress: &dyn Fn()) -> Result<Simulated, SimulateError> {
    let file = ex.file.display().to_string();
    let mut notes = Vec::new();
    let built = crate::study::build::build_model(&ex.structure, &file)?;
    let mesher = |what: &str| {
        crate::study::build::joint_spec(&ex.structure).ok_or_else(|| {
            SimulateError::Study(StudyError {
                file: file.clone(),
                key: what.into(),
                message: format!(
                    "{what} needs the mesher's structure (structure.source = \"mesher\")"
                ),
            })
        })
    };
    // A compliant base: the joint with its base face free on springs (same mesh, same points).
    let base = match &ex.base_springs {
        None => built.model.clone(),
        Some(springs) => {
            let spec = mesher("base_springs")?;
            let m = crate::fe::base::joint_model_on_springs(
                &spec,
                springs,
                &format!("{file}: base_springs"),
            )
            .map_err(|e| failed("base springs", e))?;
            notes.push(format!(
                "base springs: k_n = {:.4e} N/m^3, k_t = {:.4e} N/m^3 under the adhesive ({} DOFs)",
                springs.normal_n_m3,
                springs.tangential_n_m3,
                m.n_dof()
            ));
            m
        }
    };
    let mut model = crate::study::build::with_sensor_masses_on(
        &base,
        &ex.structure,
        &ex.sensors,
        ex.base_springs.as_ref(),
        &file,
    )?;
    if let Some(((x0, x1), loss)) = ex.degraded_bond {
        let spec = mesher("degraded_bond")?;
        let region_of = if ex.base_springs.is_some() {
            crate::fe::region::adhesive_region_stiffness_free_base
        } else {
            crate::fe::region::adhesive_region_stiffness
        };
        let region = region_of(&spec, x0, x1, &format!("{file}: degraded_bond.x_start"))
            .map_err(|e| failed("degraded bond", e))?;
        model = model
            .with_degraded_region(&region.s_region, loss)
            .map_err(|e| failed("degraded bond", e))?;
        notes.push(format!(
            "degraded bond: {} adhesive elements over x = [{:.4}, {:.4}] m at {:.1} % of the modulus",
            region.n_elements,
            region.x_range_m.0,
            region.x_range_m.1,
            100.0 * (1.0 - loss)
        ));
    }
    // A resonator (after the edits above, which act on the joint's own DOFs): one more DOF, its
    // mass, on a spring to the point. The force is read at the structure, so the resonator is
    // part of the structure the data see.
    for (i, &(id, mass, stiffness)) in ex.resonators.iter().enumerate() {
        let at = model
            .points
            .iter()
            .position(|p| p.id == id)
            .unwrap_or(usize::MAX);
        let (with, _) = model
            .with_shaker(at, mass, stiffness, u32::MAX - i as u32)
            .map_err(|e| failed("resonators", e))?;
        model = with;
        // The resonator's own DOF is no measured point.
        model.points.pop();
        notes.push(format!(
            "resonator at point {id}: {:.4e} kg on {:.4e} N/m ({:.2} Hz)",
            mass,
            stiffness,
            (stiffness / mass).sqrt() / std::f64::consts::TAU
        ));
    }
    let (engine, engine_note) = plant_engine(&model, built.excitation, ex)?;
    notes.extend(engine_note);
    let exc = &model.points[built.excitation];
    let labels = ChannelLabel::for_responses(
        model.points.iter().map(|p| (p.id, p.direction)),
        (exc.id, exc.direction),
    );
    let mut set = FrfSet::default();
    let mut truths = Vec::new();
    for (k, lv) in ex.levels.iter().enumerate() {
        let at = |e: &dyn std::fmt::Display| failed(&format!("level {}", lv.name), e);
        let law = crate::material::model_from_name(&lv.law, lv.branches).map_err(|e| at(&e))?;
        let modulus = |w: f64| law.modulus(&lv.params, w);
        let engine_plant = EnginePlant {
            engine: engine.as_ref(),
            modulus: &modulus,
            input_col: 0,
            drive_output: built.excitation,
        };
        let shaker_plant = ex.shaker_side_force.map(|shaker| ShakerSidePlant {
            inner: &engine_plant,
            shaker,
        });
        let plant: &dyn crate::experiment::Plant = match &shaker_plant {
            Some(p) => p,
            None => &engine_plant,
        };
        let mut chain = ex.chain.clone();
        chain.force_rms_n = lv.force_rms_n;
        chain.seed = ex.seed.wrapping_add(1000 * k as u64);
        chain.gains = ex.gains.clone();
        chain.delays_s = ex.delays_s.clone();
        let t = std::time::Instant::now();
        let sim = simulate_level(plant, &chain).map_err(|e| at(&e))?;
        let level = sim.to_frf_level(&lv.name, &labels).map_err(|e| at(&e))?;
        assert_eq!(level.quantity, Quantity::Accelerance);
        let mut tj = sim.truth.to_json();
        if let Some(o) = tj.as_object_mut() {
            o.insert("level".into(), json!(lv.name));
            o.insert("law".into(), json!(lv.law));
            let params: serde_json::Map<String, serde_json::Value> = lv
                .param_names
                .iter()
                .zip(&lv.params)
                .map(|(n, v)| (n.clone(), json!(v)))
                .collect();
            o.insert("params".into(), serde_json::Value::Object(params));
            o.insert("seconds".into(), json!(t.elapsed().as_secs_f64()));
        }
        truths.push(tj);
        set.levels.push(level);
        progress();
    }
    let truth = json!({
        "simulated": true,
        "note": "SIMULATED DATA written by rfmlab simulate: not a measurement",
        "experiment_file": file,
        "experiment": ex.name,
        "description": ex.description,
        "mode": if ex.frequency_domain { "frequency" } else { "time" },
        "seed": ex.seed,
        "sensor_masses": ex.sensors.iter().map(|s| json!({"point": s.point, "mass_kg": s.mass_kg, "directions": if s.all_directions { "xyz" } else { "measured" }})).collect::<Vec<_>>(),
        "resonators": ex.resonators.iter().map(|(id, m, k)| json!({"point": id, "mass_kg": m, "stiffness_n_m": k})).collect::<Vec<_>>(),
        "degraded_bond": ex.degraded_bond.map(|((x0, x1), loss)| json!({"x_start_m": x0, "x_end_m": x1, "loss": loss})),
        "base_springs": ex.base_springs.map(|b| json!({"normal_n_m3": b.normal_n_m3, "tangential_n_m3": b.tangential_n_m3, "compliance_m3_n": 1.0 / b.normal_n_m3})),
        "shaker_side_force": ex.shaker_side_force.map(|s| json!({"shaker_mass_kg": s.armature_mass_kg, "stinger_stiffness_n_m": s.stinger_stiffness_n_m})),
        "files": serde_json::Value::Null,
        "levels": truths,
    });
    Ok(Simulated {
        set,
        truth,
        notes,
        name: ex.name.clone(),
        seed: ex.seed,
        binary: ex.binary,
    })
}
