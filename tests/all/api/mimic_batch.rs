//! The batched API (`sodyn::batch`) on models in reduced coordinates (mimic joints): results
//! bit for bit those of the sequential `sodyn::algo` / `sodyn::deriv` calls, whatever the
//! number of threads; errors name the failing state, the argument or the output.

use nalgebra::{DMatrix, DVector};
use sodyn::Error;
use sodyn::algo::{self, Data};
use sodyn::batch::{self, BatchData, BatchPool, FdSoResult, IdSoResult};
use sodyn::deriv;
use sodyn::model::{Model, UrdfOptions, load_urdf_file};
use sodyn::rng::Rng;
use std::path::PathBuf;
use std::sync::Arc;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

/// The test arm (fixed and floating: a prismatic pair, a continuous joint mimicking a revolute
/// one, a joint mimicking an ancestor) and the panda with a finger mimic of multiplier −0.6 and
/// offset 0.02.
fn models() -> Vec<Model> {
    let o = |floating_base| UrdfOptions { floating_base, strict_inertia: false, mimic: true };
    vec![
        load_urdf_file(&data("mimic_arm.urdf"), &o(false)).unwrap(),
        load_urdf_file(&data("mimic_arm.urdf"), &o(true)).unwrap(),
        load_urdf_file(&data("mimic_panda_coeffs.urdf"), &o(false)).unwrap(),
    ]
}

struct States {
    q: Vec<DVector<f64>>,
    v: Vec<DVector<f64>>,
    a: Vec<DVector<f64>>,
    tau: Vec<DVector<f64>>,
}

fn states(m: &Model, n: usize, seed: u64) -> States {
    let mut rng = Rng::new(seed);
    let mut s = States { q: vec![], v: vec![], a: vec![], tau: vec![] };
    for _ in 0..n {
        s.q.push(m.random_configuration(&mut rng));
        let mut r = || DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        s.v.push(r());
        s.a.push(r());
        s.tau.push(r());
    }
    s
}

fn vecs(m: &Model, n: usize) -> Vec<DVector<f64>> {
    vec![DVector::zeros(m.nv()); n]
}

fn mats(m: &Model, n: usize) -> Vec<DMatrix<f64>> {
    vec![DMatrix::zeros(m.nv(), m.nv()); n]
}

/// Batch workspaces with dense second-order capacity on a pool of `threads` threads.
fn so_batch(m: &Model, threads: usize) -> BatchData {
    BatchData::from_workspace(
        Arc::new(BatchPool::new(threads).unwrap()),
        Data::with_second_order(m),
    )
}

