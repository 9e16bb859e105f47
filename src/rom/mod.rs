//! Certified reduced-order FRF engine and the pencil sweep.
//!
//! The dynamic stiffness (method.md) is Z(w, E*) = -w^2 M + K_b + j w C_b + j D_b + E* S:
//! the adhesive enters through one complex scalar per frequency line. The ROM projects Z
//! on a real basis V (n x n_r, M-orthonormal):
//!
//! Z_r(w, E*) = V^T Z V = -w^2 M_r + K_r + j w C_r + j D_r + E* S_r,  B_r = V^T B,
//!
//! and H(w) ~ B_r^T Z_r^-1 B_r. V is spanned by block Krylov (load-dependent Ritz) vectors
//! (K_b + E_ref S)^-1 (M (K_b + E_ref S)^-1)^k B at log-spaced real E_ref across the declared
//! modulus range ([`basis`]); the Krylov sequence of (K, M) converges to the low modes seen
//! by the observation points, so the modes below a cutoff are contained in it.
//! The ROM is certified against full-model sparse LU solves on a validation grid of
//! moduli x lines and enriched (more E_ref, deeper Krylov) until the error relative to the
//! peak of each FRF is below the tolerance ([`certify`]).
//! [`pencil::PencilSweep`] then evaluates a whole sweep in O(N_f n_terms n_out n_in) from a
//! per-line eigen-decomposition of the reduced pencil prepared once per frequency grid.

pub mod basis;
pub mod cache;
pub mod certify;
pub mod compress;
pub(crate) mod dense;
pub mod pencil;
pub mod reduced;
pub mod reference;
pub(crate) mod sparse;
pub mod term_build;
pub(crate) mod term_reference;
pub mod terms;

pub use certify::{build_basis_only, build_rom};
pub use pencil::{PencilParams, PencilSweep};
pub use reduced::ReducedModel;
pub use term_build::{add_scaled, build_term_rom, model_with_term};
pub use terms::{TermCertificate, TermRom, TermSpec, WithTerms};

/// Declared range of the adhesive's complex modulus E* = E' + j E'' (Pa).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModulusRange {
    /// (min, max) storage modulus E' (Pa).
    pub e_storage_pa: (f64, f64),
    /// (min, max) loss modulus E'' (Pa).
    pub e_loss_pa: (f64, f64),
}

impl Default for ModulusRange {
    /// The default modulus range: E' in [0.5, 50] MPa, E'' in [0.01, 20] MPa.
    fn default() -> Self {
        ModulusRange {
            e_storage_pa: (0.5e6, 50e6),
            e_loss_pa: (0.01e6, 20e6),
        }
    }
}

impl ModulusRange {
    /// Centre of the box in the complex plane (the pencil's expansion point e0).
    pub fn centre(&self) -> crate::common::C64 {
        crate::common::C64::new(
            0.5 * (self.e_storage_pa.0 + self.e_storage_pa.1),
            0.5 * (self.e_loss_pa.0 + self.e_loss_pa.1),
        )
    }
    /// Largest |E* - centre| over the box (half its diagonal).
    pub fn radius(&self) -> f64 {
        0.5 * (self.e_storage_pa.1 - self.e_storage_pa.0).hypot(self.e_loss_pa.1 - self.e_loss_pa.0)
    }
    fn validate(&self) -> Result<(), RomError> {
        let (a, b) = self.e_storage_pa;
        let (c, d) = self.e_loss_pa;
        if !(a > 0.0 && b >= a && c >= 0.0 && d >= c && b.is_finite() && d.is_finite()) {
            return Err(RomError::Params(format!(
                "modulus range must have 0 < E'min <= E'max and 0 <= E''min <= E''max (Pa); got E' {:?}, E'' {:?}",
                self.e_storage_pa, self.e_loss_pa
            )));
        }
        Ok(())
    }
}

