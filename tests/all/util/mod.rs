//! Shared helpers for the oracle tests.
#![allow(dead_code)]

pub mod mimic;

use ContactReference::{Local, LocalWorldAligned as Lwa};
use ContactType::{D3, D6};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use num_dual::{Dual64 as D, HyperHyperDual64 as H};
use sodyn::algo::{Contact, ContactReference, ContactType};
use sodyn::model::{Model, builtin, exp6};
use sodyn::reference::kinematics::forward_kinematics;
use sodyn::rng::Rng;
use sodyn::spatial::Motion;
use sodyn::tensor::Tensor3;

/// Relative error `max|a − b| / max(1, max|b|)`.
pub fn rel_err_mat(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}

/// Relative error of vectors.
pub fn rel_err_vec(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    assert_eq!(a.len(), b.len());
    (a - b).amax() / b.amax().max(1.0)
}

/// Relative error of tensors.
pub fn rel_err_tensor(a: &Tensor3, b: &Tensor3) -> f64 {
    assert_eq!(a.dims(), b.dims());
    a.max_abs_diff(b) / b.max_abs().max(1.0)
}

/// A random state (q, v, a-or-tau) for `model`.
pub fn random_state(model: &Model, rng: &mut Rng) -> (DVector<f64>, DVector<f64>, DVector<f64>) {
    let q = model.random_configuration(rng);
    let v = DVector::from_fn(model.nv(), |_, _| rng.range(-1.0, 1.0));
    let a = DVector::from_fn(model.nv(), |_, _| rng.range(-1.0, 1.0));
    (q, v, a)
}

/// Test models: chains, the built-in robots and random trees mixing every joint type, fixed and
/// floating base, with and without armature, and the models in reduced coordinates
/// (`mimic::models`: the mimic arm fixed, floating, fixed with an armature, and the MJCF model
/// with tendon couplings), up to `max_dof` degrees of freedom.
pub fn test_models(max_dof: usize) -> Vec<Model> {
    let mut out = vec![builtin::serial_chain(1), builtin::serial_chain(7), builtin::pendulum(2)];
    out.push(builtin::quadruped());
    out.push(builtin::humanoid());
    out.push(with_random_armature(&builtin::quadruped(), 1, true));
    for seed in 0..6u64 {
        for &n in &[3usize, 8, 15, 24, 35] {
            for &ff in &[false, true] {
                let m = builtin::random_tree(n, seed * 31 + n as u64, ff);
                // Half of the random trees with an armature (seeds 1, 3, 5), on the free
                // flyer's DoFs too for seed 3.
                let m = if seed % 2 == 1 {
                    with_random_armature(&m, seed + n as u64, seed == 3)
                } else {
                    m
                };
                out.push(m);
            }
        }
    }
    out.extend(mimic::models());
    out.retain(|m| m.nv() <= max_dof);
    out
}

/// Every `k`-th model of `models`, and every model in reduced coordinates among the others (so
/// that each family test sees the mimic models however it samples).
pub fn every(models: Vec<Model>, k: usize) -> Vec<Model> {
    models
        .into_iter()
        .enumerate()
        .filter(|(i, m)| i % k == 0 || m.is_reduced())
        .map(|(_, m)| m)
        .collect()
}

/// `m` with a random armature in `[0, 0.5)` on each DoF (except a root free flyer's six unless
/// `root`), about one DoF in five left at zero.
pub fn with_random_armature(m: &Model, seed: u64, root: bool) -> Model {
    let mut rng = Rng::new(1000 + seed);
    let ff = matches!(m.joints().get(1), Some(sodyn::model::JointType::FreeFlyer));
    let a: Vec<f64> = (0..m.nv())
        .map(|k| {
            let x = rng.range(0.0, 0.5);
            let y = rng.range(0.0, 1.0);
            if (ff && k < 6 && !root) || y < 0.2 { 0.0 } else { x }
        })
        .collect();
    m.with_armature(&a).unwrap()
}

/// Tracks and reports the worst relative error of a quantity.
pub struct Worst {
    pub name: &'static str,
    pub err: f64,
    pub at: String,
}

impl Worst {
    pub fn new(name: &'static str) -> Self {
        Self { name, err: 0.0, at: String::new() }
    }
    pub fn add(&mut self, err: f64, at: &str) {
        assert!(err.is_finite(), "{}: non-finite error at {at}", self.name);
        if err > self.err {
            self.err = err;
            self.at = at.to_string();
        }
    }
    /// Prints and asserts the worst error is at most `tol`.
    pub fn check(&self, tol: f64) {
        eprintln!(
            "{:<28} max rel err {:.3e} (at {}), tolerance {:e}",
            self.name, self.err, self.at, tol
        );
        assert!(
            self.err <= tol,
            "{}: max rel err {:e} > {:e} at {}",
            self.name,
            self.err,
            tol,
            self.at
        );
    }
}

