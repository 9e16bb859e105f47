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

impl FrfLevel {
    /// The level in another quantity: accelerance = j w mobility = -w^2 receptance
    /// (w = 2 pi f). Converting towards receptance divides by j w, so a 0 Hz line becomes
    /// non-finite: drop it first.
    pub fn convert(&self, to: Quantity) -> FrfLevel {
        let mut out = self.clone();
        out.quantity = to;
        if to != self.quantity {
            for ch in &mut out.channels {
                for (h, f) in ch.values.iter_mut().zip(&self.freq_hz) {
                    *h = crate::data::uff_frf::convert_value(*h, *f, self.quantity, to);
                }
            }
        }
        out
    }

    /// Index of the channel with this response and reference (axes compared, signs ignored).
    pub fn find_channel(
        &self,
        response: (u32, Direction),
        reference: (u32, Direction),
    ) -> Option<usize> {
        self.channels.iter().position(|c| {
            c.response_id == response.0
                && c.response_dir.axis == response.1.axis
                && c.reference_id == reference.0
                && c.reference_dir.axis == reference.1.axis
        })
    }
}
