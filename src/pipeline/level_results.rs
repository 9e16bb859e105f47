//! [`LevelResults`]: what a run computed for one level, the deterministic identification and
//! the Bayesian stages' results.

use crate::bayes::PosteriorResult;
use crate::identify::Identification;

/// Everything computed for one level: the deterministic identification (its fields read
/// through this value), the posteriors of the `[inference]` models, and the change from the
/// lower `[inference]` level (set on the higher level).
#[derive(Clone, Debug)]
pub struct LevelResults {
    pub identification: Identification,
    /// Posteriors of the `[inference]` models at this level.
    pub posteriors: Vec<PosteriorResult>,
    /// The change from the lower `[inference]` level to this one (set on the higher level).
    pub across_levels: Option<crate::bayes::levels::LevelComparison>,
}

impl LevelResults {
    /// The level's results before its inference stages.
    pub fn new(identification: Identification) -> Self {
        LevelResults {
            identification,
            posteriors: Vec::new(),
            across_levels: None,
        }
    }
}

impl std::ops::Deref for LevelResults {
    type Target = Identification;
    fn deref(&self) -> &Identification {
        &self.identification
    }
}
