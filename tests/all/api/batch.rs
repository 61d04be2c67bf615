//! The batched API (`sodyn::batch`): results identical to the sequential calls, whatever the
//! number of threads; errors name the failing state.

use nalgebra::{DMatrix, DVector};
use sodyn::Error;
use sodyn::algo::{Data, aba, crba, rnea};
use sodyn::batch::*;
use sodyn::deriv::{fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};
use sodyn::model::{Model, builtin};
use sodyn::rng::Rng;
use std::sync::Arc;
use std::time::Duration;

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

fn models() -> Vec<Model> {
    let mut out = vec![
        builtin::quadruped(),
        builtin::humanoid(),
        builtin::random_tree(12, 3, true),
        builtin::random_tree(9, 5, false),
    ];
    out.extend(mimic_models());
    out
}

/// Models in reduced coordinates: the mimic arm fixed and floating (`util::mimic`), and the
/// panda with a finger mimic of multiplier −0.6 and offset 0.02.
fn mimic_models() -> Vec<Model> {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/mimic_panda_coeffs.urdf");
    let panda = sodyn::model::load_urdf_file(&path, &crate::util::mimic::opts(false)).unwrap();
    vec![crate::util::mimic::arm(false), crate::util::mimic::arm(true), panda]
}

/// Batch workspaces with dense second-order capacity on a pool of `threads` threads.
fn so_batch(m: &Model, threads: usize) -> BatchData {
    BatchData::from_workspace(
        Arc::new(BatchPool::new(threads).unwrap()),
        Data::with_second_order(m),
    )
}

fn vecs(m: &Model, n: usize) -> Vec<DVector<f64>> {
    vec![DVector::zeros(m.nv()); n]
}

fn mats(m: &Model, n: usize) -> Vec<DMatrix<f64>> {
    vec![DMatrix::zeros(m.nv(), m.nv()); n]
}

/// Runs every batched function (on `bd`'s pool) and compares with sequential calls.
fn check_identical(m: &Model, s: &States, mut bd: BatchData, label: &str) {
    let n = s.q.len();
    let mut d = Data::new(m);

    let mut tau = vecs(m, n);
    rnea_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut tau).unwrap();
    let mut mm = mats(m, n);
    crba_batch(m, &mut bd, &s.q, &mut mm).unwrap();
    let mut qdd = vecs(m, n);
    aba_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut qdd).unwrap();
    let (mut idq, mut idv) = (mats(m, n), mats(m, n));
    id_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut idq, &mut idv).unwrap();
    let (mut fdq, mut fdv) = (mats(m, n), mats(m, n));
    fd_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut fdq, &mut fdv).unwrap();

    for k in 0..n {
        let at = format!("{label}: model {} state {k}", m.name());
        assert_eq!(tau[k], *rnea(m, &mut d, &s.q[k], &s.v[k], &s.a[k], None).unwrap(), "rnea {at}");
        assert_eq!(mm[k], *crba(m, &mut d, &s.q[k]).unwrap(), "crba {at}");
        assert_eq!(qdd[k], *aba(m, &mut d, &s.q[k], &s.v[k], &s.tau[k], None).unwrap(), "aba {at}");
        id_derivatives(m, &mut d, &s.q[k], &s.v[k], &s.a[k], None).unwrap();
        assert_eq!(&idq[k], d.dtau_dq(), "dtau_dq {at}");
        assert_eq!(&idv[k], d.dtau_dv(), "dtau_dv {at}");
        fd_derivatives(m, &mut d, &s.q[k], &s.v[k], &s.tau[k], None).unwrap();
        assert_eq!(&fdq[k], d.dqdd_dq(), "dqdd_dq {at}");
        assert_eq!(&fdv[k], d.dqdd_dv(), "dqdd_dv {at}");
    }
}

