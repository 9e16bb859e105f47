//! Joint model: mesh counts, total mass, S exactly linear in E, K_b + E S positive definite,
//! point mapping, and one bad spec per FeError variant.

use crate::numerics::spmv;
use faer::Side;
use rfmlab::common::{Axis, Direction};
use rfmlab::fe::assembly::{Assembler, DofMap};
use rfmlab::fe::geometry::Elasticity;
use rfmlab::fe::joint::{
    build_joint_model, joint_mesh_from_spec, layer_divisions, Divisions, JointSpec, MeshSize,
    PointSpec,
};
use rfmlab::fe::mesh::Region;
use rfmlab::fe::points::PointMapping;
use rfmlab::fe::FeError;

fn spec(h: f64) -> JointSpec {
    let mut s = JointSpec::paper();
    s.mesh.size = MeshSize::ElementSize(h);
    s
}

#[test]
fn counts_for_10_and_5_mm() {
    // hand counts of the 20-node lattice (see method.md: ~1.9k and ~10.7k DOFs incl. fixed)
    let (_, i10) = build_joint_model(&spec(0.01)).unwrap();
    assert_eq!((i10.n_elements, i10.n_adhesive_elements), (70, 10));
    assert_eq!(i10.n_nodes, 646);
    assert_eq!(i10.n_dof, 3 * (646 - 45));
    let (m5, i5) = build_joint_model(&spec(0.005)).unwrap();
    assert_eq!((i5.n_elements, i5.n_adhesive_elements), (560, 80));
    assert_eq!(i5.n_nodes, 3565);
    assert_eq!(i5.n_dof, 3 * (3565 - 149));
    assert_eq!(m5.n_dof(), i5.n_dof);
    for d in 0..3 {
        assert!((i5.element_size_m[d] - 0.005).abs() < 1e-15);
    }
    println!("10 mm: {i10:?}\n5 mm: {i5:?}");
    // divisions give the same mesh as the element size
    let mut s = spec(0.005);
    s.mesh.size = MeshSize::Divisions(Divisions {
        x_adhesive: 10,
        x_outside: 50,
        y_beam: 2,
        y_adhesive: 2,
        z: 4,
    });
    let (_, id) = build_joint_model(&s).unwrap();
    assert_eq!((id.n_elements, id.n_nodes, id.n_dof), (560, 3565, i5.n_dof));
}

#[test]
fn thin_layers_get_two_elements_through_their_thickness() {
    // ceil(t / h) through a layer at least one element thick (the paper's meshes above), 2
    // through a layer thinner than the element size
    for (t, h, n) in [
        (0.010, 0.010, 1),
        (0.010, 0.005, 2),
        (0.012, 0.005, 3),
        (0.003, 0.005, 2),
        (0.001, 0.005, 2),
        (0.0005, 0.010, 2),
    ] {
        assert_eq!(layer_divisions(t, h), n, "t {t} m, h {h} m");
    }
    // a 3 mm bond line under 5 mm elements: 2 through it; along x its 50 mm at most 10
    // times its 1.5 mm element thickness, so 10 elements; 4 across the 20 mm width
    let mut s = spec(0.005);
    s.geometry.adhesive_thickness_m = 0.003;
    let (_, info) = build_joint_model(&s).unwrap();
    assert_eq!(info.n_adhesive_elements, 10 * 2 * 4);
    // a 1 mm bond line: 0.5 mm thick elements at most 5 mm long, still 10 along x
    s.geometry.adhesive_thickness_m = 0.001;
    let (_, info) = build_joint_model(&s).unwrap();
    assert_eq!(info.n_adhesive_elements, 10 * 2 * 4);
    // 0.5 mm: 0.25 mm thick elements at most 2.5 mm long, 20 along x
    s.geometry.adhesive_thickness_m = 0.0005;
    let (_, info) = build_joint_model(&s).unwrap();
    assert_eq!(info.n_adhesive_elements, 20 * 2 * 4);
}

