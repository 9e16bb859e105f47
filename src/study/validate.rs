//! Raw study -> validated [`Study`]: every check names the file, the key and the fix.

use super::ctx::Ctx;
use super::raw::*;
use super::*;
use sha2::{Digest, Sha256};

/// Read, parse and validate a study file.
pub fn load(path: &Path) -> Result<Study, StudyError> {
    let bytes = std::fs::read(path).map_err(|e| StudyError {
        file: path.display().to_string(),
        key: "(file)".into(),
        message: format!("cannot read the study file: {e}; check the path"),
    })?;
    let text = String::from_utf8(bytes).map_err(|_| StudyError {
        file: path.display().to_string(),
        key: "(file)".into(),
        message: "the study file is not valid UTF-8 text; save it as UTF-8".into(),
    })?;
    parse_str(&text, path)
}

/// Parse and validate study text; `path` names the file in errors and anchors relative paths.
pub fn parse_str(text: &str, path: &Path) -> Result<Study, StudyError> {
    let raw: RawStudy = toml::from_str(text).map_err(|e| toml_error(path, text, &e))?;
    let ctx = Ctx { file: path };
    let name = raw
        .study
        .name
        .clone()
        .or_else(|| path.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "study".into());
    if name.is_empty() || name.contains(['/', '\\']) {
        return Err(ctx.err(
            "study.name",
            "must be a non-empty name without path separators (it names the results folder)",
        ));
    }
    let structure = structure(&ctx, &raw.structure)?;
    let measurements = match &raw.measurements {
        Some(m) => Some(measurements(&ctx, m, &structure)?),
        None => None,
    };
    let solver = solver(&ctx, raw.solver.as_ref())?;
    let analyses = analyses(&ctx, raw.analyses.as_ref())?;
    let level_names: Vec<String> = measurements
        .as_ref()
        .map(|m| m.levels.iter().map(|l| l.name.clone()).collect())
        .unwrap_or_default();
    let mut models = Vec::new();
    for (i, m) in raw.models.iter().enumerate() {
        models.push(model(&ctx, i, m, &level_names)?);
    }
    let inference = match &raw.inference {
        None => None,
        Some(r) => Some(super::inference::inference(&ctx, r, &models, &level_names)?),
    };
    let point_ids: Vec<u32> = structure.points.iter().map(|p| p.id).collect();
    let declared_effects = super::effects::effects(&ctx, &raw.structure.effects, &point_ids)?;
    let closed_loop = match &raw.closed_loop {
        None => None,
        Some(r) => Some(super::effects::closed_loop(&ctx, r)?),
    };
    let design = match &raw.design {
        None => None,
        Some(r) => {
            let d = super::design::design(&ctx, r, &point_ids)?;
            if let Some(ms) = &d.models {
                if let Some(m) = ms
                    .iter()
                    .find(|m| !models.iter().any(|s| s.name.eq_ignore_ascii_case(m)))
                {
                    return Err(ctx.err(
                        "design.models",
                        format!(
                            "\"{m}\" is not among [[models]] ({}): add it there or remove it here",
                            models
                                .iter()
                                .map(|s| s.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                }
            }
            Some(d)
        }
    };
    let sha256 = {
        let mut h = Sha256::new();
        h.update(text.as_bytes());
        h.finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    };
    let output_dir = match &raw.study.output_dir {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from("results").join(&name),
    };
    Ok(Study {
        file: path.to_path_buf(),
        sha256,
        name,
        description: raw.study.description.clone().unwrap_or_default(),
        seed: raw.study.seed.unwrap_or(0),
        output_dir,
        structure,
        measurements,
        models,
        solver,
        analyses,
        inference,
        declared_effects,
        closed_loop,
        design,
    })
}

/// The key (with its table, `section.key`) and the value written on the line of byte offset
/// `at` of a TOML text, when that line is `key = value`.
fn key_at(text: &str, at: usize) -> Option<(String, String)> {
    let at = at.min(text.len());
    let start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    let end = text[at..].find('\n').map_or(text.len(), |i| at + i);
    let line = &text[start..end];
    let (k, v) = line.split_once('=')?;
    let k = k.trim().trim_matches('"');
    if k.is_empty() || k.starts_with('#') || k.starts_with('[') {
        return None;
    }
    // the value without a trailing comment (a '#' outside quotes)
    let mut quoted = false;
    let mut cut = v.len();
    for (i, c) in v.char_indices() {
        match c {
            '"' | '\'' => quoted = !quoted,
            '#' if !quoted => {
                cut = i;
                break;
            }
            _ => {}
        }
    }
    let value = v[..cut].trim().to_string();
    let table = text[..start]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    let key = match table {
        Some(t) if !t.is_empty() => format!("{t}.{k}"),
        _ => k.to_string(),
    };
    Some((key, value))
}

/// A type name of serde's wording ("f64", "a boolean", "string \"x\"") in plain words.
fn plain_type(t: &str) -> String {
    let t = t.trim();
    let word = t.split_whitespace().next().unwrap_or(t);
    match word {
        "f64" | "f32" | "float" | "floating" => "a number (e.g. 0.3 or 2.1e9)".into(),
        "u8" | "u16" | "u32" | "u64" | "usize" | "i8" | "i16" | "i32" | "i64" | "isize"
        | "integer" => "a whole number (e.g. 4)".into(),
        "bool" | "boolean" => "true or false".into(),
        "string" | "str" | "char" => "a text in quotes (e.g. \"+y\")".into(),
        "sequence" | "array" => "a list in brackets (e.g. [1.0, 500.0])".into(),
        "map" | "table" | "struct" => "a table (a [section] or { key = value })".into(),
        "a" | "an" => plain_type(t.split_once(' ').map_or(t, |x| x.1)),
        _ => t.to_string(),
    }
}

/// Turn a TOML / serde error into a StudyError with the line, the offending key, the value
/// given, what is allowed and the fix, in plain words.
pub(crate) fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> StudyError {
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    let msg = e.message().trim().to_string();
    let at = e.span().and_then(|s| key_at(text, s.start));
    let (key, message) = if let Some(rest) = msg.strip_prefix("unknown field `") {
        let k = rest.split('`').next().unwrap_or("?").to_string();
        let allowed = rest
            .split_once("expected ")
            .map(|x| format!("; the keys allowed here are {}", x.1.replace('`', "")))
            .unwrap_or_default();
        (
            k.clone(),
            format!("{k} is not a key of this section{allowed}: remove or rename it (docs/study-files.md lists every key)"),
        )
    } else if let Some(rest) = msg.strip_prefix("missing field `") {
        let k = rest.split('`').next().unwrap_or("?").to_string();
        (
            k.clone(),
            format!("the key {k} is required in this section: add it (docs/study-files.md gives its meaning and units)"),
        )
    } else if let Some(rest) = msg.strip_prefix("invalid type: ") {
        let (given, expected) = rest.split_once(", expected ").unwrap_or((rest, "?"));
        let (k, v) = at.unwrap_or_else(|| ("(value)".into(), String::new()));
        let given = plain_type(given);
        (
            k.clone(),
            format!(
                "{k} = {v} is {given}, but {k} takes {}: write it as such (e.g. without quotes for a number); docs/study-files.md gives every key's type and units",
                plain_type(expected)
            ),
        )
    } else if let Some(rest) = msg.strip_prefix("invalid value: ") {
        let (given, expected) = rest.split_once(", expected ").unwrap_or((rest, "?"));
        let (k, v) = at.unwrap_or_else(|| ("(value)".into(), String::new()));
        (
            k.clone(),
            format!(
                "{k} = {v} ({given}) is not allowed: {k} takes {}; docs/study-files.md gives every key's range",
                plain_type(expected)
            ),
        )
    } else if let Some(rest) = msg.strip_prefix("unknown variant `") {
        let v = rest.split('`').next().unwrap_or("?");
        let allowed = rest
            .split_once("expected ")
            .map(|x| x.1.replace('`', "\""))
            .unwrap_or_default();
        let (k, _) = at.unwrap_or_else(|| ("(value)".into(), String::new()));
        (
            k.clone(),
            format!("\"{v}\" is not one of the allowed values of {k}: use {allowed}"),
        )
    } else {
        (
            at.map(|(k, _)| k).unwrap_or_else(|| "(TOML syntax)".into()),
            format!("the file is not valid TOML here ({msg}): write `key = value` with text in quotes, numbers without, lists in [ ] and sections as [name]"),
        )
    };
    StudyError {
        file: match line {
            Some(l) => format!("{}:{l}", path.display()),
            None => path.display().to_string(),
        },
        key,
        message,
    }
}

pub(super) fn structure(ctx: &Ctx, s: &RawStructure) -> Result<Structure, StudyError> {
    let source_name = s.source.as_deref().unwrap_or("mesher");
    let source = match source_name {
        "mesher" if s.joint.as_deref() == Some("single_lap") => {
            let l = s.lap.as_ref().ok_or_else(|| {
                ctx.err(
                    "structure.lap",
                    "joint = \"single_lap\" needs [structure.lap] with length, thickness, width, overlap, material and adhesive",
                )
            })?;
            let (spec, rule) = super::lap::lap(ctx, l)?;
            StructureSource::Lap(spec, rule)
        }
        "mesher" => {
            if let Some(j) = s.joint.as_deref().filter(|j| *j != "beam_on_block") {
                return Err(ctx.err(
                    "structure.joint",
                    format!("\"{j}\": use \"beam_on_block\" (default: a beam on an adhesive layer over a rigid base) or \"single_lap\""),
                ));
            }
            let beam = s.beam.as_ref().ok_or_else(|| {
                ctx.err(
                    "structure.beam",
                    "missing: give length, thickness, width (m) and [structure.beam.material]",
                )
            })?;
            let ad = s.adhesive.as_ref().ok_or_else(|| {
                ctx.err(
                    "structure.adhesive",
                    "missing: give length, thickness, x_start (m), nu and rho",
                )
            })?;
            let j = joint(ctx, beam, ad, s.mesh.as_ref())?;
            StructureSource::Mesher(j)
        }
        "matrix_market" | "harwell_boeing" | "abaqus" => {
            use crate::fe::foreign::{ImportFormat, Units};
            let format = match source_name {
                "harwell_boeing" => ImportFormat::HarwellBoeing,
                "abaqus" => ImportFormat::Abaqus,
                _ => ImportFormat::MatrixMarket,
            };
            let im = s.import.as_ref().ok_or_else(|| {
                ctx.err("structure.import", format!("source = \"{source_name}\" needs [structure.import] with mass, stiffness, adhesive_sensitivity and dof_map files"))
            })?;
            let f = |key: &str, p: &str| -> Result<PathBuf, StudyError> {
                let r = resolve(ctx.file, p);
                if r.is_file() {
                    Ok(r)
                } else if r.is_dir() {
                    Err(ctx.err(
                        format!("structure.import.{key}"),
                        format!(
                            "{} is a folder, not a file: give the file inside it (paths are relative to the study file)",
                            r.display()
                        ),
                    ))
                } else {
                    Err(ctx.err(
                        format!("structure.import.{key}"),
                        format!(
                            "file {} not found: check the path (relative to the study file)",
                            r.display()
                        ),
                    ))
                }
            };
            let units = match im.units.as_deref() {
                None => Units::Si,
                Some(u) => Units::parse(u).ok_or_else(|| {
                    ctx.err(
                        "structure.import.units",
                        format!("\"{u}\" is not a unit system: use \"SI\" (m, kg, s; default) or \"mm-t-s\" (mm, tonne, s, N, MPa)"),
                    )
                })?,
            };
            if im.mapping.is_some() && format != ImportFormat::HarwellBoeing {
                return Err(ctx.err(
                    "structure.import.mapping",
                    format!("the ANSYS mapping file goes with source = \"harwell_boeing\"; remove it for \"{source_name}\""),
                ));
            }
            StructureSource::MatrixMarket(Import {
                format,
                mapping: im.mapping.as_deref().map(|p| f("mapping", p)).transpose()?,
                units,
                mass: f("mass", &im.mass)?,
                stiffness: f("stiffness", &im.stiffness)?,
                adhesive_sensitivity: f("adhesive_sensitivity", &im.adhesive_sensitivity)?,
                viscous_damping: im
                    .viscous_damping
                    .as_deref()
                    .map(|p| f("viscous_damping", p))
                    .transpose()?,
                structural_damping: im
                    .structural_damping
                    .as_deref()
                    .map(|p| f("structural_damping", p))
                    .transpose()?,
                dof_map: f("dof_map", &im.dof_map)?,
            })
        }
        other => {
            return Err(ctx.err(
                "structure.source",
                format!(
                    "unknown source \"{other}\": use \"mesher\" (default), \"matrix_market\", \"harwell_boeing\" or \"abaqus\""
                ),
            ))
        }
    };
    let mut points = Vec::new();
    for (i, p) in s.points.iter().enumerate() {
        let key = format!("structure.points[{i}]");
        if p.position.len() != 3 || p.position.iter().any(|v| !v.is_finite()) {
            return Err(ctx.err(
                format!("{key}.position"),
                "must be [x, y, z] in metres (three finite numbers)",
            ));
        }
        let direction = Direction::parse(&p.direction).ok_or_else(|| {
            ctx.err(format!("{key}.direction"), format!("\"{}\" is not a direction: use \"+x\", \"+y\", \"+z\", \"-x\", \"-y\" or \"-z\"", p.direction))
        })?;
        if points.iter().any(|q: &Point| q.id == p.id) {
            return Err(ctx.err(
                format!("{key}.id"),
                format!("point id {} is used twice: ids must be unique", p.id),
            ));
        }
        points.push(Point {
            id: p.id,
            position_m: [p.position[0], p.position[1], p.position[2]],
            direction,
            optional: p.optional.unwrap_or(false),
        });
    }
    if points.is_empty() {
        return Err(ctx.err("structure.points", "no measurement points: add [[structure.points]] entries with id, position (m) and direction"));
    }
    if let StructureSource::Mesher(j) = &source {
        for (i, p) in points.iter().enumerate() {
            check_point_on_beam(ctx, i, p, j)?;
        }
    }
    let excitation = s.excitation.ok_or_else(|| {
        ctx.err(
            "structure.excitation",
            "missing: give the id of the point where the force is applied",
        )
    })?;
    if !points.iter().any(|p| p.id == excitation) {
        return Err(ctx.err(
            "structure.excitation",
            format!("point {excitation} is not among structure.points (ids: {:?}): add it or fix the id", points.iter().map(|p| p.id).collect::<Vec<_>>()),
        ));
    }
    Ok(Structure {
        name: s.name.clone().unwrap_or_else(|| "bonded joint".into()),
        source,
        points,
        excitation,
    })
}

fn check_point_on_beam(ctx: &Ctx, i: usize, p: &Point, j: &Joint) -> Result<(), StudyError> {
    let [x, y, z] = p.position_m;
    let tol = 1e-6;
    let inside = x >= -tol
        && x <= j.beam_length_m + tol
        && y >= -tol
        && y <= j.beam_thickness_m + tol
        && z >= -tol
        && z <= j.beam_width_m + tol;
    let on_face = (x.abs() < tol || (x - j.beam_length_m).abs() < tol)
        || (y.abs() < tol || (y - j.beam_thickness_m).abs() < tol)
        || (z.abs() < tol || (z - j.beam_width_m).abs() < tol);
    if !(inside && on_face) {
        return Err(ctx.err(
            format!("structure.points[{i}].position"),
            format!(
                "point {} at ({x}, {y}, {z}) m is not on the beam surface (beam: x in [0, {}], y in [0, {}], z in [0, {}] m): put it on a face, e.g. the upper face y = {}",
                p.id, j.beam_length_m, j.beam_thickness_m, j.beam_width_m, j.beam_thickness_m
            ),
        ));
    }
    Ok(())
}

/// Elements beyond which a mesh is refused outright, before its divisions are resolved or
/// anything is allocated (10^8 20-node hexahedra need terabytes; the memory check of the
/// model's cost estimate refuses far fewer on a real machine).
const MAX_ELEMENTS: f64 = 1e8;

fn joint(
    ctx: &Ctx,
    b: &RawBeam,
    a: &RawAdhesive,
    mesh: Option<&RawMesh>,
) -> Result<Joint, StudyError> {
    let bl = ctx.positive("structure.beam.length", b.length, "m")?;
    let bt = ctx.positive("structure.beam.thickness", b.thickness, "m")?;
    let bw = ctx.positive("structure.beam.width", b.width, "m")?;
    let be = ctx.positive("structure.beam.material.E", b.material.e, "Pa")?;
    let bnu = ctx.poisson("structure.beam.material.nu", b.material.nu)?;
    let brho = ctx.positive("structure.beam.material.rho", b.material.rho, "kg/m^3")?;
    let d = b.damping.as_ref();
    let damping = Damping {
        rayleigh_alpha_per_s: ctx.non_negative(
            "structure.beam.damping.rayleigh_alpha",
            d.and_then(|d| d.rayleigh_alpha).unwrap_or(0.0),
            "1/s",
        )?,
        rayleigh_beta_s: ctx.non_negative(
            "structure.beam.damping.rayleigh_beta",
            d.and_then(|d| d.rayleigh_beta).unwrap_or(0.0),
            "s",
        )?,
        structural_loss_factor: ctx.non_negative(
            "structure.beam.damping.structural",
            d.and_then(|d| d.structural).unwrap_or(0.0),
            "-",
        )?,
    };
    // The adhesive's fixed lower face is the structure's only support: without adhesive the
    // model is unconstrained (free-free), so say so rather than only "must be positive".
    for (key, v) in [
        ("structure.adhesive.length", a.length),
        ("structure.adhesive.thickness", a.thickness),
    ] {
        if v == 0.0 {
            return Err(ctx.err(
                key,
                "is 0: the model would be unconstrained (the adhesive's fixed lower face is its only support); give the adhesive a positive size in m",
            ));
        }
    }
    let al = ctx.positive("structure.adhesive.length", a.length, "m")?;
    let at = ctx.positive("structure.adhesive.thickness", a.thickness, "m")?;
    let ax = ctx.non_negative("structure.adhesive.x_start", a.x_start.unwrap_or(0.0), "m")?;
    if ax + al > bl * (1.0 + 1e-12) {
        return Err(ctx.err(
            "structure.adhesive.length",
            format!("the adhesive (x from {ax} to {} m) is longer than the beam ({bl} m): shorten it or move structure.adhesive.x_start", ax + al),
        ));
    }
    let anu = ctx.poisson("structure.adhesive.nu", a.nu)?;
    let arho = ctx.positive("structure.adhesive.rho", a.rho, "kg/m^3")?;
    let default_mesh = RawMesh::default();
    let m = mesh.unwrap_or(&default_mesh);
    let size = match (&m.element_size, &m.divisions) {
        (Some(_), Some(_)) => {
            return Err(ctx.err(
                "structure.mesh",
                "give either element_size or divisions, not both",
            ))
        }
        // without a size: the default largest cell, refined to the tolerance
        (None, None) => MeshSize::ElementSize(crate::discretisation::DEFAULT_ELEMENT_SIZE_M),
        (Some(h), None) => {
            let h = ctx.positive("structure.mesh.element_size", *h, "m")?;
            if h > bl.max(bt).max(bw) {
                return Err(ctx.err("structure.mesh.element_size", format!("{h} m is larger than the beam itself: use a size of a few millimetres, e.g. 0.005")));
            }
            let cells = |l: f64| (l / h).ceil();
            let n = cells(bl) * (cells(bt).max(2.0) + cells(at).max(2.0)) * cells(bw);
            if n > MAX_ELEMENTS {
                return Err(ctx.err("structure.mesh.element_size", format!("{h} m makes about {n:.1e} elements, far beyond any computer (the limit is {MAX_ELEMENTS:.0e}; the memory check refuses much less): use a size of a few millimetres, e.g. 0.005")));
            }
            MeshSize::ElementSize(h)
        }
        (None, Some(dv)) => {
            for (k, v) in [
                ("x_adhesive", dv.x_adhesive),
                ("y_beam", dv.y_beam),
                ("y_adhesive", dv.y_adhesive),
                ("z", dv.z),
            ] {
                if v == 0 {
                    return Err(ctx.err(
                        format!("structure.mesh.divisions.{k}"),
                        "must be at least 1",
                    ));
                }
            }
            if dv.x_outside == 0 && al < bl * (1.0 - 1e-12) {
                return Err(ctx.err(
                    "structure.mesh.divisions.x_outside",
                    "must be at least 1: part of the beam lies outside the adhesive",
                ));
            }
            let n = (dv.x_adhesive as f64 + dv.x_outside as f64)
                * (dv.y_beam as f64 + dv.y_adhesive as f64)
                * dv.z as f64;
            if n > MAX_ELEMENTS {
                return Err(ctx.err("structure.mesh.divisions", format!("{n:.1e} elements, far beyond any computer (the limit is {MAX_ELEMENTS:.0e}; the memory check refuses much less): use a few to a few tens of divisions per direction")));
            }
            MeshSize::Divisions {
                x_adhesive: dv.x_adhesive,
                x_outside: dv.x_outside,
                y_beam: dv.y_beam,
                y_adhesive: dv.y_adhesive,
                z: dv.z,
            }
        }
    };
    let mesh_rule = mesh_rule(
        ctx,
        "structure.mesh",
        MeshRuleKeys {
            refine: m.refine,
            tolerance: m.tolerance,
            allowance: m.allowance,
            reference_modulus: m.reference_modulus,
        },
        matches!(size, MeshSize::Divisions { .. }),
    )?;
    let full_integration = match m.integration.as_deref().unwrap_or("full") {
        "full" => true,
        "reduced" => false,
        o => {
            return Err(ctx.err(
                "structure.mesh.integration",
                format!("\"{o}\": use \"full\" (3x3x3 Gauss) or \"reduced\" (2x2x2)"),
            ))
        }
    };
    let snap_points = match m.point_mapping.as_deref().unwrap_or("interpolate") {
        "interpolate" => false,
        "snap" => true,
        o => {
            return Err(ctx.err(
                "structure.mesh.point_mapping",
                format!("\"{o}\": use \"interpolate\" or \"snap\""),
            ))
        }
    };
    Ok(Joint {
        beam_length_m: bl,
        beam_thickness_m: bt,
        beam_width_m: bw,
        beam_e_pa: be,
        beam_nu: bnu,
        beam_rho_kg_m3: brho,
        damping,
        adhesive_length_m: al,
        adhesive_thickness_m: at,
        adhesive_x_start_m: ax,
        adhesive_nu: anu,
        adhesive_rho_kg_m3: arho,
        mesh: size,
        full_integration,
        snap_points,
        mesh_grading: m.grading_ratio,
        mesh_rule,
    })
}

/// The mesh's refine, tolerance, allowance and reference_modulus keys as given.
pub(super) struct MeshRuleKeys {
    pub refine: Option<bool>,
    pub tolerance: Option<f64>,
    pub allowance: Option<bool>,
    pub reference_modulus: Option<f64>,
}

/// A mesh table's (`table`) refine, tolerance and allowance keys: refinement by default with
/// an element size; `divisions` (`fixed`) fix the mesh.
pub(super) fn mesh_rule(
    ctx: &Ctx,
    table: &str,
    m: MeshRuleKeys,
    fixed: bool,
) -> Result<MeshRule, StudyError> {
    let refine = match (m.refine, fixed) {
        (Some(true), true) => {
            return Err(ctx.err(
                format!("{table}.refine"),
                "true, but divisions fix the mesh: give element_size (the largest cell) to let rfmlab refine, or drop refine",
            ))
        }
        (Some(r), _) => r,
        (None, f) => !f,
    };
    let tolerance = match m.tolerance {
        Some(t) if t.is_finite() && t > 0.0 && t < 0.1 => t,
        Some(t) => {
            return Err(ctx.err(
                format!("{table}.tolerance"),
                format!("{t} is not a relative frequency error in (0, 0.1): give e.g. 0.005 (0.5 % of each in-band mode)"),
            ))
        }
        None => MeshRule::DEFAULT_TOLERANCE,
    };
    let reference_modulus_pa = match m.reference_modulus {
        Some(e) => ctx.positive(&format!("{table}.reference_modulus"), e, "Pa")?,
        None => MeshRule::DEFAULT_REFERENCE_MODULUS_PA,
    };
    Ok(MeshRule {
        refine,
        tolerance,
        allowance: m.allowance.unwrap_or(true),
        reference_modulus_pa,
    })
}

fn measurements(ctx: &Ctx, m: &RawMeasurements, s: &Structure) -> Result<Measurements, StudyError> {
    if m.levels.is_empty() {
        return Err(ctx.err(
            "measurements.levels",
            "no levels: add [[measurements.levels]] with name and files",
        ));
    }
    let mut levels: Vec<Level> = Vec::new();
    for (i, l) in m.levels.iter().enumerate() {
        let key = format!("measurements.levels[{i}]");
        if l.name.is_empty() || levels.iter().any(|o| o.name == l.name) {
            return Err(ctx.err(
                format!("{key}.name"),
                format!("level name \"{}\" is empty or used twice", l.name),
            ));
        }
        if l.files.is_empty() {
            return Err(ctx.err(
                format!("{key}.files"),
                "no files: list the UFF58 or CSV files of this level",
            ));
        }
        let mut files = Vec::new();
        for (k, f) in l.files.iter().enumerate() {
            let r = resolve(ctx.file, f);
            if r.is_dir() {
                return Err(ctx.err(
                    format!("{key}.files[{k}]"),
                    format!("{} is a folder, not a data file: give the UFF58 (.uff) or CSV (.csv) file inside it (paths are relative to the study file)", r.display()),
                ));
            }
            if !r.is_file() {
                return Err(ctx.err(
                    format!("{key}.files[{k}]"),
                    format!("data file {} not found: check the path (relative to the study file), or create it with `rfmlab simulate`", r.display()),
                ));
            }
            files.push(r);
        }
        if let Some(fr) = l.force_rms_n {
            ctx.positive(&format!("{key}.force_rms_n"), fr, "N")?;
        }
        levels.push(Level {
            name: l.name.clone(),
            files,
            force_rms_n: l.force_rms_n,
        });
    }
    let band_hz = match &m.band_hz {
        None => None,
        Some(b)
            if b.len() == 2
                && b[0].is_finite()
                && b[1].is_finite()
                && b[0] >= 0.0
                && b[1] > b[0] =>
        {
            Some((b[0], b[1]))
        }
        Some(b) => {
            return Err(ctx.err(
                "measurements.band_hz",
                format!("{b:?} is not a band: give [f_low, f_high] in Hz with 0 <= f_low < f_high"),
            ))
        }
    };
    if let Some(ch) = &m.channels {
        for (k, id) in ch.iter().enumerate() {
            if !s.points.iter().any(|p| p.id == *id) {
                return Err(ctx.err(
                    format!("measurements.channels[{k}]"),
                    format!("point {id} is not among structure.points"),
                ));
            }
        }
    }
    let estimator = match &m.estimator {
        None => None,
        Some(e) => {
            let key = "measurements.estimator";
            let window =
                e.window
                    .parse()
                    .map_err(|e: crate::experiment::spec::UnknownWindow| {
                        ctx.err(format!("{key}.window"), e.to_string())
                    })?;
            let block_s = ctx.positive(&format!("{key}.block_s"), e.block_s, "s")?;
            let fs_hz = match e.fs_hz {
                Some(f) => ctx.positive(&format!("{key}.fs_hz"), f, "Hz")?,
                None => 2048.0,
            };
            let nb = fs_hz * block_s;
            if (nb - nb.round()).abs() > 1e-9 * nb || nb < 4.0 {
                return Err(ctx.err(
                    format!("{key}.fs_hz"),
                    format!("fs_hz * block_s = {nb} must be a whole number of samples (>= 4): give the analyser's sampling rate"),
                ));
            }
            let shaker = match &e.shaker {
                None => None,
                Some(s) => Some(crate::experiment::Shaker {
                    armature_mass_kg: ctx.positive(
                        &format!("{key}.shaker.armature_mass"),
                        s.armature_mass,
                        "kg",
                    )?,
                    stinger_stiffness_n_m: ctx.positive(
                        &format!("{key}.shaker.stinger_stiffness"),
                        s.stinger_stiffness,
                        "N/m",
                    )?,
                }),
            };
            let force_band_hz = match &e.force_band_hz {
                None => None,
                Some(b) => {
                    let k = format!("{key}.force_band_hz");
                    let &[lo, hi] = b.as_slice() else {
                        return Err(ctx.err(k, format!("{b:?} is not a band: give [f_low, f_high] in Hz, e.g. [0.0, 500.0] for a baseband random source")));
                    };
                    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
                        return Err(ctx.err(
                            k,
                            format!("[{lo}, {hi}] is not a band: give 0 <= f_low < f_high in Hz"),
                        ));
                    }
                    if hi >= 0.5 * fs_hz {
                        return Err(ctx.err(
                            k,
                            format!(
                                "f_high = {hi} Hz must be below fs_hz / 2 = {} Hz",
                                0.5 * fs_hz
                            ),
                        ));
                    }
                    let df = 1.0 / block_s;
                    if [lo, hi]
                        .iter()
                        .any(|e| (e / df - (e / df).round()).abs() > 1e-6)
                    {
                        return Err(ctx.err(k, format!("edges [{lo}, {hi}] must be multiples of the line spacing 1 / block_s = {df} Hz")));
                    }
                    Some((lo, hi))
                }
            };
            Some(Estimator {
                window,
                block_s,
                fs_hz,
                shaker,
                force_band_hz,
            })
        }
    };
    let truth = match &m.truth {
        None => None,
        Some(t) => {
            let r = resolve(ctx.file, t);
            if !r.is_file() {
                return Err(ctx.err(
                    "measurements.truth",
                    format!("truth file {} not found: give the .truth.json that `rfmlab simulate` wrote beside the data, or remove the key", r.display()),
                ));
            }
            Some(r)
        }
    };
    Ok(Measurements {
        levels,
        band_hz,
        channels: m.channels.clone(),
        estimator,
        truth,
    })
}

fn solver(ctx: &Ctx, s: Option<&RawSolver>) -> Result<Solver, StudyError> {
    let mut out = Solver::default();
    let Some(s) = s else { return Ok(out) };
    if let Some(e) = &s.engine {
        out.engine = match e.as_str() {
            "rom" => Engine::Rom,
            "full" => Engine::Full,
            o => {
                return Err(ctx.err(
                    "solver.engine",
                    format!("\"{o}\": use \"rom\" (certified reduced model, default) or \"full\""),
                ))
            }
        };
    }
    if let Some(n) = s.max_iterations {
        if n == 0 {
            return Err(ctx.err("solver.max_iterations", "must be at least 1"));
        }
        out.max_iterations = n;
    }
    if let Some(t) = s.tolerance {
        out.tolerance = ctx.positive("solver.tolerance", t, "-")?;
    }
    if let Some(t) = s.svd_rtol {
        out.svd_rtol = ctx.positive("solver.svd_rtol", t, "-")?;
    }
    if let Some(t) = s.rom_tolerance {
        out.rom_tolerance = ctx.positive("solver.rom_tolerance", t, "-")?;
    }
    if let Some(t) = s.threads {
        if t == 0 {
            return Err(ctx.err(
                "solver.threads",
                "must be at least 1 (or leave it out to use all cores)",
            ));
        }
        out.threads = Some(t);
    }
    Ok(out)
}

fn analyses(ctx: &Ctx, a: Option<&RawAnalyses>) -> Result<Analyses, StudyError> {
    let mut out = Analyses::default();
    let Some(a) = a else { return Ok(out) };
    let band = |key: String, b: &RawBand| -> Result<Band, StudyError> {
        let c = ctx.positive(&format!("{key}.center_hz"), b.center_hz, "Hz")?;
        let w = ctx.positive(&format!("{key}.width_hz"), b.width_hz.unwrap_or(10.0), "Hz")?;
        Ok(Band {
            center_hz: c,
            width_hz: w,
        })
    };
    for (i, b) in a.band_constant.iter().enumerate() {
        out.band_constant
            .push(band(format!("analyses.band_constant[{i}]"), b)?);
    }
    for (i, b) in a.iem.iter().enumerate() {
        out.iem.push(band(format!("analyses.iem[{i}]"), b)?);
    }
    if let Some(v) = a.per_line {
        out.per_line = v;
    }
    if let Some(v) = a.correlation {
        out.correlation = v;
    }
    if let Some(v) = a.sensitivity {
        out.sensitivity = v;
    }
    if let Some(v) = a.figures {
        out.figures = v;
    }
    if let Some(v) = a.mesh_error {
        out.mesh_error = v;
    }
    Ok(out)
}

fn model(ctx: &Ctx, i: usize, m: &RawModel, levels: &[String]) -> Result<ModelSpec, StudyError> {
    let key = format!("models[{i}]");
    let law = crate::material::model_from_name(&m.name, m.branches)
        .map_err(|e| ctx.err(format!("{key}.name"), e.to_string()))?;
    let names = law.param_names();
    let bounds = law.bounds();
    let mut initial = Vec::with_capacity(names.len());
    for (k, n) in names.iter().enumerate() {
        let v = *m.initial.get(n).ok_or_else(|| {
            ctx.err(
                format!("{key}.initial.{n}"),
                format!(
                    "missing initial value of {n} ({}) for {}: add `{n} = <value>` to initial",
                    law.param_units()[k],
                    m.name
                ),
            )
        })?;
        let (lo, hi) = bounds[k];
        if !(v.is_finite() && v > lo && v < hi) {
            return Err(ctx.err(
                format!("{key}.initial.{n}"),
                format!("{v} is outside the admissible range ({lo}, {hi}) {}: give a value inside it (SI units)", law.param_units()[k]),
            ));
        }
        initial.push(v);
    }
    for k in m.initial.keys() {
        if !names.contains(k) {
            return Err(ctx.err(
                format!("{key}.initial.{k}"),
                format!(
                    "{} has no parameter {k}; its parameters are {names:?}",
                    m.name
                ),
            ));
        }
    }
    let lv = match &m.levels {
        None => levels.to_vec(),
        Some(l) => {
            for (k, n) in l.iter().enumerate() {
                if !levels.contains(n) {
                    return Err(ctx.err(
                        format!("{key}.levels[{k}]"),
                        format!("level \"{n}\" is not among measurements.levels {levels:?}"),
                    ));
                }
            }
            l.clone()
        }
    };
    Ok(ModelSpec {
        name: m.name.clone(),
        branches: m.branches,
        initial,
        param_names: names,
        levels: lv,
    })
}
