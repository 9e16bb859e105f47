//! `rfmlab modes STUDY.toml [--modulus E',E''] [--count N] [--json]`

use super::common::{
    build_model, load_study, parse_modulus, print_json, spinner, Global, DEFAULT_MODULUS,
};
use rfmlab::modes::{complex_modes, ModesParams};
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
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &ModesArgs, g: &Global) -> anyhow::Result<()> {
    let e = match &a.modulus {
        Some(s) => parse_modulus(s)?,
        None => DEFAULT_MODULUS,
    };
    let study = load_study(&a.study)?;
    let b = build_model(g, &study)?;
    let sp = spinner(g, "complex modes");
    let t = std::time::Instant::now();
    let modes = complex_modes(
        &b.model,
        e,
        a.count,
        b.dof_axes.as_deref(),
        &ModesParams::default(),
    )?;
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
