//! Core dynamics: RNEA vs CRBA, the nonlinear effects vs RNEA at `q̈ = 0` and the full tree's,
//! ABA vs M⁻¹(τ − b), LᵀDL vs dense solves, point positions, Jacobians and drift vs dual numbers,
//! energy balance along an integrated trajectory, input errors; the armature (`M_a = M +
//! diag(a)`) against the same model without it, on every SIMD level.

use crate::util::*;
use nalgebra::{DMatrix, DVector, Matrix3xX, Vector3};
use num_dual::HyperDual64;
use sodyn::algo::*;
use sodyn::model::{JointType, Model, ModelBuilder, builtin};
use sodyn::reference;
use sodyn::rng::Rng;
use sodyn::spatial::{Force, Inertia, Transform};
use sodyn::{Error, deriv};

#[test]
fn models_cover_every_joint_type_and_60_dof() {
    let models = test_models(60);
    let mut seen = std::collections::BTreeSet::new();
    for m in &models {
        for j in &m.joints()[1..] {
            seen.insert(j.name());
        }
    }
    for t in ["revolute", "continuous", "prismatic", "spherical", "free_flyer", "planar"] {
        assert!(seen.contains(t), "no test model has a {t} joint");
    }
    let big = builtin::random_tree(40, 11, true);
    assert!(big.nv() >= 50, "want a large random tree, got nv = {}", big.nv());
}

fn big_models() -> Vec<Model> {
    let mut v = test_models(60);
    v.push(builtin::random_tree(40, 11, true));
    v.push(builtin::random_tree(40, 12, false));
    v.retain(|m| m.nv() <= 60);
    v
}

#[test]
fn rnea_equals_crba_times_qdd_plus_nle_and_reference() {
    let mut w_id = Worst::new("tau = M qdd + b");
    let mut w_ref = Worst::new("rnea vs reference rnea");
    let mut w_sym = Worst::new("M symmetric");
    // Two computations of one formula: `b` against RNEA at `q̈ = 0`, and against the full tree's
    // `Gᵀ b_full(expand(q), G q̇)` (the same for a model that is not reduced).
    let mut w_nle = Worst::new("nle = rnea(a = 0)");
    let mut w_nle_full = Worst::new("nle = G^T b_full");
    let mut rng = Rng::new(1);
    for m in big_models() {
        let mut d = Data::new(&m);
        let mut d_full = Data::new(m.full_tree());
        let (g, zero) = (m.velocity_map(), DVector::zeros(m.nv()));
        for s in 0..3 {
            let (q, v, a) = random_state(&m, &mut rng);
            let tau = rnea(&m, &mut d, &q, &v, &a, None).unwrap().clone();
            let b = nonlinear_effects(&m, &mut d, &q, &v).unwrap().clone();
            assert_eq!(d.nle(), &b);
            let at = format!("{} nv={} state {s}", m.name(), m.nv());
            w_nle.add(rel_err_vec(&b, rnea(&m, &mut d, &q, &v, &zero, None).unwrap()), &at);
            let (qf, vf) = (m.expand_q(&q).unwrap(), &g * &v);
            let bf = nonlinear_effects(m.full_tree(), &mut d_full, &qf, &vf).unwrap();
            w_nle_full.add(rel_err_vec(&b, &(g.transpose() * bf)), &at);
            let mm = crba(&m, &mut d, &q).unwrap().clone();
            w_id.add(rel_err_vec(&(&mm * &a + &b), &tau), &at);
            w_sym.add(rel_err_mat(&mm, &mm.transpose()), &at);
            let r = reference::rnea::<f64>(&m, q.as_slice(), v.as_slice(), a.as_slice(), None);
            let r = DVector::from_vec(r);
            assert!(r.amax() > 0.0);
            w_ref.add(rel_err_vec(&tau, &r), &at);
        }
    }
    w_id.check(1e-12);
    w_ref.check(1e-12);
    w_sym.check(0.0);
    w_nle.check(1e-14);
    w_nle_full.check(1e-14);
}

