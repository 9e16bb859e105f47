//! Experimental modal analysis of measured FRFs: single-mode circle fit (the paper's
//! Table 2, used by the IEM for lambda_X = w_r^2 (1 + j eta_r)).

pub mod circle_fit;

pub use circle_fit::{circle_fit, CircleFitParams, CircleFitResult};

/// What can go wrong in a modal analysis of measured FRFs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModalError {
    /// Frequencies and values differ in length.
    #[error("{n_freq} frequency lines but {n_values} FRF values: give one value per line")]
    LengthMismatch { n_freq: usize, n_values: usize },
    /// The band is empty, reversed or has too few usable lines.
    #[error("band {lo_hz} - {hi_hz} Hz holds {n_points} usable lines (lines at 0 Hz excluded); the circle fit needs at least {needed}: widen the band (width_hz of its [analyses] entry) or give data on finer frequency lines")]
    TooFewPoints {
        lo_hz: f64,
        hi_hz: f64,
        n_points: usize,
        needed: usize,
    },
    /// A value or a frequency in the band is NaN or infinite.
    #[error("non-finite FRF value or frequency at {freq_hz} Hz in the band: clean the data or move the band")]
    NonFinite { freq_hz: f64 },
    /// The frequency lines in the band are not strictly increasing.
    #[error("frequency lines are not strictly increasing near {freq_hz} Hz")]
    NotIncreasing { freq_hz: f64 },
    /// The points do not describe a circle (collinear, coincident, or a degenerate fit).
    #[error("the FRF points in {lo_hz} - {hi_hz} Hz do not form a circle ({why}): check the band holds one resonance")]
    DegenerateCircle { lo_hz: f64, hi_hz: f64, why: String },
    /// No points on both sides of the located resonance, so no loss factor.
    #[error("the resonance located at {freq_hz} Hz has no fitted points on one side (band {lo_hz} - {hi_hz} Hz): centre the band on the peak")]
    OneSided {
        freq_hz: f64,
        lo_hz: f64,
        hi_hz: f64,
    },
}