/// Settings of the ROM build and certificate.
#[derive(Clone, Debug)]
pub struct RomParams {
    /// Frequency band (Hz) the ROM must cover. Default (1, 500).
    pub band_hz: (f64, f64),
    /// Declared modulus range. Default [`ModulusRange::default`].
    pub range: ModulusRange,
    /// Certificate tolerance: max |H_rom - H_full| / max_w |H_full| per FRF and modulus. Default 1e-6.
    pub tolerance: f64,
    /// Return an uncertified ROM (certificate.passed = false) instead of an error. Default false.
    pub allow_uncertified: bool,
    /// Number of log-spaced real E_ref at the first enrichment level (then 2x-1 per level). Default 3.
    pub n_e_ref_initial: usize,
    /// Krylov blocks per E_ref at the first level. Default 4.
    pub krylov_depth_initial: usize,
    /// Extra Krylov blocks per E_ref at each further level. Default 3.
    pub krylov_depth_step: usize,
    /// Maximum enrichment levels. Default 5.
    pub max_levels: usize,
    /// A new vector is dropped when its M-norm after orthogonalisation falls below this
    /// fraction of its norm before. Default 1e-10.
    pub deflation_tol: f64,
    /// Validation moduli per axis (log-spaced incl. the corners). Default 3 (9 moduli).
    pub n_cert_moduli_per_axis: usize,
    /// Validation lines, linearly spaced across the band incl. its ends. Default 25.
    pub n_cert_lines: usize,
    /// How the certificate's full-model FRFs are computed. Default [`Reference::default`].
    pub reference: Reference,
    /// ROMs with terms only ([`term_build::build_term_rom`]): the second-stage compression of the
    /// certified basis ([`compress`]); None keeps the enriched basis. Default
    /// [`compress::CompressParams::default`].
    pub compress: Option<compress::CompressParams>,
    /// Outputs (indices into the model's points) whose loads start the basis's Krylov
    /// sequences (with the inputs) and whose FRFs the certificate judges; `None`: every output.
    /// The others are carried by the same basis, uncertified: a test plan's many candidate
    /// sensors ride on the basis certified at the study's points.
    /// Default `None`.
    pub certified_outputs: Option<Vec<usize>>,
}

/// The certificate's full-model solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reference {
    /// A complex sparse LU of Z per validation point: about 0.3 s per point on the 5 mm
    /// mesh, 37 s and 4 GB on the 2.5 mm mesh.
    SparseLu,
    /// GMRES with the ROM as coarse space and the basis's real Cholesky factors as
    /// preconditioner ([`reference`]), to ||b - Z x||_{P^-1} <= `residual_tol` ||b||_{P^-1}
    /// at every point (the residual in the energy norm of the preconditioner P = K_b + e S),
    /// at most `max_iter` iterations.
    Iterative { residual_tol: f64, max_iter: usize },
    /// Per validation modulus, one complex sparse LU of Z at the middle of the band (in w^2) and
    /// the block Krylov space of its shift-invert operator, whose shifted systems give every
    /// line ([`term_reference::shifted_lines`]), to a preconditioned residual of
    /// [`term_reference::SHIFTED_RESIDUAL_TOL`]; the lines it does not resolve, and a model with
    /// viscous damping C_b, by the sparse LU at the point.
    Shifted,
}

impl Reference {
    /// The cheaper reference for a model of `n_dof` DOFs, whatever its inputs: the shifted
    /// Krylov solver ([`Reference::Shifted`]) up to `SHIFTED_REFERENCE_MAX_DOF` DOFs, GMRES
    /// above. The shifted solver factors once per validation modulus (9 sparse LUs for 225
    /// points, every input at once), GMRES needs no complex factorisation but one Krylov solve
    /// per point and input, the sparse LU at every point one factorisation per point. Measured
    /// (`rfmlab rom STUDY`, the certificate's seconds, release, 2 cores):
    ///
    /// | model | DOFs | inputs | shifted | GMRES | LU per point |
    /// |---|---|---|---|---|---|
    /// | paper joint, 5 mm (`default.toml`) | 10,248 | 4 | 2.6 | 4.5 | 43.5 |
    /// | independent time-domain joint | 15,846 | 4 | 5.0 | 25.8 | |
    /// | lap joint | 37,896 | 4 | 57 | 78 | |
    /// | 5 mm block off the beam's end | 46,380 | 4 | 159 | 22 | |
    ///
    /// Above some 40,000 DOFs the LU's fill grows faster than the mesh (44 million entries of
    /// the Cholesky factor for the last row, 21 million for the lap joint) and each of the
    /// shifted solver's factorisations costs more than GMRES's whole sweep.
    pub fn suited(n_dof: usize) -> Reference {
        if n_dof <= SHIFTED_REFERENCE_MAX_DOF {
            Reference::Shifted
        } else {
            Reference::default()
        }
    }
}

/// [`Reference::suited`]: the largest model (DOFs) for which the shifted Krylov reference is
/// chosen.
pub const SHIFTED_REFERENCE_MAX_DOF: usize = 40_000;

