//! The No-U-Turn Sampler (Hoffman and Gelman 2014, JMLR 15) through nuts-rs, the core of
//! nutpie: multinomial NUTS with a diagonal mass matrix and step size adapted during warm-up
//! (nuts-rs's default schedule; dual averaging toward `target_accept`).
//!
//! One chain per start, chains run in parallel with rayon. Chain `c` draws all its randomness
//! from [`unit_rng`]`(seed, c)` (nuts-rs seeds its own ChaCha8 generator from that stream), so
//! a chain's draws depend only on the seed, its index, its start and the settings: never on the
//! thread count or on the other chains. Warm-up draws are discarded.
//!
//! A density error of kind [`DensityError::Recoverable`] (or a non-finite value or gradient) is
//! a divergence for nuts-rs: the trajectory stops and sampling continues. A
//! [`DensityError::Fatal`] stops the run with its message.
//!
//! With a checkpoint directory, each finished chain is saved to its own file named by its index
//! and the key of the run (seed, settings, dimension, names, starts); a rerun loads the chains
//! already finished and runs the others, and its result is bit-identical to an uninterrupted
//! run.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nuts_rs::{Chain, CpuLogpFunc, CpuMath, CpuMathError, DiagNutsSettings, HasDims, Settings};
use rayon::prelude::*;

use super::checkpoint::{self, Decoder, Encoder};
use super::sampling::{in_range, nonzero, Progress, SamplerError};
use super::{unit_rng, DensityError, Posterior};

/// NUTS settings.
#[derive(Debug, Clone, PartialEq)]
pub struct NutsParams {
    /// Number of chains; must equal the number of starts. Default 4.
    pub chains: usize,
    /// Warm-up (adaptation) iterations per chain, discarded. Default 1000.
    pub tune: u64,
    /// Kept draws per chain. Default 1000.
    pub draws: u64,
    /// Seed of the run; chain `c` uses stream `unit_rng(seed, c)`. Default 0.
    pub seed: u64,
    /// Maximum tree depth (at most `2^depth - 1` leapfrog steps per draw). Default 10.
    pub max_tree_depth: u64,
    /// Target mean acceptance statistic of the step-size adaptation, in (0, 1). Default 0.8.
    pub target_accept: f64,
    /// Report [`Progress::NutsDraws`] every this many iterations of a chain. Default 100.
    pub progress_every: u64,
}

impl Default for NutsParams {
    fn default() -> Self {
        Self {
            chains: 4,
            tune: 1000,
            draws: 1000,
            seed: 0,
            max_tree_depth: 10,
            target_accept: 0.8,
            progress_every: 100,
        }
    }
}

/// The kept draws of one chain, one entry per draw in every column (`x` and `constrained`
/// hold one row per draw): the shape of the per-draw table (chain, draw, parameters, lp,
/// log_lik, log_prior, sampler statistics).
#[derive(Debug, Clone, PartialEq)]
pub struct ChainDraws {
    /// Chain index.
    pub chain: usize,
    /// Unconstrained coordinates, one row per draw.
    pub x: Vec<Vec<f64>>,
    /// Physical values ([`Posterior::constrained`]), one row per draw.
    pub constrained: Vec<Vec<f64>>,
    /// Log posterior (up to log Z) as nuts-rs evaluated it.
    pub lp: Vec<f64>,
    /// Log likelihood at the draw (re-evaluated; `-inf` if that failed recoverably).
    pub log_lik: Vec<f64>,
    /// Log prior at the draw.
    pub log_prior: Vec<f64>,
    /// Step size of the draw's trajectory.
    pub step_size: Vec<f64>,
    /// Tree depth.
    pub tree_depth: Vec<u64>,
    /// Leapfrog steps.
    pub n_steps: Vec<u64>,
    /// Whether the trajectory diverged.
    pub divergent: Vec<bool>,
    /// Hamiltonian at the draw as nuts-rs reports it: kinetic energy minus (log posterior + log
    /// determinant of the adapted mass-matrix transform). The offset is constant after warm-up,
    /// so differences (E-BFMI) are those of the usual `-lp + kinetic`.
    pub energy: Vec<f64>,
    /// Divergences during warm-up (the draws themselves are not kept).
    pub tune_divergences: u64,
}

