//! Constrained inverse dynamics `τ = M q̈ + b − J_cᵀλ` (eq. eqn_IDc) and its derivatives:
//! first order (IDSVAc, eq. eqn_ID_FO_contact) and second order w.r.t. `q` (IDSVA-SOc).
//!
//! The contact forces `λ` are world-frame forces at points fixed on the bodies, so
//! `f_ext` of the contact body is `[p × λ; λ]` (notes, before eq. eqn_fic_ext_FO_1). Instead of
//! the extra backward pass of Alg. IDSVAc, the contact term `∂(J_cᵀλ)/∂q` and its second
//! derivative are evaluated per contact along its root path (`O(d²)` and `O(d³)` entries), with
//! `∂u_x/∂q_l` (`u_x` the velocity of the contact point per unit `q̇_x`) from identities J1 and
//! `∂p/∂q_l = J_c(:, l)` (eqs. eqn_fic_ext_FO_1, eqn_fic_ext_FO_2); the second derivative is the
//! same expression evaluated with dual base quantities (see `contact_kin`). For 6-D contacts and
//! the local reference, `λ` has 3 or 6 rows per contact in the contact's axes (held fixed in
//! those axes when differentiating) and the entry is `λ · ∂(J_c column x)/∂q_l` from the
//! generic row kinematics (`djac_col_dq`).

use super::contact::{ContactWs, base, sub_djtl_dq, update_points};
use super::contact_kin::{Dir, djac_col_dq, djtl_dq, rows_dot};
use super::contact_loop::loop_djac_col_dq;
use super::id_fo::id_derivatives_unchecked;
use super::id_so::{SoData, id_so_unchecked};
use crate::algo::Data;
use crate::error::Result;
use crate::model::{Model, check_vec};
use nalgebra::{DVector, Vector3};

fn check(
    model: &Model,
    cd: &ContactWs,
    v: &DVector<f64>,
    a: &DVector<f64>,
    lambda: &DVector<f64>,
    q: &DVector<f64>,
) -> Result<()> {
    model.check_q(q)?;
    cd.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_vec("lambda", lambda, cd.dim())?;
    if cd.jac.ncols() != model.nv {
        return Err(crate::error::Error::Dimension {
            what: "ContactData (built for another model): nv".into(),
            expected: model.nv,
            got: cd.jac.ncols(),
        });
    }
    Ok(())
}

/// First-order derivatives of constrained inverse dynamics at `(q, q̇, q̈, λ)`: fills
/// `data.tau` (`= RNEA − J_cᵀλ`), `data.dtau_dq`, `data.dtau_dv`, `data.m` and `cd.jac`.
pub(crate) fn constrained_id_derivatives_ws(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactWs,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    lambda: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        cd.check(model)?;
        let md = data.reduced(model)?;
        return reduced::constrained_id_cd(r, md, cd, None, q, v, a, lambda);
    }
    check(model, cd, v, a, lambda, q)?;
    data.check_tree(model)?;
    // IDSVA writes the entries of DoFs on one root path only; a loop's contact term also has
    // entries between its two chains, cleared first (`ContactWs::has_loops`).
    if cd.has_loops() {
        data.dtau_dq.fill(0.0);
    }
    id_derivatives_unchecked(model, data, q, v, a, None);
    contact_terms_fo(model, data, cd, lambda);
    data.dtau_dq_off_path = cd.has_loops();
    Ok(())
}

fn contact_terms_fo(model: &Model, data: &mut Data, cd: &mut ContactWs, lambda: &DVector<f64>) {
    update_points(model, data, cd, -model.gravity);
    data.tau.gemv_tr(-1.0, &cd.jac, lambda, 1.0);
    sub_djtl_dq(&data.s_world, cd, lambda.as_slice(), &mut data.dtau_dq);
}