impl Default for Reference {
    /// Iterative, residual 1e-9 (energy norm), at most 80 iterations. The worst validation
    /// points are near-resonant and lightly damped, where the ROM's error is known to a few
    /// 1e-8 of the peak whatever the reference: on the 10 mm joint the certificate reads
    /// 6.96e-8 with the sparse LU, 7.6e-9 / 1.15e-8 with GMRES at 1e-9 / 1e-10; on the 2.5 mm
    /// joint 1.19e-7 / 1.29e-7 (1e-10 costs 4x the time). A residual of 1e-8 moved the 2.5 mm
    /// reference by up to 1e-7 of a peak.
    fn default() -> Self {
        Reference::Iterative {
            residual_tol: 1e-9,
            max_iter: 80,
        }
    }
}

impl Default for RomParams {
    fn default() -> Self {
        RomParams {
            band_hz: (1.0, 500.0),
            range: ModulusRange::default(),
            tolerance: 1e-6,
            allow_uncertified: false,
            n_e_ref_initial: 3,
            krylov_depth_initial: 4,
            krylov_depth_step: 3,
            max_levels: 5,
            deflation_tol: 1e-10,
            n_cert_moduli_per_axis: 3,
            n_cert_lines: 25,
            reference: Reference::default(),
            compress: Some(compress::CompressParams::default()),
            certified_outputs: None,
        }
    }
}

/// Outcome of the certificate.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Certificate {
    /// Largest error over the validation set, relative to the peak |H_full| of each FRF.
    pub max_rel_error: f64,
    /// Validation moduli.
    pub n_moduli: usize,
    /// Validation lines.
    pub n_lines: usize,
    /// n_r, the number of basis vectors.
    pub basis_size: usize,
    /// Time spent building the basis and the reduced matrices (s).
    pub seconds_basis: f64,
    /// Time spent on the full-model reference solves and the comparison (s).
    pub seconds_certify: f64,
    pub passed: bool,
    /// Enrichment levels used.
    pub levels: usize,
    /// The E_ref (Pa) used by the basis.
    pub e_ref_pa: Vec<f64>,
    /// Largest error after each level (same measure as max_rel_error).
    pub error_history: Vec<f64>,
    /// The reference solver: "shifted Krylov", "GMRES" or "sparse LU".
    #[serde(default)]
    pub reference: String,
    /// GMRES: the largest final relative residual ||b - Z x||_{P^-1} / ||b||_{P^-1} (energy norm of
    /// the preconditioner P = K_b + e S) and the largest iteration count. Shifted Krylov: the
    /// largest final residual ||F^-1 (b - Z x)|| / ||F^-1 b|| of a resolved line and the largest
    /// Krylov space (vectors).
    #[serde(default)]
    pub reference_residual: Option<f64>,
    #[serde(default)]
    pub reference_iterations: Option<usize>,
    /// GMRES and shifted Krylov: validation points solved by sparse LU instead, those the
    /// iterative solver did not resolve and those where the ROM missed its solution by more than
    /// the tolerance (an iterative solution near a lightly damped resonance can be off by that
    /// much, and it carries no floor).
    #[serde(default)]
    pub reference_direct_points: usize,
    /// Validation points where double precision cannot resolve the full model to the
    /// tolerance: the sparse LU's iterative refinement stagnates at a relative step above
    /// tolerance / [`certify::FLOOR_FACTOR`] (a stiff adherend held by a soft layer, near a
    /// resonance). There the ROM is judged against `FLOOR_FACTOR` x that floor, and
    /// `max_rel_error` is the error scaled to the tolerance (error x tolerance / allowance).
    #[serde(default)]
    pub floor_points: usize,
    /// The largest attainable relative accuracy of a sparse-LU reference solve (the size of
    /// its second refinement step relative to the solution).
    #[serde(default)]
    pub floor_max: f64,
    /// The largest plain relative error at the floor-limited points.
    #[serde(default)]
    pub floor_points_error: f64,
}

/// Errors of the ROM build and sweeps.
#[derive(Debug, thiserror::Error)]
pub enum RomError {
    #[error("invalid ROM parameters: {0}")]
    Params(String),
    #[error("invalid model: {0}")]
    Model(String),
    #[error("factorization failed: {0}")]
    Factorization(String),
    #[error("the ROM is not certified: max relative error {error:.3e} > tolerance {tolerance:.1e} with {basis_size} basis vectors after {levels} levels; loosen solver.rom_tolerance (`rfmlab rom --tolerance`), narrow the analysis band or the modulus range, or use solver.engine = \"full\"")]
    Uncertified {
        error: f64,
        tolerance: f64,
        basis_size: usize,
        levels: usize,
    },
    #[error("pencil sweep: {0}")]
    Pencil(String),
}

impl From<RomError> for crate::frf::FrfError {
    fn from(e: RomError) -> Self {
        crate::frf::FrfError::Other(e.to_string())
    }
}
