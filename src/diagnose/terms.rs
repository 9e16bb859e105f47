//! Engines for effects that need new matrices: the degraded-bond regions, the base springs and
//! the adherend damping among a run's effects become the extra terms of a certified ROM
//! ([`crate::rom::terms`]) that wraps the run's effect-free engine
//! ([`crate::rom::terms::WithTerms`]), so the effect-free forward model keeps its engine and
//! its numbers.
//!
//! With base springs the term ROM's model is the joint with its base face free
//! ([`crate::fe::base`]) holding springs of compliance `BASE_V_REF`, and the springs' term is a
//! compliance ([`crate::rom::terms::TermMap::Compliance`]): at compliance 0 (floored at
//! `BASE_V_FLOOR`, springs 1e10 times stiffer than the prior's stiffest) it is the fixed base,
//! certified against the full model like every other value.
//! The term ROM's modulus box ([`super::term_modulus_range`]) is that of the study's inference
//! models: E*(w) of each model's initial values over the band, widened by 2 either way (the
//! rule of the effect-free ROM's box, [`crate::stage::engine::initial_modulus_range`], without
//! its floor at the default box E' 0.5-50 MPa, E'' 0.01-20 MPa). Over the default box the enriched basis stalls
//! near 1.4e-6 of the peak (above the 1e-6 target): the soft corner (E' 0.5 MPa, a 10 times
//! softer adhesive than the paper's) needs the Krylov vectors of its own. The loop only
//! evaluates moduli near its MAPs, and [`super::outside_box`] tells when a MAP's modulus leaves
//! the certified box.

use super::params::{key_error, TermParams};
use crate::common::C64;
use crate::forward::Effect;
use crate::frf::FrfEngine;
use crate::rom::term_build::build_term_rom;
use crate::rom::terms::{TermCertificate, TermMap, TermRom, TermSpec};
use crate::stage::RunError;
use crate::study::build::BuiltModel;

