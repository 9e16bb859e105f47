//! FRF evaluation: one interface for the full model and the reduced-order model.
//!
//! Receptance H(w) = Z(w)^-1 read at observation points, accelerance H' = -w^2 H.
//! Sensitivities (paper eq. 44-47): dH/dp = -H (dZ/dp) H, so with Z depending on the
//! adhesive through E* = E' + j E'' only, dH_ij/dE' = -H_i^T S H_j and dH_ij/dE'' = j dH_ij/dE'.

use crate::common::C64;

pub mod full;
pub use full::{FullModel, FullParams};

/// What a sweep returns, for n_lines frequency lines, n_out observation points (outputs) and
/// n_in input (excitation) points. Index of entry (line l, output i, input j):
/// `(l * n_out + i) * n_in + j`.
#[derive(Clone, Debug, Default)]
pub struct Sweep {
    pub n_lines: usize,
    pub n_out: usize,
    pub n_in: usize,
    /// Receptance H_ij (m/N).
    pub h: Vec<C64>,
    /// dH_ij/dE' (m/N/Pa); dH_ij/dE'' = j dH_ij/dE'. Empty unless derivatives were requested.
    pub dh_de: Vec<C64>,
    /// b_i^T S H_j: the adhesive sensitivity matrix applied to receptance column j, read at
    /// output i (m/N * m = m^2/N ... per unit modulus). Used by the RFM fill of unmeasured
    /// entries. Empty unless derivatives were requested.
    pub sh: Vec<C64>,
}

impl Sweep {
    #[inline]
    pub fn idx(&self, line: usize, out: usize, inp: usize) -> usize {
        (line * self.n_out + out) * self.n_in + inp
    }
    /// Allocate zeroed storage.
    pub fn zeros(n_lines: usize, n_out: usize, n_in: usize, with_derivatives: bool) -> Self {
        let n = n_lines * n_out * n_in;
        Sweep {
            n_lines,
            n_out,
            n_in,
            h: vec![C64::new(0.0, 0.0); n],
            dh_de: if with_derivatives {
                vec![C64::new(0.0, 0.0); n]
            } else {
                Vec::new()
            },
            sh: if with_derivatives {
                vec![C64::new(0.0, 0.0); n]
            } else {
                Vec::new()
            },
        }
    }
}

/// Errors of FRF evaluation.
#[derive(Debug, thiserror::Error)]
pub enum FrfError {
    #[error("the dynamic stiffness is singular at {freq_hz} Hz (E* = {modulus:?} Pa): is the model constrained?")]
    Singular { freq_hz: f64, modulus: C64 },
    #[error("{what}: expected length {expected}, got {got}")]
    Length {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("input point index {0} is not an observation point of the model")]
    BadInput(usize),
    #[error("{0}")]
    Other(String),
}

/// Check that a sweep got one modulus per frequency line (every engine's first check).
pub fn check_line_lengths(omega_rad_s: &[f64], modulus_pa: &[C64]) -> Result<(), FrfError> {
    if modulus_pa.len() != omega_rad_s.len() {
        return Err(FrfError::Length {
            what: "modulus_pa (one complex modulus per frequency line)",
            expected: omega_rad_s.len(),
            got: modulus_pa.len(),
        });
    }
    Ok(())
}

/// One interface for full and reduced FRF evaluation.
pub trait FrfEngine: Send + Sync {
    /// Number of observation points (outputs).
    fn n_out(&self) -> usize;
    /// Indices (into the outputs) of the excitation points.
    fn inputs(&self) -> &[usize];
    /// Evaluate receptances (and optionally dH/dE' and S H) on the given lines.
    /// `omega_rad_s` and `modulus_pa` have one entry per line; `out` is resized as needed.
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError>;

    /// Allocating convenience form of [`FrfEngine::sweep_into`].
    fn sweep(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
    ) -> Result<Sweep, FrfError> {
        let mut s = Sweep::default();
        self.sweep_into(omega_rad_s, modulus_pa, with_derivatives, &mut s)?;
        Ok(s)
    }

    /// The lowest `n_modes` complex modes of (K_b + j D_b + E* S, M) at a constant modulus
    /// (Pa), sorted by Re lambda, when this engine computes modes itself (the ROM does, from
    /// its reduced pencil); `None` sends callers to [`crate::modes::complex_modes`] on the
    /// full model.
    fn complex_modes(
        &self,
        _modulus_pa: C64,
        _n_modes: usize,
    ) -> Option<Result<Vec<EngineMode>, FrfError>> {
        None
    }

