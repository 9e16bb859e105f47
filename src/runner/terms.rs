//! Engines for effects that need new matrices: the degraded-bond regions
//! and base springs among a run's effects become the extra terms of a certified ROM
//! and the adherend damping among a run's effects become the extra terms of a certified ROM
//! ([`crate::rom::terms`]) that wraps the run's effect-free engine
//! ([`crate::rom::terms::WithTerms`]), so the effect-free forward model keeps its engine and
//! its numbers.
//!
//! With base springs the term ROM's model is the joint with its base face free
//! ([`crate::fe::base`]) holding springs of compliance `BASE_V_REF`, and the springs' term is a
//! compliance ([`crate::rom::terms::TermMap::Compliance`]): at compliance 0 (floored at
//! `BASE_V_FLOOR`, springs 1e10 times stiffer than the prior's stiffest) it is the fixed base,
//! certified against the full model like every other value.
//! The term ROM's modulus box ([`term_modulus_range`]) is that of the study's inference
//! models: E*(w) of each model's initial values over the band, widened by 2 either way (the
//! rule of the effect-free ROM's box, [`super::modulus_range`], without its floor at the
//! default box E' 0.5-50 MPa, E'' 0.01-20 MPa). Over the default box the enriched basis stalls
//! near 1.4e-6 of the peak (above the 1e-6 target): the soft corner (E' 0.5 MPa, a 10 times
//! softer adhesive than the paper's) needs the Krylov vectors of its own. The loop only
//! evaluates moduli near its MAPs, and [`outside_box`] tells when a MAP's modulus leaves the
//! certified box.

use super::{RunError, Study};
use crate::common::C64;
use crate::forward::Effect;
use crate::frf::FrfEngine;
use crate::rom::terms::{build_term_rom, TermCertificate, TermMap, TermRom, TermSpec};
use crate::study::build::BuiltModel;

/// Loss fractions whose full-model Krylov vectors enrich the basis, and those the certificate
/// checks (0 is the effect-free model).
const BOND_ENRICH: [f64; 2] = [0.5, 0.95];
const BOND_CERT: [f64; 3] = [0.0, 0.5, 0.95];
/// Base springs (compliance 1 / k_n, m^3/N): the term ROM model's own springs, the floor of
/// the rigid limit, the enrichment and certificate values (the default prior is 0-1e-9).
const BASE_V_REF: f64 = 1e-10;
const BASE_V_FLOOR: f64 = 1e-19;
const BASE_ENRICH: [f64; 3] = [0.0, 1e-11, 1e-9];
const BASE_CERT: [f64; 4] = [0.0, 1e-11, 1e-10, 1e-9];

/// The base springs' term: the joint of `spec` with its base face free on springs of
/// compliance `BASE_V_REF` (the term ROM's model), and the springs' compliance term
/// (`G = K_n + K_t / normal_over_tangential`, named as [`Effect::BaseSprings`]).
pub fn base_springs_term(
    spec: &crate::fe::joint::JointSpec,
    normal_over_tangential: f64,
) -> Result<(crate::fe::StructuralModel, TermSpec), String> {
    let b = crate::fe::base::base_spring_model(spec).map_err(|e| e.to_string())?;
    let g = b
        .combined(normal_over_tangential)
        .map_err(|e| e.to_string())?;
    let mut m = b.free.clone();
    m.k_b =
        crate::rom::terms::add_scaled(&m.k_b, &g, 1.0 / BASE_V_REF).map_err(|e| e.to_string())?;
    m.description = format!(
        "{} on base springs of compliance {BASE_V_REF:e} m^3/N",
        m.description
    );
    let t = TermSpec {
        name: Effect::BaseSprings {
            normal_over_tangential,
        }
        .name(),
        matrix: g,
        offset: C64::new(1.0, 0.0),
        per_modulus: 0.0,
        enrich_values: BASE_ENRICH.to_vec(),
        cert_values: BASE_CERT.to_vec(),
        map: TermMap::Compliance {
            v_ref: BASE_V_REF,
            v_floor: BASE_V_FLOOR,
        },
    };
    Ok((m, t))
}

/// Adherend loss factors the certificate checks (the default prior's upper edge, 0.01, and
/// twice it); the damping term needs no enrichment: j g K_b is a small perturbation of the
/// beam's stiffness, whose response the basis spans (tests/suite/rom_terms.rs).
const DAMPING_CERT: [f64; 2] = [0.01, 0.02];