/// Second-order batched functions against sequential calls (small models: nv³ tensors); `bd`
/// made with dense second-order capacity.
fn check_identical_so(m: &Model, s: &States, mut bd: BatchData, label: &str) {
    let n = s.q.len();
    let mut d = Data::with_second_order(m);
    let mut so = vec![IdSoResult::zeros(m); n];
    id_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut so).unwrap();
    let mut fso = vec![FdSoResult::zeros(m); n];
    fd_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut fso).unwrap();
    for k in 0..n {
        let at = format!("{label}: model {} state {k}", m.name());
        let so1 = id_so_derivatives(m, &mut d, &s.q[k], &s.v[k], &s.a[k], None).unwrap();
        assert_eq!(so[k].d2tau_dq2.as_slice(), so1.d2tau_dq2().as_slice(), "d2tau_dq2 {at}");
        assert_eq!(so[k].d2tau_dv2.as_slice(), so1.d2tau_dv2().as_slice(), "d2tau_dv2 {at}");
        assert_eq!(so[k].d2tau_dqdv.as_slice(), so1.d2tau_dqdv().as_slice(), "d2tau_dqdv {at}");
        assert_eq!(so[k].dm_dq.as_slice(), so1.dm_dq().as_slice(), "dM_dq {at}");
        let fso1 = fd_so_derivatives(m, &mut d, &s.q[k], &s.v[k], &s.tau[k], None).unwrap();
        assert_eq!(fso[k].d2qdd_dq2.as_slice(), fso1.d2qdd_dq2().as_slice(), "d2qdd_dq2 {at}");
        assert_eq!(fso[k].d2qdd_dv2.as_slice(), fso1.d2qdd_dv2().as_slice(), "d2qdd_dv2 {at}");
        assert_eq!(fso[k].d2qdd_dqdv.as_slice(), fso1.d2qdd_dqdv().as_slice(), "d2qdd_dqdv {at}");
        assert_eq!(
            fso[k].d2qdd_dtaudq.as_slice(),
            fso1.d2qdd_dtaudq().as_slice(),
            "d2qdd_dtaudq {at}"
        );
    }
}

#[test]
fn batch_equals_sequential_shared_pool() {
    for (i, m) in models().iter().enumerate() {
        check_identical(m, &states(m, 37, 10 + i as u64), BatchData::new(m), "shared pool");
    }
}

/// 1, 2 and 3 threads (3 on a 2-core machine: more threads than cores), with batch sizes
/// below, at and far above the number of threads; spinning helpers (default spin time and
/// none) and rayon helpers.
#[test]
fn batch_equals_sequential_one_two_and_three_threads() {
    type MakePool = fn(usize) -> sodyn::Result<BatchPool>;
    let kinds: [(&str, MakePool); 3] = [
        ("spinning", BatchPool::new),
        ("no spin", |t| BatchPool::with_spin(t, Duration::ZERO)),
        ("rayon", BatchPool::with_rayon),
    ];
    for (threads, (kind, make)) in [1, 2, 3].into_iter().flat_map(|t| kinds.map(|k| (t, k))) {
        let pool = Arc::new(make(threads).unwrap());
        assert_eq!(pool.threads(), threads, "{kind}");
        for (i, m) in models().iter().enumerate() {
            for n in [1, 2, 3, 23, 301] {
                let s = states(m, n, 20 + i as u64);
                let bd = BatchData::with_pool(m, pool.clone());
                assert_eq!(bd.threads(), threads);
                check_identical(m, &s, bd, &format!("{kind}: {threads} threads, {n} states"));
            }
        }
    }
}

#[test]
fn batch_second_order_equals_sequential() {
    let pool = Arc::new(BatchPool::new(2).unwrap());
    let plain = [builtin::quadruped(), builtin::random_tree(8, 7, true)];
    for m in plain.into_iter().chain(mimic_models()) {
        let s = states(&m, 9, 30);
        check_identical_so(&m, &s, BatchData::with_second_order(&m), "shared pool");
        let bd = BatchData::from_workspace(pool.clone(), Data::with_second_order(&m));
        check_identical_so(&m, &s, bd, "2 threads");
    }
}

