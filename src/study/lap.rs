//! The `[structure.lap]` section: a single-lap joint built by the mesher
//! ([`crate::fe::lap`]), chosen with `structure.joint = "single_lap"`.
//!
//! ```toml
//! [structure]
//! joint = "single_lap"
//! excitation = 3
//!
//! [structure.lap]
//! length = 0.100          # m, each strip
//! thickness = 0.003       # m, both strips (thickness_upper = ... for a different upper strip)
//! width = 0.025           # m
//! overlap = 0.025         # m
//! support = "clamped"     # the lower strip's end x = 0 fixed; or "free" (free-free)
//! material = { E = 70e9, nu = 0.33, rho = 2700.0 }
//! adhesive = { thickness = 0.001, nu = 0.44, rho = 1160.0 }
//! # damping = { rayleigh_alpha = 0.0, rayleigh_beta = 0.0, structural = 0.0 }
//! # mesh = { element_size = 0.005, y_adhesive = 2, y_strip = 2, z = 5, end_aspect = 4.0,
//! #          max_aspect = 10.0, grading_ratio = 1.5, integration = "full", point_mapping = "interpolate",
//! #          refine = true, tolerance = 0.005, allowance = true, reference_modulus = 5e6 }
//! ```
//!
//! Points lie on either strip's surface: the lower strip is x in [0, L], y in [0, t1]; the
//! upper x in [L - overlap, 2 L - overlap], y in [t1 + t_a, t1 + t_a + t2]; z in [0, w].

use super::ctx::Ctx;
use super::raw::{RawLap, RawLapMesh};
use super::validate::{mesh_rule, MeshRuleKeys};
use super::{MeshRule, StudyError};
use crate::fe::element::Integration;
use crate::fe::joint::{AdherendDamping, IsoMaterial};
use crate::fe::lap::{LapGeometry, LapMeshParams, LapSpec, LapSupport};
use crate::fe::points::PointMapping;

