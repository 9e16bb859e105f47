//! The expected information each candidate channel gives about a law's parameters: the
//! Fisher information of the likelihood rfmlab fits ([`FrfLikelihood::channel_information`]:
//! the same forward model, H1 measurement model and coherence noise model), with the noise
//! scales predicted from the measurement chain ([`crate::experiment::expected_coherence`]: the
//! force level, the window's leakage, the sensors' noise), at parameter draws, per level and
//! drive point, in the priors' unconstrained coordinates.
//!
//! For independent channels the information of a design is the sum of its channels'. A
//! sensor's mass is part of the structure: the information is computed on the reduced model
//! with the masses of a given set of places added ([`crate::rom::ReducedModel::with_point_masses`]),
//! its pencil prepared on the grids below ([`RomEngine::prepared`]).

use crate::experiment::plant::EnginePlant;
use crate::experiment::ChainParams;
use crate::forward::{ForwardModel, MeasurementModel};
use crate::frf::FrfEngine;
use crate::inference::likelihood::{FrfData, FrfLikelihood, NoiseModel};
use crate::inference::prior::Prior;
use crate::material::ConstitutiveModel;
use crate::stage::rom_engine::RomEngine;

/// One model's parameter point and the priors' curvature there.
#[derive(Clone, Debug)]
pub struct Draw {
    /// Physical values (SI).
    pub p: Vec<f64>,
    /// `dp/dx` per parameter.
    pub dp_dx: Vec<f64>,
    /// `-d^2 log prior / dx^2` per parameter (the priors are independent).
    pub prior_curvature: Vec<f64>,
}

impl Draw {
    pub fn at(p: &[f64], priors: &[Prior]) -> Draw {
        let mut dp_dx = Vec::new();
        let mut prior_curvature = Vec::new();
        for (v, pr) in p.iter().zip(priors) {
            let x = pr.to_unconstrained(*v);
            dp_dx.push(pr.dp_dx(x));
            let e = 1e-5 * (1.0 + x.abs());
            let c = -(pr.log_density_x(x + e).1 - pr.log_density_x(x - e).1) / (2.0 * e);
            prior_curvature.push(c.max(0.0));
        }
        Draw {
            p: p.to_vec(),
            dp_dx,
            prior_curvature,
        }
    }
}

/// What one information pass needs besides the draws.
pub struct Chain<'a> {
    /// Lines (Hz) of the planned H1.
    pub freq_hz: &'a [f64],
    /// The analyser's measurement model on those lines, when the study states its estimator.
    pub measurement: Option<&'a MeasurementModel>,
    /// Per level: the measurement chain whose expected coherence sets the noise scales.
    pub levels: &'a [ChainParams],
    pub noise: &'a NoiseModel,
}

/// Information per channel: `[level][channel]`, row-major `np x np` in the unconstrained
/// coordinates (`D F D`, `D = diag dp/dx`), of one model at one draw, one drive and one set of
/// sensor masses.
pub type ChannelInfo = Vec<Vec<Vec<f64>>>;

/// The grids (rad/s) whose pencils ([`RomEngine::prepared`]) serve the information for `chain`: the measurement model's fine grid
/// (or the lines) and the expected coherence's band grid (without 0 Hz).
pub fn grids(chain: &Chain<'_>) -> Vec<Vec<f64>> {
    let lines = match chain.measurement {
        Some(m) => m.fine_omega(),
        None => chain
            .freq_hz
            .iter()
            .map(|f| std::f64::consts::TAU * f)
            .collect(),
    };
    let band: Vec<f64> = crate::experiment::band_grid_hz(&chain.levels[0])
        .into_iter()
        .filter(|f| *f > 0.0)
        .map(|f| 2.0 * std::f64::consts::PI * f)
        .collect();
    vec![lines, band]
}