#[test]
fn empty_batch_is_ok() {
    let m = builtin::quadruped();
    let mut bd = BatchData::new(&m);
    let mut out: Vec<DVector<f64>> = vec![];
    rnea_batch(&m, &mut bd, &[], &[], &[], &mut out).unwrap();
    let (mut a, mut b): (Vec<DMatrix<f64>>, Vec<DMatrix<f64>>) = (vec![], vec![]);
    id_derivatives_batch(&m, &mut bd, &[], &[], &[], &mut a, &mut b).unwrap();
}

/// The quadruped has a free-flyer root: a non-unit quaternion in state `k` must be reported
/// as an error of state `k`.
#[test]
fn invalid_configuration_names_the_state() {
    let m = builtin::quadruped();
    let n = 40;
    let k = 29;
    let mut s = states(&m, n, 4);
    for x in s.q[k].iter_mut().skip(3).take(4) {
        *x *= 2.0;
    }
    let check = |e: Error| {
        assert!(matches!(e, Error::InvalidConfiguration { .. }), "variant kept: {e:?}");
        let msg = e.to_string();
        assert!(msg.contains(&format!("state {k}")), "message names state {k}: {msg}");
    };
    // Dense second-order capacity, for id_so_derivatives_batch below.
    let pool = Arc::new(BatchPool::new(2).unwrap());
    let mut bd = BatchData::from_workspace(pool, Data::with_second_order(&m));
    check(
        id_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut mats(&m, n), &mut mats(&m, n))
            .unwrap_err(),
    );
    check(
        fd_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut mats(&m, n), &mut mats(&m, n))
            .unwrap_err(),
    );
    check(rnea_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut vecs(&m, n)).unwrap_err());
    check(aba_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut vecs(&m, n)).unwrap_err());
    check(crba_batch(&m, &mut bd, &s.q, &mut mats(&m, n)).unwrap_err());
    check(
        id_so_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut vec![IdSoResult::zeros(&m); n])
            .unwrap_err(),
    );
}

#[test]
fn first_failing_state_is_reported() {
    let m = builtin::random_tree(10, 2, false);
    let n = 50;
    let mut s = states(&m, n, 5);
    // A wrong-length velocity in state 31 and a non-finite acceleration in state 12 (and 44):
    // the lowest index wins, whatever the thread that met it first.
    s.v[31] = DVector::zeros(m.nv() + 1);
    s.a[12][0] = f64::NAN;
    s.a[44][0] = f64::INFINITY;
    // Repeated, as the threads race for the states.
    for threads in [1, 2, 3] {
        let mut bd = BatchData::with_pool(&m, Arc::new(BatchPool::new(threads).unwrap()));
        for _ in 0..20 {
            let (mut dq, mut dv) = (mats(&m, n), mats(&m, n));
            let e =
                id_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut dq, &mut dv).unwrap_err();
            assert!(matches!(e, Error::NotFinite { .. }), "{threads} threads: {e:?}");
            assert!(e.to_string().contains("state 12"), "{threads} threads: {e}");
        }
    }
    // A failure late in a long batch, after states that all succeed.
    let mut long = states(&m, 2000, 8);
    long.a[1999][3] = f64::NAN;
    long.a[1703][2] = f64::NAN;
    let mut bd = BatchData::with_pool(&m, Arc::new(BatchPool::new(2).unwrap()));
    for _ in 0..5 {
        let e =
            rnea_batch(&m, &mut bd, &long.q, &long.v, &long.a, &mut vecs(&m, 2000)).unwrap_err();
        assert!(e.to_string().contains("state 1703"), "{e}");
    }
    s.a[12][0] = 0.0;
    s.a[44][0] = 0.0;
    let e = rnea_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut vecs(&m, n)).unwrap_err();
    assert!(
        matches!(e, Error::Dimension { expected, got, .. } if expected == m.nv() && got == m.nv() + 1)
    );
    assert!(e.to_string().contains("state 31"), "{e}");
}