/// Every mimic batched function on `bd`'s pool against the sequential calls, bit for bit
/// (`bd` with dense second-order capacity).
fn check_identical(m: &Model, s: &States, bd: &mut BatchData, label: &str) {
    let n = s.q.len();
    let mut tau = vecs(m, n);
    batch::rnea_batch(m, bd, &s.q, &s.v, &s.a, &mut tau).unwrap();
    let mut mm = mats(m, n);
    batch::crba_batch(m, bd, &s.q, &mut mm).unwrap();
    let mut qdd = vecs(m, n);
    batch::aba_batch(m, bd, &s.q, &s.v, &s.tau, &mut qdd).unwrap();
    let (mut idq, mut idv) = (mats(m, n), mats(m, n));
    batch::id_derivatives_batch(m, bd, &s.q, &s.v, &s.a, &mut idq, &mut idv).unwrap();
    let (mut fdq, mut fdv) = (mats(m, n), mats(m, n));
    batch::fd_derivatives_batch(m, bd, &s.q, &s.v, &s.tau, &mut fdq, &mut fdv).unwrap();
    let mut so = vec![IdSoResult::zeros(m); n];
    batch::id_so_derivatives_batch(m, bd, &s.q, &s.v, &s.a, &mut so).unwrap();
    let mut fso = vec![FdSoResult::zeros(m); n];
    batch::fd_so_derivatives_batch(m, bd, &s.q, &s.v, &s.tau, &mut fso).unwrap();

    let mut d = Data::with_second_order(m);
    for k in 0..n {
        let at = format!("{label}: model {} state {k}", m.name());
        let (q, v, a, t) = (&s.q[k], &s.v[k], &s.a[k], &s.tau[k]);
        assert_eq!(tau[k], *algo::rnea(m, &mut d, q, v, a, None).unwrap(), "rnea {at}");
        assert_eq!(mm[k], *algo::crba(m, &mut d, q).unwrap(), "crba {at}");
        assert_eq!(qdd[k], *algo::aba(m, &mut d, q, v, t, None).unwrap(), "aba {at}");
        deriv::id_derivatives(m, &mut d, q, v, a, None).unwrap();
        assert_eq!(&idq[k], d.dtau_dq(), "dtau_dq {at}");
        assert_eq!(&idv[k], d.dtau_dv(), "dtau_dv {at}");
        deriv::fd_derivatives(m, &mut d, q, v, t, None).unwrap();
        assert_eq!(&fdq[k], d.dqdd_dq(), "dqdd_dq {at}");
        assert_eq!(&fdv[k], d.dqdd_dv(), "dqdd_dv {at}");
        let (b, r) = (&so[k], deriv::id_so_derivatives(m, &mut d, q, v, a, None).unwrap());
        assert_eq!(b.d2tau_dq2.as_slice(), r.d2tau_dq2().as_slice(), "d2tau_dq2 {at}");
        assert_eq!(b.d2tau_dv2.as_slice(), r.d2tau_dv2().as_slice(), "d2tau_dv2 {at}");
        assert_eq!(b.d2tau_dqdv.as_slice(), r.d2tau_dqdv().as_slice(), "d2tau_dqdv {at}");
        assert_eq!(b.dm_dq.as_slice(), r.dm_dq().as_slice(), "dM_dq {at}");
        let (b, r) = (&fso[k], deriv::fd_so_derivatives(m, &mut d, q, v, t, None).unwrap());
        assert_eq!(b.d2qdd_dq2.as_slice(), r.d2qdd_dq2().as_slice(), "d2qdd_dq2 {at}");
        assert_eq!(b.d2qdd_dv2.as_slice(), r.d2qdd_dv2().as_slice(), "d2qdd_dv2 {at}");
        assert_eq!(b.d2qdd_dqdv.as_slice(), r.d2qdd_dqdv().as_slice(), "d2qdd_dqdv {at}");
        assert_eq!(b.d2qdd_dtaudq.as_slice(), r.d2qdd_dtaudq().as_slice(), "d2qdd_dtaudq {at}");
    }
}

/// 1 and 2 threads (and 3: more threads than the machine's cores), with batch sizes below, at
/// and above the number of threads, and the shared pool; the same `BatchData` reused.
#[test]
fn mimic_batch_equals_sequential_one_and_two_threads() {
    for (i, m) in models().iter().enumerate() {
        for threads in [1, 2, 3] {
            let mut bd = so_batch(m, threads);
            assert_eq!(bd.threads(), threads);
            for n in [1, 2, 5, 41] {
                let s = states(m, n, 100 * i as u64 + n as u64);
                check_identical(m, &s, &mut bd, &format!("{threads} threads, {n} states"));
            }
        }
        let mut bd = BatchData::with_second_order(m);
        check_identical(m, &states(m, 23, 7 + i as u64), &mut bd, "shared pool");
    }
}

#[test]
fn mimic_empty_batch_is_ok() {
    let m = &models()[0];
    let mut bd = BatchData::with_second_order(m);
    batch::rnea_batch(m, &mut bd, &[], &[], &[], &mut []).unwrap();
    batch::crba_batch(m, &mut bd, &[], &mut []).unwrap();
    let (mut a, mut b): (Vec<DMatrix<f64>>, Vec<DMatrix<f64>>) = (vec![], vec![]);
    batch::fd_derivatives_batch(m, &mut bd, &[], &[], &[], &mut a, &mut b).unwrap();
    batch::fd_so_derivatives_batch(m, &mut bd, &[], &[], &[], &mut []).unwrap();
}

