//! `rfmlab simulate EXPERIMENT.toml`: the virtual experiment. Writes UFF58 (H1 and coherence,
//! labelled as simulated) and a `<output>.truth.json` sidecar stating the truth.

use super::common::{print_json, progress, spinner, Global};
use anyhow::Context;
use rfmlab::data::{FrfSet, Quantity};
use rfmlab::experiment::plant::{EnginePlant, ShakerSidePlant};
use rfmlab::experiment::{simulate_level, ChannelLabel};
use rfmlab::study::experiment::load_experiment;
use serde_json::json;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Experiment file (truth, structure and measurement chain).
    pub experiment: PathBuf,
    /// Write here instead of the file's `experiment.output`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print a JSON summary for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &SimulateArgs, g: &Global) -> anyhow::Result<()> {
    let ex = load_experiment(&a.experiment)?;
    let out = a.out.clone().unwrap_or_else(|| ex.output.clone());
    let file = ex.file.display().to_string();
    let sp = spinner(g, "assembling the FE model");
    let built = rfmlab::study::build::build_model(&ex.structure, &file)?;
    sp.finish_and_clear();
    let masses: Vec<(usize, f64)> = ex
        .sensors
        .iter()
        .map(|(id, m)| {
            (
                built
                    .model
                    .points
                    .iter()
                    .position(|p| p.id == *id)
                    .unwrap_or(usize::MAX),
                *m,
            )
        })
        .collect();
    // A compliant base: the joint with its base face free on springs (same mesh, same points).
    let base = match &ex.base_springs {
        None => built.model.clone(),
        Some(springs) => {
            let spec = rfmlab::study::build::joint_spec(&ex.structure)
                .context("base_springs needs the mesher's structure")?;
            let m = rfmlab::fe::base::joint_model_on_springs(
                &spec,
                springs,
                &format!("{file}: base_springs"),
            )?;
            if !g.quiet {
                eprintln!(
                    "base springs: k_n = {:.4e} N/m^3, k_t = {:.4e} N/m^3 under the adhesive ({} DOFs)",
                    springs.normal_n_m3,
                    springs.tangential_n_m3,
                    m.n_dof()
                );
            }
            m
        }
    };
    let mut model = if masses.is_empty() {
        base
    } else {
        base.with_point_masses(&masses)
            .map_err(anyhow::Error::msg)?
    };
    if let Some(((x0, x1), loss)) = ex.degraded_bond {
        let spec = rfmlab::study::build::joint_spec(&ex.structure)
            .context("degraded_bond needs the mesher's structure")?;
        let region_of = if ex.base_springs.is_some() {
            rfmlab::fe::region::adhesive_region_stiffness_free_base
        } else {
            rfmlab::fe::region::adhesive_region_stiffness
        };
        let region = region_of(&spec, x0, x1, &format!("{file}: degraded_bond.x_start"))?;
        model = model
            .with_degraded_region(&region.s_region, loss)
            .map_err(anyhow::Error::msg)?;
        if !g.quiet {
            eprintln!(
                "degraded bond: {} adhesive elements over x = [{:.4}, {:.4}] m at {:.1} % of the modulus",
                region.n_elements,
                region.x_range_m.0,
                region.x_range_m.1,
                100.0 * (1.0 - loss)
            );
        }
    }
    let sp = spinner(g, "preparing the FRF engine");
    let engine = super::engine::plant_engine(&model, built.excitation, &ex, g)?;
    sp.finish_and_clear();
    let exc = &model.points[built.excitation];
    let labels: Vec<ChannelLabel> = model
        .points
        .iter()
        .map(|p| ChannelLabel {
            response_id: p.id,
            response_dir: p.direction,
            reference_id: exc.id,
            reference_dir: exc.direction,
        })
        .collect();
    let pb = progress(g, ex.levels.len() as u64, "simulating levels");
    let mut set = FrfSet::default();
    let mut truths = Vec::new();
    for (k, lv) in ex.levels.iter().enumerate() {
        let law = rfmlab::material::model_from_name(&lv.law, lv.branches)?;
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
        let plant: &dyn rfmlab::experiment::Plant = match &shaker_plant {
            Some(p) => p,
            None => &engine_plant,
        };
        let mut chain = ex.chain.clone();
        chain.force_rms_n = lv.force_rms_n;
        chain.seed = ex.seed.wrapping_add(1000 * k as u64);
        chain.gains = ex.gains.clone();
        chain.delays_s = ex.delays_s.clone();
        let t = std::time::Instant::now();
        let sim = simulate_level(plant, &chain).with_context(|| format!("level {}", lv.name))?;
        let level = sim.to_frf_level(&lv.name, &labels)?;
        debug_assert_eq!(level.quantity, Quantity::Accelerance);
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
        pb.inc(1);
    }
    pb.finish_and_clear();
    if let Some(dir) = out.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    // One file per level keeps levels separate for studies: <stem>_<level>.uff.
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "simulated".into());
    let ext = out
        .extension()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "uff".into());
    let dir = out.parent().map(|p| p.to_path_buf()).unwrap_or_default();
    let mut written = Vec::new();
    for lv in &set.levels {
        let p = dir.join(format!("{stem}_{}.{ext}", lv.name));
        let one = FrfSet {
            levels: vec![lv.clone()],
        };
        let mut datasets = rfmlab::data::uff_frf::frf_set_datasets(&one);
        for d in &mut datasets {
            // ID line 2 says what these data are, so no reader mistakes them for a measurement.
            d.ids[1] = format!(
                "SIMULATED by rfmlab simulate ({}, seed {})",
                ex.name, ex.seed
            );
        }
        rfmlab::data::uff58::write_uff(&p, &datasets, ex.binary)?;
        written.push(p);
    }
    let sidecar = dir.join(format!("{stem}.truth.json"));
    let doc = json!({
        "simulated": true,
        "note": "SIMULATED DATA written by rfmlab simulate: not a measurement",
        "experiment_file": file,
        "experiment": ex.name,
        "description": ex.description,
        "mode": if ex.frequency_domain { "frequency" } else { "time" },
        "seed": ex.seed,
        "sensor_masses": ex.sensors.iter().map(|(id, m)| json!({"point": id, "mass_kg": m})).collect::<Vec<_>>(),
        "degraded_bond": ex.degraded_bond.map(|((x0, x1), loss)| json!({"x_start_m": x0, "x_end_m": x1, "loss": loss})),
        "base_springs": ex.base_springs.map(|b| json!({"normal_n_m3": b.normal_n_m3, "tangential_n_m3": b.tangential_n_m3, "compliance_m3_n": 1.0 / b.normal_n_m3})),
        "shaker_side_force": ex.shaker_side_force.map(|s| json!({"shaker_mass_kg": s.armature_mass_kg, "stinger_stiffness_n_m": s.stinger_stiffness_n_m})),
        "files": written.iter().map(|p| p.file_name().map(|f| f.to_string_lossy().into_owned())).collect::<Vec<_>>(),
        "levels": truths,
    });
    let bytes = serde_json::to_vec_pretty(&doc)?;
    rfmlab::output::write_atomic_bytes(&sidecar, &bytes)?;
    if a.json {
        return print_json(
            &json!({"files": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(), "truth": sidecar.display().to_string()}),
        );
    }
    if !g.quiet {
        for p in &written {
            println!("wrote {}", p.display());
        }
        println!("wrote {}", sidecar.display());
    }
    Ok(())
}