#[test]
fn inconsistent_lengths_and_shapes_are_errors() {
    let m = builtin::quadruped();
    let s = states(&m, 5, 6);
    // Dense second-order capacity: only the tensor outputs below are wrong.
    let mut bd = BatchData::with_second_order(&m);
    // One velocity too few.
    let e = rnea_batch(&m, &mut bd, &s.q, &s.v[..4], &s.a, &mut vecs(&m, 5)).unwrap_err();
    assert!(e.to_string().contains("vs"), "{e}");
    // One output too few.
    let e = id_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut mats(&m, 4), &mut mats(&m, 5))
        .unwrap_err();
    assert!(e.to_string().contains("out_dq"), "{e}");
    // A wrongly sized output matrix.
    let mut dv = mats(&m, 5);
    dv[3] = DMatrix::zeros(m.nv(), m.nv() - 1);
    let e =
        id_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut mats(&m, 5), &mut dv).unwrap_err();
    assert!(e.to_string().contains("out_dv[3]"), "{e}");
    // Tensor workspaces made for another model.
    let other = builtin::humanoid();
    let mut wrong = vec![IdSoResult::zeros(&other); 5];
    let e = id_so_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut wrong).unwrap_err();
    assert!(e.to_string().contains("out[0]"), "{e}");
    assert!(BatchPool::new(0).is_err());
}

/// One `BatchData` serves many calls with results bit for bit those of the sequential calls;
/// a `BatchData` made for another model is an error that names it, and leaves the outputs
/// untouched.
#[test]
fn batch_data_is_reused_and_checked() {
    let m = builtin::humanoid();
    let mut bd = BatchData::with_pool(&m, Arc::new(BatchPool::new(2).unwrap()));
    let mut d = Data::new(&m);
    for seed in 0..3 {
        let s = states(&m, 24, 40 + seed);
        let (mut dq, mut dv) = (mats(&m, 24), mats(&m, 24));
        fd_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut dq, &mut dv).unwrap();
        for k in 0..24 {
            fd_derivatives(&m, &mut d, &s.q[k], &s.v[k], &s.tau[k], None).unwrap();
            assert_eq!(&dq[k], d.dqdd_dq(), "seed {seed} state {k}");
            assert_eq!(&dv[k], d.dqdd_dv(), "seed {seed} state {k}");
        }
    }
    let other = builtin::quadruped();
    let s = states(&other, 6, 7);
    let mut out = vec![DVector::from_element(other.nv(), 3.0); 6];
    let e = rnea_batch(&other, &mut bd, &s.q, &s.v, &s.a, &mut out).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
    assert!(e.to_string().contains("model \"quadruped\" has 14"), "{e}");
    assert!(out.iter().all(|x| x.iter().all(|&y| y == 3.0)), "outputs untouched");
}

/// Clones of a `BatchData` share its pool; two of them used at once from two threads give the
/// sequential results.
#[test]
fn clones_share_the_pool_from_several_threads() {
    let m = builtin::humanoid();
    let bd = BatchData::with_pool(&m, Arc::new(BatchPool::new(2).unwrap()));
    let (s1, s2) = (states(&m, 150, 50), states(&m, 150, 51));
    let run = |mut bd: BatchData, s: &States| {
        let mut tau = vecs(&m, 150);
        for _ in 0..20 {
            rnea_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut tau).unwrap();
        }
        tau
    };
    let (t1, t2) = std::thread::scope(|sc| {
        let (b1, b2) = (bd.clone(), bd.clone());
        let h1 = sc.spawn(|| run(b1, &s1));
        let h2 = sc.spawn(|| run(b2, &s2));
        (h1.join().unwrap(), h2.join().unwrap())
    });
    assert!(Arc::ptr_eq(bd.pool(), bd.clone().pool()));
    let mut d = Data::new(&m);
    for k in 0..150 {
        assert_eq!(t1[k], *rnea(&m, &mut d, &s1.q[k], &s1.v[k], &s1.a[k], None).unwrap());
        assert_eq!(t2[k], *rnea(&m, &mut d, &s2.q[k], &s2.v[k], &s2.a[k], None).unwrap());
    }
}