/// Why a term's matrices could not be made.
#[derive(Debug, thiserror::Error)]
pub enum TermError {
    /// Meshing or assembling the joint with its base face free.
    #[error(transparent)]
    Fe(#[from] crate::fe::FeError),
    /// Adding the springs' stiffness to the beam's.
    #[error(transparent)]
    Rom(#[from] crate::rom::RomError),
}

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
) -> Result<(crate::fe::StructuralModel, TermSpec), TermError> {
    let (m, mut t) = base_springs_terms(spec, &[normal_over_tangential])?;
    Ok((m, t.remove(0)))
}

/// [`base_springs_term`] for several shapes of the springs (ratios `normal_over_tangential`,
/// the first held by the model): one compliance term each, the others replacing the held
/// springs when on ([`TermSpec::held`]), so that one term ROM serves every shape.
pub fn base_springs_terms(
    spec: &crate::fe::joint::JointSpec,
    normal_over_tangential: &[f64],
) -> Result<(crate::fe::StructuralModel, Vec<TermSpec>), TermError> {
    let b = crate::fe::base::base_spring_model(spec)?;
    let gs: Vec<crate::fe::model::SpMat> = normal_over_tangential
        .iter()
        .map(|&r| b.combined(r))
        .collect::<Result<_, _>>()?;
    let mut m = b.free.clone();
    m.k_b = crate::rom::term_build::add_scaled(&m.k_b, &gs[0], 1.0 / BASE_V_REF)?;
    m.description = format!(
        "{} on base springs of compliance {BASE_V_REF:e} m^3/N",
        m.description
    );
    let terms = normal_over_tangential
        .iter()
        .zip(&gs)
        .enumerate()
        .map(|(k, (&normal_over_tangential, g))| TermSpec {
            name: Effect::BaseSprings {
                normal_over_tangential,
            }
            .name(),
            matrix: g.clone(),
            offset: C64::new(1.0, 0.0),
            per_modulus: 0.0,
            enrich_values: BASE_ENRICH.to_vec(),
            cert_values: BASE_CERT.to_vec(),
            map: TermMap::Compliance {
                v_ref: BASE_V_REF,
                v_floor: BASE_V_FLOOR,
            },
            held: (k > 0).then(|| gs[0].clone()),
        })
        .collect();
    Ok((m, terms))
}

/// Masses (kg) of a sensor's three-direction term at which the basis takes the Krylov vectors
/// of the full model with it on, and those the certificate checks (the default prior is
/// 0-100 g). On the paper's joint on base springs (5 mm mesh, both spring shapes and a sensor
/// at point 4) the term ROM has 210 vectors (156 without the sensor), certified to 1.5e-7 of
/// each FRF's peak, and with the springs and the sensor on together it is within 5e-8 of the
/// full model. Starting the basis from the unit loads of the point's x and z directions as
/// well made it larger (312 vectors) and no more accurate (4.6e-7).
const SENSOR_ENRICH: [f64; 2] = [0.02, 0.1];
const SENSOR_CERT: [f64; 3] = [0.01, 0.03, 0.1];

/// `spec` with every direction of the points `ids` among its points (the missing ones
/// appended after the measured ones, so that the measured points keep their indices), and
/// each point's x, y and z indices among them. An id that is not a point is an error.
pub fn with_sensor_directions(
    spec: &crate::fe::joint::JointSpec,
    ids: &[u32],
) -> Result<(crate::fe::joint::JointSpec, Vec<[usize; 3]>), String> {
    use crate::common::{Axis, Direction};
    let mut out = spec.clone();
    let mut at = Vec::with_capacity(ids.len());
    for &id in ids {
        let Some(p) = spec.points.iter().find(|p| p.id == id) else {
            return Err(format!("point {id} is not a point of the structure"));
        };
        let position_m = p.position_m;
        let mut idx = [0; 3];
        for (slot, axis) in idx.iter_mut().zip([Axis::X, Axis::Y, Axis::Z]) {
            *slot = match out
                .points
                .iter()
                .position(|q| q.id == id && q.direction.axis == axis)
            {
                Some(k) => k,
                None => {
                    out.points.push(crate::fe::joint::PointSpec {
                        id,
                        position_m,
                        direction: Direction::new(axis, 1),
                    });
                    out.points.len() - 1
                }
            };
        }
        at.push(idx);
    }
    Ok((out, at))
}

/// The term of a sensor's mass at point `id` in x, y and z on `model`, whose observation
/// points `at` are that point's x, y and z directions ([`with_sensor_directions`]): `G =
/// sum_d w_d w_d^T` per unit mass (`w_d` a direction's DOF weights,
/// [`crate::fe::StructuralModel::point_mass_matrix`]), with the coefficient `-w^2 m`
/// ([`TermMap::Inertia`]).
pub fn sensor_mass_term(
    model: &crate::fe::StructuralModel,
    id: u32,
    at: [usize; 3],
) -> Result<TermSpec, String> {
    let g = model
        .point_mass_matrix(&at.map(|k| (k, 1.0)))
        .map_err(|e| format!("a sensor's mass matrix: {e}"))?;
    Ok(TermSpec {
        name: Effect::SensorMassTerm { id }.name(),
        matrix: g,
        offset: C64::new(1.0, 0.0),
        per_modulus: 0.0,
        enrich_values: SENSOR_ENRICH.to_vec(),
        cert_values: SENSOR_CERT.to_vec(),
        map: TermMap::Inertia,
        held: None,
    })
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
        held: None,
    }
}