#[test]
fn aba_equals_dense_solve_and_ltl_solve_equals_dense() {
    let mut w_aba = Worst::new("aba vs M^-1 (tau - b)");
    let mut w_ltl = Worst::new("LTDL solve vs dense");
    let mut w_ref = Worst::new("aba vs reference aba");
    let mut rng = Rng::new(2);
    for m in big_models() {
        let mut d = Data::new(&m);
        for s in 0..3 {
            let (q, v, tau) = random_state(&m, &mut rng);
            let qdd = aba(&m, &mut d, &q, &v, &tau, None).unwrap().clone();
            let b = nonlinear_effects(&m, &mut d, &q, &v).unwrap().clone();
            let mm = crba(&m, &mut d, &q).unwrap().clone();
            let dense = mm.clone().lu().solve(&(&tau - &b)).unwrap();
            let at = format!("{} nv={} state {s}", m.name(), m.nv());
            w_aba.add(rel_err_vec(&qdd, &dense), &at);
            if m.is_reduced() {
                // The sparse LᵀDL factorisation is the full tree's (its sparsity is the tree's):
                // a reduced model is refused, naming the full tree.
                let e = factorize_ltl(&m, &mut d).unwrap_err().to_string();
                assert!(e.contains("Model::full_tree"), "{e}");
            } else {
                factorize_ltl(&m, &mut d).unwrap();
                let mut x = &tau - &b;
                solve_ltl(&m, &d, &mut x).unwrap();
                w_ltl.add(rel_err_vec(&x, &dense), &at);
                let mut bm = DMatrix::from_fn(m.nv(), 3, |i, j| (i * 3 + j) as f64 * 0.1 - 1.0);
                let dense_m = mm.clone().lu().solve(&bm).unwrap();
                solve_ltl_matrix(&m, &d, &mut bm).unwrap();
                w_ltl.add(rel_err_mat(&bm, &dense_m), &at);
            }
            let r = reference::aba::<f64>(&m, q.as_slice(), v.as_slice(), tau.as_slice(), None);
            w_ref.add(rel_err_vec(&qdd, &DVector::from_vec(r)), &at);
        }
    }
    w_aba.check(1e-10);
    w_ltl.check(1e-10);
    w_ref.check(1e-10);
}

#[test]
fn external_forces_match_reference_and_jacobian_transpose() {
    // fext in body frames: RNEA/ABA against the reference (world-frame fext) and τ = ... − Jᵀf.
    let mut w = Worst::new("rnea/aba with fext");
    let mut rng = Rng::new(3);
    for m in every(test_models(40), 3) {
        let mut d = Data::new(&m);
        let (q, v, a) = random_state(&m, &mut rng);
        let fext: Vec<Force> = (0..m.njoints())
            .map(|_| {
                Force::new(
                    Vector3::from_fn(|_, _| rng.normal()),
                    Vector3::from_fn(|_, _| rng.normal()),
                )
            })
            .collect();
        let tau = rnea(&m, &mut d, &q, &v, &a, Some(&fext)).unwrap().clone();
        // world-frame forces for the reference
        forward_kinematics(&m, &mut d, &q, None, None).unwrap();
        let fw: Vec<[f64; 6]> = (0..m.njoints())
            .map(|i| {
                let f = if i == 0 { Force::zero() } else { d.o_m_i()[i].act_force(&fext[i]) };
                [f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z]
            })
            .collect();
        let r = reference::rnea::<f64>(&m, q.as_slice(), v.as_slice(), a.as_slice(), Some(&fw));
        w.add(rel_err_vec(&tau, &DVector::from_vec(r)), m.name());
        let qdd = aba(&m, &mut d, &q, &v, &tau, Some(&fext)).unwrap().clone();
        w.add(rel_err_vec(&qdd, &a), m.name());
    }
    w.check(1e-10);
}

