//! Tests of the built-in models (`sodyn::model::builtin`).

use nalgebra::{DMatrix, Vector3};
use sodyn::model::builtin::{
    MAX_NAMED_JOINTS, by_name, humanoid, names, pendulum, quadruped, random_tree, serial_chain,
};
use sodyn::model::{JointType, Model};
use sodyn::rng::Rng;
use sodyn::spatial::Transform;

/// World poses of every joint's child frame at configuration `q`.
fn poses(m: &Model, q: &[f64]) -> Vec<Transform> {
    let mut o = vec![Transform::identity(); m.njoints()];
    for i in 1..m.njoints() {
        let (a, n) = (m.idx_q()[i], m.nqs()[i]);
        let xj = m.joints()[i].transform(&q[a..a + n]);
        o[i] = o[m.parents()[i]].compose(&m.placements()[i]).compose(&xj);
    }
    o
}

/// World pose of frame `name` at configuration `q`.
fn frame_pose(m: &Model, q: &[f64], name: &str) -> Transform {
    let f = &m.frames()[m.frame_id(name).unwrap()];
    poses(m, q)[f.joint].compose(&f.placement)
}

/// Joint-space mass matrix by summing `Jᵢᵀ Iᵢ Jᵢ` over bodies (world-frame Jacobians): an
/// independent, slow oracle that only uses the model description.
fn mass_matrix(m: &Model, q: &[f64]) -> DMatrix<f64> {
    let o = poses(m, q);
    let cols: Vec<_> =
        (0..m.nv()).map(|k| o[m.dof_joint()[k]].act_motion(&m.subspace()[k])).collect();
    let mut mm = DMatrix::zeros(m.nv(), m.nv());
    for (i, (oi, inertia)) in o.iter().zip(m.inertias()).enumerate().skip(1) {
        let iw = oi.act_inertia(inertia);
        let dofs: Vec<usize> =
            (0..m.nv()).filter(|&k| m.is_ancestor(m.dof_joint()[k], i)).collect();
        for &a in &dofs {
            let f = iw.mul_motion(&cols[a]);
            for &b in &dofs {
                mm[(b, a)] += cols[b].dot(&f);
            }
        }
    }
    mm
}

fn total_mass(m: &Model) -> f64 {
    m.inertias().iter().skip(1).map(|i| i.mass).sum()
}

/// Every body inertia physical and massive; limits consistent; frames point to real joints.
fn check_model(m: &Model) {
    assert_eq!(m.njoints(), m.names().len());
    assert_eq!(m.nq(), m.nqs().iter().sum::<usize>());
    assert_eq!(m.nv(), m.nvs().iter().sum::<usize>());
    for i in 1..m.njoints() {
        assert!(m.parents()[i] < i, "{}: parent of joint {i}", m.name());
        let inertia = &m.inertias()[i];
        inertia
            .check_physical()
            .unwrap_or_else(|e| panic!("{}: body {} ({}): {e}", m.name(), i, m.names()[i]));
        assert!(inertia.mass > 0.0, "{}: body {} is massless", m.name(), m.names()[i]);
        assert_eq!(m.nqs()[i], m.joints()[i].nq());
        assert_eq!(m.nvs()[i], m.joints()[i].nv());
    }
    for k in 0..m.nq() {
        assert!(
            m.lower()[k] <= m.upper()[k]
                || (m.lower()[k].is_infinite() && m.upper()[k].is_infinite())
        );
        if m.lower()[k].is_finite() {
            assert!(m.lower()[k] < m.upper()[k], "{}: empty limit range at q[{k}]", m.name());
        }
    }
    for f in m.frames() {
        assert!(f.joint < m.njoints(), "{}: frame {} on joint {}", m.name(), f.name, f.joint);
    }
    let mut names: Vec<&str> = m.frames().iter().map(|f| f.name.as_str()).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), m.frames().len(), "{}: duplicate frame names", m.name());
}

/// The mass matrix is symmetric positive definite at a few random configurations.
fn check_mass_matrix_pd(m: &Model, seed: u64) {
    let mut rng = Rng::new(seed);
    for _ in 0..3 {
        let q = m.random_configuration(&mut rng);
        let mm = mass_matrix(m, q.as_slice());
        let asym = (&mm - mm.transpose()).amax();
        assert!(asym <= 1e-9 * mm.amax().max(1.0), "{}: M not symmetric", m.name());
        let ev = mm.symmetric_eigen().eigenvalues;
        assert!(
            ev.min() > 1e-9,
            "{}: M not positive definite (min eigenvalue {})",
            m.name(),
            ev.min()
        );
    }
}

