//! `rfmlab rom STUDY.toml [--band f0,f1] [--storage a,b] [--loss c,d] [--tolerance t]
//! [--cert-moduli n] [--cert-lines n] [--inputs all|excitation] [--json]`:
//! build and certify the reduced-order model of a study's structure.

use super::common::{build_model, load_study, parse_pair, print_json, spinner, Global, InputError};
use rfmlab::rom::{build_rom, ModulusRange, RomParams};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RomArgs {
    /// Study file (its [structure] section is used).
    pub study: PathBuf,
    /// Band in Hz.
    #[arg(long, default_value = "1,500")]
    pub band: String,
    /// Storage modulus range E'min,E'max in Pa.
    #[arg(long, default_value = "0.5e6,50e6")]
    pub storage: String,
    /// Loss modulus range E''min,E''max in Pa.
    #[arg(long, default_value = "0.01e6,20e6")]
    pub loss: String,
    /// Certificate tolerance (max error relative to each FRF's peak).
    #[arg(long, default_value_t = 1e-6)]
    pub tolerance: f64,
    /// Validation moduli per axis of the modulus box (log-spaced, corners included): the
    /// certificate solves the full model at (this squared) x `--cert-lines` points.
    #[arg(long, default_value_t = RomParams::default().n_cert_moduli_per_axis)]
    pub cert_moduli: usize,
    /// Validation lines across the band (ends included).
    #[arg(long, default_value_t = RomParams::default().n_cert_lines)]
    pub cert_lines: usize,
    /// Inputs of the certified FRFs: `all` observation points (the n x n FRF matrix, what
    /// `rfmlab run` builds for mass loading and reciprocity), or the structure's
    /// `excitation` point only (n FRFs, what `rfmlab simulate` builds).
    #[arg(long, value_enum, default_value_t = Inputs::All)]
    pub inputs: Inputs,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Inputs {
    All,
    Excitation,
}

/// The flags' ranges, checked before anything is built.
fn check_flags(a: &RomArgs) -> Result<(), InputError> {
    if !(a.tolerance.is_finite() && a.tolerance > 0.0 && a.tolerance < 1.0) {
        return Err(InputError(format!(
            "--tolerance {}: the certificate's tolerance is a relative error between 0 and 1 (exclusive), e.g. --tolerance 1e-6 (the default)",
            a.tolerance
        )));
    }
    if a.cert_lines < 2 {
        return Err(InputError(format!(
            "--cert-lines {}: the certificate needs at least 2 validation lines (the band's ends); give 2 or more (default {})",
            a.cert_lines,
            RomParams::default().n_cert_lines
        )));
    }
    if a.cert_moduli < 2 {
        return Err(InputError(format!(
            "--cert-moduli {}: the certificate needs at least 2 moduli per axis (the box's corners); give 2 or more (default {})",
            a.cert_moduli,
            RomParams::default().n_cert_moduli_per_axis
        )));
    }
    Ok(())
}

pub fn run(a: &RomArgs, g: &Global) -> anyhow::Result<()> {
    check_flags(a)?;
    let band = parse_pair("--band", &a.band)?;
    let storage = parse_pair("--storage", &a.storage)?;
    let loss = parse_pair("--loss", &a.loss)?;
    let study = load_study(&a.study)?;
    let b = build_model(g, &study)?;
    let inputs: Vec<usize> = match a.inputs {
        Inputs::All => (0..b.model.points.len()).collect(),
        Inputs::Excitation => vec![b.excitation],
    };
    let params = RomParams {
        band_hz: band,
        range: ModulusRange {
            e_storage_pa: storage,
            e_loss_pa: loss,
        },
        tolerance: a.tolerance,
        n_cert_moduli_per_axis: a.cert_moduli,
        n_cert_lines: a.cert_lines,
        // the reference `rfmlab run` and `diagnose` choose for this model and these inputs
        reference: rfmlab::rom::Reference::suited(b.model.n_dof()),
        ..RomParams::default()
    };
    let sp = spinner(g, "building and certifying the ROM");
    let t = std::time::Instant::now();
    let (_rom, cert) = build_rom(&b.model, &inputs, &params)?;
    let secs = t.elapsed().as_secs_f64();
    sp.finish_and_clear();
    if a.json {
        return print_json(&serde_json::json!({
            "study": study.file.display().to_string(),
            "n_dof": b.model.n_dof(),
            "band_hz": band,
            "range": params.range,
            "tolerance": a.tolerance,
            "inputs": inputs.iter().map(|&i| b.model.points[i].id).collect::<Vec<_>>(),
            "seconds_total": secs,
            "certificate": cert,
        }));
    }
    println!(
        "{}: {} DOFs, {} x {} FRFs -> {} basis vectors; max error {:.3e} (tolerance {:.0e}) on {} moduli x {} lines; {}",
        study.file.display(),
        b.model.n_dof(),
        b.model.points.len(),
        inputs.len(),
        cert.basis_size,
        cert.max_rel_error,
        a.tolerance,
        cert.n_moduli,
        cert.n_lines,
        if cert.passed { "CERTIFIED" } else { "NOT certified" }
    );
    if cert.floor_points > 0 {
        println!(
            "{} validation point(s) at the floating-point floor: the full model itself is resolved only to {:.1e} there; the ROM is within {:.2e} of it (allowed {:.0} x the floor)",
            cert.floor_points,
            cert.floor_max,
            cert.floor_points_error,
            rfmlab::rom::certify::FLOOR_FACTOR
        );
    }
    println!(
        "basis {:.2} s, certificate {:.2} s ({} reference), total {secs:.2} s, {} enrichment level(s)",
        cert.seconds_basis, cert.seconds_certify, cert.reference, cert.levels
    );
    Ok(())
}