/// The floating arm has a free-flyer root: a non-unit quaternion in state `k` is an error of
/// state `k` (variant kept) in every batched function that reads `q`.
#[test]
fn mimic_invalid_configuration_names_the_state() {
    let m = &models()[1];
    let (n, k) = (30, 17);
    let mut s = states(m, n, 4);
    for x in s.q[k].iter_mut().skip(3).take(4) {
        *x *= 2.0;
    }
    let check = |e: Error| {
        assert!(matches!(e, Error::InvalidConfiguration { .. }), "variant kept: {e:?}");
        let msg = e.to_string();
        assert!(msg.contains(&format!("state {k}")), "message names state {k}: {msg}");
    };
    let mut bd = so_batch(m, 2);
    check(batch::rnea_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut vecs(m, n)).unwrap_err());
    check(batch::crba_batch(m, &mut bd, &s.q, &mut mats(m, n)).unwrap_err());
    check(batch::aba_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut vecs(m, n)).unwrap_err());
    check(
        batch::id_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut mats(m, n), &mut mats(m, n))
            .unwrap_err(),
    );
    check(
        batch::fd_derivatives_batch(
            m,
            &mut bd,
            &s.q,
            &s.v,
            &s.tau,
            &mut mats(m, n),
            &mut mats(m, n),
        )
        .unwrap_err(),
    );
    let mut so = vec![IdSoResult::zeros(m); n];
    check(batch::id_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut so).unwrap_err());
    let mut fso = vec![FdSoResult::zeros(m); n];
    check(batch::fd_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut fso).unwrap_err());
}

/// NaN, infinite and wrong-length inputs: the lowest failing state wins, whatever the thread
/// that met it first; a configuration of the full tree's length is an error of its state.
#[test]
fn mimic_first_failing_state_is_reported() {
    let m = &models()[2];
    let n = 50;
    let mut s = states(m, n, 5);
    s.v[31] = DVector::zeros(m.nv() + 1);
    s.a[12][0] = f64::NAN;
    s.a[44][0] = f64::INFINITY;
    s.tau[9][1] = f64::NAN;
    for threads in [1, 2] {
        let mut bd = BatchData::with_pool(m, Arc::new(BatchPool::new(threads).unwrap()));
        for _ in 0..10 {
            let (mut dq, mut dv) = (mats(m, n), mats(m, n));
            let e = batch::id_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut dq, &mut dv)
                .unwrap_err();
            assert!(matches!(e, Error::NotFinite { .. }), "{threads} threads: {e:?}");
            let msg = e.to_string();
            assert!(msg.contains("state 12") && msg.contains('a'), "{threads} threads: {msg}");
            let e = batch::aba_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut vecs(m, n)).unwrap_err();
            assert!(matches!(e, Error::NotFinite { .. }), "{threads} threads: {e:?}");
            let msg = e.to_string();
            assert!(msg.contains("tau") && msg.contains("state 9"), "{threads} threads: {msg}");
        }
    }
    let mut bd = BatchData::with_pool(m, Arc::new(BatchPool::new(2).unwrap()));
    s.a[12][0] = 0.0;
    s.a[44][0] = 0.0;
    let e = batch::rnea_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut vecs(m, n)).unwrap_err();
    assert!(
        matches!(e, Error::Dimension { expected, got, .. } if expected == m.nv() && got == m.nv() + 1),
        "{e:?}"
    );
    assert!(e.to_string().contains("state 31"), "{e}");
    // A configuration of the full tree (mimic joints included) in state 3.
    s.v[31] = DVector::zeros(m.nv());
    s.q[3] = DVector::zeros(m.nq_full());
    let e = batch::crba_batch(m, &mut bd, &s.q, &mut mats(m, n)).unwrap_err();
    assert!(
        matches!(e, Error::Dimension { expected, got, .. } if expected == m.nq() && got == m.nq_full()),
        "{e:?}"
    );
    assert!(e.to_string().contains("state 3"), "{e}");
}

