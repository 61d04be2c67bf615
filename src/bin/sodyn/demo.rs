//! `sodyn demo`: every algorithm on a model at a random state, with timings and the maximum
//! error against the automatic-differentiation oracle of [`sodyn::reference`].

use super::{DemoArgs, load_model};
use nalgebra::{DMatrix, DVector, Matrix3xX, Vector3};
use sodyn::algo::{Data, aba, crba, factorize_ltl, point_jacobian, rnea, solve_ltl};
use sodyn::deriv::{fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};
use sodyn::error::{Error, Result};
use sodyn::reference;
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;
use std::time::Instant;

/// Median wall time of `f` in microseconds over enough repetitions (about 0.2 s, at most 2000);
/// the first error of `f` (e.g. a singular mass matrix of a URDF) is returned, not a panic.
pub(crate) fn time_us(mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    f()?;
    let t0 = Instant::now();
    f()?;
    let once = t0.elapsed().as_secs_f64().max(1e-9);
    let reps = ((0.2 / once) as usize).clamp(3, 2000);
    let mut samples = Vec::with_capacity(reps);
    for _ in 0..reps {
        let t = Instant::now();
        f()?;
        samples.push(t.elapsed().as_secs_f64() * 1e6);
    }
    samples.sort_by(|a, b| a.total_cmp(b));
    Ok(samples[reps / 2])
}

pub(crate) fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax().max(1.0)
}

pub(crate) fn rel_t(a: &Tensor3, b: &Tensor3) -> f64 {
    a.max_abs_diff(b) / b.max_abs().max(1.0)
}

pub(crate) fn rel_v(a: &DVector<f64>, b: &[f64]) -> f64 {
    let b = DVector::from_column_slice(b);
    (a - &b).amax() / b.amax().max(1.0)
}