#[test]
fn total_mass_is_rho_v_per_direction() {
    let s = spec(0.005);
    let (mesh, _) = joint_mesh_from_spec(&s).unwrap();
    let dofs = DofMap::unconstrained(mesh.n_nodes());
    let asm = Assembler::new(&mesh, &dofs);
    let all: Vec<usize> = (0..mesh.n_elements()).collect();
    let m = asm
        .mass(&asm.pattern(&all), |e| {
            if mesh.regions[e] == Region::Beam {
                7800.0
            } else {
                1160.0
            }
        })
        .unwrap();
    let want = 7800.0 * 0.3 * 0.01 * 0.02 + 1160.0 * 0.05 * 0.01 * 0.02;
    for c in 0..3 {
        let u: Vec<f64> = (0..dofs.n_free)
            .map(|d| if d % 3 == c { 1.0 } else { 0.0 })
            .collect();
        let mu = spmv(&m, &u);
        let total: f64 = u.iter().zip(&mu).map(|(a, b)| a * b).sum();
        assert!(
            (total - want).abs() < 1e-12 * want,
            "direction {c}: {total} vs {want}"
        );
    }
    // the constrained model's beam part: translation of beam-only DOFs is a lower bound check
    let (model, _) = build_joint_model(&s).unwrap();
    let u: Vec<f64> = (0..model.n_dof())
        .map(|d| if d % 3 == 1 { 1.0 } else { 0.0 })
        .collect();
    let total: f64 = u.iter().zip(spmv(&model.m, &u)).map(|(a, b)| a * b).sum();
    assert!(
        total < want && total > 0.468,
        "free-DOF mass {total} between beam mass and total"
    );
}

#[test]
fn s_is_exactly_linear_in_e() {
    let s = spec(0.005);
    let (model, _) = build_joint_model(&s).unwrap();
    let (mesh, _) = joint_mesh_from_spec(&s).unwrap();
    let dofs = DofMap::new(&mesh);
    let asm = Assembler::new(&mesh, &dofs);
    let pat = asm.pattern(&mesh.elements_in(Region::Adhesive));
    for e in [6.974e6, 1.0e9, 3.3] {
        let k = asm
            .stiffness(
                &pat,
                |_| Elasticity { e_pa: e, nu: 0.44 },
                s.mesh.integration,
            )
            .unwrap();
        let (ks, kv) = k.parts();
        let (ss, sv) = model.s.parts();
        assert_eq!(ks.col_ptr(), ss.col_ptr());
        assert_eq!(ks.row_idx(), ss.row_idx());
        let max = kv.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = kv
            .iter()
            .zip(sv)
            .fold(0.0f64, |m, (a, b)| m.max((a - e * b).abs()));
        assert!(
            worst <= 1e-14 * max,
            "E = {e}: |K(E) - E S| = {worst:e}, max {max:e}"
        );
    }
}

#[test]
fn k_b_plus_e_s_is_positive_definite_and_symmetric() {
    let (model, _) = build_joint_model(&spec(0.005)).unwrap();
    let e = 6.974e6;
    let k = faer::sparse::ops::binary_op(
        model.k_b.as_ref(),
        model.s.as_ref(),
        |a: Option<&f64>, b: Option<&f64>| {
            a.copied().unwrap_or(0.0) + e * b.copied().unwrap_or(0.0)
        },
    )
    .unwrap();
    assert!(k.sp_cholesky(Side::Lower).is_ok(), "K_b + E S is SPD");
    assert!(model.m.sp_cholesky(Side::Lower).is_ok(), "M is SPD");
    // K_b alone is singular? No: beam nodes on the bond face are free and the adhesive-only
    // nodes have empty rows, so K_b alone must fail Cholesky
    assert!(model.k_b.nrows() == model.n_dof());
    // symmetry of the assembled matrices
    for a in [&model.m, &model.k_b, &model.s] {
        let n = a.nrows();
        let mut rng = 0x9E37_79B9_7F4A_7C15u64;
        let mut x = vec![0.0; n];
        let mut y = vec![0.0; n];
        for v in x.iter_mut().chain(y.iter_mut()) {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        }
        let yax: f64 = y.iter().zip(spmv(a, &x)).map(|(p, q)| p * q).sum();
        let xay: f64 = x.iter().zip(spmv(a, &y)).map(|(p, q)| p * q).sum();
        assert!((yax - xay).abs() <= 1e-12 * yax.abs().max(xay.abs()));
    }
}