/// Point position, Jacobian, velocity `J q̇` and drift against the reference point position
/// and its dual / hyper-dual derivatives, on every frame of the test models and of the panda in
/// reduced coordinates (its finger mimic with multiplier −0.6 and offset 0.02).
#[test]
fn point_jacobian_and_drift_match_dual_numbers() {
    let mut wp = Worst::new("point position vs reference");
    let mut wj = Worst::new("point jacobian vs dual");
    let mut wv = Worst::new("point velocity J v vs dual");
    let mut wd = Worst::new("point drift vs hyper-dual");
    let mut wd_reduced = Worst::new("point drift (reduced) vs h.-d.");
    let mut rng = Rng::new(4);
    let mut models = test_models(40);
    models.push(mimic::panda());
    for m in models {
        let mut d = Data::new(&m);
        let (q, v, _) = random_state(&m, &mut rng);
        for f in 1..m.frames().len() {
            let point = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.3;
            let mut jac = Matrix3xX::zeros(m.nv());
            point_jacobian(&m, &mut d, &q, f, &point, &mut jac).unwrap();
            let pt = [point.x, point.y, point.z];
            let at = format!("{} frame {}", m.name(), m.frames()[f].name);
            let jref = reference::d_point_position_dq(&m, q.as_slice(), f, &pt);
            wj.add((&jac - &jref).amax() / jref.amax().max(1.0), &at);
            let pos = point_position(&m, &mut d, &q, f, &point).unwrap();
            let pref = Vector3::from(reference::point_position(&m, q.as_slice(), f, &pt));
            wp.add((pos - pref).amax() / (1.0 + pref.amax()), &at);
            // drift: d²/dt² p(q ⊕ t v) at t = 0 (q̈ = 0 along the exponential curve); velocity:
            // its first derivative
            let drift = point_drift(&m, &mut d, &q, &v, f, &point).unwrap();
            let t = HyperDual64::new(0.0, 1.0, 1.0, 0.0);
            let qh: Vec<HyperDual64> = q.iter().map(|&x| HyperDual64::from(x)).collect();
            let delta: Vec<HyperDual64> = v.iter().map(|&x| t * x).collect();
            let qq = reference::integrate(&m, &qh, &delta);
            let p = reference::point_position(&m, &qq, f, &pt.map(HyperDual64::from));
            let vref = Vector3::new(p[0].eps1, p[1].eps1, p[2].eps1);
            wv.add((&jac * &v - vref).amax() / (1.0 + vref.amax()), &at);
            let dref = Vector3::new(p[0].eps1eps2, p[1].eps1eps2, p[2].eps1eps2);
            let e = (drift - dref).amax() / dref.amax().max(1.0);
            if m.is_reduced() { wd_reduced.add(e, &at) } else { wd.add(e, &at) }
        }
    }
    wp.check(1e-12);
    wj.check(1e-12);
    wv.check(1e-12);
    wd.check(1e-11);
    wd_reduced.check(1e-12);
}

/// Energy balance along a trajectory integrated with RK4 on the configuration manifold:
/// T(t1) − T(t0) = ∫ q̇ᵀ(τ − g) dt (Simpson quadrature). The stage combination of RK4 across
/// tangent spaces is only second-order accurate on Lie groups, so the test integrates with h and
/// h/2 and requires the discrepancy to be small and to converge (a wrong Coriolis or gravity term
/// would give an O(1) discrepancy that does not shrink with h).
#[test]
fn kinetic_energy_rate_along_integrated_trajectory() {
    let mut w = Worst::new("energy balance (h/2)");
    let mut rng = Rng::new(5);
    for m in [
        builtin::serial_chain(5),
        builtin::quadruped(),
        builtin::random_tree(8, 3, true),
        builtin::random_tree(10, 4, false),
    ] {
        let (q0, v0, _) = random_state(&m, &mut rng);
        let tau = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let e1 = energy_discrepancy(&m, &q0, &v0, &tau, 1e-3, 200);
        let e2 = energy_discrepancy(&m, &q0, &v0, &tau, 5e-4, 400);
        assert!(
            e2 < 1e-11 || e1 / e2 > 3.0,
            "{}: energy discrepancy does not converge: {e1:e} -> {e2:e}",
            m.name()
        );
        w.add(e2, m.name());
    }
    w.check(1e-7);
}