/// The adherend damping's term of `model`: `G = K_b`, `c = j g` (offset j, no modulus part),
/// certified at g = 0.01 and 0.02, no enrichment.
pub fn adherend_damping_term(model: &crate::fe::model::StructuralModel) -> TermSpec {
    TermSpec {
        name: Effect::AdherendDamping.name(),
        matrix: model.k_b.clone(),
        offset: C64::new(0.0, 1.0),
        per_modulus: 0.0,
        enrich_values: Vec::new(),
        cert_values: DAMPING_CERT.to_vec(),
        map: TermMap::Linear,
    }
}

/// The candidates that need the term ROM: a degraded-bond strip of `width_m` at each end of
/// the block ([`bond_candidates`]) and the adherend damping.
pub fn term_candidates(study: &Study, width_m: f64) -> Vec<Effect> {
    let mut out = bond_candidates(study, width_m);
    out.push(Effect::AdherendDamping);
    out
}

/// The term ROM's modulus box (see the module doc): E*(w) of the initial values of the
/// inference models (every model when the study has no `[inference]`) over `band_hz`, widened
/// by 2 either way. Falls back to the effect-free ROM's box when no model gives a modulus.
pub fn term_modulus_range(study: &Study, band_hz: (f64, f64)) -> crate::rom::ModulusRange {
    let names: Option<&Vec<String>> = study.inference.as_ref().map(|i| &i.models);
    let mut r = crate::rom::ModulusRange {
        e_storage_pa: (f64::INFINITY, 0.0),
        e_loss_pa: (f64::INFINITY, 0.0),
    };
    for m in study
        .models
        .iter()
        .filter(|m| names.is_none_or(|n| n.iter().any(|x| x.eq_ignore_ascii_case(&m.name))))
    {
        let Ok(law) = crate::material::model_from_name(&m.name, m.branches) else {
            continue;
        };
        for k in 0..=50 {
            let f = band_hz.0 + (band_hz.1 - band_hz.0) * k as f64 / 50.0;
            let e = law.modulus(&m.initial, std::f64::consts::TAU * f.max(1e-3));
            if e.re.is_finite() && e.im.is_finite() && e.re > 0.0 && e.im >= 0.0 {
                r.e_storage_pa.0 = r.e_storage_pa.0.min(e.re / 2.0);
                r.e_storage_pa.1 = r.e_storage_pa.1.max(e.re * 2.0);
                r.e_loss_pa.0 = r.e_loss_pa.0.min(e.im / 2.0);
                r.e_loss_pa.1 = r.e_loss_pa.1.max(e.im * 2.0);
            }
        }
    }
    if r.e_storage_pa.0 < r.e_storage_pa.1 && r.e_loss_pa.0 < r.e_loss_pa.1 {
        r
    } else {
        super::modulus_range(study, band_hz)
    }
}

/// The largest factor by which `law` at `params` leaves `range` on `freq_hz` (1: inside; 2:
/// somewhere twice above the top or half below the bottom of E' or E'').
pub fn outside_box(
    law: &dyn crate::material::ConstitutiveModel,
    params: &[f64],
    freq_hz: &[f64],
    range: &crate::rom::ModulusRange,
) -> f64 {
    let ratio = |x: f64, (lo, hi): (f64, f64)| {
        if x < lo {
            if x > 0.0 {
                lo / x
            } else {
                f64::INFINITY
            }
        } else if x > hi {
            x / hi
        } else {
            1.0
        }
    };
    freq_hz
        .iter()
        .map(|&f| {
            let e = law.modulus(params, std::f64::consts::TAU * f);
            ratio(e.re, range.e_storage_pa).max(ratio(e.im, range.e_loss_pa))
        })
        .fold(1.0, f64::max)
}

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

