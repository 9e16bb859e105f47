//! `rfmlab frf STUDY.toml ... -o FILE.parquet` and `rfmlab export-mm STUDY.toml -o DIR`.

use super::common::{
    build_model, load_study, parse_modulus, parse_pair, print_json, progress, Global, InputError,
    DEFAULT_MODULUS,
};
use rfmlab::common::C64;
use rfmlab::fe::cost::{available_memory_bytes, check_memory, format_seconds};
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;
use rfmlab::output::Table;
use serde_json::json;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct FrfArgs {
    /// Study file (its [structure] section is used).
    pub study: PathBuf,
    /// Constant adhesive modulus E',E'' in Pa (default 6.974e6,1.4827e6).
    #[arg(long)]
    pub modulus: Option<String>,
    /// Band f_low,f_high in Hz.
    #[arg(long, default_value = "1,500")]
    pub band: String,
    /// Line spacing in Hz.
    #[arg(long, default_value_t = 1.0)]
    pub step: f64,
    /// Also write dH'/dE' (sensitivity, (m/s^2)/N/Pa).
    #[arg(long)]
    pub derivatives: bool,
    /// Parquet file to write (columns in docs/outputs.md), replaced when rfmlab wrote it; a
    /// file rfmlab did not write is refused unless --force; default: none, the peaks are
    /// printed only.
    #[arg(short = 'o', long = "output", alias = "out", value_name = "FILE")]
    pub out: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Print JSON for scripts (summary: peaks per channel).
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct ExportMmArgs {
    /// Study file (its [structure] section is used).
    pub study: PathBuf,
    /// Folder of M.mtx, K_b.mtx, S.mtx (C_b.mtx, D_b.mtx), dofmap.csv and manifest.json,
    /// replaced as a whole when rfmlab wrote it (default: `results/<study name>.matrices`,
    /// relative to the current directory); a folder with other files, or a file, is refused
    /// unless --force.
    #[arg(short = 'o', long = "output", alias = "dir", value_name = "DIR")]
    pub dir: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Print a JSON summary (folder, files, DOFs) on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &FrfArgs, g: &Global) -> anyhow::Result<()> {
    let e = match &a.modulus {
        Some(s) => parse_modulus(s)?,
        None => DEFAULT_MODULUS,
    };
    let (f0, f1) = parse_pair("--band", &a.band)?;
    if !(a.step > 0.0 && a.step.is_finite()) {
        return Err(InputError(format!(
            "--step {}: give a positive line spacing in Hz",
            a.step
        ))
        .into());
    }
    let f0 = if f0 == 0.0 { a.step } else { f0 };
    let n_f = ((f1 - f0) / a.step + 1e-9).floor() + 1.0;
    let study = load_study(&a.study)?;
    // The output contract before anything is computed.
    if let Some(out) = &a.out {
        super::common::claim_file(out, a.force, rfmlab::output::contract::is_rfmlab_table)?;
    }
    // the size first: lines x channels of results, and the model's own cost
    let (n_points, model_cost) = match rfmlab::study::build::joint_spec(&study.structure) {
        Some(spec) => (
            spec.points.len(),
            Some(
                rfmlab::fe::joint::joint_cost_estimate(&spec)
                    .map_err(|e| InputError(format!("{}: {e}", study.file.display())))?,
            ),
        ),
        None => (study.structure.points.len(), None),
    };
    let per_line = 32.0 + (n_points as f64) * (if a.derivatives { 2.0 } else { 1.0 }) * 80.0;
    let bytes = n_f * per_line + model_cost.map_or(0.0, |c| c.memory_bytes);
    if let Err(msg) = check_memory(bytes, available_memory_bytes()) {
        let secs = model_cost.map_or(String::new(), |c| {
            format!(
                " and about {}",
                format_seconds(n_f * c.factor_seconds.max(1e-3))
            )
        });
        return Err(InputError(format!(
            "--step {}: {n_f:.3e} lines over {f0}-{f1} Hz {msg}{secs}: use a larger --step or a narrower --band",
            a.step
        ))
        .into());
    }
    let n = n_f as usize;
    let freq: Vec<f64> = (0..n).map(|k| f0 + k as f64 * a.step).collect();
    let omega: Vec<f64> = freq
        .iter()
        .map(|f| 2.0 * std::f64::consts::PI * f)
        .collect();
    let b = build_model(g, &study)?;
    let engine = FullModel::new(&b.model, &[b.excitation], FullParams::default())?;
    let pb = progress(g, n as u64, "full-model sweep");
    let chunk = 20usize;
    let mut acc = vec![Vec::with_capacity(n); b.model.points.len()];
    let mut dacc = vec![Vec::with_capacity(n); b.model.points.len()];
    let t = std::time::Instant::now();
    for (om, _) in omega.chunks(chunk).zip(freq.chunks(chunk)) {
        let moduli = vec![e; om.len()];
        let s = engine.sweep(om, &moduli, a.derivatives)?;
        for (l, &w) in om.iter().enumerate() {
            for i in 0..s.n_out {
                acc[i].push(-w * w * s.h[s.idx(l, i, 0)]);
                if a.derivatives {
                    dacc[i].push(-w * w * s.dh_de[s.idx(l, i, 0)]);
                }
            }
        }
        pb.inc(om.len() as u64);
    }
    pb.finish_and_clear();
    let secs = t.elapsed().as_secs_f64();
    let exc = &b.model.points[b.excitation];
    if let Some(out) = &a.out {
        let mut tab = Table::new("frf");
        let mut fcol = Vec::new();
        let mut rid = Vec::new();
        let mut rdir = Vec::new();
        let mut vals: Vec<C64> = Vec::new();
        let mut dvals: Vec<C64> = Vec::new();
        for (i, p) in b.model.points.iter().enumerate() {
            fcol.extend_from_slice(&freq);
            rid.extend(std::iter::repeat_n(p.id, n));
            rdir.extend(std::iter::repeat_n(p.direction.to_string(), n));
            vals.extend_from_slice(&acc[i]);
            if a.derivatives {
                dvals.extend_from_slice(&dacc[i]);
            }
        }
        let rows = fcol.len();
        tab.push_u32("response_id", "-", rid)?;
        tab.push_str("response_dir", rdir)?;
        tab.push_u32("reference_id", "-", vec![exc.id; rows])?;
        tab.push_str("reference_dir", vec![exc.direction.to_string(); rows])?;
        tab.push_f64("freq_hz", "Hz", fcol)?;
        tab.push_c64("accelerance", "(m/s^2)/N", &vals)?;
        if a.derivatives {
            tab.push_c64("daccelerance_de_storage", "(m/s^2)/N/Pa", &dvals)?;
        }
        tab.push_f64("modulus_storage", "Pa", vec![e.re; rows])?;
        tab.push_f64("modulus_loss", "Pa", vec![e.im; rows])?;
        tab.write_parquet(out)?;
    }
    if a.json {
        let chans: Vec<_> = b
            .model
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let (k, v) = acc[i]
                    .iter()
                    .enumerate()
                    .max_by(|x, y| x.1.norm().total_cmp(&y.1.norm()))
                    .map(|(k, v)| (k, v.norm()))
                    .unwrap_or((0, 0.0));
                json!({"response_id": p.id, "response_dir": p.direction.to_string(), "peak_freq_hz": freq[k], "peak_accelerance": v})
            })
            .collect();
        return print_json(&json!({
            "study": study.file.display().to_string(),
            "modulus_pa": [e.re, e.im],
            "n_dof": b.model.n_dof(),
            "n_lines": n,
            "seconds": secs,
            "out": a.out.as_ref().map(|p| p.display().to_string()),
            "channels": chans,
        }));
    }
    println!(
        "{} lines x {} channels (excitation at point {} {}), {} DOFs, {secs:.2} s",
        n,
        b.model.points.len(),
        exc.id,
        exc.direction,
        b.model.n_dof()
    );
    for (i, p) in b.model.points.iter().enumerate() {
        let (k, v) = acc[i]
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.norm().total_cmp(&y.1.norm()))
            .map(|(k, v)| (k, v.norm()))
            .unwrap_or((0, 0.0));
        println!(
            "  point {:>3} {}: peak |H'| = {v:.4e} (m/s^2)/N at {:.2} Hz",
            p.id, p.direction, freq[k]
        );
    }
    if let Some(out) = &a.out {
        println!("wrote {}", out.display());
    }
    Ok(())
}

