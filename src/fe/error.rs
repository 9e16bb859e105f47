//! Typed errors of the FE layer. Every variant names the study key it concerns
//! (`structure.beam.length`, `structure.points[2].position`, ...) and says how to fix it.

use thiserror::Error;

/// Errors raised while validating a joint specification, meshing or assembling.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FeError {
    /// A length that must be positive and finite is not.
    #[error("{key}: {value} m is not a valid dimension: give a positive, finite length in metres")]
    InvalidDimension { key: String, value: f64 },

    /// The adhesive does not lie within the beam along x.
    #[error("{key}: {detail}")]
    AdhesiveOutsideBeam { key: String, detail: String },

    /// A material constant is out of its admissible range.
    #[error("{key}: {value} is not admissible: {requirement}")]
    InvalidMaterial {
        key: String,
        value: f64,
        requirement: String,
    },

    /// Element size or divisions that do not give at least one element per direction.
    #[error("{key}: {detail}")]
    InvalidMesh { key: String, detail: String },

    /// A point outside the beam.
    #[error("{key}: point {id} at ({x}, {y}, {z}) m is off the beam (outside it by {distance_m:.3e} m): give coordinates on the beam surface, x in [0, L], y in [0, t_b], z in [0, w]")]
    PointOffBeam {
        key: String,
        id: u32,
        x: f64,
        y: f64,
        z: f64,
        distance_m: f64,
    },

    /// A point inside the beam but not on its surface.
    #[error("{key}: point {id} at ({x}, {y}, {z}) m is inside the beam, {distance_m:.3e} m from its nearest surface (tolerance 1e-6 m): move it onto a face, e.g. the upper face y = t_b")]
    PointNotOnSurface {
        key: String,
        id: u32,
        x: f64,
        y: f64,
        z: f64,
        distance_m: f64,
    },

    /// A direction that is not a unit axis direction, or the same (id, direction) twice.
    #[error("{key}: {detail}")]
    InvalidPointDirection { key: String, detail: String },

    /// The model has no fixed DOF: its stiffness is singular.
    #[error("{key}: the model has no fixed DOF (rigid-body motion is free, the stiffness is singular): {fix}")]
    Unconstrained { key: String, fix: String },

    /// The sparse algebra could not allocate (mesh too fine for the available memory).
    #[error("{key}: out of memory while forming {what}: use a coarser mesh")]
    OutOfMemory { key: String, what: String },

    /// An element with a non-positive Jacobian determinant (inverted or degenerate).
    #[error("{key}: element {element} has a non-positive Jacobian determinant ({det_j:e}) at a Gauss point: the mesh is inverted or degenerate")]
    DegenerateElement {
        key: String,
        element: usize,
        det_j: f64,
    },
}

impl FeError {
    /// The message without its leading `key: ` (for errors that name the key themselves).
    pub fn detail(&self) -> String {
        let msg = self.to_string();
        match msg.strip_prefix(&format!("{}: ", self.key())) {
            Some(rest) => rest.to_string(),
            None => msg,
        }
    }

    /// The study key this error concerns, e.g. `structure.adhesive.length`.
    pub fn key(&self) -> &str {
        match self {
            FeError::InvalidDimension { key, .. }
            | FeError::AdhesiveOutsideBeam { key, .. }
            | FeError::InvalidMaterial { key, .. }
            | FeError::InvalidMesh { key, .. }
            | FeError::PointOffBeam { key, .. }
            | FeError::PointNotOnSurface { key, .. }
            | FeError::InvalidPointDirection { key, .. }
            | FeError::Unconstrained { key, .. }
            | FeError::OutOfMemory { key, .. }
            | FeError::DegenerateElement { key, .. } => key,
        }
    }
}

/// Errors of the model's copy-with-an-effect methods (point masses, a shaker, a degraded bond
/// region): programming or input errors of the caller, named with the value at fault.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ModelEditError {
    /// A point index beyond the model's observation points.
    #[error("point index {index} is out of range ({n_points} points)")]
    PointOutOfRange { index: usize, n_points: usize },

    /// A physical parameter of the effect outside its admissible range.
    #[error("{0}")]
    InvalidParameter(String),

    /// The sparse matrix with the effect could not be formed.
    #[error("cannot form {what}: {detail}")]
    Sparse { what: &'static str, detail: String },
}
