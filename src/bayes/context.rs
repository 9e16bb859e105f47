//! What the inference stages read of a run besides their stage parameters
//! ([`super::InferenceParams`]): the seed, the identified models with their laws, what the
//! likelihood needs to know of the measurements and the structure ([`PosteriorInputs`]), and
//! where checkpoints go ([`Checkpoints`]). The pipeline fills them from the validated study.

use crate::material::ConstitutiveModel;
use crate::stage::LevelData;
use crate::study::effects::DeclaredEffect;
use crate::study::{Estimator, ModelSpec};
use std::path::{Path, PathBuf};

/// What every posterior of a run is built from besides its stage's priors and settings.
#[derive(Clone, Copy, Debug)]
pub struct PosteriorInputs<'a> {
    /// The study file, named in input errors.
    pub file: &'a Path,
    /// The analyser's H1 estimator (`measurements.estimator`): with it, the forward model
    /// predicts the expected H1 of the measurement model.
    pub estimator: Option<&'a Estimator>,
    /// Ids of the structure's points in the engine's order (declared point masses name them).
    pub point_ids: &'a [u32],
    /// The study's declared effects (`[[structure.effects]]`).
    pub declared: &'a [DeclaredEffect],
}

/// Which stage a step belongs to: the level, the model, and the seed of the stage's streams.
#[derive(Clone, Copy, Debug)]
pub struct At<'a> {
    pub level: &'a LevelData,
    pub model: &'a str,
    pub seed: u64,
}

/// The run-wide inputs of the inference stages.
pub struct RunContext<'a> {
    pub posterior: PosteriorInputs<'a>,
    /// The study's seed: the MAP search, samplers and evidence of each (model, level) derive
    /// their streams from it.
    pub seed: u64,
    /// The identified models (names, initial values), with their laws in the same order.
    pub models: &'a [ModelSpec],
    pub laws: &'a [Box<dyn ConstitutiveModel>],
    pub checkpoints: Checkpoints<'a>,
}

impl RunContext<'_> {
    /// The spec and law of the model named `name` (case-insensitive).
    pub fn model(&self, name: &str) -> Option<(&ModelSpec, &dyn ConstitutiveModel)> {
        self.models
            .iter()
            .zip(self.laws)
            .find(|(m, _)| m.name.eq_ignore_ascii_case(name))
            .map(|(m, l)| (m, l.as_ref()))
    }
}

/// Where the samplers and the stepping-stone evidence keep their checkpoints, so that an
/// interrupted run resumes where it stopped and ends with the same draws: one folder per
/// study, level, model and stage under `folder` (the samplers key their files by their own
/// settings).
#[derive(Clone, Copy, Debug)]
pub struct Checkpoints<'a> {
    /// `.checkpoints/` beside the results folder.
    pub folder: &'a Path,
    /// The study's name and the SHA-256 of its file (hex): part of every folder's name.
    pub study: &'a str,
    pub study_sha256: &'a str,
}

impl Checkpoints<'_> {
    /// The folder of `stage` ("nuts", "tmcmc", "stepping_stone") of `model` at `level`:
    /// `<study>-<level>-<model>-<stage>-<hash>`, the hash (FNV-1a) of the level's data and of
    /// the study file's SHA-256.
    pub fn dir(&self, level: &LevelData, model: &str, stage: &str) -> PathBuf {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |b: u64| {
            for k in 0..8 {
                h = (h ^ ((b >> (8 * k)) & 0xff)).wrapping_mul(0x0000_0100_0000_01B3);
            }
        };
        for v in &level.column.accelerance {
            eat(v.re.to_bits());
            eat(v.im.to_bits());
        }
        for c in level.coherence.iter().flatten() {
            eat(c.to_bits());
        }
        for b in self.study_sha256.bytes() {
            eat(b as u64);
        }
        self.folder.join(format!(
            "{}-{}-{}-{}-{:016x}",
            self.study, level.name, model, stage, h
        ))
    }
}