/// First- and second-order derivatives of constrained inverse dynamics: as
/// [`constrained_id_derivatives`], plus `so` (IDSVA-SOc): `so.d2tau_dq2()` includes
/// `−∂²(J_cᵀλ)/∂q²`; `d2tau_dv2`, `d2tau_dqdv` and `dm_dq` do not depend on `λ`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn constrained_id_so_derivatives_ws(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactWs,
    so: &mut SoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    lambda: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        cd.check(model)?;
        let so = crate::algo::data::reduced::reduced_ws(&mut so.red, "SoData", model)?;
        let md = data.reduced(model)?;
        return reduced::constrained_id_cd(r, md, cd, Some(so), q, v, a, lambda);
    }
    check(model, cd, v, a, lambda, q)?;
    data.check_tree(model)?;
    so.check_tree(model)?;
    if cd.has_loops() {
        data.dtau_dq.fill(0.0);
        so.d2tau_dq2_mut().as_mut_slice().fill(0.0);
    }
    id_so_unchecked(model, data, so, q, v, a, None, -model.gravity);
    contact_terms_fo(model, data, cd, lambda);
    data.dtau_dq_off_path = cd.has_loops();
    so.d2tau_dq2_off_path = cd.has_loops();
    let b = base(model, data, cd);
    let t = so.d2tau_dq2_mut();
    for (c, path) in cd.paths.iter().enumerate() {
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        if let Some(lp) = &cd.loops[c] {
            // Two-frame constraints: λ · ∂²J_x/∂q_l∂q_k from `contact_loop`'s row kinematics.
            let lam = &lambda.as_slice()[r0..r0 + geo.dim()];
            for &k in &path.dofs {
                for &l in &path.dofs {
                    for &x in &path.dofs {
                        let d = loop_djac_col_dq(&b, geo, lp, x, l, Dir::Q(k));
                        t[(x, l, k)] -= rows_dot(geo, &d, lam).1;
                    }
                }
            }
            continue;
        }
        if !geo.is_point() {
            let lam = &lambda.as_slice()[r0..r0 + geo.dim()];
            for &k in &path.dofs {
                for &l in &path.dofs {
                    for &x in &path.dofs {
                        let d = djac_col_dq(&b, geo, &path.rot, &path.p, x, l, Dir::Q(k));
                        t[(x, l, k)] -= rows_dot(geo, &d, lam).1;
                    }
                }
            }
            continue;
        }
        let lam = Vector3::new(lambda[r0], lambda[r0 + 1], lambda[r0 + 2]);
        for &k in &path.dofs {
            for &l in &path.dofs {
                for &x in &path.dofs {
                    t[(x, l, k)] -= djtl_dq(&b, &path.p, &lam, x, l, Dir::Q(k)).1;
                }
            }
        }
    }
    Ok(())
}

/// Constrained inverse dynamics of a model in reduced coordinates (mimic joints): the full
/// tree's, reduced with `G`.
mod reduced {
    use crate::algo::data::reduced::{MimicData, prepare};
    use crate::deriv::contact::ContactWs;
    use crate::deriv::id_fo::reduced::reduce_fo;
    use crate::deriv::id_so::reduced::MimicSoData;
    use crate::error::Result;
    use crate::model::reduction::MimicModel;
    use nalgebra::DVector;

    /// `constrained_id_derivatives` of a reduced model with the full tree's contact workspace `cd`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn constrained_id_cd(
        model: &MimicModel,
        data: &mut MimicData,
        cd: &mut ContactWs,
        so: Option<&mut MimicSoData>,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        lambda: &DVector<f64>,
    ) -> Result<()> {
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        crate::model::check_vec("lambda", lambda, cd.dim())?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        match so {
            None => super::constrained_id_derivatives_ws(
                &model.full,
                &mut data.full,
                cd,
                &data.q,
                &data.v,
                &data.a,
                lambda,
            )?,
            Some(so) => {
                so.check(model)?;
                super::constrained_id_so_derivatives_ws(
                    &model.full,
                    &mut data.full,
                    cd,
                    &mut so.full,
                    &data.q,
                    &data.v,
                    &data.a,
                    lambda,
                )?;
                model.reduce_tensor(so.full.d2tau_dq2(), &mut so.d2tau_dq2);
                model.reduce_tensor(so.full.d2tau_dv2(), &mut so.d2tau_dv2);
                model.reduce_tensor(so.full.d2tau_dqdv(), &mut so.d2tau_dqdv);
                model.reduce_tensor(so.full.dm_dq(), &mut so.dm_dq);
            }
        }
        reduce_fo(model, data);
        Ok(())
    }
}