fn energy_discrepancy(
    m: &Model,
    q0: &DVector<f64>,
    v0: &DVector<f64>,
    tau: &DVector<f64>,
    h: f64,
    steps: usize,
) -> f64 {
    let mut d = Data::new(m);
    let zero = DVector::zeros(m.nv());
    let f = |d: &mut Data, q: &DVector<f64>, v: &DVector<f64>| -> (DVector<f64>, f64, f64) {
        let qdd = aba(m, d, q, v, tau, None).unwrap().clone();
        let g = rnea(m, d, q, &zero, &zero, None).unwrap().clone();
        let mm = crba(m, d, q).unwrap().clone();
        (qdd, 0.5 * v.dot(&(&mm * v)), v.dot(&(tau - &g)))
    };
    let (mut q, mut v) = (q0.clone(), v0.clone());
    let (_, ke0, p0) = f(&mut d, &q, &v);
    let mut powers = vec![p0];
    let mut ke = ke0;
    for _ in 0..steps {
        let (a1, _, _) = f(&mut d, &q, &v);
        let v1 = v.clone();
        let q2 = m.integrate(&q, &(&v1 * (h / 2.0))).unwrap();
        let v2 = &v + &a1 * (h / 2.0);
        let (a2, _, _) = f(&mut d, &q2, &v2);
        let q3 = m.integrate(&q, &(&v2 * (h / 2.0))).unwrap();
        let v3 = &v + &a2 * (h / 2.0);
        let (a3, _, _) = f(&mut d, &q3, &v3);
        let q4 = m.integrate(&q, &(&v3 * h)).unwrap();
        let v4 = &v + &a3 * h;
        let (a4, _, _) = f(&mut d, &q4, &v4);
        let dq = (&v1 + &v2 * 2.0 + &v3 * 2.0 + &v4) * (h / 6.0);
        q = m.integrate(&q, &dq).unwrap();
        v += (&a1 + &a2 * 2.0 + &a3 * 2.0 + &a4) * (h / 6.0);
        let (_, ke_new, p_new) = f(&mut d, &q, &v);
        powers.push(p_new);
        ke = ke_new;
    }
    let work: f64 = (0..steps / 2)
        .map(|s| h / 3.0 * (powers[2 * s] + 4.0 * powers[2 * s + 1] + powers[2 * s + 2]))
        .sum();
    ((ke - ke0) - work).abs() / ke0.abs().max(1.0)
}

#[test]
fn fixed_joints_merge_into_parent_and_frames_follow() {
    // A body on a fixed joint gives the same dynamics as its inertia lumped into the parent.
    let inertia_a = Inertia::from_com(
        2.0,
        Vector3::new(0.1, 0.0, 0.05),
        nalgebra::Matrix3::from_diagonal(&Vector3::new(0.02, 0.03, 0.04)),
    );
    let inertia_b = Inertia::from_com(
        0.5,
        Vector3::new(0.0, 0.2, 0.0),
        nalgebra::Matrix3::from_diagonal(&Vector3::new(0.01, 0.01, 0.015)),
    );
    let x_b = Transform::from_rpy_xyz([0.3, -0.2, 0.1], [0.2, 0.1, -0.3]);
    let mut b1 = ModelBuilder::new("merged");
    let j = b1
        .add_body(
            0,
            "j1",
            JointType::Revolute { axis: Vector3::y() },
            Transform::identity(),
            "a",
            inertia_a,
        )
        .unwrap();
    b1.append_inertia(j, &x_b, &inertia_b).unwrap();
    b1.add_frame("b", j, x_b).unwrap();
    let m1 = b1.build().unwrap();
    let mut b2 = ModelBuilder::new("lumped");
    b2.add_body(
        0,
        "j1",
        JointType::Revolute { axis: Vector3::y() },
        Transform::identity(),
        "a",
        inertia_a + x_b.act_inertia(&inertia_b),
    )
    .unwrap();
    let m2 = b2.build().unwrap();
    let q = DVector::from_vec(vec![0.4]);
    let (mut d1, mut d2) = (Data::new(&m1), Data::new(&m2));
    let t1 =
        rnea(&m1, &mut d1, &q, &DVector::from_vec(vec![0.3]), &DVector::from_vec(vec![-0.2]), None)
            .unwrap()[0];
    let t2 =
        rnea(&m2, &mut d2, &q, &DVector::from_vec(vec![0.3]), &DVector::from_vec(vec![-0.2]), None)
            .unwrap()[0];
    assert!((t1 - t2).abs() < 1e-14);
    let fb = m1.frame_id("b").unwrap();
    let p = point_position(&m1, &mut d1, &q, fb, &Vector3::zeros()).unwrap();
    let expect = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 0.4) * x_b.trans;
    assert!((p - expect).amax() < 1e-14);
}