pub fn run_export(a: &ExportMmArgs, g: &Global) -> anyhow::Result<()> {
    let study = load_study(&a.study)?;
    let dir = a.dir.clone().unwrap_or_else(|| {
        std::path::Path::new("results").join(format!("{}.matrices", study.name))
    });
    // The output contract before the model is built.
    let replace = super::common::claim_folder(&dir, a.force)?;
    let b = build_model(g, &study)?;
    // Filled as a temporary sibling and swapped in whole, with a manifest marking it as rfmlab's.
    let files = rfmlab::output::replace_dir_as(&dir, replace, |tmp| -> anyhow::Result<_> {
        rfmlab::fe::matrix_market::export_model(&b.model, tmp)?;
        let mut files: Vec<String> = std::fs::read_dir(tmp)?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        let mut manifest = rfmlab::output::Manifest::new(&study.file, None);
        for f in &files {
            manifest.add_file(f.clone(), rfmlab::output::sha256_file(tmp.join(f)).ok());
        }
        manifest.add_note(format!("Matrix Market export: {}", b.model.description));
        manifest.write(tmp.join(rfmlab::output::contract::MANIFEST))?;
        files.push(rfmlab::output::contract::MANIFEST.to_string());
        Ok(files)
    })?;
    if a.json {
        return print_json(&json!({
            "study": study.file.display().to_string(),
            "output_dir": dir.display().to_string(),
            "n_dof": b.model.n_dof(),
            "files": files,
        }));
    }
    if !g.quiet {
        println!(
            "wrote {} ({} free DOFs) to {}",
            files.join(", "),
            b.model.n_dof(),
            dir.display()
        );
    }
    Ok(())
}