impl ChainDraws {
    /// Number of kept draws.
    pub fn len(&self) -> usize {
        self.lp.len()
    }
    /// Whether no draw was kept.
    pub fn is_empty(&self) -> bool {
        self.lp.is_empty()
    }
    /// Number of divergent kept draws.
    pub fn n_divergent(&self) -> usize {
        self.divergent.iter().filter(|&&d| d).count()
    }

    fn encode(&self, e: &mut Encoder) {
        e.u64(self.chain as u64)
            .rows(&self.x)
            .rows(&self.constrained)
            .f64s(&self.lp)
            .f64s(&self.log_lik)
            .f64s(&self.log_prior)
            .f64s(&self.step_size)
            .u64s(&self.tree_depth)
            .u64s(&self.n_steps)
            .bools(&self.divergent)
            .f64s(&self.energy)
            .u64(self.tune_divergences);
    }

    fn decode(b: &[u8]) -> Option<Self> {
        let mut d = Decoder::new(b);
        let c = Self {
            chain: usize::try_from(d.u64()?).ok()?,
            x: d.rows()?,
            constrained: d.rows()?,
            lp: d.f64s()?,
            log_lik: d.f64s()?,
            log_prior: d.f64s()?,
            step_size: d.f64s()?,
            tree_depth: d.u64s()?,
            n_steps: d.u64s()?,
            divergent: d.bools()?,
            energy: d.f64s()?,
            tune_divergences: d.u64()?,
        };
        d.at_end().then_some(c)
    }
}

/// The result of [`sample_nuts`].
#[derive(Debug, Clone, PartialEq)]
pub struct NutsRun {
    /// Coordinate names ([`Posterior::names`]).
    pub names: Vec<String>,
    /// One entry per chain, in chain order.
    pub chains: Vec<ChainDraws>,
    /// Chains loaded from the checkpoint directory rather than run.
    pub loaded_chains: Vec<usize>,
}

impl NutsRun {
    /// Divergent kept draws over all chains.
    pub fn n_divergent(&self) -> usize {
        self.chains.iter().map(ChainDraws::n_divergent).sum()
    }
}

/// nuts-rs's view of a density error: recoverable ones are divergences.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct NutsDensityError(DensityError);

impl nuts_rs::LogpError for NutsDensityError {
    fn is_recoverable(&self) -> bool {
        matches!(self.0, DensityError::Recoverable(_))
    }
}

/// Adapter of a [`Posterior`] to nuts-rs's CPU density; remembers a fatal error's message.
struct NutsDensity<'a> {
    post: &'a dyn Posterior,
    fatal: &'a RefCell<Option<String>>,
}

impl HasDims for NutsDensity<'_> {
    fn dim_sizes(&self) -> HashMap<String, u64> {
        // nuts-rs needs both names at run time (its storage sizes traces by them).
        let d = self.post.dim() as u64;
        HashMap::from([
            ("unconstrained_parameter".to_string(), d),
            ("dim".to_string(), d),
        ])
    }
}