fn count_kind(m: &Model, name: &str) -> usize {
    m.joints().iter().skip(1).filter(|j| j.name() == name).count()
}

fn assert_same(a: &Model, b: &Model) {
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
}

#[test]
fn serial_chain_dimensions_and_axes() {
    for n in [1, 2, 3, 6, 7, 12, 30] {
        let m = serial_chain(n);
        check_model(&m);
        assert_eq!((m.nq(), m.nv(), m.njoints()), (n, n, n + 1));
        assert!(m.joints().iter().skip(1).all(|j| matches!(j, JointType::Revolute { .. })));
        for i in 1..=n {
            assert_eq!(m.parents()[i], i - 1);
            assert!(m.frame_id(&format!("link_{i}")).is_ok());
            assert_eq!(m.joint_id(&format!("joint_{i}")).unwrap(), i);
        }
        assert!(m.frame_id("ee").is_ok());
        check_mass_matrix_pd(&m, n as u64);
    }
    // Consecutive axes (in their own frames) are not parallel, and inertias are non-diagonal.
    let m = serial_chain(10);
    let axis = |i: usize| match m.joints()[i] {
        JointType::Revolute { axis } => axis,
        _ => unreachable!(),
    };
    for i in 1..10 {
        assert!(axis(i).cross(&axis(i + 1)).norm() > 0.1);
        let ic = m.inertias()[i].inertia_about_com();
        assert!(ic[(0, 1)].abs() + ic[(0, 2)].abs() + ic[(1, 2)].abs() > 1e-4);
        assert!(m.inertias()[i].com().norm() > 0.05);
        assert!(m.placements()[i].trans.norm() > 0.05);
    }
    assert_eq!(serial_chain(0).nv(), 0);
}

#[test]
fn pendulum_matches_closed_form_mass_matrix() {
    for n in 1..=5 {
        let m = pendulum(n);
        check_model(&m);
        assert_eq!((m.nq(), m.nv()), (n, n));
        assert!((total_mass(&m) - n as f64).abs() < 1e-12);
    }
    // Double pendulum, unit masses and lengths: M = [[3 + 2c₂, 1 + c₂], [1 + c₂, 1]].
    let m = pendulum(2);
    for q2 in [0.0, 0.4, -1.3, 2.5] {
        let mm = mass_matrix(&m, &[0.7, q2]);
        let c = f64::cos(q2);
        let expected = DMatrix::from_row_slice(2, 2, &[3.0 + 2.0 * c, 1.0 + c, 1.0 + c, 1.0]);
        assert!((mm - expected).amax() < 1e-12);
    }
    // The tip hangs n metres below the origin at q = 0.
    let m = pendulum(3);
    let tip = frame_pose(&m, &[0.0; 3], "tip").trans;
    assert!((tip - Vector3::new(0.0, 0.0, -3.0)).norm() < 1e-12);
}

#[test]
fn quadruped_structure() {
    let m = quadruped();
    check_model(&m);
    assert_eq!((m.nq(), m.nv(), m.njoints()), (19, 18, 14));
    assert_eq!(m.joints()[1], JointType::FreeFlyer);
    assert_eq!(m.names()[1], "root_joint");
    assert_eq!(count_kind(&m, "revolute"), 12);
    let mass = total_mass(&m);
    assert!((mass - 17.4).abs() < 1e-9, "quadruped mass {mass}");
    assert!((m.inertias()[1].mass - 10.0).abs() < 1e-12);
    let q0 = m.neutral();
    for (leg, fx, sy) in
        [("LF", 1.0, 1.0), ("RF", 1.0, -1.0), ("LH", -1.0, 1.0), ("RH", -1.0, -1.0)]
    {
        let haa = m.joint_id(&format!("{leg}_HAA")).unwrap();
        let hfe = m.joint_id(&format!("{leg}_HFE")).unwrap();
        let kfe = m.joint_id(&format!("{leg}_KFE")).unwrap();
        assert_eq!(m.joints()[haa], JointType::Revolute { axis: Vector3::x() });
        assert_eq!(m.joints()[hfe], JointType::Revolute { axis: Vector3::y() });
        assert_eq!(m.joints()[kfe], JointType::Revolute { axis: Vector3::y() });
        assert_eq!((m.parents()[haa], m.parents()[hfe], m.parents()[kfe]), (1, haa, hfe));
        for j in [haa, hfe, kfe] {
            let a = m.idx_q()[j];
            assert!(m.lower()[a].is_finite() && m.upper()[a].is_finite());
        }
        let foot = frame_pose(&m, q0.as_slice(), &format!("{leg}_FOOT")).trans;
        let expected = Vector3::new(0.2 * fx, 0.16 * sy, -0.4);
        assert!((foot - expected).norm() < 1e-12, "{leg}: foot at {foot:?}");
        assert_eq!(m.frames()[m.frame_id(&format!("{leg}_FOOT")).unwrap()].joint, kfe);
    }
    check_mass_matrix_pd(&m, 1);
}

