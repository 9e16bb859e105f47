//! Choosing the FRF engine (full model or certified ROM) for CLI commands.

use super::common::Global;
use rfmlab::common::C64;
use rfmlab::fe::StructuralModel;
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;
use rfmlab::rom::{build_rom, ModulusRange, RomParams};
use rfmlab::study::experiment::Experiment;

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

/// The engine that drives a virtual experiment (all points as outputs, the drive point as input):
/// the certified ROM over the band the experiment evaluates, or the full model on request.
pub fn plant_engine(
    model: &StructuralModel,
    excitation: usize,
    ex: &Experiment,
    g: &Global,
) -> anyhow::Result<Box<dyn FrfEngine>> {
    if ex.use_full_model {
        return Ok(Box::new(FullModel::new(
            model,
            &[excitation],
            FullParams::default(),
        )?));
    }
    let (f0, f1) = ex.chain.band_hz;
    let lo = (f0 - ex.chain.kernel.half_width_hz).max(0.25);
    let hi = f1 + ex.chain.kernel.half_width_hz + 1.0;
    let mut moduli = Vec::new();
    for lv in &ex.levels {
        let law = rfmlab::material::model_from_name(&lv.law, lv.branches)?;
        for k in 0..=200 {
            let f = lo + (hi - lo) * k as f64 / 200.0;
            moduli.push(law.modulus(&lv.params, 2.0 * std::f64::consts::PI * f));
        }
    }
    let params = RomParams {
        band_hz: (lo, hi),
        range: modulus_box(&moduli),
        // 1e-5 of each FRF's peak: two orders below the 0.2 % sensor noise of a typical rig and
        // the ~1 % random error of H1 with 200 averages at the heavily damped peak.
        tolerance: 1e-5,
        ..RomParams::default()
    };
    let (rom, cert) = build_rom(model, &[excitation], &params)?;
    if !g.quiet {
        eprintln!(
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
    }
    Ok(Box::new(rom))
}
