//! The run's ROM engine: the certified reduced model with pencils prepared for the grids the
//! run evaluates (the band's lines, the measurement model's fine grid per level).

use crate::common::C64;
use crate::frf::{FrfEngine, FrfError, Sweep};

/// The ROM with pencils prepared for the grids a caller evaluates; other grids fall back to
/// the reduced model's LU sweep (both are certified over the same range).
pub struct RomEngine {
    pub rom: crate::rom::ReducedModel,
    /// Prepared pencils: a run's band lines and the measurement model's fine grid per level; a
    /// test plan's measurement and expected-coherence grids.
    pub pencils: Vec<crate::rom::PencilSweep>,
}

impl RomEngine {
    /// `rom` with its pencil prepared on each of `grids` (rad/s).
    pub fn prepared(
        rom: crate::rom::ReducedModel,
        grids: &[Vec<f64>],
    ) -> Result<RomEngine, crate::rom::RomError> {
        let pencils = grids
            .iter()
            .map(|g| rom.prepare(g))
            .collect::<Result<_, _>>()?;
        Ok(RomEngine { rom, pencils })
    }

    fn pencil_for(&self, omega_rad_s: &[f64]) -> Option<&crate::rom::PencilSweep> {
        self.pencils.iter().find(|p| {
            omega_rad_s.len() == p.omega_rad_s().len()
                && omega_rad_s
                    .iter()
                    .zip(p.omega_rad_s())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
        })
    }
}

/// A [`RomEngine`] computing a subset of its input columns, read at a subset of its outputs,
/// without `S H` on its prepared grids ([`FrfEngine::with_fewer_points`]).
struct RomColumns<'a> {
    whole: &'a RomEngine,
    inputs: Vec<usize>,
    /// positions of `inputs` in the whole engine's inputs
    cols: Vec<usize>,
    /// the output rows computed on a prepared grid (None: every output)
    rows: Option<Vec<usize>>,
}

impl FrfEngine for RomColumns<'_> {
    fn n_out(&self) -> usize {
        self.whole.n_out()
    }
    fn inputs(&self) -> &[usize] {
        &self.inputs
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        if let Some(p) = self.whole.pencil_for(omega_rad_s) {
            // The likelihood reads H and dH/dE' only: no S H.
            return p.sweep_block_into(
                modulus_pa,
                self.rows.as_deref(),
                &self.cols,
                with_derivatives,
                false,
                out,
            );
        }
        // An unprepared grid: the reduced model's LU sweep of these columns.
        self.whole
            .rom
            .with_inputs(&self.inputs)
            .map_err(FrfError::from)?
            .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
    }
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        self.whole.complex_modes(modulus_pa, n_modes)
    }
    fn complex_modes_with_masses(
        &self,
        modulus_pa: C64,
        n_modes: usize,
        masses: &[(usize, f64)],
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        self.whole
            .complex_modes_with_masses(modulus_pa, n_modes, masses)
    }
}

impl FrfEngine for RomEngine {
    fn n_out(&self) -> usize {
        self.rom.n_out()
    }
    fn with_fewer_points(
        &self,
        inputs: &[usize],
        outputs: &[usize],
    ) -> Option<Box<dyn FrfEngine + '_>> {
        let cols = inputs
            .iter()
            .map(|j| self.rom.inputs().iter().position(|k| k == j))
            .collect::<Option<Vec<usize>>>()?;
        let n_out = self.rom.n_out();
        if outputs.iter().any(|&i| i >= n_out) {
            return None;
        }
        let rows = (outputs.len() < n_out).then(|| outputs.to_vec());
        Some(Box::new(RomColumns {
            whole: self,
            inputs: inputs.to_vec(),
            cols,
            rows,
        }))
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
        if let Some(p) = self.pencil_for(omega_rad_s) {
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