#[test]
fn damping_matrices_only_when_non_zero() {
    let mut s = spec(0.01);
    let (m0, _) = build_joint_model(&s).unwrap();
    assert!(m0.c_b.is_none() && m0.d_b.is_none());
    s.damping.rayleigh_alpha_per_s = 2.0;
    s.damping.rayleigh_beta_s = 1e-6;
    s.damping.structural_loss_factor = 0.01;
    let (m1, _) = build_joint_model(&s).unwrap();
    let c = m1.c_b.as_ref().unwrap();
    let d = m1.d_b.as_ref().unwrap();
    let x: Vec<f64> = (0..m1.n_dof())
        .map(|i| ((i * 7919) % 13) as f64 - 6.0)
        .collect();
    let (cx, mx, kx, dx) = (spmv(c, &x), spmv(&m1.m, &x), spmv(&m1.k_b, &x), spmv(d, &x));
    for i in 0..x.len() {
        let want = 2.0 * mx[i] + 1e-6 * kx[i];
        assert!((cx[i] - want).abs() <= 1e-12 * (2.0 * mx[i].abs() + 1e-6 * kx[i].abs()) + 1e-300);
        assert!((dx[i] - 0.01 * kx[i]).abs() <= 1e-14 * kx[i].abs());
    }
}

#[test]
fn points_on_nodes_between_nodes_and_snapped() {
    let mut s = spec(0.01);
    s.points = vec![
        PointSpec {
            id: 1,
            position_m: [0.10, 0.01, 0.01],
            direction: Direction::PY,
        },
        PointSpec {
            id: 2,
            position_m: [0.123, 0.01, 0.0137],
            direction: Direction::new(Axis::Y, -1),
        },
        PointSpec {
            id: 2,
            position_m: [0.123, 0.01, 0.0137],
            direction: Direction::PZ,
        },
    ];
    let (model, _) = build_joint_model(&s).unwrap();
    let (mesh, _) = joint_mesh_from_spec(&s).unwrap();
    let dofs = DofMap::new(&mesh);
    assert_eq!(model.points[0].dofs.len(), 1);
    assert_eq!(model.points[0].dofs[0].1, 1.0);
    // interpolated: weights sum to the sign, reproduce a quadratic field exactly on the face
    for p in &model.points[1..] {
        let sign = p.direction.sign as f64;
        let sum: f64 = p.dofs.iter().map(|d| d.1).sum();
        assert!((sum - sign).abs() < 1e-14, "weights sum {sum}");
        assert!(p.dofs.len() <= 8, "only the face's 8 nodes");
        // u_c(x) = 1 + 2x + 3z + x z + x^2 on nodes; the 20-node face interpolates it exactly
        let f =
            |x: &[f64; 3]| 1.0 + 2.0 * x[0] + 3.0 * x[2] + 40.0 * x[0] * x[2] + 10.0 * x[0] * x[0];
        let mut u = vec![0.0; model.n_dof()];
        let c = p.direction.axis.index();
        for (n, x) in mesh.nodes.iter().enumerate() {
            if let Some(d) = dofs.dof(n, c) {
                u[d] = f(x);
            }
        }
        let got: f64 = p.dofs.iter().map(|&(d, w)| w * u[d]).sum();
        let want = sign * f(&[0.123, 0.01, 0.0137]);
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }
    s.mesh.point_mapping = PointMapping::Snap;
    let (snap, _) = build_joint_model(&s).unwrap();
    assert_eq!(snap.points[1].dofs.len(), 1);
    assert!(
        snap.points[1].note.contains("snapped to node"),
        "{}",
        snap.points[1].note
    );
    assert_eq!(snap.points[1].dofs[0].1, -1.0);
}