#[test]
fn humanoid_structure() {
    let m = humanoid();
    check_model(&m);
    assert_eq!((m.nq(), m.nv()), (39, 38));
    assert!((30..=40).contains(&m.nv()));
    assert_eq!(m.joints()[1], JointType::FreeFlyer);
    assert_eq!(m.names()[1], "root_joint");
    // All joints but the root are limited revolute joints.
    for i in 2..m.njoints() {
        assert!(matches!(m.joints()[i], JointType::Revolute { .. }), "{}", m.names()[i]);
        let a = m.idx_q()[i];
        assert!(m.lower()[a].is_finite() && m.upper()[a].is_finite(), "{} unlimited", m.names()[i]);
        assert!(
            m.lower()[a] <= 0.0 && m.upper()[a] >= 0.0,
            "{}: neutral outside limits",
            m.names()[i]
        );
    }
    let mass = total_mass(&m);
    assert!((60.0..=80.0).contains(&mass), "humanoid mass {mass}");
    for name in [
        "torso_yaw",
        "torso_pitch",
        "head_yaw",
        "head_pitch",
        "left_hip_yaw",
        "left_hip_roll",
        "left_hip_pitch",
        "left_knee",
        "left_ankle_pitch",
        "left_ankle_roll",
        "right_hip_yaw",
        "right_knee",
        "left_shoulder_pitch",
        "left_shoulder_roll",
        "left_shoulder_yaw",
        "left_elbow",
        "left_wrist_yaw",
        "left_wrist_pitch",
        "left_wrist_roll",
        "left_gripper",
        "right_elbow",
        "right_gripper",
    ] {
        assert!(m.joint_id(name).is_ok(), "missing joint {name}");
    }
    for name in ["left_sole", "right_sole", "left_hand", "right_hand", "head", "pelvis", "torso"] {
        assert!(m.frame_id(name).is_ok(), "missing frame {name}");
    }
    // Standing pose: soles 1 m below the pelvis, symmetric; hands below the shoulders.
    let q0 = m.neutral();
    let ls = frame_pose(&m, q0.as_slice(), "left_sole").trans;
    let rs = frame_pose(&m, q0.as_slice(), "right_sole").trans;
    assert!((ls - Vector3::new(0.0, 0.1, -1.0)).norm() < 1e-12, "left sole {ls:?}");
    assert!((rs - Vector3::new(0.0, -0.1, -1.0)).norm() < 1e-12, "right sole {rs:?}");
    let lh = frame_pose(&m, q0.as_slice(), "left_hand").trans;
    let rh = frame_pose(&m, q0.as_slice(), "right_hand").trans;
    assert!((lh.y + rh.y).abs() < 1e-12 && lh.y > 0.2 && lh.z < 0.0);
    let head = frame_pose(&m, q0.as_slice(), "head").trans;
    assert!(head.z > 0.6);
    // Left/right mass symmetry.
    let side_mass = |side: &str| -> f64 {
        (1..m.njoints())
            .filter(|&i| m.names()[i].starts_with(side))
            .map(|i| m.inertias()[i].mass)
            .sum()
    };
    assert!((side_mass("left_") - side_mass("right_")).abs() < 1e-12);
    check_mass_matrix_pd(&m, 2);
}

