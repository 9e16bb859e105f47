//! ROM and pencil-sweep tests on a small beam-on-adhesive model (Euler-Bernoulli beam FE,
//! 300 mm steel, resting on a layer of adhesive springs with their own mass under the first
//! 50 mm, fixed below), with a dense complex reference solve of the full model.

use crate::rom_model::beam_model;
use rfmlab::common::C64;
use rfmlab::fe::model::{SpMat, StructuralModel};
use rfmlab::frf::FrfEngine;
use rfmlab::rom::{build_rom, ModulusRange, RomError, RomParams};
use std::f64::consts::PI;

fn dense(a: &SpMat) -> Vec<Vec<f64>> {
    let n = a.nrows();
    let mut d = vec![vec![0.0; n]; n];
    for j in 0..n {
        for p in a.symbolic().col_range(j) {
            d[a.symbolic().row_idx()[p]][j] += a.val()[p];
        }
    }
    d
}

/// Full-model receptance H_i,input by dense Gaussian elimination.
fn full_h(model: &StructuralModel, omega: f64, e: C64, input: usize) -> Vec<C64> {
    let n = model.n_dof();
    let (m, k, s) = (dense(&model.m), dense(&model.k_b), dense(&model.s));
    let c = dense(model.c_b.as_ref().unwrap());
    let d = dense(model.d_b.as_ref().unwrap());
    let mut a: Vec<Vec<C64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    C64::new(
                        -omega * omega * m[i][j] + k[i][j],
                        omega * c[i][j] + d[i][j],
                    ) + e * s[i][j]
                })
                .collect()
        })
        .collect();
    let mut b = vec![C64::new(0.0, 0.0); n];
    for &(dof, w) in &model.points[input].dofs {
        b[dof] += w;
    }
    for col in 0..n {
        let p = (col..n)
            .max_by(|&x, &y| a[x][col].norm().total_cmp(&a[y][col].norm()))
            .unwrap();
        a.swap(col, p);
        b.swap(col, p);
        for r in col + 1..n {
            let f = a[r][col] / a[col][col];
            for cc in col..n {
                let v = a[col][cc];
                a[r][cc] -= f * v;
            }
            let v = b[col];
            b[r] -= f * v;
        }
    }
    for r in (0..n).rev() {
        let mut acc = b[r];
        for cc in r + 1..n {
            acc -= a[r][cc] * b[cc];
        }
        b[r] = acc / a[r][r];
    }
    model
        .points
        .iter()
        .map(|p| p.dofs.iter().map(|&(dof, w)| b[dof] * w).sum())
        .collect()
}

/// Deterministic pseudo-random numbers (xorshift), in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn random_modulus(r: &mut Rng, range: &ModulusRange) -> C64 {
    let lg = |a: f64, b: f64, u: f64| (a.ln() + (b.ln() - a.ln()) * u).exp();
    C64::new(
        lg(range.e_storage_pa.0, range.e_storage_pa.1, r.next()),
        lg(range.e_loss_pa.0, range.e_loss_pa.1, r.next()),
    )
}

fn lines_500() -> Vec<f64> {
    (1..=500).map(|f| 2.0 * PI * f as f64).collect()
}

/// Max over FRFs of max_l |a - b| / max_l |b|.
fn rel_err(a: &[C64], b: &[C64], n_lines: usize, blk: usize) -> f64 {
    (0..blk)
        .map(|q| {
            let peak = (0..n_lines)
                .map(|l| b[l * blk + q].norm())
                .fold(0.0, f64::max);
            (0..n_lines)
                .map(|l| (a[l * blk + q] - b[l * blk + q]).norm())
                .fold(0.0, f64::max)
                / peak
        })
        .fold(0.0, f64::max)
}

#[test]
fn certified_rom_matches_full_model_off_the_validation_set() {
    let model = beam_model(60);
    let params = RomParams::default();
    let (rom, cert) = build_rom(&model, &[1], &params).expect("certified ROM");
    eprintln!("n = {}, certificate: {cert:?}", model.n_dof());
    assert!(cert.passed && cert.max_rel_error <= 1e-6);
    assert!(
        cert.basis_size < model.n_dof(),
        "basis must be smaller than the model"
    );
    // random moduli (not on the validation grid), 1 Hz lines; error relative to each FRF's peak
    let mut r = Rng(0x5eed_1234);
    let omega: Vec<f64> = (0..120)
        .map(|k| 2.0 * PI * (1.0 + 499.0 * k as f64 / 119.0 + 0.37))
        .collect();
    for _ in 0..4 {
        let e = random_modulus(&mut r, &params.range);
        let sw = rom.lu_sweep(&omega, &vec![e; omega.len()], false).unwrap();
        let full: Vec<C64> = omega
            .iter()
            .flat_map(|&w| full_h(&model, w, e, 1))
            .collect();
        let err = rel_err(&sw.h, &full, omega.len(), 4);
        eprintln!("E* = {e:.3e}: ROM vs dense full {err:.2e}");
        assert!(err < 1e-5, "ROM error {err} at E* = {e}");
    }
}