#[test]
fn graded_mesh_refines_the_bond_line_edges_and_refuses_bad_input() {
    // the paper's joint with a 3 mm bond line, graded at 1.5 from 3 / 8 mm cells
    let mut s = spec(0.005);
    s.geometry.adhesive_thickness_m = 0.003;
    s.mesh.grading = Some(1.5);
    let (mesh, _) = joint_mesh_from_spec(&s).unwrap();
    let (xs, ys, zs) = (&mesh.grid.xs, &mesh.grid.ys, &mesh.grid.zs);
    let edge = 0.003 / 8.0;
    let sizes = |v: &[f64]| v.windows(2).map(|w| w[1] - w[0]).collect::<Vec<f64>>();
    // x: the adhesive's ends (0 and 50 mm) are nodes, with edge-sized cells at 0 and on both
    // sides of 50 mm; z: both sides; y: both faces of the bond line (y = -3 mm and 0)
    let j = xs
        .iter()
        .position(|&x| (x - 0.05).abs() < 1e-12)
        .expect("x = 50 mm is a node");
    let near = |v: f64| (v - edge).abs() < 0.15 * edge;
    let (dx, dy, dz) = (sizes(xs), sizes(ys), sizes(zs));
    assert!(
        near(dx[0]) && near(dx[j - 1]) && near(dx[j]),
        "x cells {dx:?}"
    );
    assert!(near(dz[0]) && near(dz[dz.len() - 1]), "z cells {dz:?}");
    let k = ys
        .iter()
        .position(|&y| y.abs() < 1e-15)
        .expect("y = 0 is a node");
    assert!(k >= 4, "{k} cells through the bond line");
    assert!(near(dy[0]) && near(dy[k - 1]), "y cells {dy:?}");
    // sizes never grow faster than the ratio (within the partition's rescaling) nor beyond 5 mm
    // (through the thickness within the bond line: the beam above keeps its equal cells)
    for d in [&dx[..], &dy[..k], &dz[..]] {
        assert!(d.iter().all(|&v| v <= 0.005 * (1.0 + 1e-9)));
        assert!(d
            .windows(2)
            .all(|w| w[1] / w[0] <= 1.5 * 1.1 && w[0] / w[1] <= 1.5 * 1.1));
    }
    // the model builds, with more DOFs than the uniform mesh
    let (_, graded) = build_joint_model(&s).unwrap();
    s.mesh.grading = None;
    let (_, uniform) = build_joint_model(&s).unwrap();
    assert!(graded.n_dof > uniform.n_dof);
    // a ratio out of (1, 3], or grading with divisions, names the key
    let divisions = MeshSize::Divisions(Divisions {
        x_adhesive: 10,
        x_outside: 50,
        y_beam: 2,
        y_adhesive: 2,
        z: 4,
    });
    for (r, size) in [
        (1.0, MeshSize::ElementSize(0.005)),
        (f64::NAN, MeshSize::ElementSize(0.005)),
        (1.5, divisions),
    ] {
        s.mesh.grading = Some(r);
        s.mesh.size = size;
        let (key, msg) = err_key(&s);
        assert_eq!(key, "structure.mesh.grading_ratio", "{msg}");
    }
}

fn err_key(s: &JointSpec) -> (String, String) {
    match build_joint_model(s) {
        Ok(_) => panic!("expected an error"),
        Err(e) => (e.key().to_string(), e.to_string()),
    }
}