impl CpuLogpFunc for NutsDensity<'_> {
    type LogpError = NutsDensityError;
    type FlowParameters = ();
    type ExpandedVector = ();

    fn dim(&self) -> usize {
        self.post.dim()
    }

    fn logp(&mut self, x: &[f64], grad: &mut [f64]) -> Result<f64, NutsDensityError> {
        match self.post.log_posterior(x, Some(grad)) {
            Ok(v) if v.is_finite() && grad.iter().all(|g| g.is_finite()) => Ok(v),
            Ok(v) => Err(NutsDensityError(DensityError::Recoverable(format!(
                "log posterior {v} or its gradient is not finite"
            )))),
            Err(DensityError::Fatal(m)) => {
                *self.fatal.borrow_mut() = Some(m.clone());
                Err(NutsDensityError(DensityError::Fatal(m)))
            }
            Err(e) => Err(NutsDensityError(e)),
        }
    }

    fn expand_vector<R: rand::Rng + ?Sized>(
        &mut self,
        _rng: &mut R,
        _x: &[f64],
    ) -> Result<(), CpuMathError> {
        Ok(())
    }
}

fn validate(post: &dyn Posterior, starts: &[Vec<f64>], p: &NutsParams) -> Result<(), SamplerError> {
    nonzero("chains", p.chains)?;
    nonzero("draws", p.draws as usize)?;
    nonzero("max_tree_depth", p.max_tree_depth as usize)?;
    in_range(
        "target_accept",
        p.target_accept,
        0.0,
        1.0,
        "a mean acceptance in (0, 1), e.g. 0.8 (0.9-0.95 for difficult geometry)",
    )?;
    if starts.len() != p.chains {
        return Err(SamplerError::StartCount {
            got: starts.len(),
            chains: p.chains,
        });
    }
    let dim = post.dim();
    for (index, s) in starts.iter().enumerate() {
        if s.len() != dim {
            return Err(SamplerError::StartDim {
                index,
                got: s.len(),
                dim,
            });
        }
    }
    Ok(())
}

/// The start nuts-rs is given: `start` itself, unless a gradient component is exactly zero
/// there (a start at the MAP, or on a symmetry plane), which nuts-rs rejects because it
/// initialises the diagonal mass matrix from the gradient; those coordinates are then moved by
/// `1e-6 max(1, |x_k|)` (up to three times, tenfold each time). Deterministic.
fn usable_start(
    post: &dyn Posterior,
    index: usize,
    start: &[f64],
) -> Result<Vec<f64>, SamplerError> {
    let mut x = start.to_vec();
    let mut g = vec![0.0; x.len()];
    let mut step = 1e-6;
    for attempt in 0..4 {
        match post.log_posterior(&x, Some(&mut g)) {
            Err(DensityError::Fatal(m)) => return Err(SamplerError::Fatal(m)),
            Err(e @ DensityError::Recoverable(_)) => {
                return Err(SamplerError::BadStart {
                    index,
                    detail: e.to_string(),
                })
            }
            Ok(v) if !v.is_finite() || g.iter().any(|g| !g.is_finite()) => {
                return Err(SamplerError::BadStart {
                    index,
                    detail: format!("log posterior {v}, gradient {g:?}"),
                })
            }
            Ok(_) if g.iter().all(|&g| g != 0.0) => return Ok(x),
            Ok(_) if attempt == 3 => {
                return Err(SamplerError::BadStart {
                    index,
                    detail: format!(
                        "gradient {g:?} has a zero component even after nudging the start"
                    ),
                })
            }
            Ok(_) => {
                for (xk, gk) in x.iter_mut().zip(&g) {
                    if *gk == 0.0 {
                        *xk += step * xk.abs().max(1.0);
                    }
                }
                step *= 10.0;
            }
        }
    }
    unreachable!("the loop returns on its last attempt")
}

/// The key of a NUTS run: everything its draws depend on except the posterior itself.
fn run_key(post: &dyn Posterior, starts: &[Vec<f64>], p: &NutsParams) -> [u8; 32] {
    let mut e = Encoder::new();
    e.str("rfmlab nuts v1 (nuts-rs 0.19 diag)")
        .u64(p.seed)
        .u64(p.chains as u64)
        .u64(p.tune)
        .u64(p.draws)
        .u64(p.max_tree_depth)
        .f64(p.target_accept)
        .u64(post.dim() as u64);
    for n in post.names() {
        e.str(&n);
    }
    e.rows(starts);
    e.key()
}

