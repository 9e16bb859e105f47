//! The resonator (a mass on a spring at a measured point, force read at the structure;
//! src/forward/effects.rs) against the full model and finite differences, and the closed loop
//! on data that carry one:
//! * on the test beam's certified ROM, the point-mass identity with the effective mass
//!   `m k / (k - w^2 m)` equals the full sparse solve of the model with the mass as one extra
//!   DOF on a spring to the point (relative error <= 1e-6 of each FRF's peak), over the band and
//!   at lines within 0.1 % to 1e-6 of the resonator's own frequency, at the drive point and
//!   away from it; k -> inf gives a point mass;
//! * its Jacobian column matches central differences, at a size and at zero;
//! * 20 g on 2e5 N/m at the drive point of the dense chain: the refit evidence of the
//!   resonator beats the point mass's at the same point (a fast check), and the whole loop
//!   names the resonator first within 15 % and accepts no point mass or beam factor.

use crate::closed_loop::{posterior, simulate, TRUTH};
use crate::spring_model::measured_engine;
use crate::structural_effects::{column_error, fd_column, rel_err_per_channel};
use rfmlab::forward::{Effect, EffectTerm, Effects, ForwardModel};
use rfmlab::inference::likelihood::FrfPosterior;
use rfmlab::material::Model3;
use std::f64::consts::TAU;

fn term(effect: Effect, value: f64, free: bool) -> EffectTerm {
    EffectTerm {
        effect,
        value,
        free,
    }
}

fn resonator(point: usize, k: f64) -> Effect {
    Effect::Resonator {
        point,
        id: point as u32 + 1,
        stiffness_n_m: k,
    }
}

/// The lines of the check: off the certificate's grid across the ROM's band (its modes among
/// them), and at relative offsets of 1e-3 to 1e-6 about the resonator's own frequency `f_r_hz`.
fn lines(f_r_hz: f64) -> Vec<f64> {
    let mut w: Vec<f64> = (0..150)
        .map(|k| TAU * (1.0 + 478.0 * k as f64 / 149.0 + 0.37))
        .collect();
    for d in [-1e-3, -1e-5, -1e-6, 1e-6, 1e-4, 1e-3] {
        w.push(TAU * f_r_hz * (1.0 + d));
    }
    w
}

#[test]
fn resonator_on_the_rom_equals_the_full_model_with_the_mass_as_a_dof() {
    use rfmlab::frf::{FullModel, FullParams};
    use rfmlab::rom::{build_rom, RomParams};
    let model = crate::rom_model::beam_model(60);
    let inputs = [0, 1, 2, 3];
    let (rom, cert) = build_rom(&model, &inputs, &RomParams::default()).unwrap();
    assert!(cert.passed);
    let outs = [0, 1, 2, 3];
    let drive = 1;
    // (point, m, k): at the drive point and away from it, both tuned inside the band.
    for (point, m, k) in [(1, 0.02_f64, 1e5_f64), (3, 0.01, 4e4)] {
        let f_r = (k / m).sqrt() / TAU;
        let w = lines(f_r);
        // The full model with one more DOF, the mass m, joined by a spring k to the point: the
        // arrangement of a shaker's moving mass on its stinger, driven here at the structure.
        let (aug, _) = model.with_shaker(point, m, k, 9001).unwrap();
        let full = FullModel::new(&aug, &[drive], FullParams::default()).unwrap();
        let reference = ForwardModel::new(&full, &Model3, &w, drive, &outs, None)
            .unwrap()
            .exact(&TRUTH, false)
            .unwrap()
            .values;
        let mut fm = ForwardModel::new(&rom, &Model3, &w, drive, &outs, None).unwrap();
        fm.set_effects(Effects {
            terms: vec![term(resonator(point, k), m, false)],
        })
        .unwrap();
        let got = fm.exact(&TRUTH, false).unwrap().values;
        let e = rel_err_per_channel(&got, &reference, 4);
        let plain = ForwardModel::new(&rom, &Model3, &w, drive, &outs, None)
            .unwrap()
            .exact(&TRUTH, false)
            .unwrap()
            .values;
        let e_plain = rel_err_per_channel(&plain, &reference, 4);
        let mut rigid = ForwardModel::new(&rom, &Model3, &w, drive, &outs, None).unwrap();
        rigid
            .set_effects(Effects {
                terms: vec![term(
                    Effect::PointMass {
                        point,
                        id: point as u32 + 1,
                    },
                    m,
                    false,
                )],
            })
            .unwrap();
        let e_rigid =
            rel_err_per_channel(&rigid.exact(&TRUTH, false).unwrap().values, &reference, 4);
        eprintln!(
            "resonator {m} kg on {k:e} N/m at point {point} ({f_r:.2} Hz): ROM + algebra vs full model {e:.2e} of the peak; without it {e_plain:.2e}; as a rigid mass {e_rigid:.2e}"
        );
        assert!(e <= 1e-6, "relative error {e:e}");
        // Neither the bare structure nor a rigid mass of the same size stands in for it (the
        // test can fail).
        assert!(e_plain > 1e-2 && e_rigid > 1e-2, "{e_plain:e} {e_rigid:e}");
    }
}

