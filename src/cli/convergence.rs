//! `rfmlab convergence STUDY.toml [--sizes 0.01,0.005,0.0025] [--json]`: the paper's Table 1.

use super::common::{
    load_study, parse_modulus, print_json, progress, Global, InputError, DEFAULT_MODULUS,
};
use rfmlab::modes::{complex_modes, ModesParams};
use rfmlab::rom::{build_basis_only, ModulusRange, RomParams};
use rfmlab::study::{MeshSize, StructureSource};
use serde_json::json;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ConvergenceArgs {
    /// Study file (its [structure] section is used; the mesh size is replaced).
    pub study: PathBuf,
    /// Element sizes in metres, comma separated.
    #[arg(long, default_value = "0.01,0.005,0.0025")]
    pub sizes: String,
    /// Adhesive modulus E',E'' in Pa (default 6.974e6,1.4827e6).
    #[arg(long)]
    pub modulus: Option<String>,
    /// Number of complex modes to compute per mesh (the first two y-dominant ones are reported).
    #[arg(long, default_value_t = 8)]
    pub count: usize,
    /// How to compute the modes: "full" (shift-invert Lanczos and Rayleigh-quotient refinement
    /// with a complex sparse LU per step: exact, but about 3 GB and minutes per LU at 67k
    /// DOFs), "rom" (complex modes of a Krylov basis of the measured points' loads at this
    /// modulus: one real Cholesky per reference modulus; the modes the points see), or "auto"
    /// (full below 20 000 DOFs, rom above).
    #[arg(long, default_value = "auto")]
    pub method: String,
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &ConvergenceArgs, g: &Global) -> anyhow::Result<()> {
    let e = match &a.modulus {
        Some(s) => parse_modulus(s)?,
        None => DEFAULT_MODULUS,
    };
    let sizes: Vec<f64> = a
        .sizes
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            InputError(format!(
                "--sizes {:?}: give element sizes in metres, e.g. 0.01,0.005,0.0025",
                a.sizes
            ))
        })?;
    if sizes.is_empty() || sizes.iter().any(|h| h.is_nan() || *h <= 0.0) {
        return Err(
            InputError(format!("--sizes {:?}: sizes must be positive (m)", a.sizes)).into(),
        );
    }
    let study = load_study(&a.study)?;
    let pb = progress(g, sizes.len() as u64, "mesh convergence");
    let mut rows = Vec::new();
    for &h in &sizes {
        let mut s = study.structure.clone();
        match &mut s.source {
            // each size as given: the comparison is the user's, not the refinement's
            StructureSource::Mesher(j) => {
                j.mesh = MeshSize::ElementSize(h);
                j.mesh_rule.refine = false;
                j.mesh_rule.allowance = false;
            }
            StructureSource::Lap(l, rule) => {
                l.mesh.element_size_m = h;
                rule.refine = false;
                rule.allowance = false;
            }
            StructureSource::MatrixMarket(_) => {
                return Err(InputError(
                    "convergence needs a meshed structure (structure.source = \"mesher\")".into(),
                )
                .into())
            }
        }
        let t = std::time::Instant::now();
        let b = rfmlab::study::build::build_model(&s, &study.file.display().to_string())?;
        let t_asm = t.elapsed().as_secs_f64();
        let use_rom = match a.method.as_str() {
            "full" => false,
            "rom" => true,
            "auto" => b.model.n_dof() > 20_000,
            o => {
                return Err(InputError(format!(
                    "--method {o:?}: use \"full\", \"rom\" or \"auto\""
                ))
                .into())
            }
        };
        // (freq_hz, loss_factor) of the first two y-dominant modes
        let y: Vec<(f64, f64)> = if use_rom {
            let inputs: Vec<usize> = (0..b.model.points.len()).collect();
            let params = RomParams {
                range: ModulusRange {
                    e_storage_pa: (e.re, e.re),
                    e_loss_pa: (e.im, e.im),
                },
                krylov_depth_initial: 6,
                ..RomParams::default()
            };
            let rom = build_basis_only(&b.model, &inputs, &params, b.dof_axes.as_deref())?;
            let modes = rom.complex_modes(e, a.count)?;
            let threshold = ModesParams::default().y_dominant_threshold;
            modes
                .iter()
                .filter(|m| m.energy_fraction_xyz.is_some_and(|f| f[1] > threshold))
                .take(2)
                .map(|m| (m.freq_hz(), m.loss_factor()))
                .collect()
        } else {
            complex_modes(
                &b.model,
                e,
                a.count,
                b.dof_axes.as_deref(),
                &ModesParams::default(),
            )?
            .iter()
            .filter(|m| m.y_dominant == Some(true))
            .take(2)
            .map(|m| (m.freq_hz, m.loss_factor))
            .collect()
        };
        let secs = t.elapsed().as_secs_f64();
        let info = b.mesh.as_ref();
        rows.push(json!({
            "element_size_m": h,
            "elements": info.map(|i| i.n_elements),
            "dofs": b.model.n_dof(),
            "method": if use_rom { "rom" } else { "full" },
            "y_mode1_freq_hz": y.first().map(|m| m.0),
            "y_mode1_loss_factor": y.first().map(|m| m.1),
            "y_mode2_freq_hz": y.get(1).map(|m| m.0),
            "y_mode2_loss_factor": y.get(1).map(|m| m.1),
            "assembly_seconds": t_asm,
            "seconds": secs,
        }));
        pb.inc(1);
    }
    pb.finish_and_clear();
    if a.json {
        return print_json(&json!({"modulus_pa": [e.re, e.im], "meshes": rows}));
    }
    println!(
        "Mesh convergence at E* = {:.4} + {:.4} j MPa (first two y-dominant modes)",
        e.re / 1e6,
        e.im / 1e6
    );
    println!(
        "{:>8} {:>9} {:>8} {:>11} {:>8} {:>11} {:>8} {:>8} {:>6}",
        "size_mm", "elements", "dofs", "f1_hz", "eta1", "f2_hz", "eta2", "time_s", "method"
    );
    for r in &rows {
        let f = |k: &str| {
            r[k].as_f64()
                .map(|v| format!("{v:.3}"))
                .unwrap_or("-".into())
        };
        let f5 = |k: &str| {
            r[k].as_f64()
                .map(|v| format!("{v:.4}"))
                .unwrap_or("-".into())
        };
        println!(
            "{:>8.2} {:>9} {:>8} {:>11} {:>8} {:>11} {:>8} {:>8.1} {:>6}",
            r["element_size_m"].as_f64().unwrap_or(0.0) * 1e3,
            r["elements"]
                .as_u64()
                .map(|v| v.to_string())
                .unwrap_or("-".into()),
            r["dofs"],
            f("y_mode1_freq_hz"),
            f5("y_mode1_loss_factor"),
            f("y_mode2_freq_hz"),
            f5("y_mode2_loss_factor"),
            r["seconds"].as_f64().unwrap_or(0.0),
            r["method"].as_str().unwrap_or("")
        );
    }
    Ok(())
}
