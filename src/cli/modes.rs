//! `rfmlab modes STUDY.toml [--modulus E',E''] [--count N] [--json]`

use super::common::InputError;
use super::common::{
    build_model, load_study, parse_modulus, print_json, spinner, Global, DEFAULT_MODULUS,
};
use rfmlab::fe::cost::{available_memory_bytes, check_memory, format_bytes};
use rfmlab::modes::{complex_modes, complex_modes_memory, ModesParams};
use serde_json::json;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ModesArgs {
    /// Study file (its [structure] section is used).
    pub study: PathBuf,
    /// Adhesive modulus E',E'' in Pa (default: the paper's IEM value for Level 1 mode 1, 6.974e6,1.4827e6).
    #[arg(long)]
    pub modulus: Option<String>,
    /// Number of modes.
    #[arg(long, default_value_t = 8)]
    pub count: usize,
    /// Convergence tolerance of each complex mode: relative residual
    /// ||(K - lambda M) phi|| / ||K phi|| (a mode whose backward error is at the rounding
    /// level is accepted as well).
    #[arg(long, default_value_t = ModesParams::default().tol)]
    pub tol: f64,
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &ModesArgs, g: &Global) -> anyhow::Result<()> {
    let e = match &a.modulus {
        Some(s) => parse_modulus(s)?,
        None => DEFAULT_MODULUS,
    };
    if !(a.tol > 0.0 && a.tol < 1.0) {
        return Err(InputError(format!(
            "--tol {}: give a relative residual between 0 and 1, e.g. 1e-6",
            a.tol
        ))
        .into());
    }
    if a.count == 0 {
        return Err(InputError("--count 0: ask for at least one mode".into()).into());
    }
    let params = ModesParams {
        tol: a.tol,
        ..ModesParams::default()
    };
    let study = load_study(&a.study)?;
    // the size first, from the mesh divisions: nothing large is allocated before the checks
    if let Some(spec) = rfmlab::study::build::joint_spec(&study.structure) {
        let cost = rfmlab::fe::joint::joint_cost_estimate(&spec)
            .map_err(|e| InputError(format!("{}: {e}", study.file.display())))?;
        check_count(a.count, cost.n_dof, &params)?;
    }
    let b = build_model(g, &study)?;
    check_count(a.count, b.model.n_dof(), &params)?;
    let sp = spinner(g, "complex modes");
    let t = std::time::Instant::now();
    let modes = complex_modes(&b.model, e, a.count, b.dof_axes.as_deref(), &params)?;
    let secs = t.elapsed().as_secs_f64();
    sp.finish_and_clear();
    if a.json {
        let list: Vec<_> = modes
            .iter()
            .enumerate()
            .map(|(k, m)| {
                json!({
                    "mode": k + 1,
                    "freq_hz": m.freq_hz,
                    "loss_factor": m.loss_factor,
                    "lambda": [m.lambda.re, m.lambda.im],
                    "phi_s_phi": [m.phi_s_phi.re, m.phi_s_phi.im],
                    "energy_fraction_xyz": m.energy_fraction_xyz,
                    "y_dominant": m.y_dominant,
                    "residual": m.residual,
                    "at_points": b.model.points.iter().zip(&m.at_points).map(|(p, v)| json!({"id": p.id, "direction": p.direction.to_string(), "re": v.re, "im": v.im})).collect::<Vec<_>>(),
                })
            })
            .collect();
        return print_json(&json!({
            "study": study.file.display().to_string(),
            "modulus_pa": [e.re, e.im],
            "n_dof": b.model.n_dof(),
            "seconds": secs,
            "modes": list,
        }));
    }
    println!(
        "{}: {} free DOFs, E* = {:.4} + {:.4} j MPa ({secs:.2} s)",
        study.file.display(),
        b.model.n_dof(),
        e.re / 1e6,
        e.im / 1e6
    );
    println!(
        "{:>4} {:>12} {:>10} {:>24} {:>20} {:>6}",
        "mode", "freq_hz", "loss", "phi^T S phi (m/kg)", "energy x/y/z", "y?"
    );
    for (k, m) in modes.iter().enumerate() {
        let en = m
            .energy_fraction_xyz
            .map(|f| format!("{:.2}/{:.2}/{:.2}", f[0], f[1], f[2]))
            .unwrap_or_else(|| "-".into());
        let y = match m.y_dominant {
            Some(true) => "y",
            Some(false) => "",
            None => "?",
        };
        println!(
            "{:>4} {:>12.4} {:>10.5} {:>24} {:>20} {:>6}",
            k + 1,
            m.freq_hz,
            m.loss_factor,
            format!("{:.4e}{:+.4e}j", m.phi_s_phi.re, m.phi_s_phi.im),
            en,
            y
        );
    }
    Ok(())
}

/// `--count` against the model's DOFs and the machine's memory (exit 2 before allocating).
fn check_count(count: usize, n_dof: usize, params: &ModesParams) -> Result<(), InputError> {
    // the refinement needs distinct modes from a real basis of 2 n + 8 vectors
    let most = n_dof / 3;
    let bytes = complex_modes_memory(n_dof, count, params);
    if count > most {
        return Err(InputError(format!(
            "--count {count}: the model has {n_dof} free DOFs (and {count} modes would need an estimated {} of memory); ask for at most {most} modes",
            format_bytes(bytes)
        )));
    }
    check_memory(bytes, available_memory_bytes()).map_err(|msg| {
        InputError(format!(
            "--count {count}: {count} complex modes of {n_dof} DOFs {msg}; ask for fewer modes"
        ))
    })
}