/// `map_states` batches the contact dynamics (KKT and impact, first and second order) on
/// per-thread `(Data, ContactData)` workspaces: bit for bit the sequential
/// results on 1, 2 and 3 threads, and the first failing state named.
#[test]
fn map_states_batches_the_contact_dynamics() {
    use nalgebra::Vector3;
    use sodyn::algo::Contact;
    use sodyn::deriv::{
        ContactData, impact_derivatives, impact_so_derivatives, kkt_derivatives, kkt_so_derivatives,
    };
    let m = builtin::quadruped();
    let feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
    let contacts: Vec<Contact> =
        feet.iter().map(|f| Contact::new(&m, f, Vector3::new(0.01, 0.0, -0.02)).unwrap()).collect();
    let cd = ContactData::with_second_order(&m, &contacts).unwrap();
    let n = 29;
    let mut s = states(&m, n, 60);
    let (mut d, mut cd1) = (Data::new(&m), cd.clone());
    for threads in [1, 2, 3] {
        let pool = Arc::new(BatchPool::new(threads).unwrap());
        let mut bk = BatchData::from_workspace(pool.clone(), (Data::new(&m), cd.clone()));
        let mut bi = BatchData::from_workspace(pool, (Data::new(&m), cd.clone()));
        assert_eq!(bk.threads(), threads);
        let mut kout = vec![(DMatrix::zeros(0, 0), DMatrix::zeros(0, 0), vec![]); n];
        map_states(&mut bk, &mut kout, |(d, cd), k, o| {
            kkt_derivatives(&m, d, cd, &s.q[k], &s.v[k], &s.tau[k])?;
            let kd = kkt_so_derivatives(&m, d, cd, &s.q[k], &s.v[k], &s.tau[k])?;
            *o = (
                kd.dqdd_dq().clone(),
                kd.dlambda_dq().clone(),
                kd.so().unwrap().d2qdd_dq2().as_slice().to_vec(),
            );
            Ok(())
        })
        .unwrap();
        let mut iout = vec![(DMatrix::zeros(0, 0), DMatrix::zeros(0, 0), vec![]); n];
        map_states(&mut bi, &mut iout, |(d, cd), k, o| {
            impact_derivatives(&m, d, cd, &s.q[k], &s.v[k])?;
            let im = impact_so_derivatives(&m, d, cd, &s.q[k], &s.v[k])?;
            *o = (
                im.dvplus_dq().clone(),
                im.dimpulse_dq().clone(),
                im.so().unwrap().d2vplus_dq2().as_slice().to_vec(),
            );
            Ok(())
        })
        .unwrap();
        for k in 0..n {
            kkt_derivatives(&m, &mut d, &mut cd1, &s.q[k], &s.v[k], &s.tau[k]).unwrap();
            let kd1 =
                kkt_so_derivatives(&m, &mut d, &mut cd1, &s.q[k], &s.v[k], &s.tau[k]).unwrap();
            assert_eq!(&kout[k].0, kd1.dqdd_dq(), "{threads} threads, state {k}");
            assert_eq!(&kout[k].1, kd1.dlambda_dq(), "{threads} threads, state {k}");
            assert_eq!(kout[k].2, kd1.so().unwrap().d2qdd_dq2().as_slice(), "state {k}");
            impact_derivatives(&m, &mut d, &mut cd1, &s.q[k], &s.v[k]).unwrap();
            let im1 = impact_so_derivatives(&m, &mut d, &mut cd1, &s.q[k], &s.v[k]).unwrap();
            assert_eq!(&iout[k].0, im1.dvplus_dq(), "{threads} threads, state {k}");
            assert_eq!(&iout[k].1, im1.dimpulse_dq(), "{threads} threads, state {k}");
            assert_eq!(iout[k].2, im1.so().unwrap().d2vplus_dq2().as_slice(), "state {k}");
        }
    }
    // A non-finite torque in state 17: the error names it.
    s.tau[17][2] = f64::NAN;
    let mut bk = BatchData::from_workspace(Arc::new(BatchPool::new(2).unwrap()), (d, cd));
    let e = map_states(&mut bk, &mut vec![(); n], |(d, cd), k, _| {
        kkt_derivatives(&m, d, cd, &s.q[k], &s.v[k], &s.tau[k]).map(|_| ())
    })
    .unwrap_err();
    assert!(matches!(e, Error::NotFinite { .. }), "{e:?}");
    assert!(e.to_string().contains("state 17"), "{e}");
}