#[test]
fn random_tree_mixes_every_joint_type() {
    for seed in 0..40 {
        for floating in [false, true] {
            let m = random_tree(60, seed, floating);
            check_model(&m);
            let off = usize::from(floating);
            assert_eq!(m.njoints(), 61 + off);
            for kind in ["revolute", "continuous", "prismatic", "spherical", "planar"] {
                assert!(count_kind(&m, kind) >= 1, "seed {seed}: no {kind} joint");
            }
            assert_eq!(count_kind(&m, "free_flyer"), off);
            if floating {
                assert_eq!(
                    (m.names()[1].as_str(), m.joints()[1]),
                    ("root_joint", JointType::FreeFlyer)
                );
                assert!(
                    m.parents().iter().skip(2).all(|&p| p >= 1),
                    "floating tree hangs off the world"
                );
            }
            // Fixed bodies: ⌈60/5⌉ frames on moving bodies.
            let fixed: Vec<_> =
                m.frames().iter().filter(|f| f.name.starts_with("fixed_")).collect();
            assert_eq!(fixed.len(), 12, "seed {seed}");
            assert!(fixed.iter().all(|f| f.joint >= 1));
            // Branching: some body has at least two children.
            let mut children = vec![0usize; m.njoints()];
            for i in 1..m.njoints() {
                children[m.parents()[i]] += 1;
            }
            assert!(children.iter().skip(1).any(|&c| c >= 2), "seed {seed}: no branching");
            // Some limited and some unlimited revolute/prismatic joints.
            let scalar: Vec<usize> = (1..m.njoints())
                .filter(|&i| {
                    matches!(
                        m.joints()[i],
                        JointType::Revolute { .. } | JointType::Prismatic { .. }
                    )
                })
                .collect();
            assert!(scalar.iter().any(|&i| m.lower()[m.idx_q()[i]].is_finite()));
            assert!(scalar.iter().any(|&i| m.lower()[m.idx_q()[i]].is_infinite()));
            // nv within the documented range.
            assert!((60 + 6 * off..=180 + 6 * off).contains(&m.nv()), "nv {}", m.nv());
        }
    }
}

#[test]
fn random_tree_inertias_and_dof_counts() {
    let mut nv_sum = 0;
    for seed in 0..100 {
        let m = random_tree(20, seed, seed % 2 == 1);
        check_model(&m);
        for i in 1..m.njoints() {
            let ic = m.inertias()[i].inertia_about_com();
            let ev = ic.symmetric_eigen().eigenvalues;
            assert!(ev.min() > 0.0, "seed {seed}: degenerate rotational inertia");
        }
        for (i, j) in m.joints().iter().enumerate().skip(1) {
            if let JointType::Revolute { axis }
            | JointType::Continuous { axis }
            | JointType::Prismatic { axis } = j
            {
                assert!((axis.norm() - 1.0).abs() < 1e-12, "joint {i}");
            }
        }
        nv_sum += m.nv() - if seed % 2 == 1 { 6 } else { 0 };
        if seed < 10 {
            check_mass_matrix_pd(&m, seed);
        }
    }
    let mean = nv_sum as f64 / 100.0;
    assert!((25.0..=40.0).contains(&mean), "mean nv per 20 joints = {mean}");
    // Small trees are well formed too.
    for n in 0..6 {
        for floating in [false, true] {
            let m = random_tree(n, 3, floating);
            check_model(&m);
            assert_eq!(m.njoints(), n + 1 + usize::from(floating));
        }
    }
}

#[test]
fn random_tree_is_deterministic() {
    for seed in [0, 1, 42, u64::MAX] {
        assert_same(&random_tree(30, seed, false), &random_tree(30, seed, false));
        assert_same(&random_tree(30, seed, true), &random_tree(30, seed, true));
    }
    let a = format!("{:?}", random_tree(30, 1, false));
    let b = format!("{:?}", random_tree(30, 2, false));
    assert_ne!(a, b);
    assert_same(&humanoid(), &humanoid());
    assert_same(&quadruped(), &quadruped());
}