fn chain_path(dir: &Path, chain: usize, key: &[u8; 32]) -> PathBuf {
    dir.join(format!(
        "nuts-chain{chain:03}-{}.ckpt",
        checkpoint::key_hex(key)
    ))
}

/// Runs one nuts-rs chain from `start`.
fn run_chain(
    post: &dyn Posterior,
    chain: usize,
    start: &[f64],
    p: &NutsParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<ChainDraws, SamplerError> {
    let mut settings = DiagNutsSettings {
        num_tune: p.tune,
        num_draws: p.draws,
        maxdepth: p.max_tree_depth,
        num_chains: p.chains,
        seed: p.seed,
        ..DiagNutsSettings::default()
    };
    settings.adapt_options.step_size_settings.target_accept = p.target_accept;

    let fatal = RefCell::new(None);
    let nuts_err = |e: anyhow::Error, fatal: &RefCell<Option<String>>| match fatal.take() {
        Some(m) => SamplerError::Fatal(m),
        None => {
            // nuts-rs embeds the Debug form (with a backtrace) of some inner errors: keep the text.
            let message = format!("{e:#}");
            let message = match message.find("\n\nStack backtrace:") {
                Some(i) => message[..i].to_string(),
                None => message,
            };
            SamplerError::Nuts { chain, message }
        }
    };
    let math = CpuMath::new(NutsDensity {
        post,
        fatal: &fatal,
    });
    let mut rng = unit_rng(p.seed, chain as u64);
    let mut sampler = settings
        .new_chain(chain as u64, math, &mut rng)
        .map_err(|e| nuts_err(e, &fatal))?;
    sampler
        .set_position(start)
        .map_err(|e| nuts_err(e, &fatal))?;

    let n = p.draws as usize;
    let mut out = ChainDraws {
        chain,
        x: Vec::with_capacity(n),
        constrained: Vec::with_capacity(n),
        lp: Vec::with_capacity(n),
        log_lik: Vec::with_capacity(n),
        log_prior: Vec::with_capacity(n),
        step_size: Vec::with_capacity(n),
        tree_depth: Vec::with_capacity(n),
        n_steps: Vec::with_capacity(n),
        divergent: Vec::with_capacity(n),
        energy: Vec::with_capacity(n),
        tune_divergences: 0,
    };
    let total = p.tune + p.draws;
    for it in 0..total {
        let (x, _, stats, prog) = sampler.expanded_draw().map_err(|e| nuts_err(e, &fatal))?;
        if it < p.tune {
            out.tune_divergences += prog.diverging as u64;
        } else {
            let x = x.to_vec();
            let log_prior = post.log_prior(&x, None);
            let log_lik = match post.log_likelihood(&x, None) {
                Ok(v) => v,
                Err(DensityError::Recoverable(_)) => f64::NEG_INFINITY,
                Err(DensityError::Fatal(m)) => return Err(SamplerError::Fatal(m)),
            };
            out.constrained.push(post.constrained(&x));
            out.x.push(x);
            out.lp.push(stats.point.logp);
            out.log_lik.push(log_lik);
            out.log_prior.push(log_prior);
            out.step_size.push(stats.hamiltonian.step_size);
            out.tree_depth.push(stats.depth);
            out.n_steps.push(prog.num_steps);
            out.divergent.push(prog.diverging);
            out.energy.push(stats.point.energy);
        }
        if p.progress_every > 0 && ((it + 1) % p.progress_every == 0 || it + 1 == total) {
            progress(Progress::NutsDraws {
                chain,
                done: it + 1,
                total,
            });
        }
    }
    Ok(out)
}

/// Samples `post` with NUTS: one chain per start (give dispersed starts inside the support,
/// e.g. prior draws or jittered MAP points), chains in parallel, warm-up discarded.
///
/// With `checkpoint = Some(dir)`, finished chains are saved in `dir` and reused by a rerun with
/// the same seed, settings, starts and dimension (see the module documentation).
pub fn sample_nuts(
    post: &dyn Posterior,
    starts: &[Vec<f64>],
    params: &NutsParams,
    checkpoint: Option<&Path>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<NutsRun, SamplerError> {
    validate(post, starts, params)?;
    let key = run_key(post, starts, params);
    if let Some(dir) = checkpoint {
        checkpoint::ensure_dir(dir)?;
    }
    let results: Vec<Result<(ChainDraws, bool), SamplerError>> = (0..params.chains)
        .into_par_iter()
        .map(|c| {
            if let Some(dir) = checkpoint {
                let path = chain_path(dir, c, &key);
                if let Some(bytes) = checkpoint::read_matching(&path, &key)? {
                    if let Some(draws) = ChainDraws::decode(&bytes) {
                        if draws.chain == c && draws.len() == params.draws as usize {
                            progress(Progress::NutsChainLoaded { chain: c });
                            return Ok((draws, true));
                        }
                    }
                }
            }
            let draws = run_chain(
                post,
                c,
                &usable_start(post, c, &starts[c])?,
                params,
                progress,
            )?;
            if let Some(dir) = checkpoint {
                let mut e = Encoder::new();
                draws.encode(&mut e);
                checkpoint::write_atomic(&chain_path(dir, c, &key), &key, e.bytes())?;
            }
            Ok((draws, false))
        })
        .collect();
    let mut chains = Vec::with_capacity(params.chains);
    let mut loaded_chains = Vec::new();
    for r in results {
        let (draws, loaded) = r?;
        if loaded {
            loaded_chains.push(draws.chain);
        }
        chains.push(draws);
    }
    Ok(NutsRun {
        names: post.names(),
        chains,
        loaded_chains,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inference::sampling::no_progress;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    /// Standard normal prior, Gaussian likelihood N(x; 1, 0.5^2 I) in each coordinate; fatal
    /// when `fatal_beyond` is exceeded by x[0].
    struct Toy {
        d: usize,
        fatal_beyond: f64,
    }

    impl Posterior for Toy {
        fn dim(&self) -> usize {
            self.d
        }
        fn names(&self) -> Vec<String> {
            (0..self.d).map(|i| format!("x{i}")).collect()
        }
        fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
            if let Some(g) = grad {
                g.iter_mut().zip(x).for_each(|(g, x)| *g = -x);
            }
            x.iter().map(|x| -0.5 * x * x).sum()
        }
        fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
            if x[0] > self.fatal_beyond {
                return Err(DensityError::Fatal("engine exploded".into()));
            }
            if let Some(g) = grad {
                g.iter_mut()
                    .zip(x)
                    .for_each(|(g, x)| *g = -(x - 1.0) / 0.25);
            }
            Ok(x.iter().map(|x| -0.5 * (x - 1.0) * (x - 1.0) / 0.25).sum())
        }
        fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
            (0..self.d).map(|_| StandardNormal.sample(rng)).collect()
        }
        fn constrained(&self, x: &[f64]) -> Vec<f64> {
            x.iter().map(|v| v.exp()).collect()
        }
    }

    fn small() -> NutsParams {
        NutsParams {
            chains: 2,
            tune: 100,
            draws: 50,
            ..NutsParams::default()
        }
    }

    #[test]
    fn bad_inputs_are_named() {
        let t = Toy {
            d: 2,
            fatal_beyond: f64::INFINITY,
        };
        let p = small();
        let e = sample_nuts(&t, &[vec![0.0; 2]], &p, None, &no_progress).unwrap_err();
        assert!(
            matches!(e, SamplerError::StartCount { got: 1, chains: 2 }),
            "{e}"
        );
        let e = sample_nuts(&t, &[vec![0.0; 2], vec![0.0; 3]], &p, None, &no_progress).unwrap_err();
        assert!(
            matches!(
                e,
                SamplerError::StartDim {
                    index: 1,
                    got: 3,
                    dim: 2
                }
            ),
            "{e}"
        );
        let e = sample_nuts(
            &t,
            &[vec![0.0; 2], vec![f64::NAN, 0.0]],
            &p,
            None,
            &no_progress,
        )
        .unwrap_err();
        assert!(matches!(e, SamplerError::BadStart { index: 1, .. }), "{e}");
        let zero = NutsParams {
            chains: 0,
            ..p.clone()
        };
        let e = sample_nuts(&t, &[], &zero, None, &no_progress).unwrap_err();
        assert_eq!(e.to_string(), "chains must be at least 1 (got 0)");
        let zero = NutsParams { draws: 0, ..p };
        let e = sample_nuts(&t, &vec![vec![0.0; 2]; 2], &zero, None, &no_progress).unwrap_err();
        assert_eq!(e.to_string(), "draws must be at least 1 (got 0)");
    }

    /// Standard normal posterior (flat likelihood): the gradient vanishes at 0.
    struct StdNormal;

    impl Posterior for StdNormal {
        fn dim(&self) -> usize {
            2
        }
        fn names(&self) -> Vec<String> {
            vec!["a".into(), "b".into()]
        }
        fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
            if let Some(g) = grad {
                g.iter_mut().zip(x).for_each(|(g, x)| *g = -x);
            }
            x.iter().map(|x| -0.5 * x * x).sum()
        }
        fn log_likelihood(&self, _: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
            if let Some(g) = grad {
                g.fill(0.0);
            }
            Ok(0.0)
        }
        fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
            (0..2).map(|_| StandardNormal.sample(rng)).collect()
        }
        fn constrained(&self, x: &[f64]) -> Vec<f64> {
            x.to_vec()
        }
    }

    #[test]
    fn a_start_at_the_mode_where_the_gradient_vanishes_is_nudged() {
        let x = usable_start(&StdNormal, 0, &[0.0, 0.3]).unwrap();
        assert_eq!(x, vec![1e-6, 0.3]);
        // nuts-rs alone rejects such a start ("Invalid initial point"); through sample_nuts
        // it samples.
        let run = sample_nuts(
            &StdNormal,
            &vec![vec![0.0; 2]; 2],
            &small(),
            None,
            &no_progress,
        )
        .unwrap();
        assert_eq!(run.chains[1].len(), 50);
    }

    #[test]
    fn a_fatal_density_error_stops_the_run_with_its_message() {
        let t = Toy {
            d: 2,
            fatal_beyond: 0.9,
        };
        let e = sample_nuts(&t, &vec![vec![0.0; 2]; 2], &small(), None, &no_progress).unwrap_err();
        match e {
            SamplerError::Fatal(m) => assert_eq!(m, "engine exploded"),
            other => panic!("expected Fatal, got {other}"),
        }
    }

    #[test]
    fn draws_carry_consistent_densities_and_statistics() {
        let t = Toy {
            d: 3,
            fatal_beyond: f64::INFINITY,
        };
        let run = sample_nuts(
            &t,
            &[vec![0.0; 3], vec![0.5; 3]],
            &small(),
            None,
            &no_progress,
        )
        .unwrap();
        assert_eq!(run.chains.len(), 2);
        for c in &run.chains {
            assert_eq!(c.len(), 50);
            for i in 0..c.len() {
                assert!((c.lp[i] - c.log_lik[i] - c.log_prior[i]).abs() < 1e-9);
                assert_eq!(c.constrained[i][0], c.x[i][0].exp());
                assert!(c.step_size[i] > 0.0 && c.n_steps[i] >= 1 && c.tree_depth[i] >= 1);
                assert!(c.energy[i].is_finite());
            }
        }
        assert_ne!(run.chains[0].x, run.chains[1].x);
    }
}