#[test]
fn bad_inputs_are_errors_and_leave_data_usable() {
    let m = builtin::random_tree(6, 1, true);
    let mut d = Data::new(&m);
    let mut rng = Rng::new(9);
    let (q, v, a) = random_state(&m, &mut rng);
    // wrong lengths
    let short = DVector::zeros(m.nv() - 1);
    match rnea(&m, &mut d, &q, &short, &a, None) {
        Err(Error::Dimension { what, expected, got }) => {
            assert_eq!((what.as_str(), expected, got), ("v", m.nv(), m.nv() - 1))
        }
        other => panic!("expected a dimension error, got {other:?}"),
    }
    assert!(matches!(crba(&m, &mut d, &DVector::zeros(m.nq() + 1)), Err(Error::Dimension { .. })));
    // NaN / inf
    let mut bad = a.clone();
    bad[2] = f64::NAN;
    match aba(&m, &mut d, &q, &v, &bad, None) {
        Err(Error::NotFinite { what, index }) => assert_eq!((what.as_str(), index), ("tau", 2)),
        other => panic!("expected NotFinite, got {other:?}"),
    }
    let mut bad = v.clone();
    bad[0] = f64::INFINITY;
    assert!(matches!(
        deriv::id_derivatives(&m, &mut d, &q, &bad, &a, None),
        Err(Error::NotFinite { .. })
    ));
    // non-unit quaternion of the free flyer (q[3..7])
    let mut qb = q.clone();
    qb[6] *= 1.5;
    match rnea(&m, &mut d, &qb, &v, &a, None) {
        Err(e @ Error::InvalidConfiguration { .. }) => {
            let s = e.to_string();
            assert!(s.contains("root") || s.contains(&m.names()[1]), "{s}");
            assert!(s.contains("norm"), "{s}");
        }
        other => panic!("expected InvalidConfiguration, got {other:?}"),
    }
    // Data still usable and the result unchanged by the failed calls.
    let t1 = rnea(&m, &mut d, &q, &v, &a, None).unwrap().clone();
    let t2 = rnea(&m, &mut Data::new(&m), &q, &v, &a, None).unwrap().clone();
    assert_eq!(t1, t2);
    // wrong fext length
    let fext = vec![Force::zero(); 2];
    assert!(matches!(rnea(&m, &mut d, &q, &v, &a, Some(&fext)), Err(Error::Dimension { .. })));
}

#[test]
fn singular_mass_matrix_is_reported_by_the_factorising_algorithms() {
    // A massless leaf body: M is singular.
    let mut b = ModelBuilder::new("massless");
    let j1 = b
        .add_body(
            0,
            "j1",
            JointType::Revolute { axis: Vector3::z() },
            Transform::identity(),
            "a",
            Inertia::from_com(
                1.0,
                Vector3::new(0.3, 0.0, 0.0),
                nalgebra::Matrix3::identity() * 0.01,
            ),
        )
        .unwrap();
    b.add_body(
        j1,
        "j2",
        JointType::Revolute { axis: Vector3::x() },
        Transform::from_translation(Vector3::x()),
        "b",
        Inertia::zero(),
    )
    .unwrap();
    let m = b.build().unwrap();
    let mut d = Data::new(&m);
    let q = DVector::from_vec(vec![0.1, 0.2]);
    let z = DVector::zeros(2);
    let e = aba(&m, &mut d, &q, &z, &z, None).unwrap_err();
    assert!(matches!(e, Error::Singular { .. }), "{e:?}");
    assert!(e.to_string().contains("j2"), "{e}");
    crba(&m, &mut d, &q).unwrap();
    let e = factorize_ltl(&m, &mut d).unwrap_err();
    assert!(e.to_string().contains("j2"), "{e}");
    assert!(deriv::fd_derivatives(&m, &mut d, &q, &z, &z, None).is_err());
}

