//! The stepping-stone evidence of one model at one level ([`crate::inference::stepping_stone`]):
//! by default the generalized path from a Student-t reference fitted to the posterior draws
//! ([`super::reference`]), `log Z = sum_k log E_{beta_k}[(L q / p)^(beta_{k+1} - beta_k)]`
//! over the rungs, from the prior when asked (or when no reference can be fitted); replicas
//! run independently and their spread gives the standard error. Each finished replica is
//! checkpointed in the samplers' format ([`crate::inference::checkpoint`]: bit-exact, written
//! atomically, keyed by the settings, the seed and the reference), so an interrupted run
//! resumes with the same evidence. Checked by the suite's `model_comparison` and
//! `evidence_quadrature` tests.

use super::reference::reference_for;
use super::EvidenceRow;
use crate::bayes::posterior::SamplerResult;
use crate::bayes::{fail, At, Checkpoints};
use crate::inference::checkpoint::{self, Decoder, Encoder};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;
use crate::inference::{
    combine_replicas, reference_stepping_stone_replica, stepping_stone_replica, Progress,
    Reference, SteppingStoneParams, SteppingStoneReplica,
};
use crate::stage::{Event, RunError};
use crate::study::inference::SteppingStoneSettings;
use std::path::Path;
use std::time::Instant;

/// The stepping-stone evidence with settings `ss` for the stage `at` (replicas checkpointed in
/// `checkpoints`), and the report's note on it.
#[allow(clippy::too_many_arguments)]
pub fn run(
    checkpoints: &Checkpoints<'_>,
    ss: &SteppingStoneSettings,
    post: &FrfPosterior<'_>,
    map: &MapResult,
    samplers: &[SamplerResult],
    at: &At<'_>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<(EvidenceRow, Vec<String>), RunError> {
    let (seed, level, model) = (at.seed, at.level, at.model);
    let params = SteppingStoneParams {
        particles: ss.particles,
        replicas: ss.replicas,
        seed,
        ..SteppingStoneParams::default()
    };
    let dir = checkpoints.dir(level, model, "stepping_stone");
    // The generalized path's reference (None: from the prior), and what it was fitted to.
    let (reference, fallback) = if ss.from_reference {
        match reference_for(post, map, samplers, ss.widen, ss.nu) {
            Ok(r) => (Some(r), None),
            Err(e) => (None, Some(e)),
        }
    } else {
        (None, None)
    };
    let path_note = match (&reference, fallback) {
        (Some((_, from)), _) => format!(
            "from a Student-t reference (nu {}, sd {} x those of the {from})",
            ss.nu, ss.widen
        ),
        (None, Some(e)) => format!("from the prior (no reference: {e})"),
        (None, None) => "from the prior".to_string(),
    };
    progress(Event::Start {
        step: format!(
            "{}: stepping-stone evidence of {model} ({} replicas x {} particles, {path_note})",
            level.name, params.replicas, params.particles
        ),
        total: params.replicas as u64,
    });
    let t0 = Instant::now();
    let mut replicas = Vec::new();
    let mut loaded = 0;
    let mut rungs = Vec::new();
    for r in 0..params.replicas {
        let key = replica_key(&params, r, reference.as_ref().map(|(q, _)| q));
        let file = dir.join(format!("replica-{r}-{}.ckpt", checkpoint::key_hex(&key)));
        if let Some(rep) = load_replica(&file, &key) {
            replicas.push(rep);
            loaded += 1;
            progress(Event::Advance);
            continue;
        }
        let rep = match &reference {
            Some((q, _)) => {
                reference_stepping_stone_replica(post, q, &params, r, &|_: Progress| ())
            }
            None => stepping_stone_replica(post, &params, r, &|_: Progress| ()),
        }
        .map_err(|e| fail(format!("stepping-stone of {model} at {}", level.name), e))?;
        rungs.push(rep.rungs.len());
        save_replica(&file, &key, &rep);
        replicas.push(rep);
        progress(Event::Advance);
    }
    progress(Event::Finish);
    let run = combine_replicas(replicas);
    let logs: Vec<String> = run
        .replicas
        .iter()
        .map(|r| format!("{:.2}", r.log_evidence))
        .collect();
    let notes = vec![format!(
        "stepping-stone {path_note}: {} replicas x {} particles ({} loaded from checkpoints; rungs per run replica {:?}), replica log evidences [{}]",
        params.replicas,
        params.particles,
        loaded,
        rungs,
        logs.join(", ")
    )];
    Ok((
        EvidenceRow {
            estimator: "stepping_stone".into(),
            prior: "declared".into(),
            log_evidence: run.log_evidence,
            se: run.log_evidence_se,
            n_loglik: run.n_loglik,
            seconds: t0.elapsed().as_secs_f64(),
        },
        notes,
    ))
}

/// The checkpoint key of replica `r`: the settings, the seed and the reference's numbers
/// (a replica saved with other settings or another reference is not reused).
fn replica_key(params: &SteppingStoneParams, r: usize, reference: Option<&Reference>) -> [u8; 32] {
    let mut e = Encoder::new();
    e.str("stepping_stone replica")
        .u64(params.particles as u64)
        .u64(params.replicas as u64)
        .u64(params.seed)
        .u64(r as u64);
    match reference {
        Some(q) => e.u64(1).f64s(&q.mean).f64s(&q.chol).f64(q.nu),
        None => e.u64(0),
    };
    e.key()
}

/// A finished replica's numbers, bit-exact; `None` when absent, written under another key or
/// unreadable (then the replica is run again).
fn load_replica(file: &Path, key: &[u8; 32]) -> Option<SteppingStoneReplica> {
    let bytes = checkpoint::read_matching(file, key).ok()??;
    let mut d = Decoder::new(&bytes);
    let rep = SteppingStoneReplica {
        log_evidence: d.f64()?,
        log_evidence_se: d.f64()?,
        rungs: Vec::new(),
        n_loglik: d.u64()?,
    };
    d.at_end().then_some(rep)
}

/// Written atomically; a failure only costs the resume.
fn save_replica(file: &Path, key: &[u8; 32], r: &SteppingStoneReplica) {
    let Some(dir) = file.parent() else { return };
    if checkpoint::ensure_dir(dir).is_err() {
        return;
    }
    let mut e = Encoder::new();
    e.f64(r.log_evidence).f64(r.log_evidence_se).u64(r.n_loglik);
    let _ = checkpoint::write_atomic(file, key, e.bytes());
}