#[test]
fn a_stiff_resonator_is_a_point_mass_and_a_massless_one_is_nothing() {
    let eng = measured_engine();
    let w: Vec<f64> = (0..160).map(|i| TAU * (8.0 + 6.0 * i as f64)).collect();
    let run = |terms: Vec<EffectTerm>| {
        let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
        fm.set_effects(Effects { terms }).unwrap();
        fm.exact(&TRUTH, false).unwrap().values
    };
    let bare = run(vec![]);
    let massless = run(vec![term(resonator(2, 2e5), 0.0, false)]);
    assert!(rel_err_per_channel(&massless, &bare, 4) < 1e-14);
    let stiff = run(vec![term(resonator(2, 1e16), 0.02, false)]);
    let mass = run(vec![term(
        Effect::PointMass { point: 2, id: 3 },
        0.02,
        false,
    )]);
    let e = rel_err_per_channel(&stiff, &mass, 4);
    assert!(e < 1e-7, "k -> inf against a point mass: {e:e}");
    assert!(rel_err_per_channel(&bare, &mass, 4) > 1e-2);
}

#[test]
fn resonator_jacobian_matches_finite_differences() {
    let eng = measured_engine();
    let w: Vec<f64> = (0..160).map(|i| TAU * (8.0 + 6.0 * i as f64)).collect();
    let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
    fm.set_effects(Effects {
        terms: vec![
            term(resonator(1, 2e5), 0.0, true),
            term(Effect::PointMass { point: 3, id: 4 }, 0.004, false),
        ],
    })
    .unwrap();
    let q = TRUTH.len();
    let mut worst: f64 = 0.0;
    for m in [0.02, 0.0] {
        let mut p = TRUTH.to_vec();
        p.push(m);
        let pred = fm.predict(&p, true).unwrap();
        // 5e-6 of the size: near the resonator's own frequency (503 Hz, lines 3 Hz away) the
        // FRF bends fast in m, and a central difference of 1e-6 kg leaves a truncation error of
        // about 1e-5 of the column.
        let h = 1e-7;
        let fd = fd_column(&fm, &p, q, h, &pred.values);
        let (err, peak) = column_error(&pred.jac[q], &fd);
        eprintln!("resonator column at {m} kg: error {err:.2e} of {peak:.2e}");
        assert!(peak > 0.0 && err < 1e-5 * peak, "error {err:e} of {peak:e}");
        worst = worst.max(err / peak);
    }
    eprintln!("resonator column: worst relative error {worst:.2e}");
}

/// The case: 20 g on the default 2e5 N/m (503 Hz) at the drive point (engine point 1, id 2).
const MASS: f64 = 0.02;

fn case() -> (Effect, rfmlab::rfm::DenseEngine) {
    (resonator(1, 2e5), measured_engine())
}