#[test]
fn workspaces_of_another_model_are_rejected() {
    let small = builtin::serial_chain(3);
    let big = builtin::quadruped();
    let mut rng = Rng::new(10);
    let (q, v, a) = random_state(&big, &mut rng);
    let mut d_small = Data::new(&small);
    let e = rnea(&big, &mut d_small, &q, &v, &a, None).unwrap_err();
    assert!(
        matches!(e, Error::Workspace(_))
            && e.to_string().contains("Data was made for a model with 4 joints"),
        "{e}"
    );
    // A second-order workspace of the small model, and a first-order one of the big model.
    let mut so_small = Data::with_second_order(&small);
    let e = deriv::id_so_derivatives(&big, &mut so_small, &q, &v, &a, None).unwrap_err();
    assert!(e.to_string().contains("Data was made for a model with 4 joints"), "{e}");
    assert!(deriv::fd_so_derivatives(&big, &mut so_small, &q, &v, &a, None).is_err());
    let mut d = Data::new(&big);
    let e = deriv::fd_so_derivatives(&big, &mut d, &q, &v, &a, None).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("Data::with_second_order")), "{e}");
}

/// Zero armature set explicitly changes nothing, bit for bit.
#[test]
fn zero_armature_is_bitwise_the_same() {
    use sodyn::deriv::fd_derivatives;
    let mut rng = Rng::new(3);
    for m in [builtin::humanoid(), builtin::random_tree(15, 2, false)] {
        let z = m.with_armature(&vec![0.0; m.nv()]).unwrap();
        let (q, v, a) = random_state(&m, &mut rng);
        let (mut d0, mut d1) = (Data::new(&m), Data::new(&m));
        assert_eq!(
            rnea(&m, &mut d0, &q, &v, &a, None).unwrap(),
            rnea(&z, &mut d1, &q, &v, &a, None).unwrap()
        );
        assert_eq!(crba(&m, &mut d0, &q).unwrap(), crba(&z, &mut d1, &q).unwrap());
        assert_eq!(
            aba(&m, &mut d0, &q, &v, &a, None).unwrap(),
            aba(&z, &mut d1, &q, &v, &a, None).unwrap()
        );
        fd_derivatives(&m, &mut d0, &q, &v, &a, None).unwrap();
        fd_derivatives(&z, &mut d1, &q, &v, &a, None).unwrap();
        assert_eq!(d0.dqdd_dq(), d1.dqdd_dq());
        assert_eq!(d0.minv(), d1.minv());
    }
}