/// Runs the demo of `o`: its model (`builtin:NAME`, a URDF or an MJCF path, with
/// `--floating-base`, `--armature`) at the random state of its seed, with its `--contacts` or
/// the default ones.
pub(crate) fn run_demo(o: &DemoArgs) -> Result<()> {
    let (spec, seed) = (o.model.as_str(), o.seed);
    let m = load_model(&o.model_args())?;
    let mut rng = Rng::new(seed);
    let q = m.random_configuration(&mut rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let a = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let tau = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let (qs, vs, as_, ts) = (q.as_slice(), v.as_slice(), a.as_slice(), tau.as_slice());
    outln!(
        "sodyn demo: model \"{}\" ({spec}), nq = {}, nv = {}, njoints = {}, seed {seed}",
        m.name(),
        m.nq(),
        m.nv(),
        m.njoints()
    );
    outln!(
        "errors: max |ours − oracle| / max(1, max |oracle|); oracle = reference code with f64 / dual / hyper-dual numbers\n"
    );
    outln!("{:<34} {:>12} {:>14}", "algorithm", "median µs", "max rel err");
    let mut d = Data::with_second_order(&m);
    let mut worst: f64 = 0.0;
    let mut row = |name: &str, us: f64, err: f64| {
        worst = worst.max(err);
        outln!("{name:<34} {us:>12.2} {err:>14.2e}");
    };

    let t = time_us(|| {
        rnea(&m, &mut d, &q, &v, &a, None)?;
        Ok(())
    })?;
    let tau_id = rnea(&m, &mut d, &q, &v, &a, None)?.clone();
    row(
        "rnea (inverse dynamics)",
        t,
        rel_v(&tau_id, &reference::rnea::<f64>(&m, qs, vs, as_, None)),
    );

    let t = time_us(|| {
        crba(&m, &mut d, &q)?;
        Ok(())
    })?;
    let mm = crba(&m, &mut d, &q)?.clone();
    let mref = reference::mass_matrix::<f64>(&m, qs);
    row("crba (mass matrix)", t, rel(&mm, &DMatrix::from_fn(m.nv(), m.nv(), |i, j| mref[i][j])));

    let t = time_us(|| {
        aba(&m, &mut d, &q, &v, &tau, None)?;
        Ok(())
    })?;
    let qdd = aba(&m, &mut d, &q, &v, &tau, None)?.clone();
    let qdd_ref = reference::aba::<f64>(&m, qs, vs, ts, None);
    row("aba (forward dynamics)", t, rel_v(&qdd, &qdd_ref));

    // The sparse LᵀDL factorisation has the full tree's sparsity: not for reduced models.
    if !m.is_reduced() {
        crba(&m, &mut d, &q)?;
        let t = time_us(|| {
            factorize_ltl(&m, &mut d)?;
            Ok(())
        })?;
        let b = reference::nle::<f64>(&m, qs, vs);
        let mut x = &tau - DVector::from_vec(b);
        solve_ltl(&m, &d, &mut x)?;
        row("LᵀDL factorisation + solve", t, rel_v(&x, &qdd_ref));
    }

    let frame = m.frames().len() - 1;
    let mut jac = Matrix3xX::zeros(m.nv());
    let point = Vector3::new(0.05, -0.02, 0.1);
    let t = time_us(|| {
        point_jacobian(&m, &mut d, &q, frame, &point, &mut jac)?;
        Ok(())
    })?;
    let jref = reference::d_point_position_dq(&m, qs, frame, &[point.x, point.y, point.z]);
    row(
        &format!("point Jacobian ({})", m.frames()[frame].name),
        t,
        (&jac - &jref).amax() / jref.amax().max(1.0),
    );

    let t = time_us(|| {
        id_derivatives(&m, &mut d, &q, &v, &a, None)?;
        Ok(())
    })?;
    id_derivatives(&m, &mut d, &q, &v, &a, None)?;
    row("id_fo (IDSVA) dtau/dq", t, rel(d.dtau_dq(), &reference::d_rnea_dq(&m, qs, vs, as_)));
    row("      dtau/dv", t, rel(d.dtau_dv(), &reference::d_rnea_dv(&m, qs, vs, as_)));

    let t = time_us(|| {
        fd_derivatives(&m, &mut d, &q, &v, &tau, None)?;
        Ok(())
    })?;
    fd_derivatives(&m, &mut d, &q, &v, &tau, None)?;
    row("fd_fo dqdd/dq", t, rel(d.dqdd_dq(), &reference::d_aba_dq(&m, qs, vs, ts)));
    row("      dqdd/dv", t, rel(d.dqdd_dv(), &reference::d_aba_dv(&m, qs, vs, ts)));
    row("      dqdd/dtau = M⁻¹", t, rel(d.minv(), &reference::d_aba_dtau(&m, qs, vs, ts)));

    let t = time_us(|| {
        id_so_derivatives(&m, &mut d, &q, &v, &a, None)?;
        Ok(())
    })?;
    let so = id_so_derivatives(&m, &mut d, &q, &v, &a, None)?;
    row(
        "id_so (IDSVA-SO) d2tau/dq2",
        t,
        rel_t(so.d2tau_dq2(), &reference::d2_rnea_dq2(&m, qs, vs, as_)),
    );
    row("      d2tau/dv2", t, rel_t(so.d2tau_dv2(), &reference::d2_rnea_dv2(&m, qs, vs, as_)));
    row("      d2tau/dqdv", t, rel_t(so.d2tau_dqdv(), &reference::d2_rnea_dqdv(&m, qs, vs, as_)));
    row("      dM/dq", t, rel_t(so.dm_dq(), &reference::dM_dq(&m, qs)));

    let t = time_us(|| {
        fd_so_derivatives(&m, &mut d, &q, &v, &tau, None)?;
        Ok(())
    })?;
    let fso = fd_so_derivatives(&m, &mut d, &q, &v, &tau, None)?;
    let big = m.nv() > 40;
    if big {
        row("fd_so (timing only; oracle > 40 DoF)", t, 0.0);
    } else {
        row("fd_so d2qdd/dq2", t, rel_t(fso.d2qdd_dq2(), &reference::d2_aba_dq2(&m, qs, vs, ts)));
        row("      d2qdd/dv2", t, rel_t(fso.d2qdd_dv2(), &reference::d2_aba_dv2(&m, qs, vs, ts)));
        row(
            "      d2qdd/dqdv",
            t,
            rel_t(fso.d2qdd_dqdv(), &reference::d2_aba_dqdv(&m, qs, vs, ts)),
        );
        row(
            "      d2qdd/dtau dq",
            t,
            rel_t(fso.d2qdd_dtaudq(), &reference::d2_aba_dtaudq(&m, qs, vs, ts)),
        );
    }

    // Contacts: those of --contacts, or by default the frames of these names that the model
    // has (the humanoid's soles, the quadruped's feet).
    let given = o.contacts.as_ref().map(|l| &l.0);
    let frames: Vec<&str> = match given {
        Some(list) => {
            for f in list {
                m.frame_id(f).map_err(|_| Error::Argument {
                    name: "--contacts".into(),
                    reason: format!("unknown frame \"{f}\" in model \"{}\" ({spec})", m.name()),
                })?;
            }
            list.iter().map(String::as_str).collect()
        }
        None => ["left_sole", "right_sole", "LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]
            .into_iter()
            .filter(|f| m.frame_id(f).is_ok())
            .collect(),
    };
    if !frames.is_empty() {
        use sodyn::algo::Contact;
        use sodyn::deriv::{
            ContactData, constrained_id_so_derivatives, impact_so_derivatives, kkt_so_derivatives,
        };
        use sodyn::reference::contact as oracle;
        let (kind, reference) = (o.contact_type, o.contact_reference);
        let contacts: Vec<Contact> = frames
            .iter()
            .map(|f| {
                Contact::new(&m, f, Vector3::zeros())
                    .map(|c| Contact { kind, ..c.with_reference(reference) })
            })
            .collect::<Result<_>>()?;
        let what = match given {
            None => String::new(),
            Some(_) => format!(" ({} {})", kind.name(), reference.name()),
        };
        outln!(
            "\ncontacts{what} on {} (oracle for second order only up to 20 DoF)",
            frames.join(", ")
        );
        let mut cd = ContactData::with_second_order(&m, &contacts)?;
        let lam = DVector::from_fn(cd.dim(), |i, _| if i % 3 == 2 { 50.0 } else { 5.0 });
        let t = time_us(|| {
            constrained_id_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam)?;
            Ok(())
        })?;
        constrained_id_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam)?;
        let so = d
            .id_so()
            .ok_or_else(|| Error::Workspace("internal: no second-order results in Data".into()))?;
        let ls = lam.as_slice();
        row(
            "constrained ID (IDSVA(-SO)c) dtau/dq",
            t,
            rel(d.dtau_dq(), &oracle::d_constrained_rnea_dq(&m, qs, vs, as_, &contacts, ls)),
        );
        row(
            "      d2tau/dq2",
            t,
            rel_t(so.d2tau_dq2(), &oracle::d2_constrained_rnea_dq2(&m, qs, vs, as_, &contacts, ls)),
        );
        let t = time_us(|| {
            kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau)?;
            Ok(())
        })?;
        let kd = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau)?;
        let fo = oracle::kkt_fo(&m, qs, vs, ts, &contacts);
        row("kkt FO+SO dqdd/dq", t, rel(kd.dqdd_dq(), &fo.dqdd_dq));
        row("      dlambda/dq", t, rel(kd.dlambda_dq(), &fo.dlambda_dq));
        row(
            "      dqdd/dv, dlambda/dv",
            t,
            rel(kd.dqdd_dv(), &fo.dqdd_dv).max(rel(kd.dlambda_dv(), &fo.dlambda_dv)),
        );
        if m.nv() <= 20 {
            let so_ref = oracle::kkt_so(&m, qs, vs, ts, &contacts);
            let k = kd.so().expect("allocated");
            row("      d2qdd/dq2", t, rel_t(k.d2qdd_dq2(), &so_ref.d2qdd_dq2));
            row("      d2lambda/dq2", t, rel_t(k.d2lambda_dq2(), &so_ref.d2lambda_dq2));
        }
        let t = time_us(|| {
            impact_so_derivatives(&m, &mut d, &mut cd, &q, &v)?;
            Ok(())
        })?;
        let im = impact_so_derivatives(&m, &mut d, &mut cd, &q, &v)?;
        let fo = oracle::impact_fo(&m, qs, vs, &contacts, 0.0);
        row("impact FO+SO dvplus/dq", t, rel(im.dvplus_dq(), &fo.dvplus_dq));
        row("      dimpulse/dq", t, rel(im.dimpulse_dq(), &fo.dimpulse_dq));
        if m.nv() <= 20 {
            let so_ref = oracle::impact_so(&m, qs, vs, &contacts, 0.0);
            let k = im.so().expect("allocated");
            row("      d2vplus/dq2", t, rel_t(k.d2vplus_dq2(), &so_ref.d2vplus_dq2));
        }
        // 6-D contacts holding the soles, rows in the soles' axes, with Baumgarte gains.
        // (Default contacts only.)
        let soles: Vec<&str> = match given {
            None => frames.iter().copied().filter(|f| f.ends_with("_sole")).collect(),
            Some(_) => vec![],
        };
        if !soles.is_empty() {
            use sodyn::model::{ContactReference, ContactType};
            let contacts: Vec<Contact> = soles
                .iter()
                .map(|f| {
                    let c = Contact::new_6d(&m, f, None)?
                        .with_reference(ContactReference::Local)
                        .with_baumgarte(10.0, 2.0)?;
                    Ok(Contact { kind: ContactType::D6, ..c })
                })
                .collect::<Result<_>>()?;
            outln!(
                "
6-D contacts (local axes, kp 10, kd 2) on {}",
                soles.join(", ")
            );
            let mut cd = ContactData::with_second_order(&m, &contacts)?;
            let t = time_us(|| {
                kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau)?;
                Ok(())
            })?;
            let kd = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau)?;
            let fo = oracle::kkt_fo(&m, qs, vs, ts, &contacts);
            row("kkt FO+SO dqdd/dq", t, rel(kd.dqdd_dq(), &fo.dqdd_dq));
            row("      dlambda/dq", t, rel(kd.dlambda_dq(), &fo.dlambda_dq));
            let t = time_us(|| {
                impact_so_derivatives(&m, &mut d, &mut cd, &q, &v)?;
                Ok(())
            })?;
            let im = impact_so_derivatives(&m, &mut d, &mut cd, &q, &v)?;
            let fo = oracle::impact_fo(&m, qs, vs, &contacts, 0.0);
            row("impact FO+SO dvplus/dq", t, rel(im.dvplus_dq(), &fo.dvplus_dq));
            row("      dimpulse/dq", t, rel(im.dimpulse_dq(), &fo.dimpulse_dq));
        }
    }
    outln!("\nmaximum relative error against the oracle: {worst:.2e}");
    Ok(())
}
