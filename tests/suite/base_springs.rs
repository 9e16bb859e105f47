//! Base springs under the adhesive (src/fe/base.rs) against physics:
//! * the unit spring matrices integrate the base face's area (a rigid translation of the face
//!   by u stores k A u^2 / 2);
//! * stiffer springs tend to the fixed base: the first modes' eigenvalues of the model on
//!   springs approach the fixed model's, the gap falling in proportion to 1 / k;
//! * the first mode falls monotonically as the springs soften.

use rfmlab::common::C64;
use rfmlab::fe::base::{base_spring_model, BaseSprings};
use rfmlab::modes::{complex_modes, ModesParams};

/// Model 4 at the first mode of level 1 (method.md).
const E_STAR: C64 = C64::new(6.974e6, 1.4827e6);

/// The first two y-dominant modes (what the rig measures; the free DOFs are numbered node by
/// node, x y z, in both models, so the DOF's axis is its index mod 3).
fn lambdas(model: &rfmlab::fe::StructuralModel) -> Vec<C64> {
    let axes: Vec<u8> = (0..model.n_dof()).map(|d| (d % 3) as u8).collect();
    let modes = complex_modes(model, E_STAR, 6, Some(&axes), &ModesParams::default()).unwrap();
    let y: Vec<C64> = modes
        .iter()
        .filter(|m| m.y_dominant == Some(true))
        .map(|m| m.lambda)
        .take(2)
        .collect();
    assert_eq!(y.len(), 2, "two y modes among the lowest six");
    y
}

#[test]
fn unit_spring_matrices_integrate_the_base_area() {
    let b = base_spring_model(&crate::runner_common::joint_spec()).unwrap();
    assert!((b.area_m2 - 0.050 * 0.020).abs() < 1e-15, "{}", b.area_m2);
    let n = b.free.n_dof();
    let sum_comp = |k: &rfmlab::fe::model::SpMat, comp: usize| -> f64 {
        k.triplet_iter()
            .filter(|t| t.row % 3 == comp && t.col % 3 == comp)
            .map(|t| *t.val)
            .sum()
    };
    let area = b.area_m2;
    assert!((sum_comp(&b.k_normal, 1) - area).abs() < 1e-15 * n as f64);
    assert!(sum_comp(&b.k_normal, 0).abs() == 0.0 && sum_comp(&b.k_normal, 2) == 0.0);
    for comp in [0, 2] {
        assert!((sum_comp(&b.k_tangential, comp) - area).abs() < 1e-15 * n as f64);
    }
    assert_eq!(sum_comp(&b.k_tangential, 1), 0.0);
    // The test structure's 10 mm mesh: 5 x 2 faces of 8 nodes, 11 x 5 lattice points less the
    // 10 face centres.
    assert_eq!(b.n_base_nodes, 11 * 5 - 10);
}

#[test]
fn stiff_springs_tend_to_the_fixed_base_and_softer_ones_lower_the_first_mode() {
    let spec = crate::runner_common::joint_spec();
    let fixed = lambdas(&rfmlab::fe::joint::build_joint_model(&spec).unwrap().0);
    let b = base_spring_model(&spec).unwrap();
    let mut gaps = Vec::new();
    let mut f1 = Vec::new();
    for k in [1e10, 3e10, 1e11, 1e13, 1e15] {
        let m = b
            .on_springs(&BaseSprings {
                normal_n_m3: k,
                tangential_n_m3: k / 3.5,
            })
            .unwrap();
        let l = lambdas(&m);
        let gap = (0..2)
            .map(|i| ((l[i] - fixed[i]) / fixed[i]).norm())
            .fold(0.0, f64::max);
        eprintln!(
            "k_n {k:.1e}: f1 ratio {:.6}, gap {gap:.3e}",
            (l[0].re / fixed[0].re).sqrt()
        );
        gaps.push(gap);
        f1.push(l[0].re);
    }
    assert!(f1.windows(2).all(|w| w[1] > w[0]), "{f1:?}");
    // 1 / k convergence: 100 times stiffer springs, about 100 times smaller gap.
    let r = gaps[3] / gaps[4];
    assert!(r > 50.0 && r < 200.0, "gap ratio {r}: {gaps:?}");
    assert!(gaps[4] < 1e-5, "{gaps:?}");
}