/// The relations of the armature against the same model without it, on every SIMD level:
/// `τ_a = τ + a∘q̈`, `M_a = M + diag(a)`, ABA's `q̈ = M_a⁻¹(τ − b)`, `LᵀDL` of `M_a`,
/// IDSVA's `∂τ/∂q`, `∂τ/∂q̇` unchanged and `∂τ/∂q̈ = M_a`, FD's
/// `∂q̈/∂τ = M_a⁻¹`, `∂q̈/∂q = −M_a⁻¹ ∂τ/∂q`, IDSVA-SO's tensors unchanged, IDFOZA/IDSOZA
/// (`∂(M x)/∂q`) unchanged.
#[test]
fn armature_relations_on_every_level() {
    use sodyn::deriv::{fd_derivatives, id_derivatives, id_so_derivatives, idfoza, idsoza};
    use sodyn::simd::{Level, set_thread_level};
    let levels = [Level::Portable, Level::Avx2, Level::Avx512];
    let mut w = [
        Worst::new("tau_a - tau - a*qdd"),
        Worst::new("M_a - M - diag(a)"),
        Worst::new("M_a qdd_aba - (tau - b)"),
        Worst::new("LDL solve vs ABA"),
        Worst::new("IDSVA dtau unchanged"),
        Worst::new("IDSVA M = M_a, tau"),
        Worst::new("FD Minv M_a - I"),
        Worst::new("FD dqdd vs -Minv dtau"),
        Worst::new("IDSVA-SO unchanged"),
        Worst::new("IDFOZA/IDSOZA unchanged"),
    ];
    let mut rng = Rng::new(17);
    for lvl in levels {
        set_thread_level(Some(lvl));
        for (m0, m) in armature_pairs() {
            let n = m.nv();
            let arm = DVector::from_column_slice(m.armature());
            let at = format!("{} nv={n} {lvl:?}", m.name());
            let (q, v, a) = random_state(&m, &mut rng);
            let (mut d0, mut d) = (Data::new(&m0), Data::new(&m));
            let t0 = rnea(&m0, &mut d0, &q, &v, &a, None).unwrap().clone();
            let t = rnea(&m, &mut d, &q, &v, &a, None).unwrap().clone();
            w[0].add(rel_err_vec(&(&t - &t0), &arm.component_mul(&a)), &at);
            let mm0 = crba(&m0, &mut d0, &q).unwrap().clone();
            let mm = crba(&m, &mut d, &q).unwrap().clone();
            w[1].add(rel_err_mat(&(&mm - &mm0), &DMatrix::from_diagonal(&arm)), &at);
            let b = nonlinear_effects(&m, &mut d, &q, &v).unwrap().clone();
            let tau = DVector::from_fn(n, |_, _| rng.range(-2.0, 2.0));
            let qdd = aba(&m, &mut d, &q, &v, &tau, None).unwrap().clone();
            w[2].add(rel_err_vec(&(&mm * &qdd), &(&tau - &b)), &at);
            crba(&m, &mut d, &q).unwrap();
            factorize_ltl(&m, &mut d).unwrap();
            let mut x = &tau - &b;
            solve_ltl(&m, &d, &mut x).unwrap();
            w[3].add(rel_err_vec(&x, &qdd), &at);
            id_derivatives(&m0, &mut d0, &q, &v, &a, None).unwrap();
            id_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
            w[4].add(
                rel_err_mat(d.dtau_dq(), d0.dtau_dq()).max(rel_err_mat(d.dtau_dv(), d0.dtau_dv())),
                &at,
            );
            w[5].add(rel_err_mat(d.m(), &mm).max(rel_err_vec(d.tau(), &t)), &at);
            fd_derivatives(&m, &mut d, &q, &v, &tau, None).unwrap();
            w[6].add(rel_err_mat(&(d.minv() * &mm), &DMatrix::identity(n, n)), &at);
            let (dq, dv) = (d.dtau_dq().clone(), d.dtau_dv().clone());
            w[7].add(
                rel_err_mat(d.dqdd_dq(), &(-d.minv() * dq))
                    .max(rel_err_mat(d.dqdd_dv(), &(-d.minv() * dv))),
                &at,
            );
            w[2].add(rel_err_vec(d.qdd(), &qdd), &at);
            d0.reserve_second_order(&m0).unwrap();
            d.reserve_second_order(&m).unwrap();
            let s0 = id_so_derivatives(&m0, &mut d0, &q, &v, &a, None).unwrap().clone();
            let s = id_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap().clone();
            let e = [
                rel_err_tensor(s.d2tau_dq2(), s0.d2tau_dq2()),
                rel_err_tensor(s.d2tau_dv2(), s0.d2tau_dv2()),
                rel_err_tensor(s.d2tau_dqdv(), s0.d2tau_dqdv()),
                rel_err_tensor(s.dm_dq(), s0.dm_dq()),
            ];
            w[8].add(e.into_iter().fold(0.0, f64::max), &at);
            w[5].add(rel_err_mat(d.m(), &mm).max(rel_err_vec(d.tau(), &t)), &at);
            let (mut z0, mut z) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
            idfoza(&m0, &mut d0, &q, &a, &mut z0).unwrap();
            idfoza(&m, &mut d, &q, &a, &mut z).unwrap();
            let mut e = rel_err_mat(&z, &z0);
            let t0 = idsoza(&m0, &mut d0, &q, &a).unwrap().clone();
            let t1 = idsoza(&m, &mut d, &q, &a).unwrap().clone();
            e = e.max(rel_err_tensor(&t1, &t0));
            w[9].add(e, &at);
        }
    }
    set_thread_level(None);
    for x in &w {
        x.check(1e-11);
    }
}