/// The refit of `post` with `effect` free from the truth: the log evidence and the size.
fn refit(post: &mut FrfPosterior<'_>, effect: Effect, start: f64) -> (f64, f64) {
    use rfmlab::inference::map::{find_map, MapParams, SearchMethod};
    use rfmlab::inference::prior::Prior;
    post.likelihood
        .forward
        .set_effects(Effects {
            terms: vec![term(effect.clone(), start, true)],
        })
        .unwrap();
    let mut priors = post.priors[..3].to_vec();
    priors.push(effect.default_prior());
    priors.extend(post.priors[3..].iter().cloned());
    assert!(matches!(priors[3], Prior::Uniform { .. }));
    post.priors = priors;
    let mut names = post.likelihood.forward.param_names();
    names.extend(post.likelihood.noise_names().iter().cloned());
    post.names = names;
    let mut p0 = TRUTH.to_vec();
    p0.push(start);
    let x0 = post.unconstrained(&p0);
    let params = MapParams {
        n_starts: 0,
        search: SearchMethod::GaussNewton,
        ..MapParams::default()
    };
    let r = find_map(&*post, Some(&x0), &params, &|| {}).unwrap();
    (r.laplace.log_evidence, r.map_physical[3])
}

/// The fast check of the loop's choice: on the case's data the resonator refitted from the
/// truth has a far higher Laplace evidence than a rigid mass at the same point refitted from
/// the resonator's low-frequency equivalent (the two tie in the score test at zero).
#[test]
fn resonator_refit_beats_a_point_mass_by_evidence() {
    let (effect, eng) = case();
    let (x, v) = simulate(&eng, Some((effect.clone(), MASS)), 7);
    let mut post = posterior(&eng, x.clone(), v.clone());
    let (ev_res, size) = refit(&mut post, effect, MASS);
    let mut post = posterior(&eng, x, v);
    let (ev_mass, m_size) = refit(&mut post, Effect::PointMass { point: 1, id: 2 }, MASS);
    eprintln!(
        "resonator refit {size:.5e} kg, log evidence {ev_res:.1}; point mass {m_size:.5e} kg, {ev_mass:.1}; gain {:.1} nats",
        ev_res - ev_mass
    );
    assert!((size - MASS).abs() < 0.02 * MASS, "size {size}");
    assert!(ev_res - ev_mass > 50.0, "{ev_res} vs {ev_mass}");
}

/// The whole loop on the case (a few seconds in debug): the resonator is named first, sized
/// within 15 %, and no point mass or beam factor is accepted with it.
#[test]
fn the_loop_names_the_resonator_at_the_drive_point() {
    use rfmlab::closed_loop::{default_candidates, run_closed_loop, ClosedLoopParams};
    let t0 = std::time::Instant::now();
    let (effect, eng) = case();
    let (x, v) = simulate(&eng, Some((effect.clone(), MASS)), 7);
    let mut post = posterior(&eng, x, v);
    let start = post.unconstrained(&[TRUTH[0] * 1.2, TRUTH[1] * 0.8, TRUTH[2] * 1.2]);
    let cands = default_candidates(&[1, 2, 3, 4], &[(0, 1), (1, 2), (2, 3), (3, 4)]);
    let res = run_closed_loop(&mut post, &start, &cands, &ClosedLoopParams::default()).unwrap();
    for c in &res.candidates {
        eprintln!(
            "round {} rank {} {} T {:.1} p {:.2e} refit {:?}",
            c.round,
            c.rank,
            c.effect.name(),
            c.score,
            c.p_value,
            c.refit
        );
    }
    eprintln!(
        "{}; chi2 {:.3} -> {:.3}; {:.0} s",
        res.conclusion,
        res.before.residuals.chi2_normalised,
        res.after.residuals.chi2_normalised,
        t0.elapsed().as_secs_f64()
    );
    let (first, size, _) = res.accepted.first().expect("nothing accepted");
    assert_eq!(first, &effect, "first accepted {}", first.name());
    assert!((size - MASS).abs() < 0.15 * MASS, "size {size}");
    for (e, _, _) in &res.accepted {
        assert!(
            !matches!(e, Effect::PointMass { .. } | Effect::BeamModulus),
            "accepted {} too: {}",
            e.name(),
            res.conclusion
        );
    }
}