/// A panic of the per-state closure reaches the caller, whether the caller's own thread, a
/// helper thread or both panicked, and the pool keeps working afterwards, with no panic left
/// over for the next call (both kinds of helpers).
#[test]
fn a_panic_reaches_the_caller_and_the_pool_survives() {
    for pool in [BatchPool::new(2).unwrap(), BatchPool::with_rayon(2).unwrap()] {
        let mut bd = BatchData::from_workspace(Arc::new(pool), 0usize);
        // Which threads panic: helpers only, the caller only, all.
        let cases = [(0, Some(true)), (1, Some(false)), (2, None), (3, Some(true)), (4, None)];
        for (round, panics_on_helper) in cases {
            let mut out = vec![0usize; 400];
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                map_states(&mut bd, &mut out, |_, k, o| {
                    // 20 ms or more in all: the helper joins long before the states run out.
                    std::thread::sleep(Duration::from_micros(50));
                    let name = std::thread::current().name().map(str::to_owned);
                    let helper = name.is_some_and(|n| n.starts_with("sodyn-batch"));
                    let panics = panics_on_helper.is_none_or(|h| h == helper);
                    assert!(!panics, "round {round}: state {k} panics");
                    *o = k;
                    Ok(())
                })
            }));
            let msg = r.expect_err("the panic is resumed on the caller");
            let msg = msg.downcast_ref::<String>().expect("a formatted panic message");
            assert!(msg.contains(&format!("round {round}: state")), "{msg}");
            map_states(&mut bd, &mut out, |_, k, o| {
                *o = 2 * k;
                Ok(())
            })
            .unwrap();
            assert!(out.iter().enumerate().all(|(k, &o)| o == 2 * k));
        }
    }
}

/// A batched call made from inside a batched call on the same pool runs on its caller alone
/// (no deadlock) and gives the same results.
#[test]
fn nested_batched_calls_on_one_pool() {
    let pool = Arc::new(BatchPool::new(2).unwrap());
    let mut outer = BatchData::from_workspace(pool.clone(), BatchData::from_workspace(pool, 0u8));
    let mut out = vec![0usize; 12];
    map_states(&mut outer, &mut out, |inner, k, o| {
        let mut v = vec![0usize; 5];
        map_states(inner, &mut v, |_, j, x| {
            *x = k * 10 + j;
            Ok(())
        })?;
        *o = v.iter().sum();
        Ok(())
    })
    .unwrap();
    assert!(out.iter().enumerate().all(|(k, &o)| o == 50 * k + 10), "{out:?}");
}

/// Per-thread workspaces are reachable: every state is counted once over the threads.
#[test]
fn per_thread_workspaces_count_every_state_once() {
    let mut bd = BatchData::from_workspace(Arc::new(BatchPool::new(2).unwrap()), 0usize);
    assert_eq!(bd.workspaces().len(), 2);
    let mut out = vec![(); 400];
    map_states(&mut bd, &mut out, |count, _, _| {
        std::thread::sleep(Duration::from_micros(20));
        *count += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(bd.workspaces().iter().sum::<usize>(), 400);
    bd.workspaces_mut().fill(0);
    assert_eq!(bd.workspaces(), &[0, 0]);
}

/// `BatchPool::with_cpus`: each helper computes its states on its own CPU, the results are bit
/// for bit those of the sequential calls, and a CPU that cannot be used is an error naming it.
#[cfg(target_os = "linux")]
#[test]
fn pinned_pool_runs_each_helper_on_its_cpu() {
    // The CPUs this process may run on.
    // SAFETY: a zeroed cpu_set_t is a valid empty set; pid 0 is the calling thread.
    let allowed: Vec<usize> = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        assert_eq!(libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set), 0);
        (0..libc::CPU_SETSIZE as usize).filter(|&c| libc::CPU_ISSET(c, &set)).collect()
    };
    // Out of the CPU set's range, and (if any) a CPU this process may not use.
    let not_allowed = (0..libc::CPU_SETSIZE as usize).find(|c| !allowed.contains(c));
    for bad in std::iter::once(5000).chain(not_allowed) {
        let err = BatchPool::with_cpus(&[allowed[0], bad], BatchPool::DEFAULT_SPIN).unwrap_err();
        assert!(err.to_string().contains(&format!("CPU {bad}")), "{err}");
    }
    assert!(BatchPool::with_cpus(&[], BatchPool::DEFAULT_SPIN).is_err());
    let cpus: Vec<usize> = allowed.iter().copied().take(3).collect();
    check_pinned(cpus.clone());
    // The helper pinned to the caller's CPU: an unpinned helper would mostly run on another.
    if allowed.len() >= 2 {
        check_pinned(vec![allowed[1], allowed[1]]);
    }
}