#[test]
fn mimic_inconsistent_lengths_shapes_and_workspaces_are_errors() {
    let ms = models();
    let (m, other) = (&ms[1], &ms[2]);
    let s = states(m, 5, 6);
    // Dense second-order capacity: only the tensor outputs below are wrong.
    let mut bd = so_batch(m, 2);
    let e = batch::rnea_batch(m, &mut bd, &s.q, &s.v[..4], &s.a, &mut vecs(m, 5)).unwrap_err();
    assert!(e.to_string().contains("vs"), "{e}");
    let e = batch::aba_batch(m, &mut bd, &s.q, &s.v, &s.tau[..3], &mut vecs(m, 5)).unwrap_err();
    assert!(e.to_string().contains("taus"), "{e}");
    let mut short = vecs(m, 5);
    short[2] = DVector::zeros(m.nv_full());
    let e = batch::rnea_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut short).unwrap_err();
    assert!(e.to_string().contains("out_tau[2]"), "{e}");
    let e =
        batch::id_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut mats(m, 4), &mut mats(m, 5))
            .unwrap_err();
    assert!(e.to_string().contains("out_dq"), "{e}");
    let mut dv = mats(m, 5);
    dv[3] = DMatrix::zeros(m.nv_full(), m.nv_full());
    let e = batch::fd_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut mats(m, 5), &mut dv)
        .unwrap_err();
    assert!(e.to_string().contains("out_dv[3]"), "{e}");
    let mut mm = mats(m, 5);
    mm[4] = DMatrix::zeros(m.nv(), m.nv() + 1);
    let e = batch::crba_batch(m, &mut bd, &s.q, &mut mm).unwrap_err();
    assert!(e.to_string().contains("out_m[4]"), "{e}");
    // Tensor outputs made for another mimic model (and one for this model among them): the
    // plain batches' dimension check names the output.
    let mut so = vec![IdSoResult::zeros(m); 5];
    so[1] = IdSoResult::zeros(other);
    let mut fso = vec![FdSoResult::zeros(m); 5];
    fso[1] = FdSoResult::zeros(other);
    let e = batch::id_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut so).unwrap_err();
    assert!(matches!(e, Error::Dimension { .. }), "{e:?}");
    assert!(e.to_string().contains("out[1]") && e.to_string().contains("nv = 8"), "{e}");
    let e = batch::fd_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut fso).unwrap_err();
    assert!(e.to_string().contains("out[1]"), "{e}");
    // Workspaces made for another model: an error naming it, the outputs untouched.
    let so_other = states(other, 5, 8);
    let mut out = vec![DVector::from_element(other.nv(), 3.0); 5];
    let e = batch::rnea_batch(other, &mut bd, &so_other.q, &so_other.v, &so_other.a, &mut out)
        .unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
    assert!(e.to_string().contains("Data"), "{e}");
    assert!(out.iter().all(|x| x.iter().all(|&y| y == 3.0)), "outputs untouched");
}

/// A singular reduced mass matrix (two opposite prismatic joints, one mimicking the other:
/// the reduced DoF moves nothing) is the error of its state, in the forward dynamics and its
/// derivatives.
#[test]
fn mimic_batch_reports_a_singular_mass_matrix() {
    let xml = r#"<robot name="t">
  <link name="base"/>
  <link name="a"/>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="ja" type="prismatic"><parent link="base"/><child link="a"/><axis xyz="1 0 0"/></joint>
  <joint name="jb" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="-1 0 0"/><mimic joint="ja"/></joint>
</robot>"#;
    let o = UrdfOptions { floating_base: false, strict_inertia: false, mimic: true };
    let m = sodyn::model::load_urdf_str(xml, "t.urdf", &o).unwrap();
    let s = states(&m, 6, 9);
    let mut bd = so_batch(&m, 2);
    let check = |e: Error| {
        assert!(matches!(e, Error::Singular { .. }), "{e:?}");
        assert!(e.to_string().contains("state 0") && e.to_string().contains("\"ja\""), "{e}");
    };
    check(batch::aba_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut vecs(&m, 6)).unwrap_err());
    check(
        batch::fd_derivatives_batch(
            &m,
            &mut bd,
            &s.q,
            &s.v,
            &s.tau,
            &mut mats(&m, 6),
            &mut mats(&m, 6),
        )
        .unwrap_err(),
    );
    let mut so = vec![FdSoResult::zeros(&m); 6];
    check(batch::fd_so_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut so).unwrap_err());
    // The inverse dynamics is defined there.
    batch::rnea_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut vecs(&m, 6)).unwrap();
}
