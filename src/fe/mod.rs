//! Finite elements: the structural model that every later stage evaluates.
//!
//! Dynamic stiffness (method.md, "Dynamic stiffness"):
//!
//! Z(w) = -w^2 M + K_b + j w C_b + j D_b + E*(w) S,   S = dK_adhesive/dE at fixed nu.
//!
//! Layers (fenris style): [`element`] reference 20-node hexahedron (shape functions only),
//! [`geometry`] physical element (geometry map, Jacobian, element matrices),
//! [`assembly`] global sparse pattern built once, values filled many times,
//! [`mesh`] structured mesher of beam + adhesive, [`lap`] the single-lap joint, [`points`] measurement point -> DOF map,
//! [`matrix_market`] import/export of externally assembled models, [`harwell_boeing`] and
//! [`abaqus`] readers of other programs' matrix files, [`foreign`] the import route over all
//! three (units, constrained DOFs, DOF maps by equation or node).

pub mod abaqus;
pub mod assembly;
pub mod base;
pub mod cost;
pub mod element;
pub mod error;
pub mod foreign;
pub mod geometry;
pub mod harwell_boeing;
pub mod joint;
pub mod lap;
pub mod matrix_market;
pub mod mesh;
pub mod model;
pub mod points;
pub mod region;
pub mod synthetic;

pub use error::{FeError, ModelEditError};
pub use model::{ObservationPoint, StructuralModel};