/// A certified term ROM for the degraded-bond regions and the adherend damping among
/// `effects` (None when there are none), for the points and inputs of `engine`, over `band_hz`
/// and [`term_modulus_range`], loaded from `cache` (a folder) when it holds one built for the
/// same model, terms and settings, else built, certified and saved there. A region outside the
/// adhesive block is an error naming the effect's key.
pub fn term_rom_for(
    study: &Study,
    built: &BuiltModel,
    engine: &dyn FrfEngine,
    effects: &[(Effect, String)],
    band_hz: (f64, f64),
    cache: Option<&std::path::Path>,
) -> Result<Option<(TermRom, TermCertificate)>, RunError> {
    let mut specs: Vec<TermSpec> = Vec::new();
    // Base springs change the model's DOFs (the base face is free): every term then lives on
    // the free-base joint.
    let base = effects
        .iter()
        .find(|(e, _)| matches!(e, Effect::BaseSprings { .. }));
    let joint = |key: &String, what: &str| {
        crate::study::build::joint_spec(&study.structure).ok_or_else(|| {
            super::study_err(
                study,
                key.clone(),
                format!("{what} needs the mesher's structure (source = \"mesher\"): an imported model has no adhesive elements"),
            )
        })
    };
    let mut model = None;
    if let Some((e, key)) = base {
        let Effect::BaseSprings {
            normal_over_tangential,
        } = *e
        else {
            unreachable!("matched above")
        };
        let spec = joint(key, "base springs")?;
        let (m, t) = base_springs_term(&spec, normal_over_tangential)
            .map_err(|err| super::study_err(study, key.clone(), err))?;
        specs.push(t);
        model = Some(m);
    }
    for (e, key) in effects {
        if specs.iter().any(|s| s.name == e.name()) {
            continue;
        }
        if let Effect::AdherendDamping = e {
            if model.is_some() {
                return Err(super::study_err(
                    study,
                    key.clone(),
                    "adherend damping together with base springs is not supported (the damping term would be assembled on the free-base DOFs with the springs in K_b): try them in separate runs",
                ));
            }
            specs.push(adherend_damping_term(&built.model));
            continue;
        }
        let Effect::DegradedBond { x_start_m, width_m } = *e else {
            continue;
        };
        let spec = joint(key, "a degraded bond")?;
        let region = if model.is_some() {
            crate::fe::region::adhesive_region_stiffness_free_base
        } else {
            crate::fe::region::adhesive_region_stiffness
        };
        let r = region(&spec, x_start_m, x_start_m + width_m, key)
            .map_err(|err| super::study_err(study, key.clone(), err.to_string()))?;
        specs.push(TermSpec {
            name: e.name(),
            matrix: r.s_region,
            offset: C64::new(0.0, 0.0),
            per_modulus: -1.0,
            enrich_values: BOND_ENRICH.to_vec(),
            cert_values: BOND_CERT.to_vec(),
            map: Default::default(),
        });
    }
    if specs.is_empty() {
        return Ok(None);
    }
    let params = crate::rom::RomParams {
        band_hz,
        range: term_modulus_range(study, band_hz),
        tolerance: study.solver.rom_tolerance,
        allow_uncertified: true,
        n_cert_moduli_per_axis: 2,
        ..Default::default()
    };
    let model = model.as_ref().unwrap_or(&built.model);
    let file = cache.map(|dir| {
        let key = crate::rom::cache::term_key(model, engine.inputs(), &params, &specs);
        (dir.join(format!("terms-{}.json", &key[..16])), key)
    });
    if let Some(hit) = file
        .as_ref()
        .and_then(|(f, key)| crate::rom::cache::load_terms(f, key))
    {
        return Ok(Some(hit));
    }
    let (rom, cert) = build_term_rom(model, engine.inputs(), &params, &specs)
        .map_err(|e| RunError::Engine(e.to_string()))?;
    if let Some((f, key)) = &file {
        // A cache that cannot be written costs time next run, nothing else.
        let _ = crate::rom::cache::save_terms(f, key, &rom, &cert);
    }
    Ok(Some((rom, cert)))
}

/// `candidates` (keyed "closed_loop.candidates") and the study's declared degraded bonds and
/// adherend damping (keyed by their `structure.effects[i]`).
pub fn with_declared(study: &Study, candidates: &[Effect]) -> Vec<(Effect, String)> {
    let mut out: Vec<(Effect, String)> = study
        .declared_effects
        .iter()
        .filter_map(|d| match d.kind {
            crate::study::effects::DeclaredKind::DegradedBond { x_start_m, width_m } => {
                Some((Effect::DegradedBond { x_start_m, width_m }, d.key.clone()))
            }
            crate::study::effects::DeclaredKind::BaseSprings {
                normal_over_tangential,
            } => Some((
                Effect::BaseSprings {
                    normal_over_tangential,
                },
                d.key.clone(),
            )),
            crate::study::effects::DeclaredKind::AdherendDamping => {
                Some((Effect::AdherendDamping, d.key.clone()))
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