#[test]
fn bad_input_gives_keyed_errors() {
    type Edit = fn(&mut JointSpec);
    let cases: Vec<(Edit, &str)> = vec![
        (|s| s.geometry.beam_length_m = 0.0, "structure.beam.length"),
        (
            |s| s.geometry.beam_thickness_m = -0.01,
            "structure.beam.thickness",
        ),
        (
            |s| s.geometry.beam_width_m = f64::NAN,
            "structure.beam.width",
        ),
        (
            |s| s.geometry.adhesive_length_m = 0.35,
            "structure.adhesive.length",
        ),
        (
            |s| s.geometry.adhesive_length_m = -1.0,
            "structure.adhesive.length",
        ),
        (
            |s| s.geometry.adhesive_length_m = 0.0,
            "structure.adhesive.length",
        ),
        (
            |s| s.geometry.adhesive_thickness_m = 0.0,
            "structure.adhesive.thickness",
        ),
        (
            |s| s.geometry.adhesive_x_start_m = -0.01,
            "structure.adhesive.x_start",
        ),
        (
            |s| s.geometry.adhesive_x_start_m = 0.28,
            "structure.adhesive.x_start",
        ),
        (|s| s.beam.e_pa = 0.0, "structure.beam.material.E"),
        (|s| s.beam.nu = 0.5, "structure.beam.material.nu"),
        (|s| s.beam.rho_kg_m3 = -1.0, "structure.beam.material.rho"),
        (|s| s.adhesive_nu = -1.0, "structure.adhesive.nu"),
        (|s| s.adhesive_rho_kg_m3 = 0.0, "structure.adhesive.rho"),
        (
            |s| s.mesh.size = MeshSize::ElementSize(0.0),
            "structure.mesh.element_size",
        ),
        (
            |s| s.mesh.size = MeshSize::ElementSize(1e-6),
            "structure.mesh.element_size",
        ),
        (
            |s| {
                s.mesh.size = MeshSize::Divisions(Divisions {
                    x_adhesive: 2,
                    x_outside: 4,
                    y_beam: 0,
                    y_adhesive: 1,
                    z: 1,
                })
            },
            "structure.mesh.divisions",
        ),
        (
            |s| {
                s.geometry.adhesive_x_start_m = 0.1;
                s.mesh.size = MeshSize::Divisions(Divisions {
                    x_adhesive: 2,
                    x_outside: 1,
                    y_beam: 1,
                    y_adhesive: 1,
                    z: 1,
                })
            },
            "structure.mesh.divisions",
        ),
        (
            |s| s.points[2].position_m = [0.2, 0.02, 0.01],
            "structure.points[2].position",
        ),
        (
            |s| s.points[1].position_m = [0.15, 0.005, 0.01],
            "structure.points[1].position",
        ),
        (
            |s| s.points[0].position_m = [0.31, 0.01, 0.01],
            "structure.points[0].position",
        ),
        (
            |s| s.points[3].direction = Direction::new(Axis::Y, 0),
            "structure.points[3].direction",
        ),
        (
            |s| s.points[3] = s.points[0],
            "structure.points[3].direction",
        ),
    ];
    for (i, (edit, key)) in cases.iter().enumerate() {
        let mut s = spec(0.01);
        edit(&mut s);
        let (k, msg) = err_key(&s);
        assert_eq!(k, *key, "case {i}: {msg}");
        assert!(
            msg.starts_with(key),
            "case {i}: message names the key: {msg}"
        );
        println!("{msg}");
    }
    // the brief's example message
    let mut s = spec(0.01);
    s.geometry.adhesive_length_m = 0.35;
    let (_, msg) = err_key(&s);
    assert!(msg.contains("longer than the beam") && msg.contains("shorten it or move x_start"));
    let mut s = spec(0.01);
    s.geometry.adhesive_length_m = 0.0;
    assert!(matches!(
        build_joint_model(&s),
        Err(FeError::Unconstrained { .. })
    ));
}

/// Size, assembly time and peak memory of the 2.5 mm model (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn assembly_2_5_mm_time_and_memory() {
    let t0 = std::time::Instant::now();
    let (model, info) = build_joint_model(&spec(0.0025)).unwrap();
    let wall = t0.elapsed().as_secs_f64();
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let hwm = status
        .lines()
        .find(|l| l.starts_with("VmHWM"))
        .unwrap_or("VmHWM: ?");
    let nnz = model.m.val().len() + model.k_b.val().len() + model.s.val().len();
    println!("2.5 mm: {info:?}, nnz(M+K_b+S) = {nnz}, build {wall:.3} s, {hwm}");
    assert_eq!(info.n_elements, 4480);
}

#[test]
fn assembly_is_bit_identical_with_1_and_2_threads() {
    let build = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| build_joint_model(&spec(0.005)).unwrap().0)
    };
    let (a, b) = (build(1), build(2));
    for (x, y) in [(&a.m, &b.m), (&a.k_b, &b.k_b), (&a.s, &b.s)] {
        assert!(x
            .val()
            .iter()
            .zip(y.val())
            .all(|(p, q)| p.to_bits() == q.to_bits()));
    }
}