/// The acceptance case `td_base_springs` (studies/data/closed_loop/cases/): its springs lower
/// the first mode of the 5 mm joint by 3 % (the case's size), at Model 4's modulus there.
#[test]
fn the_acceptance_case_lowers_the_first_mode_by_3_percent() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("studies/data/closed_loop/cases/td_base_springs.toml");
    let ex = rfmlab::study::experiment::load_experiment(&path).unwrap();
    let springs = ex.base_springs.expect("the case declares base springs");
    let spec = rfmlab::study::build::joint_spec(&ex.structure).unwrap();
    let fixed = lambdas(&rfmlab::fe::joint::build_joint_model(&spec).unwrap().0);
    let on = lambdas(&rfmlab::fe::base::joint_model_on_springs(&spec, &springs, "k").unwrap());
    let drop = 1.0 - (on[0].re / fixed[0].re).sqrt();
    eprintln!(
        "first mode {:.4} Hz -> {:.4} Hz: {:.3} % lower",
        fixed[0].re.sqrt() / std::f64::consts::TAU,
        on[0].re.sqrt() / std::f64::consts::TAU,
        100.0 * drop
    );
    assert!((drop - 0.03).abs() < 0.001, "drop {drop}");
    assert!(
        (springs.normal_n_m3 / springs.tangential_n_m3
            - rfmlab::forward::effects::DEFAULT_BASE_NORMAL_OVER_TANGENTIAL)
            .abs()
            < 1e-12
    );
}

/// The loop's base-springs engine (rfmlab::diagnose::terms::base_springs_term: a term ROM over
/// the free-base joint with a compliance term) against independent full models: the joint on
/// springs as `rfmlab simulate` builds it (fe::base::joint_model_on_springs) at the
/// acceptance case's size, and the fixed-base joint at compliance 0; dH/dc against
/// differences of the reduced sweep.
#[test]
fn base_springs_term_rom_matches_the_full_models_and_its_derivative() {
    use rfmlab::frf::{FrfEngine, FullModel, FullParams, TermCoef};
    use std::f64::consts::TAU;
    let spec = crate::runner_common::joint_spec();
    let built = crate::runner_common::built_structure();
    let inputs = [built.excitation];
    let (model, term) = rfmlab::diagnose::terms::base_springs_term(&spec, 3.5).unwrap();
    let params = crate::rom_terms::params();
    let (rom, cert) = rfmlab::rom::term_build::build_term_rom(
        &model,
        &inputs,
        &params,
        std::slice::from_ref(&term),
    )
    .unwrap();
    eprintln!(
        "base term ROM: n_r {} (enriched {}, compression error {:?}), certificate {:.3e} {:?}, basis {:.1} s, certify {:.1} s",
        cert.basis_size,
        cert.enriched_basis_size,
        cert.compression_error,
        cert.max_rel_error,
        cert.per_case,
        cert.seconds_basis,
        cert.seconds_certify
    );
    assert!(cert.passed && cert.max_rel_error <= 1e-6);
    let w: Vec<f64> = (0..60).map(|k| TAU * (3.3 + 8.1 * k as f64)).collect();
    let e = vec![C64::new(4.1e6, 1.3e6); w.len()];
    let coef = |v: f64| {
        [TermCoef {
            index: 0,
            value: v,
            offset: term.offset,
            per_modulus: 0.0,
        }]
    };
    let c_case = 1.0 / 3.13e10;
    let on_springs = rfmlab::fe::base::joint_model_on_springs(
        &spec,
        &BaseSprings {
            normal_n_m3: 1.0 / c_case,
            tangential_n_m3: 1.0 / (3.5 * c_case),
        },
        "k",
    )
    .unwrap();
    for (name, full_model, v) in [
        ("springs of the case", &on_springs, c_case),
        ("fixed base", &built.model, 0.0),
    ] {
        let full = FullModel::new(full_model, &inputs, FullParams::default()).unwrap();
        let reference = full.sweep(&w, &e, false).unwrap();
        let (got, _) = rom.sweep_terms(&w, &e, &coef(v), false).unwrap();
        let err = crate::rom_terms::rel_err(&got, &reference);
        eprintln!("{name} (c = {v:.3e}): error {err:.3e}");
        assert!(err <= 1e-6, "{name}: {err:.3e}");
    }
    // The springs do change the FRFs: the check above can fail.
    let fixed = FullModel::new(&built.model, &inputs, FullParams::default())
        .unwrap()
        .sweep(&w, &e, false)
        .unwrap();
    let (at_case, _) = rom.sweep_terms(&w, &e, &coef(c_case), false).unwrap();
    assert!(crate::rom_terms::rel_err(&at_case, &fixed) > 1e-2);
    // dH/dc: central difference at the case's size, forward difference at 0.
    let blk = at_case.n_out * at_case.n_in;
    let peak = at_case.h.iter().map(|z| z.norm()).fold(0.0, f64::max);
    // At the rigid limit the derivative is the term ROM's own forward difference over
    // 1e-4 v_ref (rom::terms::COMPLIANCE_FD_STEP): 0.1 % there against this test's smaller
    // step; 1e-7 at the case's size (the springs' forces through the pseudo-inverse).
    for (v, h, central, tol) in [
        (c_case, 1e-3 * c_case, true, 1e-5),
        (0.0, 1e-4 * c_case, false, 5e-3),
    ] {
        let (_, dt) = rom.sweep_terms(&w, &e, &coef(v), true).unwrap();
        let (p, _) = rom.sweep_terms(&w, &e, &coef(v + h), false).unwrap();
        let (m, _) = rom
            .sweep_terms(&w, &e, &coef(if central { v - h } else { v }), false)
            .unwrap();
        let step = if central { 2.0 * h } else { h };
        let err = (0..w.len() * blk)
            .map(|i| ((p.h[i] - m.h[i]) / step - dt[0][i]).norm() * c_case)
            .fold(0.0, f64::max);
        let size = dt[0].iter().map(|z| z.norm()).fold(0.0, f64::max) * c_case;
        eprintln!(
            "dH/dc at {v:.3e}: |analytic - FD| c {err:.3e}, |dH/dc| c {size:.3e}, peak {peak:.3e}"
        );
        assert!(size > 1e-2 * peak);
        assert!(err <= tol * size, "{err:.3e} of {size:.3e}");
    }
}