/// A contact of a test case: its frame, type and reference.
pub type ContactSpec = (&'static str, ContactType, ContactReference);

/// The (model, contacts) cases of the contact-family tests (KKT, impact and constrained inverse
/// dynamics, dense and contracted): 3-D and 6-D contacts, world-aligned and local, alone and
/// mixed; models with and without armature; and the mimic arm in reduced coordinates
/// (`util::mimic::ff_models`: floating, without and with an armature), its contacts below mimic
/// joints.
pub fn contact_cases() -> Vec<(Model, Vec<ContactSpec>)> {
    let arms = mimic::ff_models();
    vec![
        (
            builtin::quadruped(),
            vec![
                ("LF_FOOT", D3, Lwa),
                ("RF_FOOT", D3, Lwa),
                ("LH_FOOT", D3, Lwa),
                ("RH_FOOT", D3, Lwa),
            ],
        ),
        (
            with_random_armature(&builtin::quadruped(), 2, true),
            vec![("LF_FOOT", D3, Lwa), ("RH_FOOT", D3, Lwa)],
        ),
        (builtin::serial_chain(6), vec![("ee", D3, Lwa)]),
        (
            with_random_armature(&builtin::random_tree(8, 3, true), 3, false),
            vec![("body_5", D3, Lwa), ("body_7", D3, Lwa), ("body_2", D3, Lwa)],
        ),
        (builtin::random_tree(10, 21, false), vec![("body_9", D3, Lwa), ("body_4", D3, Lwa)]),
        (
            builtin::quadruped(),
            vec![("LF_FOOT", D3, Local), ("RF_FOOT", D3, Lwa), ("RH_FOOT", D3, Local)],
        ),
        (
            builtin::quadruped(),
            vec![("LF_FOOT", D6, Lwa), ("RF_FOOT", D3, Local), ("RH_FOOT", D3, Local)],
        ),
        (
            with_random_armature(&builtin::quadruped(), 4, true),
            vec![("RH_FOOT", D6, Local), ("LF_FOOT", D3, Lwa)],
        ),
        (with_random_armature(&builtin::serial_chain(9), 5, false), vec![("ee", D6, Lwa)]),
        (builtin::serial_chain(8), vec![("ee", D6, Local)]),
        (builtin::random_tree(8, 3, true), vec![("body_5", D6, Local), ("body_2", D3, Local)]),
        (
            with_random_armature(&builtin::random_tree(10, 21, false), 6, false),
            vec![("body_9", D3, Local), ("body_4", D3, Lwa)],
        ),
        // The floating mimic arm (`util::mimic::ff_models`): the tool below the joint that
        // mimics the shoulder, the thumb tip below the mimic thumb base.
        (arms[0].clone(), vec![("tool", D3, Lwa), ("thumb_tip", D6, Local)]),
        (arms[1].clone(), vec![("tool", D3, Local), ("thumb_tip", D6, Lwa)]),
    ]
}

/// A constraint of a test case that may close a loop: frame A, frame B (`None`: the world),
/// type, reference.
pub type LoopSpec = (&'static str, Option<&'static str>, ContactType, ContactReference);

/// The two-frame (closed-loop) cases of the contact-family tests: the four-bar (3-D, both
/// references), the delta's three loops, 3-D loops between the quadruped's feet mixed with
/// 3-D and 6-D world contacts, 6-D loops along a serial chain (both references), the
/// humanoid's hands welded together (6-D, both references) standing on both soles or with its
/// feet joined by a 3-D loop, and a random tree with a local 3-D loop and a 6-D world contact.
/// (A 6-D weld between two of the quadruped's 3-DoF feet holds six rows with six DoFs and is
/// ill-conditioned: the oracle and the first order then differ by 1e-10.)
pub fn loop_cases() -> Vec<(Model, Vec<LoopSpec>)> {
    vec![
        (builtin::fourbar(), vec![("coupler_tip", Some("rocker_tip"), D3, Lwa)]),
        (builtin::fourbar(), vec![("coupler_tip", Some("rocker_tip"), D3, Local)]),
        (
            builtin::delta(),
            vec![
                ("forearm_tip_1", Some("platform_1"), D3, Lwa),
                ("forearm_tip_2", Some("platform_2"), D3, Local),
                ("forearm_tip_3", Some("platform_3"), D3, Lwa),
            ],
        ),
        (
            builtin::quadruped(),
            vec![
                ("LF_FOOT", Some("RH_FOOT"), D3, Lwa),
                ("RF_FOOT", None, D3, Lwa),
                ("LH_FOOT", None, D3, Local),
            ],
        ),
        (
            with_random_armature(&builtin::quadruped(), 7, true),
            vec![("LF_FOOT", Some("RF_FOOT"), D3, Local), ("RH_FOOT", None, D6, Lwa)],
        ),
        (builtin::serial_chain(10), vec![("ee", Some("link_2"), D6, Local)]),
        (
            with_random_armature(&builtin::serial_chain(10), 8, false),
            vec![("ee", Some("link_3"), D6, Lwa)],
        ),
        (
            builtin::humanoid(),
            vec![
                ("left_hand", Some("right_hand"), D6, Local),
                ("left_sole", None, D6, Lwa),
                ("right_sole", None, D6, Local),
            ],
        ),
        (
            builtin::humanoid(),
            vec![
                ("right_hand", Some("left_hand"), D6, Lwa),
                ("left_sole", Some("right_sole"), D3, Local),
            ],
        ),
        (
            builtin::random_tree(10, 4, true),
            vec![("body_9", Some("body_5"), D3, Local), ("body_7", None, D6, Lwa)],
        ),
    ]
}

/// World contacts as [`LoopSpec`]s.
pub fn as_loop_spec(spec: &[ContactSpec]) -> Vec<LoopSpec> {
    spec.iter().map(|&(f, kind, reference)| (f, None, kind, reference)).collect()
}

/// [`contact_cases`] (world contacts, as [`LoopSpec`]s) followed by [`loop_cases`].
pub fn family_cases() -> Vec<(Model, Vec<LoopSpec>)> {
    let world = contact_cases().into_iter().map(|(m, spec)| (m, as_loop_spec(&spec)));
    world.chain(loop_cases()).collect()
}

/// The constraints of `spec` on `m`: as [`contacts_of`] (the same random draws for a world
/// contact), and for a loop frame B's contact frame placed at random within about 5 cm and a
/// random rotation of its link frame too.
pub fn constraints_of(m: &Model, spec: &[LoopSpec], rng: &mut Rng) -> Vec<Contact> {
    spec.iter()
        .map(|&(a, b, kind, reference)| {
            let c = contacts_of(m, &[(a, kind, reference)], rng).remove(0);
            match b {
                Some(b) => c.with_frame2(m, b, Some(&random_placement(rng))).unwrap(),
                None => c,
            }
        })
        .collect()
}

/// A placement within about 5 cm of the identity, with a random rotation.
pub fn random_placement(rng: &mut Rng) -> sodyn::spatial::Transform {
    exp6(&Motion::new(
        Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.7,
        Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05,
    ))
}

/// A case with nv ≥ 32, where the KKT and impact second order take their symmetric products
/// (`kkt::SYM_MIN_NV`); its hyper-dual oracle takes seconds, so only those tests run it.
pub fn large_contact_case() -> (Model, Vec<ContactSpec>) {
    (builtin::random_tree(28, 5, true), vec![("body_27", D6, Lwa), ("body_20", D3, Local)])
}

/// The contacts of `spec` on `m`, each frame placed at a random point within about 5 cm and a
/// random rotation of its link frame.
pub fn contacts_of(m: &Model, spec: &[ContactSpec], rng: &mut Rng) -> Vec<Contact> {
    spec.iter()
        .map(|&(f, kind, reference)| {
            let xi = Motion::new(
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.7,
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05,
            );
            let mut c = Contact::new(m, f, Vector3::zeros())
                .unwrap()
                .with_placement(m, &exp6(&xi))
                .unwrap()
                .with_reference(reference);
            c.kind = kind;
            c
        })
        .collect()
}

/// `contacts` with random Baumgarte gains (`kp` in [0, 50), `kd` in [0, 10)); `kp` is zero on
/// the two-frame constraints that take none (all but the 3-D world-aligned loops).
pub fn with_gains(contacts: &[Contact], rng: &mut Rng) -> Vec<Contact> {
    contacts
        .iter()
        .map(|c| {
            let (kp, kd) = (rng.range(0.0, 50.0), rng.range(0.0, 10.0));
            let kp_ok = !c.is_loop() || (c.kind == D3 && c.reference == Lwa);
            c.clone().with_baumgarte(if kp_ok { kp } else { 0.0 }, kd).unwrap()
        })
        .collect()
}

/// The centroidal oracle of `tests/all/kinematics/centroidal.rs`, written independently from the
/// reference placements:
/// `[k; l]` about the centre of mass and its `t`-derivative, each with its `ε`-derivative, from the
/// `H` placements (`t`: `ε₁`, `ε₂`; `ε`: `ε₃`).
pub fn centroidal_momentum_oracle(m: &Model, q: &[H]) -> [[f64; 4]; 6] {
    // Returns for each of the 6 components: [value, ∂/∂t, ∂/∂ε, ∂²/∂t∂ε].
    let world = forward_kinematics(m, q);
    // Split an H into (f, f_ε) for the value and the t-derivative: value part re/eps3,
    // t-derivative eps1/eps1eps3, second t-derivative eps1eps2/eps1eps2eps3.
    let d0 = |x: &H| D::new(x.re, x.eps3);
    let d1 = |x: &H| D::new(x.eps1, x.eps1eps3);
    let d2 = |x: &H| D::new(x.eps1eps2, x.eps1eps2eps3);
    let mut mass = 0.0;
    let mut mc = [Vector3::<D>::zeros(); 3]; // Σ m c, its 1st and 2nd t-derivatives
    let mut bodies = vec![];
    for (i, inertia) in m.inertias().iter().enumerate().skip(1) {
        let cl = inertia.com();
        let clh = Vector3::new(H::from_re(cl.x), H::from_re(cl.y), H::from_re(cl.z));
        let ci = world[i].act_point(&clh);
        let r = &world[i].rot;
        let pick = |f: &dyn Fn(&H) -> D| {
            (Matrix3::from_fn(|a, b| f(&r[(a, b)])), Vector3::from_fn(|a, _| f(&ci[a])))
        };
        let (r0, c0) = pick(&d0);
        let (r1, c1) = pick(&d1);
        let (r2, c2) = pick(&d2);
        for (acc, x) in mc.iter_mut().zip([c0, c1, c2]) {
            *acc += x * D::from(inertia.mass);
        }
        mass += inertia.mass;
        let ibar = inertia.inertia_about_com();
        let ib = Matrix3::from_fn(|a, b| D::from(ibar[(a, b)]));
        bodies.push((inertia.mass, ib, r0, r1, r2, c0, c1, c2));
    }
    let c = mc[0] / D::from(mass);
    let cd = mc[1] / D::from(mass);
    let cdd = mc[2] / D::from(mass);
    // k = Σ R Ī Rᵀ ω + m (c_i − c) × ċ_i; its t-derivative by the product rule.
    let (mut k, mut kd) = (Vector3::<D>::zeros(), Vector3::<D>::zeros());
    for (mi, ib, r0, r1, r2, c0, c1, c2) in bodies {
        let w = Vector3::new(
            (r1 * r0.transpose())[(2, 1)],
            (r1 * r0.transpose())[(0, 2)],
            (r1 * r0.transpose())[(1, 0)],
        );
        let wdm = r2 * r0.transpose() + r1 * r1.transpose();
        let wd = Vector3::new(wdm[(2, 1)], wdm[(0, 2)], wdm[(1, 0)]);
        let iw = r0 * ib * r0.transpose();
        let iwd = r1 * ib * r0.transpose() + r0 * ib * r1.transpose();
        let m_ = D::from(mi);
        k += iw * w + (c0 - c).cross(&c1) * m_;
        kd += iwd * w + iw * wd + ((c1 - cd).cross(&c1) + (c0 - c).cross(&c2)) * m_;
    }
    let l = cd * D::from(mass);
    let ld = cdd * D::from(mass);
    let mut out = [[0.0; 4]; 6];
    for j in 0..3 {
        out[j] = [k[j].re, kd[j].re, k[j].eps, kd[j].eps];
        out[3 + j] = [l[j].re, ld[j].re, l[j].eps, ld[j].eps];
    }
    out
}

/// Models with a random armature (fixed and floating base, the free flyer's DoFs included for
/// some), with their zero-armature originals.
pub fn armature_pairs() -> Vec<(Model, Model)> {
    let mut out = vec![];
    let bases = [
        builtin::serial_chain(1),
        builtin::serial_chain(4),
        builtin::serial_chain(9),
        builtin::quadruped(),
        builtin::humanoid(),
        builtin::random_tree(12, 5, false),
        builtin::random_tree(20, 6, true),
        builtin::random_tree(30, 7, true),
    ];
    for (k, m) in bases.into_iter().enumerate() {
        let a = with_random_armature(&m, 50 + k as u64, k % 2 == 1);
        out.push((m, a));
    }
    out
}