/// Pins a new thread to `cpus[0]`, runs batched calls from it on `BatchPool::with_cpus(cpus)`
/// and checks where the states ran.
#[cfg(target_os = "linux")]
fn check_pinned(cpus: Vec<usize>) {
    // Runs on a thread of its own: the test harness's thread keeps its CPU set.
    std::thread::spawn(move || {
        pin_current_thread(cpus[0]).unwrap();
        let pool = Arc::new(BatchPool::with_cpus(&cpus, Duration::ZERO).unwrap());
        assert_eq!(pool.threads(), cpus.len());
        let m = builtin::quadruped();
        let s = states(&m, 40, 11);
        check_identical(&m, &s, BatchData::with_pool(&m, pool.clone()), "pinned pool");
        let caller = std::thread::current().id();
        let mut bd = BatchData::from_workspace(pool, ());
        // Per state: computed by the caller, and on which CPU.
        let mut out = vec![(false, usize::MAX); 400];
        let mut by_helpers = 0;
        for _ in 0..20 {
            map_states(&mut bd, &mut out, |_, _, o| {
                // Some work per state, so that the helpers join.
                let mut x = 1.0f64;
                for i in 0..2000 {
                    x = std::hint::black_box(x * 1.000001 + i as f64 * 1e-9);
                }
                // SAFETY: sched_getcpu has no preconditions.
                let cpu = unsafe { libc::sched_getcpu() };
                *o = (std::thread::current().id() == caller, usize::try_from(cpu).unwrap());
                Ok(())
            })
            .unwrap();
            for &(by_caller, cpu) in &out {
                if by_caller {
                    assert_eq!(cpu, cpus[0]);
                } else {
                    assert!(cpus[1..].contains(&cpu), "a helper ran on CPU {cpu}, not {cpus:?}");
                    by_helpers += 1;
                }
            }
        }
        // The helpers took part (the states take milliseconds per call, waking takes less).
        assert!(cpus.len() == 1 || by_helpers > 0, "no state ran on a helper");
    })
    .join()
    .unwrap();
}

