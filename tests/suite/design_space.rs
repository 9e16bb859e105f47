//! The design space as a test: seeded random joints over the ranges engineers use (beam
//! 0.15-0.6 m long, 3-20 mm thick, 10-50 mm wide; adhesive 10-100 mm long, 0.5-10 mm thick,
//! anywhere along the beam; 2-6 points anywhere on the upper face, the excitation at one of
//! them), each through the whole chain with the default mesh rule (two or more elements
//! through every layer thinner than the element size):
//!
//! 1. the mesh builds and its cost estimate is within a factor 2 of the DOFs it has;
//! 2. the ROM is built and certified (the reference `rfmlab run` chooses: the shifted Krylov
//!    solver on these sizes, direct solves where it stalls or the ROM misses it);
//! 3. the ROM's lowest modes in the band agree with the full model's complex modes (1e-6
//!    relative);
//! 4. Model 4 is identified from noise-free frequency-domain data made by the full model
//!    (sparse LU per line) with the paper's parameters, to within 0.5 % by the deterministic
//!    RFM and by the MAP of a posterior with flat priors.
//!
//! The normal suite runs the `DESIGN_SPACE_FAST` seeds; the ignored
//! `design_space_40_joints_mesh_certify_and_identify_model4` runs the first `DESIGN_SPACE_LONG`
//! (`cargo test --release --test suite -- --ignored design_space_40 --nocapture` prints the
//! pass count, worst error and slowest geometry).

use rand::{RngExt, SeedableRng};
use rfmlab::common::{Direction, C64};
use rfmlab::fe::joint::{
    build_joint_model, joint_cost_estimate, JointGeometry, JointSpec, MeshParams, MeshSize,
    PointSpec,
};
use rfmlab::forward::ForwardModel;
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::inference::likelihood::{
    ErrorLaw, FrfData, FrfLikelihood, FrfPosterior, NoiseModel, Scale,
};
use rfmlab::inference::map::{find_map, MapParams};
use rfmlab::inference::prior::Prior;
use rfmlab::material::{ConstitutiveModel, Model4};
use rfmlab::rfm::{rfm_global, MeasuredColumn, RfmParams};
use rfmlab::rom::{build_rom, ModulusRange, RomParams};
use std::f64::consts::TAU;
use std::time::Instant;

/// Three of the first five seeds, the ones that differ most: a long thick beam with a 3.7 mm
/// layer (1001), the thinnest beam (5 mm) under the thickest layer (8.2 mm, 2451 DOFs, 1003)
/// and the thinnest layer (1.4 mm, 8292 DOFs, the widest band, 1-294 Hz, 1004). Seeds 1000 and
/// 1002 (beams 15.6 mm thick under 7.7-7.9 mm layers, like 1001's) run in the long test.
const DESIGN_SPACE_FAST: [u64; 3] = [1001, 1003, 1004];
const DESIGN_SPACE_LONG: usize = 40;
/// The paper's identified Model 4 (E0, h, E1, eta1) and its initial values.
const TRUTH: [f64; 4] = [6.67e6, 944e3, 3.1487e6, 4181.0];
const START: [f64; 4] = [6.0e6, 1.0e6, 3.0e6, 3.0e3];
const TOL: f64 = 5e-3;

/// A random joint of the design space (seeded).
fn draw(seed: u64) -> JointSpec {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let l = rng.random_range(0.15..0.6);
    let t_b = rng.random_range(0.003..0.020);
    let w = rng.random_range(0.010..0.050);
    let la: f64 = rng.random_range(0.010..0.100f64).min(l);
    let t_a = rng.random_range(0.0005..0.010);
    let x0 = rng.random_range(0.0..1.0) * (l - la);
    let n_pts = rng.random_range(2..=6usize);
    let mut xs: Vec<f64> = Vec::new();
    while xs.len() < n_pts {
        let x = rng.random_range(0.0..l);
        if xs.iter().all(|&y: &f64| (y - x).abs() > 0.01 * l) {
            xs.push(x);
        }
    }
    let points = xs
        .iter()
        .enumerate()
        .map(|(i, &x)| PointSpec {
            id: i as u32 + 1,
            position_m: [x, t_b, rng.random_range(0.0..w)],
            direction: Direction::PY,
        })
        .collect();
    // element size: the default 5 mm where the joint is small, coarser on long and wide ones
    // to keep each geometry to about 10^4 DOFs (the mesher puts two elements through thin layers)
    let h = 0.005f64.max(l / 40.0).max(w / 5.0);
    JointSpec {
        geometry: JointGeometry {
            beam_length_m: l,
            beam_thickness_m: t_b,
            beam_width_m: w,
            adhesive_length_m: la,
            adhesive_thickness_m: t_a,
            adhesive_x_start_m: x0,
        },
        mesh: MeshParams {
            size: MeshSize::ElementSize(h),
            ..MeshParams::default()
        },
        points,
        // the paper's steel and Sikaflex-252
        ..JointSpec::paper()
    }
}