/// Validate `[structure.lap]` into a [`LapSpec`] without points (the study's points are
/// added when the model is built).
pub(super) fn lap(ctx: &Ctx, l: &RawLap) -> Result<(LapSpec, MeshRule), StudyError> {
    let k = |s: &str| format!("structure.lap.{s}");
    let t1 = ctx.positive(&k("thickness"), l.thickness, "m")?;
    let geometry = LapGeometry {
        strip_length_m: ctx.positive(&k("length"), l.length, "m")?,
        lower_thickness_m: t1,
        upper_thickness_m: match l.thickness_upper {
            Some(t) => ctx.positive(&k("thickness_upper"), t, "m")?,
            None => t1,
        },
        width_m: ctx.positive(&k("width"), l.width, "m")?,
        overlap_m: ctx.positive(&k("overlap"), l.overlap, "m")?,
        adhesive_thickness_m: ctx.positive(&k("adhesive.thickness"), l.adhesive.thickness, "m")?,
    };
    if geometry.overlap_m >= geometry.strip_length_m {
        return Err(ctx.err(
            k("overlap"),
            format!(
                "{} m is not shorter than the strips ({} m): the overlap must be less than the strip length",
                geometry.overlap_m, geometry.strip_length_m
            ),
        ));
    }
    let support = match l.support.as_deref().unwrap_or("clamped") {
        "clamped" => LapSupport::Clamped,
        "free" => LapSupport::Free,
        o => {
            return Err(ctx.err(
                k("support"),
                format!("\"{o}\": use \"clamped\" (the lower strip's end x = 0 fixed) or \"free\""),
            ))
        }
    };
    let nu = |key: &str, v: f64| {
        if v.is_finite() && v > -1.0 && v < 0.5 {
            Ok(v)
        } else {
            Err(ctx.err(
                k(key),
                format!("{v} is not admissible: Poisson's ratio must satisfy -1 < nu < 0.5"),
            ))
        }
    };
    let adherend = IsoMaterial {
        e_pa: ctx.positive(&k("material.E"), l.material.e, "Pa")?,
        nu: nu("material.nu", l.material.nu)?,
        rho_kg_m3: ctx.positive(&k("material.rho"), l.material.rho, "kg/m^3")?,
    };
    let d = l.damping.as_ref();
    let damping = AdherendDamping {
        rayleigh_alpha_per_s: ctx.non_negative(
            &k("damping.rayleigh_alpha"),
            d.and_then(|d| d.rayleigh_alpha).unwrap_or(0.0),
            "1/s",
        )?,
        rayleigh_beta_s: ctx.non_negative(
            &k("damping.rayleigh_beta"),
            d.and_then(|d| d.rayleigh_beta).unwrap_or(0.0),
            "s",
        )?,
        structural_loss_factor: ctx.non_negative(
            &k("damping.structural"),
            d.and_then(|d| d.structural).unwrap_or(0.0),
            "-",
        )?,
    };
    let def = LapMeshParams::default();
    let m = l.mesh.as_ref();
    let get = |f: fn(&RawLapMesh) -> Option<usize>| m.and_then(f);
    let mesh = LapMeshParams {
        element_size_m: match m.and_then(|m| m.element_size) {
            Some(h) => ctx.positive(&k("mesh.element_size"), h, "m")?,
            None => def.element_size_m,
        },
        y_adhesive: {
            let v = get(|m| m.y_adhesive).unwrap_or(def.y_adhesive);
            if v < 2 {
                return Err(ctx.err(
                    k("mesh.y_adhesive"),
                    format!("{v}: the bond line needs at least 2 elements through its thickness"),
                ));
            }
            v
        },
        y_strip: {
            let v = get(|m| m.y_strip).unwrap_or(def.y_strip);
            if v == 0 {
                return Err(ctx.err(k("mesh.y_strip"), "0: give at least 1"));
            }
            v
        },
        z: match get(|m| m.z) {
            Some(0) => return Err(ctx.err(k("mesh.z"), "0: give at least 1")),
            z => z,
        },
        end_aspect: match m.and_then(|m| m.end_aspect) {
            Some(a) => ctx.positive(&k("mesh.end_aspect"), a, "-")?,
            None => def.end_aspect,
        },
        max_aspect: match m.and_then(|m| m.max_aspect) {
            Some(a) => ctx.positive(&k("mesh.max_aspect"), a, "-")?,
            None => def.max_aspect,
        },
        grading_ratio: match m.and_then(|m| m.grading_ratio) {
            Some(r) if r.is_finite() && (1.0..=3.0).contains(&r) => r,
            Some(r) => {
                return Err(ctx.err(
                    k("mesh.grading_ratio"),
                    format!("{r}: give a growth factor in [1, 3], e.g. 1.5"),
                ))
            }
            None => def.grading_ratio,
        },
        integration: match m.and_then(|m| m.integration.as_deref()).unwrap_or("full") {
            "full" => Integration::Full,
            "reduced" => Integration::Reduced,
            o => {
                return Err(ctx.err(
                    k("mesh.integration"),
                    format!("\"{o}\": use \"full\" (3x3x3 Gauss) or \"reduced\" (2x2x2)"),
                ))
            }
        },
        point_mapping: match m
            .and_then(|m| m.point_mapping.as_deref())
            .unwrap_or("interpolate")
        {
            "interpolate" => PointMapping::Interpolate,
            "snap" => PointMapping::Snap,
            o => {
                return Err(ctx.err(
                    k("mesh.point_mapping"),
                    format!("\"{o}\": use \"interpolate\" or \"snap\""),
                ))
            }
        },
    };
    let rule = mesh_rule(
        ctx,
        "structure.lap.mesh",
        MeshRuleKeys {
            refine: m.and_then(|m| m.refine),
            tolerance: m.and_then(|m| m.tolerance),
            allowance: m.and_then(|m| m.allowance),
            reference_modulus: m.and_then(|m| m.reference_modulus),
        },
        false,
    )?;
    let spec = LapSpec {
        geometry,
        support,
        adherend,
        adhesive_nu: nu("adhesive.nu", l.adhesive.nu)?,
        adhesive_rho_kg_m3: ctx.positive(&k("adhesive.rho"), l.adhesive.rho, "kg/m^3")?,
        damping,
        mesh,
        points: Vec::new(),
    };
    Ok((spec, rule))
}