/// The forward model's column of the base springs' compliance (all four points as inputs,
/// driven at the excitation, read at the four points, Model 4) against differences of its
/// own predictions, at the rigid limit (where the loop's score test evaluates it; there the
/// term ROM takes a forward difference, rom::terms::COMPLIANCE_FD_BELOW) and at the
/// acceptance case's size; and the column lies almost wholly in the span of the law's columns
/// (R^2 > 0.99): the springs soften the joint as a softer adhesive does, which is why the
/// loop reports them as confounded (src/closed_loop/confounding.rs).
#[test]
fn forward_model_column_of_the_base_springs_matches_differences() {
    use rfmlab::forward::{Effect, EffectTerm, Effects, ForwardModel};
    use rfmlab::rom::{build_term_rom, WithTerms};
    use std::f64::consts::TAU;
    let spec = crate::runner_common::joint_spec();
    let built = crate::runner_common::built_structure();
    let inputs = [0, 1, 2, 3];
    let params = crate::rom_terms::params();
    let (plain, _) = rfmlab::rom::build_rom(&built.model, &inputs, &params).unwrap();
    let (model, term) = rfmlab::diagnose::terms::base_springs_term(&spec, 3.5).unwrap();
    let (tr, cert) = build_term_rom(&model, &inputs, &params, std::slice::from_ref(&term)).unwrap();
    assert!(cert.passed);
    let eng = WithTerms::new(&plain, &tr).unwrap();
    let law = rfmlab::material::Model4;
    let p = [6.67e6, 0.944e6, 3.1487e6, 4181.0];
    let w: Vec<f64> = (0..120).map(|k| TAU * (5.0 + 4.0 * k as f64)).collect();
    let outs = [0, 1, 2, 3];
    let mut fm = ForwardModel::new(&eng, &law, &w, built.excitation, &outs, None).unwrap();
    fm.set_effects(Effects {
        terms: vec![EffectTerm {
            effect: Effect::BaseSprings {
                normal_over_tangential: 3.5,
            },
            value: 0.0,
            free: true,
        }],
    })
    .unwrap();
    let c_case = 1.0 / 3.13e10;
    let at = |c: f64, d: bool| {
        let mut q = p.to_vec();
        q.push(c);
        fm.predict(&q, d).unwrap()
    };
    let dot = |a: &[C64], b: &[C64]| a.iter().zip(b).map(|(x, y)| (x.conj() * y).re).sum::<f64>();
    for (c, h, central) in [(0.0, 3e-4 * c_case, false), (c_case, 1e-3 * c_case, true)] {
        let pred = at(c, true);
        let col = &pred.jac[4];
        let hp = at(c + h, false).values;
        let hm = at(if central { c - h } else { c }, false).values;
        let step = if central { 2.0 * h } else { h };
        let diff: Vec<C64> = hp.iter().zip(&hm).map(|(a, b)| (a - b) / step).collect();
        let size = dot(col, col).sqrt();
        let err: Vec<C64> = col.iter().zip(&diff).map(|(a, b)| a - b).collect();
        let err = dot(&err, &err).sqrt();
        // R^2 of the column on the law's (scaled by the parameters) by the normal equations.
        let law_cols: Vec<Vec<C64>> = (0..4)
            .map(|k| pred.jac[k].iter().map(|z| z * p[k]).collect())
            .collect();
        let g = faer::Mat::<f64>::from_fn(4, 4, |i, j| dot(&law_cols[i], &law_cols[j]));
        let r = faer::Mat::<f64>::from_fn(4, 1, |i, _| dot(&law_cols[i], col));
        let a = faer::linalg::solvers::Solve::solve(&g.llt(faer::Side::Lower).unwrap(), &r);
        let r2 = (0..4).map(|i| a[(i, 0)] * r[(i, 0)]).sum::<f64>() / (size * size);
        eprintln!("c = {c:.3e}: |column| {size:.3e}, |column - difference| {err:.3e}, R^2 {r2:.6}");
        assert!(err <= 1e-2 * size, "c = {c:.3e}: {err:.3e} of {size:.3e}");
        assert!(r2 > 0.99, "c = {c:.3e}: R^2 {r2}");
    }
}