#[test]
fn reduced_models_lengths_shapes_and_workspaces_are_errors() {
    let ms = mimic_models();
    let (m, other) = (&ms[1], &ms[2]);
    let s = states(m, 5, 6);
    // Dense second-order capacity: only the tensor outputs below are wrong.
    let mut bd = so_batch(m, 2);
    let e = rnea_batch(m, &mut bd, &s.q, &s.v[..4], &s.a, &mut vecs(m, 5)).unwrap_err();
    assert!(e.to_string().contains("vs"), "{e}");
    let e = aba_batch(m, &mut bd, &s.q, &s.v, &s.tau[..3], &mut vecs(m, 5)).unwrap_err();
    assert!(e.to_string().contains("taus"), "{e}");
    let mut short = vecs(m, 5);
    short[2] = DVector::zeros(m.nv_full());
    let e = rnea_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut short).unwrap_err();
    assert!(e.to_string().contains("out_tau[2]"), "{e}");
    let e = id_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut mats(m, 4), &mut mats(m, 5))
        .unwrap_err();
    assert!(e.to_string().contains("out_dq"), "{e}");
    let mut dv = mats(m, 5);
    dv[3] = DMatrix::zeros(m.nv_full(), m.nv_full());
    let e =
        fd_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut mats(m, 5), &mut dv).unwrap_err();
    assert!(e.to_string().contains("out_dv[3]"), "{e}");
    let mut mm = mats(m, 5);
    mm[4] = DMatrix::zeros(m.nv(), m.nv() + 1);
    let e = crba_batch(m, &mut bd, &s.q, &mut mm).unwrap_err();
    assert!(e.to_string().contains("out_m[4]"), "{e}");
    // Tensor outputs made for another mimic model (and one for this model among them): the
    // plain batches' dimension check names the output.
    let mut so = vec![IdSoResult::zeros(m); 5];
    so[1] = IdSoResult::zeros(other);
    let mut fso = vec![FdSoResult::zeros(m); 5];
    fso[1] = FdSoResult::zeros(other);
    let e = id_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.a, &mut so).unwrap_err();
    assert!(matches!(e, Error::Dimension { .. }), "{e:?}");
    assert!(e.to_string().contains("out[1]") && e.to_string().contains("nv = 8"), "{e}");
    let e = fd_so_derivatives_batch(m, &mut bd, &s.q, &s.v, &s.tau, &mut fso).unwrap_err();
    assert!(e.to_string().contains("out[1]"), "{e}");
    // Workspaces made for another model: an error naming it, the outputs untouched.
    let so_other = states(other, 5, 8);
    let mut out = vec![DVector::from_element(other.nv(), 3.0); 5];
    let e =
        rnea_batch(other, &mut bd, &so_other.q, &so_other.v, &so_other.a, &mut out).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
    assert!(e.to_string().contains("Data"), "{e}");
    assert!(out.iter().all(|x| x.iter().all(|&y| y == 3.0)), "outputs untouched");
}

/// A singular reduced mass matrix (two opposite prismatic joints, one mimicking the other:
/// the reduced DoF moves nothing) is the error of its state, in the forward dynamics and its
/// derivatives.
#[test]
fn a_singular_reduced_mass_matrix_names_the_state() {
    let m = crate::util::mimic::cancelling_pair();
    let s = states(&m, 6, 9);
    let mut bd = so_batch(&m, 2);
    let check = |e: Error| {
        assert!(matches!(e, Error::Singular { .. }), "{e:?}");
        assert!(e.to_string().contains("state 0") && e.to_string().contains("\"ja\""), "{e}");
    };
    check(aba_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut vecs(&m, 6)).unwrap_err());
    check(
        fd_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut mats(&m, 6), &mut mats(&m, 6))
            .unwrap_err(),
    );
    let mut so = vec![FdSoResult::zeros(&m); 6];
    check(fd_so_derivatives_batch(&m, &mut bd, &s.q, &s.v, &s.tau, &mut so).unwrap_err());
    // The inverse dynamics is defined there.
    rnea_batch(&m, &mut bd, &s.q, &s.v, &s.a, &mut vecs(&m, 6)).unwrap();
}

/// The batch API goes through the same algorithms.
#[test]
fn batch_has_armature() {
    use crate::util::{random_state, with_random_armature};
    let m = with_random_armature(&builtin::humanoid(), 9, true);
    let mut rng = Rng::new(2);
    let states: Vec<_> = (0..5).map(|_| random_state(&m, &mut rng)).collect();
    let qs: Vec<_> = states.iter().map(|s| s.0.clone()).collect();
    let vs: Vec<_> = states.iter().map(|s| s.1.clone()).collect();
    let ts: Vec<_> = states.iter().map(|s| s.2.clone()).collect();
    let mut bd = BatchData::new(&m);
    let mut ms = vec![DMatrix::zeros(m.nv(), m.nv()); 5];
    let mut qdds = vec![DVector::zeros(m.nv()); 5];
    crba_batch(&m, &mut bd, &qs, &mut ms).unwrap();
    aba_batch(&m, &mut bd, &qs, &vs, &ts, &mut qdds).unwrap();
    let mut d = Data::new(&m);
    for k in 0..5 {
        assert_eq!(&ms[k], crba(&m, &mut d, &qs[k]).unwrap());
        assert_eq!(&qdds[k], aba(&m, &mut d, &qs[k], &vs[k], &ts[k], None).unwrap());
    }
}
