//! The ROM with extra structural terms (src/rom/terms.rs) against the full
//! model's sparse solve with the same term on, and its derivatives against central
//! differences:
//! * a 10 mm degraded strip at each end of the adhesive block (E* S -> E* (S - d S_region))
//!   and a structural damping of the beam (D_b -> D_b + eta K_b): the certificate (sparse LU
//!   of the modified full model, 4 moduli x 25 lines, d = 0, 0.5, 0.95, eta = 0.01, over the
//!   modulus range a study of the paper's adhesive covers: E' 2-20 MPa, E'' 0.3-8 MPa) is at most
//!   1e-6 of each FRF's peak; an independent check on lines off the certificate's grid and a
//!   modulus inside the range, with the full-model engine [`rfmlab::frf::FullModel`] on the
//!   modified model, holds to 1e-6 as well;
//! * dH/dv_k and dH/dE' of the reduced sweep against central differences of the sweep itself;
//! * the engine that wraps the effect-free engine returns its sweeps bit for bit.

use rfmlab::common::C64;
use rfmlab::fe::region::adhesive_region_stiffness;
use rfmlab::frf::{FrfEngine, FullModel, FullParams, TermCoef};
use rfmlab::rom::term_build::{build_term_rom, model_with_term};
use rfmlab::rom::terms::{TermSpec, WithTerms};
use rfmlab::rom::{build_rom, RomParams};
use std::f64::consts::TAU;

fn joint() -> (
    rfmlab::fe::joint::JointSpec,
    rfmlab::study::build::BuiltModel,
) {
    (
        crate::runner_common::joint_spec(),
        crate::runner_common::built_structure(),
    )
}

fn terms(spec: &rfmlab::fe::joint::JointSpec, k_b: &rfmlab::fe::model::SpMat) -> Vec<TermSpec> {
    let mut out = Vec::new();
    for (x0, x1) in [(0.0, 0.010), (0.040, 0.050)] {
        let r = adhesive_region_stiffness(spec, x0, x1, "k").unwrap();
        out.push(TermSpec {
            name: format!("bond_{x0}"),
            matrix: r.s_region,
            offset: C64::new(0.0, 0.0),
            per_modulus: -1.0,
            enrich_values: vec![0.95],
            cert_values: vec![0.0, 0.5, 0.95],
            map: Default::default(),
            held: None,
        });
    }
    out.push(TermSpec {
        name: "beam_damping".into(),
        matrix: k_b.clone(),
        offset: C64::new(0.0, 1.0),
        per_modulus: 0.0,
        enrich_values: vec![],
        cert_values: vec![0.01],
        map: Default::default(),
        held: None,
    });
    out
}

/// A quick term ROM's settings, uncertified (tests of its algebra, not of its accuracy).
fn quick(max_levels: usize, n_cert_lines: usize) -> RomParams {
    RomParams {
        allow_uncertified: true,
        max_levels,
        n_cert_lines,
        ..params()
    }
}

/// The term ROMs' settings (also tests/suite/base_springs.rs).
pub(crate) fn params() -> RomParams {
    RomParams {
        n_cert_moduli_per_axis: 2,
        // the range a study's ROM covers: the paper's adhesive (E0 about 5 MPa) widened 2x
        // either way ([`rfmlab::study::build::initial_modulus_range`])
        range: rfmlab::rom::ModulusRange {
            e_storage_pa: (2e6, 2e7),
            e_loss_pa: (0.3e6, 8e6),
        },
        ..RomParams::default()
    }
}

