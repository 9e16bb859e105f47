//! The FRF data model: per excitation level, channels on one frequency grid.

use crate::common::{Direction, C64};

/// The physical quantity of an FRF (response per unit force).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Quantity {
    /// Displacement / force, m/N.
    Receptance,
    /// Velocity / force, (m/s)/N.
    Mobility,
    /// Acceleration / force, (m/s^2)/N.
    Accelerance,
}

/// One measured FRF (and optional coherence).
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    pub response_id: u32,
    pub response_dir: Direction,
    pub reference_id: u32,
    pub reference_dir: Direction,
    /// One value per line of the level's grid, in SI units of `quantity`.
    pub values: Vec<C64>,
    /// Ordinary coherence per line, if measured.
    pub coherence: Option<Vec<f64>>,
    /// Source file and dataset index (0-based) it was read from, if any.
    pub source: Option<(String, usize)>,
}

/// All channels measured at one excitation level, on one frequency grid.
#[derive(Clone, Debug, PartialEq)]
pub struct FrfLevel {
    /// Level name, e.g. "L1".
    pub name: String,
    /// RMS excitation force (N), if known.
    pub force_rms_n: Option<f64>,
    /// Number of averages of the estimator, if known.
    pub n_averages: Option<u32>,
    pub quantity: Quantity,
    /// Frequency lines (Hz), strictly increasing.
    pub freq_hz: Vec<f64>,
    pub channels: Vec<Channel>,
}

/// A measured data set: one or more excitation levels.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct FrfSet {
    pub levels: Vec<FrfLevel>,
}