#[test]
fn lookup_by_name() {
    assert_same(&by_name("humanoid").unwrap(), &humanoid());
    assert_same(&by_name("quadruped").unwrap(), &quadruped());
    assert_same(&by_name("chain7").unwrap(), &serial_chain(7));
    assert_same(&by_name("serial_chain12").unwrap(), &serial_chain(12));
    assert_same(&by_name("pendulum3").unwrap(), &pendulum(3));
    assert_same(&by_name("random_tree25").unwrap(), &random_tree(25, 0, false));
    assert_same(&by_name("random_tree25_ff").unwrap(), &random_tree(25, 0, true));
    assert_same(&by_name("random_tree25_s9").unwrap(), &random_tree(25, 9, false));
    assert_same(&by_name("random_tree25_ff_s9").unwrap(), &random_tree(25, 9, true));
    for name in names() {
        let m = by_name(name).unwrap_or_else(|| panic!("names() entry {name} not found"));
        check_model(&m);
    }
    assert!(by_name(&format!("chain{MAX_NAMED_JOINTS}")).is_some());
    for bad in [
        "",
        "Humanoid",
        "humanoid ",
        "robot",
        "chain",
        "chain0",
        "chain-1",
        "chain+3",
        "chain3x",
        "pendulum",
        "random_tree",
        "random_tree_ff",
        "random_tree10_s",
        "random_tree10_sx",
        "random_tree10_s7_ff",
        "random_tree10_ff_ff",
        "random_tree10_ff_s1_s2",
        "random_tree10__ff",
        "random_tree10_x",
        &format!("chain{}", MAX_NAMED_JOINTS + 1),
        "random_tree10_s99999999999999999999999",
    ] {
        assert!(by_name(bad).is_none(), "{bad:?} accepted");
    }
}

/// Armature (rotor inertia): `Model::with_armature` and `ModelBuilder::set_armature` check it
/// (length, sign, finiteness, naming the joint and coordinate); URDF and built-in models have none.
#[test]
fn armature_is_validated() {
    use sodyn::algo::{Data, crba};
    use sodyn::error::Error;
    use sodyn::model::{ModelBuilder, builtin};
    use sodyn::spatial::Inertia;
    let m = builtin::quadruped();
    assert!(!m.has_armature() && m.armature().iter().all(|&x| x == 0.0));
    assert_eq!(m.armature().len(), m.nv());
    match m.with_armature(&[0.1; 3]) {
        Err(Error::Dimension { expected, got, .. }) => assert_eq!((expected, got), (18, 3)),
        r => panic!("{r:?}"),
    }
    let mut a = vec![0.1; 18];
    a[8] = -0.5;
    let e = m.with_armature(&a).unwrap_err().to_string();
    let j = m.names()[m.dof_joint()[8]].clone();
    assert!(e.contains(&format!("joint \"{j}\"")) && e.contains("-0.5") && e.contains("8"), "{e}");
    a[8] = f64::NAN;
    let e = m.with_armature(&a).unwrap_err().to_string();
    assert!(e.contains("NaN") && e.contains("armature"), "{e}");
    a[8] = f64::INFINITY;
    assert!(m.with_armature(&a).is_err());
    // Zeros: no armature; the model is otherwise the same and its workspaces serve.
    let z = m.with_armature(&[0.0; 18]).unwrap();
    assert!(!z.has_armature());
    let b = m.with_armature(&[0.25; 18]).unwrap();
    assert!(b.has_armature() && b.armature() == [0.25; 18]);
    let mut d = Data::new(&m);
    crba(&b, &mut d, &b.neutral()).unwrap();
    // The builder: per joint, checked at build.
    let mut mb = ModelBuilder::new("t");
    let i = Inertia::from_com(1.0, nalgebra::Vector3::x(), nalgebra::Matrix3::identity());
    let j1 = mb.add_body(0, "j1", JointType::Spherical, Transform::identity(), "b1", i).unwrap();
    assert!(mb.set_armature(j1, &[0.1]).is_err(), "wrong length");
    assert!(mb.set_armature(0, &[]).is_err(), "the world");
    assert!(mb.set_armature(7, &[0.1]).is_err(), "no such joint");
    mb.set_armature(j1, &[0.1, 0.2, 0.3]).unwrap();
    let built = mb.clone().build().unwrap();
    assert_eq!(built.armature(), [0.1, 0.2, 0.3]);
    assert!(built.has_armature());
    mb.set_armature(j1, &[0.1, -0.2, 0.3]).unwrap();
    let e = mb.build().unwrap_err().to_string();
    assert!(e.contains("joint \"j1\"") && e.contains("-0.2") && e.contains("coordinate 1"), "{e}");
    // URDF: zeros.
    let u = builtin::serial_chain(3);
    assert!(u.armature() == [0.0; 3]);
}
