//! Engines for effects that need new matrices (issue 13, item 1): the degraded-bond regions
//! among a run's effects become the extra terms of a certified ROM ([`crate::rom::terms`])
//! that wraps the run's effect-free engine ([`crate::rom::terms::WithTerms`]), so the
//! effect-free forward model keeps its engine and its numbers.

use super::{RunError, Study};
use crate::common::C64;
use crate::forward::Effect;
use crate::frf::FrfEngine;
use crate::rom::terms::{build_term_rom, TermCertificate, TermRom, TermSpec};
use crate::study::build::BuiltModel;

/// Loss fractions whose full-model Krylov vectors enrich the basis, and those the certificate
/// checks (0 is the effect-free model).
const BOND_ENRICH: [f64; 2] = [0.5, 0.95];
const BOND_CERT: [f64; 3] = [0.0, 0.5, 0.95];

/// The degraded-bond candidates of the loop: a strip of `width_m` at each end of the block.
pub fn bond_candidates(study: &Study, width_m: f64) -> Vec<Effect> {
    let Some(spec) = crate::study::build::joint_spec(&study.structure) else {
        return Vec::new(); // an imported structure has no mesher geometry to split
    };
    let g = &spec.geometry;
    let (a0, a1) = (
        g.adhesive_x_start_m,
        g.adhesive_x_start_m + g.adhesive_length_m,
    );
    if a1 - a0 < 2.0 * width_m {
        return Vec::new();
    }
    vec![
        Effect::DegradedBond {
            x_start_m: a0,
            width_m,
        },
        Effect::DegradedBond {
            x_start_m: a1 - width_m,
            width_m,
        },
    ]
}

/// A certified term ROM for the degraded-bond regions among `effects` (None when there are
/// none), for the points and inputs of `engine`, over `band_hz` and the ROM modulus range of
/// the study. A region outside the adhesive block is an error naming `key_of(effect)`.
pub fn term_rom_for(
    study: &Study,
    built: &BuiltModel,
    engine: &dyn FrfEngine,
    effects: &[(Effect, String)],
    band_hz: (f64, f64),
) -> Result<Option<(TermRom, TermCertificate)>, RunError> {
    let mut specs: Vec<TermSpec> = Vec::new();
    for (e, key) in effects {
        let Effect::DegradedBond { x_start_m, width_m } = *e else {
            continue;
        };
        if specs.iter().any(|s| s.name == e.name()) {
            continue;
        }
        let spec = crate::study::build::joint_spec(&study.structure).ok_or_else(|| {
            super::study_err(
                study,
                key.clone(),
                "a degraded bond needs the mesher's structure (source = \"mesher\"): an imported model has no adhesive elements to split",
            )
        })?;
        let r = crate::fe::region::adhesive_region_stiffness(
            &spec,
            x_start_m,
            x_start_m + width_m,
            key,
        )
        .map_err(|err| super::study_err(study, key.clone(), err.to_string()))?;
        specs.push(TermSpec {
            name: e.name(),
            matrix: r.s_region,
            offset: C64::new(0.0, 0.0),
            per_modulus: -1.0,
            enrich_values: BOND_ENRICH.to_vec(),
            cert_values: BOND_CERT.to_vec(),
        });
    }
    if specs.is_empty() {
        return Ok(None);
    }
    let params = crate::rom::RomParams {
        band_hz,
        range: super::modulus_range(study, band_hz),
        tolerance: study.solver.rom_tolerance,
        allow_uncertified: true,
        n_cert_moduli_per_axis: 2,
        ..Default::default()
    };
    let (rom, cert) = build_term_rom(&built.model, engine.inputs(), &params, &specs)
        .map_err(|e| RunError::Engine(e.to_string()))?;
    Ok(Some((rom, cert)))
}

/// `candidates` (keyed "closed_loop.candidates") and the study's declared degraded bonds
/// (keyed by their `structure.effects[i]`).
pub fn with_declared(study: &Study, candidates: &[Effect]) -> Vec<(Effect, String)> {
    let mut out: Vec<(Effect, String)> = study
        .declared_effects
        .iter()
        .filter_map(|d| match d.kind {
            crate::study::effects::DeclaredKind::DegradedBond { x_start_m, width_m } => {
                Some((Effect::DegradedBond { x_start_m, width_m }, d.key.clone()))
            }
            _ => None,
        })
        .collect();
    out.extend(
        candidates
            .iter()
            .map(|e| (e.clone(), "closed_loop.candidates".to_string())),
    );
    out
}

/// The band (Hz) of the levels' lines.
pub fn band_of(levels: &[super::LevelData]) -> (f64, f64) {
    let lo = levels
        .iter()
        .flat_map(|l| l.freq_hz.first().copied())
        .fold(f64::INFINITY, f64::min);
    let hi = levels
        .iter()
        .flat_map(|l| l.freq_hz.last().copied())
        .fold(0.0, f64::max);
    (lo, hi)
}