/// Two shapes of the springs in one term ROM (rfmlab::diagnose::terms::base_springs_terms: the
/// model holds the thin layer's shape, the equal springs replace it when on) against the
/// independent full models of the joint on each shape's springs (fe::base::joint_model_on_springs)
/// and the fixed base; the replacing term's derivative against differences of the reduced
/// sweep. The shapes differ by more than the tolerance: the checks can fail.
#[test]
fn two_spring_shapes_share_one_term_rom_and_match_the_full_models() {
    use rfmlab::frf::{FrfEngine, FullModel, FullParams, TermCoef};
    use std::f64::consts::TAU;
    let spec = crate::runner_common::joint_spec();
    let built = crate::runner_common::built_structure();
    let inputs = [built.excitation];
    let (model, terms) = rfmlab::diagnose::terms::base_springs_terms(&spec, &[3.5, 1.0]).unwrap();
    assert_eq!(terms[0].name, "base_springs");
    assert_eq!(terms[1].name, "base_springs_iso");
    let (rom, cert) = rfmlab::rom::term_build::build_term_rom(
        &model,
        &inputs,
        &crate::rom_terms::params(),
        &terms,
    )
    .unwrap();
    eprintln!(
        "two shapes: n_r {} (enriched {}), certificate {:.3e} {:?}",
        cert.basis_size, cert.enriched_basis_size, cert.max_rel_error, cert.per_case
    );
    assert!(cert.passed && cert.max_rel_error <= 1e-6);
    assert!(cert.basis_size < cert.enriched_basis_size, "compressed");
    let w: Vec<f64> = (0..60).map(|k| TAU * (3.3 + 8.1 * k as f64)).collect();
    let e = vec![C64::new(4.1e6, 1.3e6); w.len()];
    let coef = |index: usize, value: f64| {
        [TermCoef {
            index,
            value,
            offset: C64::new(1.0, 0.0),
            per_modulus: 0.0,
        }]
    };
    let c_case = 1.0 / 3.0e10;
    let on = |ratio: f64| {
        rfmlab::fe::base::joint_model_on_springs(
            &spec,
            &BaseSprings {
                normal_n_m3: 1.0 / c_case,
                tangential_n_m3: 1.0 / (ratio * c_case),
            },
            "k",
        )
        .unwrap()
    };
    let full = |m: &rfmlab::fe::StructuralModel| {
        FullModel::new(m, &inputs, FullParams::default())
            .unwrap()
            .sweep(&w, &e, false)
            .unwrap()
    };
    let layer = full(&on(3.5));
    let equal = full(&on(1.0));
    let fixed = full(&built.model);
    for (name, index, v, reference) in [
        ("layer", 0, c_case, &layer),
        ("equal", 1, c_case, &equal),
        ("fixed by the equal springs' term", 1, 0.0, &fixed),
    ] {
        let (got, _) = rom.sweep_terms(&w, &e, &coef(index, v), false).unwrap();
        let err = crate::rom_terms::rel_err(&got, reference);
        eprintln!("{name}: error {err:.3e}");
        assert!(err <= 1e-6, "{name}: {err:.3e}");
    }
    let apart = crate::rom_terms::rel_err(&layer, &equal);
    eprintln!("layer against equal springs: {apart:.3e}");
    assert!(apart > 1e-4);
    // dH/dc of the replacing term at the case's size: central difference.
    let h = 1e-3 * c_case;
    let (_, dt) = rom.sweep_terms(&w, &e, &coef(1, c_case), true).unwrap();
    let (p, _) = rom
        .sweep_terms(&w, &e, &coef(1, c_case + h), false)
        .unwrap();
    let (m, _) = rom
        .sweep_terms(&w, &e, &coef(1, c_case - h), false)
        .unwrap();
    let err = (0..p.h.len())
        .map(|i| ((p.h[i] - m.h[i]) / (2.0 * h) - dt[0][i]).norm())
        .fold(0.0, f64::max);
    let size = dt[0].iter().map(|z| z.norm()).fold(0.0, f64::max);
    eprintln!("dH/dc of the equal springs: |analytic - FD| {err:.3e} of {size:.3e}");
    assert!(err <= 1e-5 * size, "{err:.3e} of {size:.3e}");
}