struct Outcome {
    rfm_err: f64,
    map_err: f64,
    mode_err: f64,
    seconds: f64,
    n_dof: usize,
    band_hz: (f64, f64),
}

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) / y).abs())
        .fold(0.0, f64::max)
}

fn run_geometry(seed: u64) -> Result<Outcome, String> {
    let t0 = Instant::now();
    let spec = draw(seed);
    let exc = (seed as usize * 7) % spec.points.len();
    let cost = joint_cost_estimate(&spec).map_err(|e| format!("cost: {e}"))?;
    let (model, info) = build_joint_model(&spec).map_err(|e| format!("mesh: {e}"))?;
    let ratio = cost.n_dof as f64 / info.n_dof as f64;
    if !(0.5..=2.0).contains(&ratio) {
        return Err(format!(
            "cost estimate {} DOFs against {} built",
            cost.n_dof, info.n_dof
        ));
    }
    // band: up to 1.2 x the third mode at the truth's modulus at 100 Hz
    let e_mid = Model4.modulus(&TRUTH, TAU * 100.0);
    let full_modes = rfmlab::modes::complex_modes(
        &model,
        e_mid,
        8,
        None,
        &rfmlab::modes::ModesParams::default(),
    )
    .map_err(|e| format!("full-model modes: {e}"))?;
    let f_top = (1.2 * full_modes[2].freq_hz).clamp(50.0, 3000.0);
    let band = (1.0, f_top);
    let outputs: Vec<usize> = (0..spec.points.len()).collect();
    let params = RomParams {
        band_hz: band,
        range: ModulusRange {
            e_storage_pa: (2e6, 2e7),
            e_loss_pa: (1e5, 1e7),
        },
        // the reference `rfmlab run` chooses for this model
        reference: rfmlab::rom::Reference::suited(model.n_dof()),
        ..RomParams::default()
    };
    // every point an input: the RFM needs S H_A,i for every response i
    let (rom, cert) = build_rom(&model, &outputs, &params).map_err(|e| format!("ROM: {e}"))?;
    if !cert.passed {
        return Err(format!("ROM not certified: {:e}", cert.max_rel_error));
    }
    // lowest modes: ROM against the full model
    let rom_modes = rom
        .complex_modes(e_mid, 3)
        .map_err(|e| format!("ROM modes: {e}"))?;
    // each ROM mode in the certified band against the nearest full-model mode (a mode the
    // inputs cannot reach, e.g. bending across the width under +y forces, need not be in the
    // ROM, and the ROM's modes above the band are not certified)
    let mode_err = rom_modes
        .iter()
        .filter(|a| a.freq_hz() <= band.1)
        .map(|a| {
            full_modes
                .iter()
                .map(|b| (a.lambda - b.lambda).norm() / b.lambda.norm())
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    if mode_err > 1e-6 {
        return Err(format!("ROM modes off the full model's by {mode_err:e}"));
    }
    // noise-free data from the full model, lines across the band (a sparse LU each: with 120
    // lines they were half of the largest joint's time)
    let n_lines = 60;
    let omega: Vec<f64> = (0..n_lines)
        .map(|k| TAU * (band.0 + (band.1 - band.0) * (k as f64 + 0.5) / n_lines as f64))
        .collect();
    let full = FullModel::new(&model, &[exc], FullParams::default())
        .map_err(|e| format!("full model: {e}"))?;
    let fm_full = ForwardModel::new(&full, &Model4, &omega, exc, &outputs, None)
        .map_err(|e| format!("{e}"))?;
    let acc: Vec<C64> = fm_full
        .exact(&TRUTH, false)
        .map_err(|e| format!("data: {e}"))?
        .values;
    let col = MeasuredColumn {
        omega_rad_s: omega.clone(),
        input: exc,
        outputs: outputs.clone(),
        accelerance: acc.clone(),
    };
    let rfm = rfm_global(
        &rom,
        &col,
        &Model4,
        &START,
        &RfmParams {
            max_iterations: 100,
            ..RfmParams::default()
        },
    )
    .map_err(|e| format!("RFM: {e}"))?;
    let rfm_err = rel_err(&rfm.params, &TRUTH);
    // MAP: flat priors in the parameters, 0.1 % relative noise per value
    let fm = ForwardModel::new(&rom, &Model4, &omega, exc, &outputs, None)
        .map_err(|e| format!("{e}"))?;
    let variances: Vec<f64> = acc.iter().map(|v| (1e-3 * v.norm()).powi(2)).collect();
    let data = FrfData {
        freq_hz: omega.iter().map(|w| w / TAU).collect(),
        n_out: outputs.len(),
        values: acc,
        coherence: None,
    };
    let ids: Vec<u32> = spec.points.iter().map(|p| p.id).collect();
    let lik = FrfLikelihood::new(
        fm,
        data,
        NoiseModel {
            scale: Scale::Fixed { variances },
            errors: ErrorLaw::Gaussian,
            model_error: 0.0,
        },
        &ids,
    )
    .map_err(|e| format!("likelihood: {e}"))?;
    let priors = vec![
        Prior::Uniform { lo: 1e5, hi: 1e8 },
        Prior::Uniform { lo: 1e3, hi: 1e8 },
        Prior::Uniform { lo: 1e5, hi: 1e8 },
        Prior::Uniform { lo: 1.0, hi: 1e6 },
    ];
    let post = FrfPosterior::new(lik, priors).map_err(|e| format!("posterior: {e}"))?;
    let x0 = post.unconstrained(&START);
    let map = find_map(
        &post,
        Some(&x0),
        &MapParams {
            n_starts: 2,
            ..MapParams::default()
        },
        &|| {},
    )
    .map_err(|e| format!("MAP: {e}"))?;
    let map_err = rel_err(&map.map_physical, &TRUTH);
    Ok(Outcome {
        rfm_err,
        map_err,
        mode_err,
        seconds: t0.elapsed().as_secs_f64(),
        n_dof: info.n_dof,
        band_hz: band,
    })
}

fn run_design_space(seeds: &[u64]) {
    let n = seeds.len();
    let mut passed = 0;
    let mut worst = 0.0f64;
    let mut slowest = (0.0f64, 0u64);
    let mut failures = Vec::new();
    for &seed in seeds {
        let g = draw(seed).geometry;
        match run_geometry(seed) {
            Ok(o) => {
                let err = o.rfm_err.max(o.map_err);
                eprintln!(
                    "seed {seed}: L {:.0} t_b {:.1} w {:.0} mm, adhesive {:.0} x {:.2} mm at {:.0} mm; {} DOFs, band {:.0}-{:.0} Hz: RFM {:.1e}, MAP {:.1e}, modes {:.1e}, {:.1} s",
                    g.beam_length_m * 1e3,
                    g.beam_thickness_m * 1e3,
                    g.beam_width_m * 1e3,
                    g.adhesive_length_m * 1e3,
                    g.adhesive_thickness_m * 1e3,
                    g.adhesive_x_start_m * 1e3,
                    o.n_dof,
                    o.band_hz.0,
                    o.band_hz.1,
                    o.rfm_err,
                    o.map_err,
                    o.mode_err,
                    o.seconds
                );
                if err <= TOL {
                    passed += 1;
                } else {
                    failures.push(format!("seed {seed}: Model 4 off by {err:.2e}"));
                }
                worst = worst.max(err);
                if o.seconds > slowest.0 {
                    slowest = (o.seconds, seed);
                }
            }
            Err(e) => failures.push(format!("seed {seed} ({g:?}): {e}")),
        }
    }
    eprintln!(
        "design space: {passed}/{n} geometries pass; worst Model 4 error {worst:.2e}; slowest geometry {:.1} s (seed {})",
        slowest.0, slowest.1
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn design_space_joints_mesh_certify_and_identify_model4() {
    run_design_space(&DESIGN_SPACE_FAST);
}

#[test]
#[ignore = "slow: 40 seeded joints, each meshed, its ROM certified, data made by the full model and Model 4 identified twice; run time not measured; run with --ignored"]
fn design_space_40_joints_mesh_certify_and_identify_model4() {
    let seeds: Vec<u64> = (0..DESIGN_SPACE_LONG as u64).map(|i| 1000 + i).collect();
    run_design_space(&seeds);
}