/// The information of every channel in `channels` (output indices of the engine) for a force
/// at output `drive` (the engine's one input), at `draw` of `law`, for each of `chain.levels`
/// (which differ in their force only).
pub fn channel_info(
    engine: &RomEngine,
    drive: usize,
    channels: &[usize],
    law: &dyn ConstitutiveModel,
    draw: &Draw,
    chain: &Chain<'_>,
) -> Result<ChannelInfo, String> {
    let omega: Vec<f64> = chain
        .freq_hz
        .iter()
        .map(|f| std::f64::consts::TAU * f)
        .collect();
    let forward = || {
        ForwardModel::new(
            engine,
            law,
            &omega,
            drive,
            channels,
            chain.measurement.cloned(),
        )
        .map_err(|e| e.to_string())
    };
    let pred = forward()?
        .predict(&draw.p, true)
        .map_err(|e| e.to_string())?;
    // The expected coherence of every channel (the plant's channels are the engine's outputs)
    // at every level's force.
    let modulus = |w: f64| law.modulus(&draw.p, w.abs());
    let plant = EnginePlant {
        engine: engine as &dyn FrfEngine,
        modulus: &modulus,
        input_col: 0,
        drive_output: drive,
    };
    let forces: Vec<f64> = chain.levels.iter().map(|c| c.force_rms_n).collect();
    let coh = crate::experiment::expected_coherence_at(&plant, &chain.levels[0], &forces)
        .map_err(|e| e.to_string())?;
    let np = draw.p.len();
    let ids: Vec<u32> = (0..channels.len() as u32).collect();
    let n = channels.len();
    let mut out = Vec::with_capacity(chain.levels.len());
    for coh_all in coh {
        let mut coherence = vec![0.0; chain.freq_hz.len() * n];
        for (k, &c) in channels.iter().enumerate() {
            for (l, g) in coh_all[c].iter().enumerate() {
                coherence[l * n + k] = g.max(1e-12);
            }
        }
        let data = FrfData {
            freq_hz: chain.freq_hz.to_vec(),
            n_out: n,
            values: pred.values.clone(),
            coherence: Some(coherence),
        };
        let lik = FrfLikelihood::new(forward()?, data, chain.noise.clone(), &ids)
            .map_err(|e| e.to_string())?;
        let info = lik.channel_information_of(&pred, &[]);
        out.push(
            info.into_iter()
                .map(|mut g| {
                    for i in 0..np {
                        for j in 0..np {
                            g[i * np + j] *= draw.dp_dx[i] * draw.dp_dx[j];
                        }
                    }
                    g
                })
                .collect(),
        );
    }
    Ok(out)
}

/// Posterior precision `prior + sum of channels' information` and its covariance, in the
/// unconstrained coordinates; `None` when it is not positive definite.
pub fn covariance(draw: &Draw, infos: &[&[f64]]) -> Option<(Vec<f64>, f64)> {
    let np = draw.p.len();
    let mut a = vec![0.0; np * np];
    for i in 0..np {
        a[i * np + i] = draw.prior_curvature[i];
    }
    for f in infos {
        for (x, y) in a.iter_mut().zip(f.iter()) {
            *x += y;
        }
    }
    // A flat prior direction with no information: a tiny ridge keeps the factorisation
    // defined and reports a huge variance rather than failing.
    let scale = (0..np)
        .map(|i| a[i * np + i])
        .fold(0.0, f64::max)
        .max(1e-300);
    for i in 0..np {
        a[i * np + i] += 1e-12 * scale;
    }
    let l = crate::linalg::dense::cholesky(&a, np)?;
    let logdet: f64 = (0..np).map(|i| 2.0 * l[i * np + i].ln()).sum();
    Some((crate::linalg::dense::chol_inverse(&l, np), logdet))
}

/// `ln det` of the prior's precision at `draw` (with the same ridge as [`covariance`]).
pub fn prior_logdet(draw: &Draw) -> f64 {
    let scale = draw
        .prior_curvature
        .iter()
        .copied()
        .fold(0.0, f64::max)
        .max(1e-300);
    draw.prior_curvature
        .iter()
        .map(|c| (c + 1e-12 * scale).ln())
        .sum()
}

/// Relative standard deviation of parameter `i` from the covariance in x.
pub fn relative_sd(draw: &Draw, cov: &[f64], i: usize) -> f64 {
    let np = draw.p.len();
    (cov[i * np + i].max(0.0).sqrt() * draw.dp_dx[i] / draw.p[i]).abs()
}
