//! Candidate sensor places: a grid on the structure's free faces (the mesher's joint or lap
//! joint), or the study's own points (an imported model's DOF-map rows). Every place carries
//! its x, y and z directions in the model (a sensor's mass acts in all three); the directions
//! a design may measure are the study's `design.directions`.

use crate::common::Axis;
use crate::study::design::CandidatePlaces;
use crate::study::{Point, Structure, StructureSource};

/// One place a sensor may go.
#[derive(Clone, Debug, PartialEq)]
pub struct Place {
    /// Point id in the design's model (the study's id for its own points).
    pub id: u32,
    pub position_m: [f64; 3],
    /// Which face: "top", "side", "end", "upper strip top", the study's "point", ...
    pub face: String,
    /// The study's point with this id is measured today (the current design).
    pub current: bool,
}

/// First id of generated places (the study's ids stay below it).
pub const FIRST_GENERATED_ID: u32 = 100_000;

/// Places of `structure` for the candidate rule `rule`: the study's points first (in their
/// order, one place per id), then the grid's places not closer than a tenth of the pitch to one
/// of them. Errors name what cannot be gridded.
pub fn places(structure: &Structure, rule: &CandidatePlaces) -> Result<Vec<Place>, String> {
    let mut out: Vec<Place> = Vec::new();
    for p in &structure.points {
        if !out.iter().any(|q| q.id == p.id) {
            out.push(Place {
                id: p.id,
                position_m: p.position_m,
                face: "point".into(),
                current: true,
            });
        }
    }
    let spacing = match rule {
        CandidatePlaces::Points => return Ok(out),
        CandidatePlaces::Surface { spacing_m } => *spacing_m,
    };
    let grid = match &structure.source {
        StructureSource::Mesher(j) => {
            let (l, t, w) = (j.beam_length_m, j.beam_thickness_m, j.beam_width_m);
            let s = if spacing > 0.0 { spacing } else { l / 32.0 };
            let mut g = Vec::new();
            for x in along(0.0, l, s) {
                g.push(([x, t, w / 2.0], "top"));
                g.push(([x, t, 0.0], "top edge"));
                g.push(([x, t / 2.0, w], "side"));
            }
            g
        }
        StructureSource::Lap(spec, _) => {
            let geo = &spec.geometry;
            let (l, o, w) = (geo.strip_length_m, geo.overlap_m, geo.width_m);
            let (t1, ta, t2) = (
                geo.lower_thickness_m,
                geo.adhesive_thickness_m,
                geo.upper_thickness_m,
            );
            let top2 = t1 + ta + t2;
            let s = if spacing > 0.0 { spacing } else { (2.0 * l - o) / 24.0 };
            let mut g = Vec::new();
            for x in along(0.0, 2.0 * l - o, s) {
                if x < l - o {
                    g.push(([x, t1, w / 2.0], "lower strip top"));
                    g.push(([x, t1, 0.0], "lower strip top edge"));
                }
                if x < l {
                    g.push(([x, t1 / 2.0, w], "lower strip side"));
                }
                if x > l - o {
                    g.push(([x, top2, w / 2.0], "upper strip top"));
                    g.push(([x, top2, 0.0], "upper strip top edge"));
                    g.push(([x, t1 + ta + t2 / 2.0, w], "upper strip side"));
                }
            }
            g
        }
        StructureSource::MatrixMarket(_) => {
            return Err("candidates = \"surface\" needs the mesher's geometry; for an imported model use candidates = \"points\" with every candidate row in the DOF map".into())
        }
    };
    let min_gap = 0.1 * spacing.max(1e-6);
    let mut id = FIRST_GENERATED_ID;
    for (pos, face) in grid {
        let near = out.iter().any(|p| {
            p.position_m
                .iter()
                .zip(&pos)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
                < min_gap
        });
        if near {
            continue;
        }
        out.push(Place {
            id,
            position_m: pos,
            face: face.into(),
            current: false,
        });
        id += 1;
    }
    Ok(out)
}

/// Points `s/2, 3s/2, ...` inside `(a, b)`, centred so that the ends get equal margins.
fn along(a: f64, b: f64, s: f64) -> Vec<f64> {
    let n = ((b - a) / s).floor().max(1.0) as usize;
    let margin = (b - a - (n as f64 - 1.0) * s) / 2.0;
    (0..n).map(|k| a + margin + k as f64 * s).collect()
}

/// The study's points plus every place in the directions `axes` (the study's points keep
/// their own direction first; other directions are model-only points).
pub fn design_points(structure: &Structure, places: &[Place], axes: &[Axis]) -> Vec<Point> {
    use crate::common::Direction;
    let mut out = structure.points.clone();
    for pl in places {
        for &axis in axes {
            if !out
                .iter()
                .any(|q| q.id == pl.id && q.direction.axis == axis)
            {
                out.push(Point {
                    id: pl.id,
                    position_m: pl.position_m,
                    direction: Direction::new(axis, 1),
                    optional: true,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn along_is_centred_and_inside() {
        let v = along(0.0, 0.3, 0.01);
        assert_eq!(v.len(), 30);
        assert!((v[0] - 0.005).abs() < 1e-12 && (0.3 - v[29] - 0.005).abs() < 1e-12);
    }
}