/// A certified term ROM for the degraded-bond regions, base springs and adherend damping among
/// `effects` (None when there are none), for the points and inputs of `engine`, over `band_hz`
/// and [`super::term_modulus_range`], loaded from the cache folder of `p` when it holds one
/// built for the same model, terms and settings, else built, certified and saved there. A
/// region outside the adhesive block is an error naming the effect's key.
pub fn term_rom_for(
    p: &TermParams,
    built: &BuiltModel,
    engine: &dyn FrfEngine,
    effects: &[(Effect, String)],
    band_hz: (f64, f64),
) -> Result<Option<(TermRom, TermCertificate)>, RunError> {
    let mut specs: Vec<TermSpec> = Vec::new();
    // Base springs change the model's DOFs (the base face is free): every term then lives on
    // the free-base joint. Each shape of the springs (ratio of normal to tangential stiffness)
    // is a term of its own.
    let mut shapes: Vec<(f64, &String)> = Vec::new();
    for (e, key) in effects {
        if let Effect::BaseSprings {
            normal_over_tangential,
        } = *e
        {
            if !shapes.iter().any(|(r, _)| *r == normal_over_tangential) {
                shapes.push((normal_over_tangential, key));
            }
        }
    }
    let joint = |key: &String, what: &str| {
        p.joint.as_ref().ok_or_else(|| {
            key_error(
                &p.study_file,
                key.clone(),
                format!("{what} needs the mesher's structure (source = \"mesher\"): an imported model has no adhesive elements"),
            )
        })
    };
    // Sensor masses in x, y and z: their points' three directions are located on the term
    // ROM's mesh (points appended to the measured ones, for their DOF weights only: the ROM's
    // points stay the engine's).
    let sensors: Vec<(u32, &String)> = effects
        .iter()
        .filter_map(|(e, key)| match e {
            Effect::SensorMassTerm { id } => Some((*id, key)),
            _ => None,
        })
        .collect();
    let ids: Vec<u32> = sensors.iter().map(|(id, _)| *id).collect();
    let sensor_key = sensors.first().map(|(_, key)| (*key).clone());
    let sensor_error =
        |err: String| key_error(&p.study_file, sensor_key.clone().unwrap_or_default(), err);
    let located = |spec: &crate::fe::joint::JointSpec| {
        with_sensor_directions(spec, &ids).map_err(sensor_error)
    };
    // The sensors' terms on `m`, whose points include their directions at `at`.
    let sensor_terms = |m: &crate::fe::StructuralModel, at: &[[usize; 3]]| {
        ids.iter()
            .zip(at)
            .map(|(&id, &at)| sensor_mass_term(m, id, at).map_err(sensor_error))
            .collect::<Result<Vec<_>, _>>()
    };
    let mut model = None;
    if let Some((_, key)) = shapes.first() {
        let spec = joint(key, "base springs")?;
        let n_points = spec.points.len();
        let (spec, at) = located(spec)?;
        let ratios: Vec<f64> = shapes.iter().map(|(r, _)| *r).collect();
        let (mut m, ts) = base_springs_terms(&spec, &ratios)
            .map_err(|err| key_error(&p.study_file, (*key).clone(), err.to_string()))?;
        specs.extend(ts);
        specs.extend(sensor_terms(&m, &at)?);
        m.points.truncate(n_points);
        model = Some(m);
    } else if let Some(key) = &sensor_key {
        // The fixed base: the study's model, its sensors' directions located on the same
        // mesh (the DOFs do not depend on the points).
        let spec = joint(key, "a sensor's mass as a term")?;
        let (spec, at) = located(spec)?;
        let (m, _) = crate::fe::joint::build_joint_model(&spec)
            .map_err(|err| key_error(&p.study_file, key.clone(), err.to_string()))?;
        if m.n_dof() != built.model.n_dof() {
            return Err(key_error(
                &p.study_file,
                key.clone(),
                format!(
                    "the sensor's directions were located on a model of {} DOFs, the study's has {}",
                    m.n_dof(),
                    built.model.n_dof()
                ),
            ));
        }
        specs.extend(sensor_terms(&m, &at)?);
    }
    for (e, key) in effects {
        if specs.iter().any(|s| s.name == e.name()) {
            continue;
        }
        if let Effect::AdherendDamping = e {
            if model.is_some() {
                return Err(key_error(
                    &p.study_file,
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
        let r = region(spec, x_start_m, x_start_m + width_m, key)
            .map_err(|err| key_error(&p.study_file, key.clone(), err.to_string()))?;
        specs.push(TermSpec {
            name: e.name(),
            matrix: r.s_region,
            offset: C64::new(0.0, 0.0),
            per_modulus: -1.0,
            enrich_values: BOND_ENRICH.to_vec(),
            cert_values: BOND_CERT.to_vec(),
            map: Default::default(),
            held: None,
        });
    }
    if specs.is_empty() {
        return Ok(None);
    }
    let params = crate::rom::RomParams {
        band_hz,
        range: super::term_modulus_range(p, band_hz),
        tolerance: p.tolerance,
        allow_uncertified: true,
        n_cert_moduli_per_axis: 2,
        ..Default::default()
    };
    let model = model.as_ref().unwrap_or(&built.model);
    let key = crate::rom::cache::term_key(model, engine.inputs(), &params, &specs);
    let file = p.cache.join(format!("terms-{}.json", &key[..16]));
    let (hit, _) = crate::rom::cache::load_or_build(
        &file,
        |f| crate::rom::cache::load_terms(f, &key),
        || {
            build_term_rom(model, engine.inputs(), &params, &specs)
                .map_err(|e| RunError::Engine(e.to_string()))
        },
        // A cache that cannot be written costs time next run, nothing else.
        |f, (rom, cert)| {
            let _ = crate::rom::cache::save_terms(f, &key, rom, cert);
        },
    )?;
    Ok(Some(hit))
}