    /// [`FrfEngine::complex_modes`] of the structure with point masses `(output index, kg)`
    /// added (M -> M + sum m b_k b_k^T), when this engine can (the ROM projects the masses
    /// exactly: V^T b_k is its reduced load); `None` sends callers to the full model with the
    /// masses. No masses: the plain modes.
    fn complex_modes_with_masses(
        &self,
        modulus_pa: C64,
        n_modes: usize,
        masses: &[(usize, f64)],
    ) -> Option<Result<Vec<EngineMode>, FrfError>> {
        if masses.is_empty() {
            self.complex_modes(modulus_pa, n_modes)
        } else {
            None
        }
    }

    /// The same engine computing only the input columns `inputs` (a subset of
    /// [`FrfEngine::inputs`]) and, of them, at least the output rows `outputs`, with the same
    /// values bit for bit, when that costs less than the whole sweep (the ROM's prepared
    /// pencils: the cost is proportional to the entries computed); `None` when this engine
    /// cannot, and callers use it whole. Rows outside `outputs` may hold NaN, and a sweep with
    /// derivatives may leave [`Sweep::sh`] empty. A likelihood needs H and dH/dE' in the
    /// excitation's column, plus the columns of the points that carry masses, read at the
    /// measured outputs and those points. The narrowed engine sweeps the plain structure only
    /// (no [`FrfEngine::sweep_terms`]).
    fn with_fewer_points(
        &self,
        _inputs: &[usize],
        _outputs: &[usize],
    ) -> Option<Box<dyn FrfEngine + '_>> {
        None
    }

    /// Names of the extra structural terms G_k this engine can add to its dynamic stiffness
    /// ([`FrfEngine::sweep_terms`]); none by default.
    fn term_names(&self) -> Vec<String> {
        Vec::new()
    }

    /// A sweep of `Z(w, E*) + sum_k c_k(w, E*) G_k` with `c_k = v_k (p_k + q_k E*)`
    /// ([`TermCoef`]): the receptances (with dH/dE' of the whole Z, which holds the `q_k` terms,
    /// when asked) and, when asked, dH/dv_k per term in the sweep's layout. Engines without
    /// extra terms return an error.
    fn sweep_terms(
        &self,
        _omega_rad_s: &[f64],
        _modulus_pa: &[C64],
        _terms: &[TermCoef],
        _with_derivatives: bool,
    ) -> Result<(Sweep, Vec<Vec<C64>>), FrfError> {
        Err(FrfError::Other(
            "this FRF engine carries no extra structural terms (build a ROM with terms, rom::terms)"
                .into(),
        ))
    }
}

/// `engine` restricted to the inputs of `needed` and the output rows `rows`
/// ([`FrfEngine::with_fewer_points`]) when it has other inputs or outputs too and can sweep
/// fewer; `None` to use it whole. The rows outside `rows` of its sweeps may hold NaN, and its
/// sweeps with derivatives may leave `sh` empty.
pub fn narrowed<'a>(
    engine: &'a dyn FrfEngine,
    needed: &[usize],
    rows: &[usize],
) -> Option<Box<dyn FrfEngine + 'a>> {
    let inputs: Vec<usize> = engine
        .inputs()
        .iter()
        .copied()
        .filter(|j| needed.contains(j))
        .collect();
    let outputs: Vec<usize> = (0..engine.n_out()).filter(|i| rows.contains(i)).collect();
    if inputs.is_empty()
        || outputs.is_empty()
        || (inputs.len() == engine.inputs().len() && outputs.len() == engine.n_out())
    {
        return None;
    }
    engine.with_fewer_points(&inputs, &outputs)
}

/// Coefficient of an extra structural term G_k (index into [`FrfEngine::term_names`]):
/// `c_k(w, E*) = value (offset + per_modulus E*)`, e.g. a degraded bond region
/// (offset 0, per_modulus -1, value the loss fraction d) or a structural damping of the beam
/// (offset j, per_modulus 0, G = K_b).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TermCoef {
    pub index: usize,
    pub value: f64,
    pub offset: C64,
    pub per_modulus: f64,
}

/// A complex mode as an engine sees it: eigenvalue lambda = w_r^2 (1 + j eta), its
/// sensitivity phi^T S phi = d lambda / dE' (phi^T M phi = 1, no conjugate) and the shape at
/// the observation points.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineMode {
    pub lambda: C64,
    pub phi_s_phi: C64,
    pub at_points: Vec<C64>,
    /// Kinetic-energy fractions in x, y, z DOFs (sum 1), when the engine knows the DOF axes.
    pub energy_fraction_xyz: Option<[f64; 3]>,
}

impl EngineMode {
    /// sqrt(Re lambda) / (2 pi).
    pub fn freq_hz(&self) -> f64 {
        self.lambda.re.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)
    }
    /// Im lambda / Re lambda.
    pub fn loss_factor(&self) -> f64 {
        self.lambda.im / self.lambda.re
    }
}