#[test]
fn pencil_sweep_agrees_with_reduced_lu_to_1e_10_and_derivatives_check() {
    let model = beam_model(60);
    let (rom, _) = build_rom(&model, &[1], &RomParams::default()).unwrap();
    let omega = lines_500();
    let pencil = rom.prepare(&omega).unwrap();
    let (near, mom) = pencil.mean_terms();
    eprintln!(
        "n_r = {}, near terms {near:.1}, moments {mom:.1}, fallback {}, max cond {:.2e}",
        rom.basis_size(),
        pencil.n_fallback_lines(),
        pencil.max_condition()
    );
    let mut r = Rng(42);
    for trial in 0..3 {
        // a smooth E*(w) curve inside the box plus some roughness
        let e_a = random_modulus(&mut r, &rom.range());
        let e_b = random_modulus(&mut r, &rom.range());
        let modulus: Vec<C64> = (0..omega.len())
            .map(|l| {
                let u = l as f64 / 499.0;
                e_a * (1.0 - u) + e_b * u
            })
            .collect();
        let p = pencil.sweep(&omega, &modulus, true).unwrap();
        let q = rom.lu_sweep(&omega, &modulus, true).unwrap();
        let (eh, ed, es) = (
            rel_err(&p.h, &q.h, 500, 4),
            rel_err(&p.dh_de, &q.dh_de, 500, 4),
            rel_err(&p.sh, &q.sh, 500, 4),
        );
        eprintln!("trial {trial}: h {eh:.2e} dh {ed:.2e} sh {es:.2e}");
        assert!(
            eh < 1e-10 && ed < 1e-10 && es < 1e-10,
            "pencil vs LU: {eh} {ed} {es}"
        );
    }
    // dH/dE' against a central difference of the LU sweep, and dH/dE'' = j dH/dE'
    let e = C64::new(3e6, 1e6);
    let idx = [5usize, 150, 390];
    let om: Vec<f64> = idx.iter().map(|&i| omega[i]).collect();
    let base = rom.lu_sweep(&om, &[e; 3], true).unwrap();
    let step = 1e-4 * e.norm();
    let hp = rom.lu_sweep(&om, &[e + step; 3], false).unwrap();
    let hm = rom.lu_sweep(&om, &[e - step; 3], false).unwrap();
    let hpi = rom
        .lu_sweep(&om, &[e + C64::new(0.0, step); 3], false)
        .unwrap();
    let hmi = rom
        .lu_sweep(&om, &[e - C64::new(0.0, step); 3], false)
        .unwrap();
    for q in 0..12 {
        let fd = (hp.h[q] - hm.h[q]) / (2.0 * step);
        let fdi = (hpi.h[q] - hmi.h[q]) / (2.0 * step);
        let d = base.dh_de[q];
        assert!((fd - d).norm() <= 1e-6 * d.norm(), "dH/dE' {d} vs FD {fd}");
        assert!(
            (fdi - C64::new(0.0, 1.0) * d).norm() <= 1e-6 * d.norm(),
            "dH/dE'' {fdi} vs j dH/dE' {}",
            C64::new(0.0, 1.0) * d
        );
    }
}

#[test]
fn sweeps_are_bit_identical_with_one_or_two_threads() {
    let model = beam_model(40);
    let params = RomParams::default();
    let omega = lines_500();
    let modulus: Vec<C64> = (0..500)
        .map(|l| C64::new(5e6 + 1e4 * l as f64, 1e6 + 2e3 * l as f64))
        .collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (rom, _) = build_rom(&model, &[1], &params).unwrap();
            let p = rom.prepare(&omega).unwrap();
            let s = p.sweep(&omega, &modulus, true).unwrap();
            let l = rom.lu_sweep(&omega, &modulus, true).unwrap();
            (s, l)
        })
    };
    let (a, la) = run(1);
    let (b, lb) = run(2);
    let bits = |v: &[C64]| {
        v.iter()
            .flat_map(|z| [z.re.to_bits(), z.im.to_bits()])
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&a.h), bits(&b.h));
    assert_eq!(bits(&a.dh_de), bits(&b.dh_de));
    assert_eq!(bits(&a.sh), bits(&b.sh));
    assert_eq!(bits(&la.h), bits(&lb.h));
}

#[test]
fn uncertified_rom_is_refused_unless_asked_and_bad_input_is_reported() {
    let model = beam_model(40);
    let strict = RomParams {
        tolerance: 1e-15,
        max_levels: 1,
        krylov_depth_initial: 1,
        ..RomParams::default()
    };
    match build_rom(&model, &[1], &strict) {
        Err(RomError::Uncertified { error, .. }) => assert!(error > 1e-15),
        other => panic!("expected Uncertified, got {:?}", other.map(|x| x.1)),
    }
    let (_, cert) = build_rom(
        &model,
        &[1],
        &RomParams {
            allow_uncertified: true,
            ..strict.clone()
        },
    )
    .unwrap();
    assert!(!cert.passed);
    assert!(matches!(
        build_rom(&model, &[7], &RomParams::default()),
        Err(RomError::Params(_))
    ));
    let bad = RomParams {
        range: ModulusRange {
            e_storage_pa: (5.0, 1.0),
            e_loss_pa: (0.0, 1.0),
        },
        ..RomParams::default()
    };
    assert!(matches!(
        build_rom(&model, &[1], &bad),
        Err(RomError::Params(_))
    ));
    // a pencil prepared for one grid refuses another
    let (rom, _) = build_rom(&model, &[1], &RomParams::default()).unwrap();
    let p = rom.prepare(&[10.0, 20.0]).unwrap();
    assert!(p
        .sweep(&[10.0, 21.0], &[C64::new(1e6, 0.0); 2], false)
        .is_err());
}