/// Largest error relative to each FRF's peak, sweeps of the same layout.
pub(crate) fn rel_err(a: &rfmlab::frf::Sweep, b: &rfmlab::frf::Sweep) -> f64 {
    let blk = a.n_out * a.n_in;
    (0..blk)
        .map(|k| {
            let peak = (0..a.n_lines)
                .map(|l| b.h[l * blk + k].norm())
                .fold(0.0, f64::max);
            (0..a.n_lines)
                .map(|l| (a.h[l * blk + k] - b.h[l * blk + k]).norm() / peak)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// Largest |column - central difference over +-h of parameter k| of the forward model's
/// exact values at `pp`, and the largest |column| entry.
fn column_against_difference(
    fm: &rfmlab::forward::ForwardModel<'_>,
    pp: &[f64],
    col: &[C64],
    k: usize,
    h: f64,
) -> (f64, f64) {
    let mut a = pp.to_vec();
    a[k] += h;
    let up = fm.exact(&a, false).unwrap().values;
    a[k] -= 2.0 * h;
    let dn = fm.exact(&a, false).unwrap().values;
    let scale = col.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let dev = col
        .iter()
        .zip(up.iter().zip(&dn))
        .map(|(c, (u, d))| (c - (u - d) / (2.0 * h)).norm())
        .fold(0.0, f64::max);
    (dev, scale)
}

#[test]
fn term_rom_is_certified_against_the_full_model_with_the_term_on() {
    let (spec, built) = joint();
    let model = &built.model;
    let inputs = [built.excitation];
    let ts = terms(&spec, &model.k_b);
    let t0 = std::time::Instant::now();
    let (rom, cert) = build_term_rom(model, &inputs, &params(), &ts).unwrap();
    eprintln!(
        "term ROM: n_r {} (enriched {}, compression error {:?}; levels {}), certificate {:.3e} ({:?}), basis {:.1} s, certify {:.1} s, total {:.1} s",
        cert.basis_size,
        cert.enriched_basis_size,
        cert.compression_error,
        cert.levels,
        cert.max_rel_error,
        cert.per_case,
        cert.seconds_basis,
        cert.seconds_certify,
        t0.elapsed().as_secs_f64()
    );
    assert!(cert.passed && cert.max_rel_error <= 1e-6);
    assert_eq!(cert.per_case.len(), 7);
    // The POD compression (src/rom/compress.rs) was kept: the sweeps and the checks below
    // are the compressed ROM's.
    assert!(
        cert.basis_size < cert.enriched_basis_size
            && cert.compression_error.is_some_and(|e| e <= 1e-6)
    );
    // Independent check off the certificate's grid, full model with the term on.
    let w: Vec<f64> = (0..60).map(|k| TAU * (3.3 + 8.1 * k as f64)).collect();
    let e = vec![C64::new(4.1e6, 1.3e6); w.len()];
    for (k, (t, v)) in [(0usize, 0.95), (1, 0.95), (1, 0.3), (2, 0.02)]
        .into_iter()
        .map(|(k, v)| (k, (&ts[k], v)))
    {
        let m = model_with_term(model, t, v).unwrap();
        let full = FullModel::new(&m, &inputs, FullParams::default()).unwrap();
        let reference = full.sweep(&w, &e, false).unwrap();
        let coef = [TermCoef {
            index: k,
            value: v,
            offset: t.offset,
            per_modulus: t.per_modulus,
        }];
        let t1 = std::time::Instant::now();
        let (got, _) = rom.sweep_terms(&w, &e, &coef, false).unwrap();
        eprintln!(
            "sweep with the term: {} lines in {:.1} ms (n_r {})",
            w.len(),
            1e3 * t1.elapsed().as_secs_f64(),
            rom.basis_size()
        );
        let err = rel_err(&got, &reference);
        eprintln!("{} at {v}: off-grid error {err:.3e}", t.name);
        assert!(err <= 1e-6, "{} at {v}: {err:.3e}", t.name);
        // the term does change the FRFs (the check can fail)
        let (plain, _) = rom.sweep_terms(&w, &e, &[], false).unwrap();
        assert!(rel_err(&plain, &reference) > 1e-3);
    }
}

#[test]
fn term_derivatives_match_central_differences() {
    let (spec, built) = joint();
    let model = &built.model;
    let inputs = [built.excitation];
    let ts = terms(&spec, &model.k_b);
    let p = quick(2, 5);
    let (rom, _) = build_term_rom(model, &inputs, &p, &ts[1..]).unwrap();
    let w: Vec<f64> = [40.0, 170.0, 333.0].iter().map(|f| TAU * f).collect();
    let e = vec![C64::new(5e6, 1e6); w.len()];
    let coef = |d: f64, eta: f64| {
        [
            TermCoef {
                index: 0,
                value: d,
                offset: C64::new(0.0, 0.0),
                per_modulus: -1.0,
            },
            TermCoef {
                index: 1,
                value: eta,
                offset: C64::new(0.0, 1.0),
                per_modulus: 0.0,
            },
        ]
    };
    let (d0, eta0) = (0.4, 0.01);
    let (sw, dt) = rom.sweep_terms(&w, &e, &coef(d0, eta0), true).unwrap();
    let scale = sw.h.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let fd = |f: &dyn Fn(f64) -> Vec<C64>, h: f64| -> Vec<C64> {
        f(h).iter()
            .zip(f(-h))
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect()
    };
    let check = |name: &str, an: &[C64], num: &[C64], size: f64| {
        let err = an
            .iter()
            .zip(num)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        let ref_scale = num.iter().map(|z| z.norm()).fold(0.0, f64::max);
        eprintln!("{name}: max |analytic - FD| {err:.3e} of {ref_scale:.3e} (typical size {size})");
        // the parameter's typical size moves H by more than 0.1 % of its peak
        assert!(
            ref_scale * size > 1e-3 * scale,
            "{name}: the derivative is negligible"
        );
        assert!(
            err <= 1e-6 * ref_scale,
            "{name}: {err:.3e} vs {ref_scale:.3e}"
        );
    };
    let h = 1e-5;
    let num = fd(
        &|s| {
            rom.sweep_terms(&w, &e, &coef(d0 + s, eta0), false)
                .unwrap()
                .0
                .h
        },
        h,
    );
    check("dH/dd", &dt[0], &num, 0.1);
    let num = fd(
        &|s| {
            rom.sweep_terms(&w, &e, &coef(d0, eta0 + s), false)
                .unwrap()
                .0
                .h
        },
        1e-6,
    );
    check("dH/deta", &dt[1], &num, 0.01);
    let de = 1.0;
    let num = fd(
        &|s| {
            let e2: Vec<C64> = e.iter().map(|x| x + s).collect();
            rom.sweep_terms(&w, &e2, &coef(d0, eta0), false)
                .unwrap()
                .0
                .h
        },
        de,
    );
    check("dH/dE'", &sw.dh_de, &num, 5e5);
}

#[test]
fn wrapped_engine_keeps_the_plain_sweep() {
    let (spec, built) = joint();
    let model = &built.model;
    let inputs = [built.excitation];
    let (plain, _) = build_rom(model, &inputs, &RomParams::default()).unwrap();
    let ts = terms(&spec, &model.k_b);
    let p = quick(1, 3);
    let (tr, _) = build_term_rom(model, &inputs, &p, &ts[..1]).unwrap();
    let eng = WithTerms::new(&plain, &tr).unwrap();
    let w: Vec<f64> = (1..50).map(|k| TAU * 9.7 * k as f64).collect();
    let e = vec![C64::new(6e6, 1e6); w.len()];
    let a = eng.sweep(&w, &e, true).unwrap();
    let b = plain.sweep(&w, &e, true).unwrap();
    assert_eq!(a.h, b.h);
    assert_eq!(a.dh_de, b.dh_de);
    assert_eq!(eng.term_names(), vec!["bond_0".to_string()]);
    assert!(plain.term_names().is_empty());
    assert!(plain.sweep_terms(&w, &e, &[], false).is_err());
}

/// The degraded-bond effect of the forward model (on the term ROM wrapping the certified ROM)
/// equals the full model with the strip degraded, with a 12 g mass at point 4 on as well; its
/// Jacobian column matches a central difference of the forward model.
#[test]
fn degraded_bond_effect_equals_the_full_model_with_the_strip_degraded() {
    use rfmlab::forward::{Effect, EffectTerm, Effects, ForwardModel};
    let (spec, built) = joint();
    let model = &built.model;
    let inputs = [0, 1, 2, 3];
    let (plain, _) = build_rom(model, &inputs, &params()).unwrap();
    let eff = Effect::DegradedBond {
        x_start_m: 0.040,
        width_m: 0.010,
    };
    let r = adhesive_region_stiffness(&spec, 0.040, 0.050, "k").unwrap();
    let ts = vec![TermSpec {
        name: eff.name(),
        matrix: r.s_region.clone(),
        offset: C64::new(0.0, 0.0),
        per_modulus: -1.0,
        enrich_values: vec![0.5, 0.95],
        cert_values: vec![0.95],
        map: Default::default(),
        held: None,
    }];
    let (tr, cert) = build_term_rom(model, &inputs, &params(), &ts).unwrap();
    assert!(cert.passed);
    let eng = WithTerms::new(&plain, &tr).unwrap();
    let law = rfmlab::material::Model3;
    let p = [4.7121e6, 5.5573e6, 6.0491e3];
    let w: Vec<f64> = (0..80).map(|k| TAU * (2.1 + 6.2 * k as f64)).collect();
    let outs = [0, 1, 2, 3];
    let mass = Effect::PointMass { point: 3, id: 4 };
    let mut fm = ForwardModel::new(&eng, &law, &w, built.excitation, &outs, None).unwrap();
    fm.set_effects(Effects {
        terms: vec![
            EffectTerm {
                effect: eff.clone(),
                value: 0.95,
                free: true,
            },
            EffectTerm {
                effect: mass,
                value: 0.012,
                free: false,
            },
        ],
    })
    .unwrap();
    let mut pp = p.to_vec();
    pp.push(0.95);
    let got = fm.exact(&pp, true).unwrap();
    let truth = model
        .with_degraded_region(&r.s_region, 0.95)
        .unwrap()
        .with_point_masses(&[(3, 0.012)])
        .unwrap();
    let full = FullModel::new(&truth, &[built.excitation], FullParams::default()).unwrap();
    let reference = ForwardModel::new(&full, &law, &w, built.excitation, &outs, None)
        .unwrap()
        .exact(&p, false)
        .unwrap()
        .values;
    let err = crate::structural_effects::rel_err_per_channel(&got.values, &reference, 4);
    eprintln!("degraded bond + 12 g mass, forward model vs full: {err:.3e}");
    assert!(err <= 1e-6, "{err:.3e}");
    // Jacobian column of d against a central difference
    let (dev, scale) = column_against_difference(&fm, &pp, &got.jac[3], 3, 1e-5);
    eprintln!("dH/dd: analytic vs FD {dev:.3e} of {scale:.3e}");
    assert!(
        scale > 0.0 && dev <= 1e-5 * scale,
        "{dev:.3e} of {scale:.3e}"
    );
    // timing of one forward evaluation with the effect on (80 lines, 4 outputs, Jacobian)
    let t = std::time::Instant::now();
    fm.exact(&pp, true).unwrap();
    eprintln!(
        "forward evaluation with the degraded bond (80 lines, Jacobian): {:.1} ms",
        1e3 * t.elapsed().as_secs_f64()
    );
}

/// `[[structure.effects]]` of type "degraded_bond": x_start needed, width positive, value a
/// loss fraction in [0, 1); errors name the key.
#[test]
fn declared_degraded_bond_is_validated() {
    let parse = |eff: &str| {
        rfmlab::study::parse_str(
            &format!(
                "[study]\nname = \"gen\"\n{}\n[[structure.effects]]\ntype = \"degraded_bond\"\n{eff}\n",
                crate::runner_common::structure()
            ),
            std::path::Path::new("gen.toml"),
        )
    };
    let ok = parse("x_start = 0.040\nwidth = 0.010\nvalue = 0.95").unwrap();
    assert_eq!(
        ok.declared_effects[0].kind,
        rfmlab::study::effects::DeclaredKind::DegradedBond {
            x_start_m: 0.040,
            width_m: 0.010
        }
    );
    for (text, key) in [
        ("width = 0.010\nvalue = 0.5", "structure.effects[0].x_start"),
        (
            "x_start = 0.0\nwidth = -0.01\nvalue = 0.5",
            "structure.effects[0].width",
        ),
        ("x_start = 0.0\nvalue = 1.0", "structure.effects[0].value"),
        (
            "x_start = 0.0\nvalue = 0.5\npoint = 2",
            "structure.effects[0].point",
        ),
    ] {
        let msg = parse(text).unwrap_err().to_string();
        assert!(
            msg.contains(key) && msg.contains("gen.toml"),
            "{text}: {msg}"
        );
    }
    // A region outside the block: the runner's assembly names the key.
    let (spec, _) = joint();
    let msg = adhesive_region_stiffness(&spec, 0.045, 0.060, "structure.effects[0].x_start")
        .unwrap_err()
        .to_string();
    assert!(msg.contains("structure.effects[0].x_start"), "{msg}");
}

/// The adherend-damping effect of the forward model (the runner's term `j g K_b` on the term
/// ROM wrapping the certified ROM) equals the full sparse model whose beam damping
/// `D_b = g K_b` is assembled by the mesher (`[structure.beam.damping] structural = g`), also
/// with a beam modulus factor on (the mesher's beam at (1 + b) E, D_b = g K_b of that beam);
/// its Jacobian column matches a central difference of the forward model.
#[test]
fn adherend_damping_effect_equals_the_full_model_with_beam_damping() {
    use rfmlab::forward::{Effect, EffectTerm, Effects, ForwardModel};
    let (_, built) = joint();
    let model = &built.model;
    assert!(model.d_b.is_none());
    let inputs = [0, 1, 2, 3];
    let (plain, _) = build_rom(model, &inputs, &params()).unwrap();
    let ts = vec![rfmlab::diagnose::terms::adherend_damping_term(model)];
    let (tr, cert) = build_term_rom(model, &inputs, &params(), &ts).unwrap();
    eprintln!(
        "adherend damping term ROM: n_r {}, certificate {:.3e} ({:?})",
        cert.basis_size, cert.max_rel_error, cert.per_case
    );
    assert!(cert.passed && cert.max_rel_error <= 1e-6);
    let eng = WithTerms::new(&plain, &tr).unwrap();
    let law = rfmlab::material::Model3;
    let p = [4.7121e6, 5.5573e6, 6.0491e3];
    let w: Vec<f64> = (0..80).map(|k| TAU * (2.1 + 6.2 * k as f64)).collect();
    let outs = [0, 1, 2, 3];
    let g = 0.004;
    // The mesher's model with the beam at (1 + b) E and D_b = g K_b (independent assembly).
    let mesher = |b: f64| {
        let text = format!(
            "{}[structure.beam.damping]\nstructural = {g}\n",
            crate::runner_common::structure()
                .replace("E = 198e9", &format!("E = {:e}", 198e9 * (1.0 + b)))
        );
        let study = rfmlab::study::parse_str(
            &format!("[study]\nname = \"gen\"\n{text}"),
            std::path::Path::new("gen.toml"),
        )
        .unwrap();
        rfmlab::study::build::build_model(&study.structure, "gen.toml").unwrap()
    };
    for b in [0.0, 0.03] {
        let mut fm = ForwardModel::new(&eng, &law, &w, built.excitation, &outs, None).unwrap();
        fm.set_effects(Effects {
            terms: vec![
                EffectTerm {
                    effect: Effect::AdherendDamping,
                    value: g,
                    free: true,
                },
                EffectTerm {
                    effect: Effect::BeamModulus,
                    value: b,
                    free: false,
                },
            ],
        })
        .unwrap();
        let mut pp = p.to_vec();
        pp.push(g);
        let got = fm.exact(&pp, true).unwrap();
        let truth = mesher(b);
        assert!(truth.model.d_b.is_some());
        let full =
            FullModel::new(&truth.model, &[built.excitation], FullParams::default()).unwrap();
        let reference = ForwardModel::new(&full, &law, &w, built.excitation, &outs, None)
            .unwrap()
            .exact(&p, false)
            .unwrap()
            .values;
        let peak_err = |x: &[C64]| crate::structural_effects::rel_err_per_channel(x, &reference, 4);
        let err = peak_err(&got.values);
        // Without the damping the model is far from the reference: the check can fail.
        let mut p0 = pp.clone();
        p0[3] = 0.0;
        let undamped = peak_err(&fm.exact(&p0, false).unwrap().values);
        eprintln!("adherend damping g = {g}, beam factor {b}: forward model vs full {err:.3e} (undamped {undamped:.3e})");
        assert!(err <= 1e-6, "b = {b}: {err:.3e}");
        assert!(
            undamped > 1e-2,
            "b = {b}: damping changes the FRFs by {undamped:.3e} only"
        );
        // Jacobian column of g against a central difference
        let (dev, scale) = column_against_difference(&fm, &pp, &got.jac[3], 3, 1e-6);
        eprintln!("dH/dg: analytic vs FD {dev:.3e} of {scale:.3e}");
        assert!(
            scale > 0.0 && dev <= 1e-5 * scale,
            "{dev:.3e} of {scale:.3e}"
        );
    }
}

/// `[[structure.effects]]` of type "adherend_damping": a loss factor >= 0, no point, channel or
/// region keys; errors name the key. Its default prior is U(0, 0.01), one-sided, unit "1".
#[test]
fn declared_adherend_damping_is_validated() {
    use rfmlab::forward::Effect;
    let parse = |eff: &str| {
        rfmlab::study::parse_str(
            &format!(
                "[study]\nname = \"gen\"\n{}\n[[structure.effects]]\ntype = \"adherend_damping\"\n{eff}\n",
                crate::runner_common::structure()
            ),
            std::path::Path::new("gen.toml"),
        )
    };
    let ok = parse("value = 0.002").unwrap();
    assert_eq!(
        ok.declared_effects[0].kind,
        rfmlab::study::effects::DeclaredKind::AdherendDamping
    );
    for (text, key) in [
        ("value = -0.001", "structure.effects[0].value"),
        ("value = 0.001\npoint = 2", "structure.effects[0].point"),
        (
            "value = 0.001\nx_start = 0.0",
            "structure.effects[0].x_start",
        ),
    ] {
        let msg = parse(text).unwrap_err().to_string();
        assert!(
            msg.contains(key) && msg.contains("gen.toml"),
            "{text}: {msg}"
        );
    }
    let e = Effect::AdherendDamping;
    assert_eq!(
        (e.name().as_str(), e.kind(), e.unit()),
        ("adherend_damping", "adherend_damping", "1")
    );
    assert!(e.one_sided());
    assert_eq!(
        e.default_prior(),
        rfmlab::inference::prior::Prior::Uniform { lo: 0.0, hi: 0.01 }
    );
}

/// The term ROM's cache (src/rom/cache.rs): a saved ROM loads back with its certificate and
/// sweeps (values, dH/dE' and the terms' columns) bit for bit; the key changes with a term's
/// matrix, its enrichment values, the compression and the inputs; a damaged file or another
/// key loads nothing.
#[test]
fn term_rom_cache_round_trips_bit_for_bit_and_keys_every_setting() {
    use rfmlab::rom::cache::{load_terms, save_terms, term_key};
    let (spec, built) = joint();
    let model = &built.model;
    let inputs = [built.excitation];
    let ts = terms(&spec, &model.k_b);
    let p = quick(1, 3);
    let (tr, cert) = build_term_rom(model, &inputs, &p, &ts[..1]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("terms.json");
    let key = term_key(model, &inputs, &p, &ts[..1]);
    save_terms(&file, &key, &tr, &cert).unwrap();
    let (back, cert_back) = load_terms(&file, &key).expect("cached term ROM");
    assert_eq!(cert_back.basis_size, cert.basis_size);
    // The certificate's numbers are JSON floats (serde_json's parser may be 1 ulp off); the
    // matrices are bit patterns, exact.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * a.abs().max(b.abs());
    assert!(close(cert_back.max_rel_error, cert.max_rel_error));
    assert_eq!(cert_back.per_case.len(), cert.per_case.len());
    for (a, b) in cert_back.per_case.iter().zip(&cert.per_case) {
        assert!(
            a.0 == b.0 && close(a.1, b.1) && close(a.2, b.2),
            "{a:?} vs {b:?}"
        );
    }
    let (plain, _) = build_rom(model, &inputs, &RomParams::default()).unwrap();
    let a_eng = WithTerms::new(&plain, &tr).unwrap();
    let b_eng = WithTerms::new(&plain, &back).unwrap();
    let w: Vec<f64> = (1..40).map(|k| TAU * 11.3 * k as f64).collect();
    let e = vec![C64::new(6e6, 1e6); w.len()];
    let coef = [TermCoef {
        index: 0,
        value: 0.7,
        offset: C64::new(0.0, 0.0),
        per_modulus: -1.0,
    }];
    let a = a_eng.sweep_terms(&w, &e, &coef, true).unwrap();
    let b = b_eng.sweep_terms(&w, &e, &coef, true).unwrap();
    assert_eq!(a.0.h, b.0.h);
    assert_eq!(a.0.dh_de, b.0.dh_de);
    assert_eq!(a.1, b.1);
    // Every setting is in the key.
    let mut other = ts[..1].to_vec();
    other[0].enrich_values = vec![0.9];
    assert_ne!(term_key(model, &inputs, &p, &other), key);
    assert_ne!(term_key(model, &inputs, &p, &ts[1..2]), key);
    let no_compress = RomParams {
        compress: None,
        ..p.clone()
    };
    assert_ne!(term_key(model, &inputs, &no_compress, &ts[..1]), key);
    assert_ne!(term_key(model, &[0], &p, &ts[..1]), key);
    assert_eq!(term_key(model, &inputs, &p, &ts[..1]), key);
    // Another key or a damaged file: nothing.
    assert!(load_terms(&file, &key[1..]).is_none());
    let text = std::fs::read(&file).unwrap();
    std::fs::write(&file, &text[..text.len() / 2]).unwrap();
    assert!(load_terms(&file, &key).is_none());
}
