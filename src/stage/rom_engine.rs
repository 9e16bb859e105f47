//! The run's ROM engine: the certified reduced model with pencils prepared for the grids the
//! run evaluates (the band's lines, the measurement model's fine grid per level).

use crate::common::C64;
use crate::frf::{FrfEngine, FrfError, Sweep};

/// The ROM with a prepared pencil for the band's lines; other grids fall back to the reduced
/// model's LU sweep (both are certified over the same range).
pub(super) struct RomEngine {
    pub(super) rom: crate::rom::ReducedModel,
    /// Prepared pencils: the band's lines, and the measurement model's fine grid per level.
    pub(super) pencils: Vec<crate::rom::PencilSweep>,
}

impl FrfEngine for RomEngine {
    fn n_out(&self) -> usize {
        self.rom.n_out()
    }
    fn inputs(&self) -> &[usize] {
        self.rom.inputs()
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        let same = |p: &crate::rom::PencilSweep| {
            omega_rad_s.len() == p.omega_rad_s().len()
                && omega_rad_s
                    .iter()
                    .zip(p.omega_rad_s())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if let Some(p) = self.pencils.iter().find(|p| same(p)) {
            p.sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
        } else {
            self.rom
                .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
        }
    }
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        FrfEngine::complex_modes(&self.rom, modulus_pa, n_modes)
    }
    fn complex_modes_with_masses(
        &self,
        modulus_pa: C64,
        n_modes: usize,
        masses: &[(usize, f64)],
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        FrfEngine::complex_modes_with_masses(&self.rom, modulus_pa, n_modes, masses)
    }
}
