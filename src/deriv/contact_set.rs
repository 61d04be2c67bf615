//! The contact-set data and the public functions of the constrained families: KKT (contact)
//! dynamics, impact dynamics and constrained inverse dynamics, first and second order, dense
//! and contracted.
//!
//! One [`ContactData`] per model, contact set and thread (Pinocchio's `RigidConstraintData`),
//! beside the model's [`Data`]: it holds the contact set, the workspaces of the three families
//! and their results. Its second-order capacity is chosen when it is made, as [`Data`]'s:
//!
//! | made by | first order | contracted second order | dense second order |
//! |---|---|---|---|
//! | [`ContactData::new`] | yes | | |
//! | [`ContactData::with_contracted`] | yes | yes (`O(nv²)`) | |
//! | [`ContactData::with_second_order`] | yes | yes | yes (`nv³` tensors) |
//!
//! A function that needs a capacity the workspace lacks returns
//! [`crate::Error::Workspace`] naming the constructor to use.
//!
//! ```
//! use nalgebra::{DVector, Vector3};
//! use sodyn::algo::{Contact, Data};
//! use sodyn::deriv::{ContactData, kkt_derivatives};
//! use sodyn::{model::builtin, rng::Rng};
//! let m = builtin::quadruped();
//! let feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
//! let contacts: Vec<Contact> =
//!     feet.iter().map(|f| Contact::new(&m, f, Vector3::zeros())).collect::<Result<_, _>>()?;
//! let (mut data, mut cd) = (Data::new(&m), ContactData::new(&m, &contacts)?);
//! let q = m.random_configuration(&mut Rng::new(1));
//! let (v, tau) = (DVector::zeros(m.nv()), DVector::zeros(m.nv()));
//! let kkt = kkt_derivatives(&m, &mut data, &mut cd, &q, &v, &tau)?;
//! assert_eq!(kkt.dlambda_dq().shape(), (12, m.nv()));
//! # Ok::<(), sodyn::Error>(())
//! ```

use super::contact::ContactWs;
use super::impact::{ImpactContracted, ImpactData};
use super::kkt::{KktContracted, KktData};
use crate::algo::Data;
use crate::algo::data::Part;
use crate::error::{Error, Result};
use crate::model::{Contact, Model};
use nalgebra::{DMatrix, DVector};

/// Workspace and results of the constrained families for one contact set on one model: KKT
/// dynamics, impact dynamics and constrained inverse dynamics (see the
/// [module documentation](self)). Allocated once; the calls allocate nothing.
#[derive(Clone, Debug)]
pub struct ContactData {
    /// Constrained inverse dynamics' contact workspace.
    id: ContactWs,
    kkt: KktData,
    impact: ImpactData,
    kkt_c: Option<KktContracted>,
    impact_c: Option<ImpactContracted>,
    /// The family of the last call (whose Jacobian [`ContactData::jac`] returns).
    last: Family,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Family {
    Kkt,
    Impact,
    ConstrainedId,
}

impl ContactData {
    /// Contact-set data for `contacts` on `model`, first order: [`kkt_dynamics`],
    /// [`kkt_derivatives`], [`impact_dynamics`], [`impact_derivatives`],
    /// [`constrained_id_derivatives`] (and [`constrained_id_so_derivatives`] with a [`Data`]
    /// made by [`Data::with_second_order`]).
    ///
    /// # Errors
    /// [`Error::Argument`] for more than [`super::contact::MAX_CONTACTS`] contacts or a
    /// Baumgarte gain that is negative or not finite; [`Error::Unknown`] for a contact whose
    /// frame is not in `model`; [`Error::Singular`] for a contact on the world.
    pub fn new(model: &Model, contacts: &[Contact]) -> Result<Self> {
        let ws = ContactWs::new(model, contacts)?;
        Ok(Self {
            kkt: KktData::new(model, ws.clone()),
            impact: ImpactData::new(model, ws.clone()),
            id: ws,
            kkt_c: None,
            impact_c: None,
            last: Family::Kkt,
        })
    }
    /// As [`ContactData::new`], with the contracted second order too: [`kkt_so_contracted`],
    /// [`impact_so_contracted`] (`O(nv²)` more).
    ///
    /// # Errors
    /// As [`ContactData::new`].
    pub fn with_contracted(model: &Model, contacts: &[Contact]) -> Result<Self> {
        let mut cd = Self::new(model, contacts)?;
        cd.kkt_c = Some(KktContracted::new(model, &cd.kkt));
        cd.impact_c = Some(ImpactContracted::new(model, &cd.impact));
        Ok(cd)
    }
    /// As [`ContactData::with_contracted`], with the dense second order too:
    /// [`kkt_so_derivatives`], [`impact_so_derivatives`] (`nv³` tensors).
    ///
    /// # Errors
    /// As [`ContactData::new`].
    pub fn with_second_order(model: &Model, contacts: &[Contact]) -> Result<Self> {
        let mut cd = Self::with_contracted(model, contacts)?;
        cd.kkt = cd.kkt.with_second_order(model);
        cd.impact = cd.impact.with_second_order(model);
        Ok(cd)
    }
    /// Adds the capacity of [`ContactData::with_contracted`] if this workspace lacks it.
    ///
    /// # Errors
    /// [`Error::Workspace`] for a workspace of another model (nothing is added).
    pub fn reserve_contracted(&mut self, model: &Model) -> Result<()> {
        self.check(model)?;
        if self.kkt_c.is_none() {
            self.kkt_c = Some(KktContracted::new(model, &self.kkt));
            self.impact_c = Some(ImpactContracted::new(model, &self.impact));
        }
        Ok(())
    }
    /// Adds the capacity of [`ContactData::with_second_order`] if this workspace lacks it.
    ///
    /// # Errors
    /// As [`ContactData::reserve_contracted`].
    pub fn reserve_second_order(&mut self, model: &Model) -> Result<()> {
        self.reserve_contracted(model)?;
        if !self.has_second_order() {
            let kkt = std::mem::replace(&mut self.kkt, KktData::new(model, self.id.clone()));
            self.kkt = kkt.with_second_order(model);
            let imp = std::mem::replace(&mut self.impact, ImpactData::new(model, self.id.clone()));
            self.impact = imp.with_second_order(model);
        }
        Ok(())
    }
    /// The contacts.
    pub fn contacts(&self) -> &[Contact] {
        self.id.contacts()
    }
    /// Number of constraint rows `m` (3 per 3-D contact, 6 per 6-D contact).
    pub fn dim(&self) -> usize {
        self.id.dim()
    }
    /// Contact Jacobian `J_c` (`m × nv`) at the configuration of the last call (the contacts'
    /// velocity rows, `crate::model::Contact`).
    pub fn jac(&self) -> &DMatrix<f64> {
        self.ws().jac()
    }
    /// Drift `J̇_c q̇` of the last KKT call (classical point accelerations at `q̈ = 0`).
    pub fn drift(&self) -> &DVector<f64> {
        self.kkt.cd().drift()
    }
    /// The contact workspace of the last call's family.
    fn ws(&self) -> &ContactWs {
        match self.last {
            Family::Kkt => self.kkt.cd(),
            Family::Impact => self.impact.cd(),
            Family::ConstrainedId => &self.id,
        }
    }
    /// Regularisation `μ ≥ 0` added to the Delassus matrix `J M⁻¹ Jᵀ` (default 0: a
    /// rank-deficient contact set is an error).
    pub fn damping(&self) -> f64 {
        self.id.damping()
    }
    /// Sets the damping `μ` of the KKT and impact Delassus solves: with `μ > 0` the solves are
    /// `(J M⁻¹ Jᵀ + μ I) λ = …`, and all derivatives are those of the damped system.
    ///
    /// # Errors
    /// [`Error::Argument`] for a negative or non-finite `μ`, or a non-zero `μ` on a model in
    /// reduced coordinates (the value is unchanged).
    pub fn set_damping(&mut self, damping: f64) -> Result<()> {
        // The three checks are the same: the first that fails leaves all three unchanged.
        self.kkt.set_damping(damping)?;
        self.impact.set_damping(damping)?;
        self.id.set_damping(damping)
    }
    /// Coefficient of restitution `e` of the impact dynamics (default 0):
    /// `J_c q̇⁺ = −e J_c q̇⁻`.
    pub fn restitution(&self) -> f64 {
        self.impact.restitution()
    }
    /// Sets the coefficient of restitution `e ≥ 0`.
    ///
    /// # Errors
    /// [`Error::Argument`] for a NaN, infinite or negative `e` (the value is unchanged).
    pub fn set_restitution(&mut self, e: f64) -> Result<()> {
        self.impact.set_restitution(e)
    }
    /// Whether this workspace has dense second-order capacity.
    pub fn has_second_order(&self) -> bool {
        self.kkt.has_so()
    }
    /// Whether this workspace has contracted second-order capacity.
    pub fn has_contracted(&self) -> bool {
        self.kkt_c.is_some()
    }
    /// Checks that this workspace was made for `model`.
    ///
    /// # Errors
    /// [`Error::Workspace`] naming what differs.
    pub fn check(&self, model: &Model) -> Result<()> {
        self.id.check(model)
    }
    /// The results of the last KKT call ([`kkt_dynamics`], [`kkt_derivatives`],
    /// [`kkt_so_derivatives`]).
    pub fn kkt(&self) -> &KktData {
        &self.kkt
    }
    /// The results of the last impact call ([`impact_dynamics`], [`impact_derivatives`],
    /// [`impact_so_derivatives`]).
    pub fn impact(&self) -> &ImpactData {
        &self.impact
    }
    /// The results of the last [`kkt_so_contracted`]; `None` without contracted capacity.
    pub fn kkt_contracted(&self) -> Option<&KktContracted> {
        self.kkt_c.as_ref()
    }
    /// The results of the last [`impact_so_contracted`]; `None` without contracted capacity.
    pub fn impact_contracted(&self) -> Option<&ImpactContracted> {
        self.impact_c.as_ref()
    }
}

/// The error of a call that needs a capacity `cd` lacks.
fn no_capacity(function: &str, what: &str, make: &str) -> Error {
    Error::Workspace(format!(
        "{function} needs a ContactData with {what} capacity: make it with {make}(&model, \
         &contacts)"
    ))
}

/// Constrained (KKT) forward dynamics `q̈`, `λ` at `(q, q̇, τ)` (the results: `cd.kkt()`).
///
/// # Errors
/// As [`Model::check_q`]; `v`, `tau` of the wrong length or not finite; workspaces of another
/// model; [`Error::Singular`] for a rank-deficient contact set without damping.
pub fn kkt_dynamics<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<&'a KktData> {
    cd.check(model)?;
    cd.last = Family::Kkt;
    super::kkt::kkt_dynamics_ws(model, data, &mut cd.kkt, q, v, tau)?;
    Ok(&cd.kkt)
}

/// First-order derivatives of the KKT dynamics: `∂q̈/∂(q, q̇, τ)` and `∂λ/∂(q, q̇, τ)`
/// (the results: `cd.kkt()`).
///
/// # Errors
/// As [`kkt_dynamics`].
pub fn kkt_derivatives<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<&'a KktData> {
    cd.check(model)?;
    cd.last = Family::Kkt;
    super::kkt::kkt_derivatives_ws(model, data, &mut cd.kkt, q, v, tau)?;
    Ok(&cd.kkt)
}

/// First- and second-order derivatives of the KKT dynamics (the second order:
/// `cd.kkt().so()`, `T[i][j][k] = ∂/∂x_k (∂y_i/∂u_j)`); `cd` made by
/// [`ContactData::with_second_order`].
///
/// # Errors
/// As [`kkt_dynamics`]; [`Error::Workspace`] without dense second-order capacity.
pub fn kkt_so_derivatives<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<&'a KktData> {
    if !cd.has_second_order() {
        return Err(no_capacity(
            "kkt_so_derivatives",
            "dense second-order",
            "ContactData::with_second_order",
        ));
    }
    cd.check(model)?;
    cd.last = Family::Kkt;
    super::kkt::kkt_so_derivatives_ws(model, data, &mut cd.kkt, q, v, tau)?;
    Ok(&cd.kkt)
}

/// The Hessians of `w_q̈ᵀ q̈ + w_λᵀ λ` of the KKT dynamics (`cd.kkt_contracted()`), with the
/// first-order derivatives (`cd.kkt()`); `cd` made by [`ContactData::with_contracted`] or
/// [`ContactData::with_second_order`].
///
/// # Errors
/// As [`kkt_dynamics`]; weights of the wrong length or not finite; [`Error::Workspace`]
/// without contracted capacity.
#[allow(clippy::too_many_arguments)]
pub fn kkt_so_contracted<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    w_qdd: &DVector<f64>,
    w_lambda: &DVector<f64>,
) -> Result<&'a KktContracted> {
    cd.check(model)?;
    let Some(kc) = cd.kkt_c.as_mut() else {
        return Err(no_capacity(
            "kkt_so_contracted",
            "contracted second-order",
            "ContactData::with_contracted",
        ));
    };
    cd.last = Family::Kkt;
    super::kkt::kkt_so_contracted_ws(model, data, &mut cd.kkt, kc, q, v, tau, w_qdd, w_lambda)?;
    Ok(kc)
}

/// Impact dynamics: the post-impact velocity `q̇⁺` and the impulses `λ̂` at `(q, q̇⁻)`, with
/// `cd`'s restitution (the results: `cd.impact()`).
///
/// # Errors
/// As [`kkt_dynamics`], with `vminus` for `v`.
pub fn impact_dynamics<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<&'a ImpactData> {
    cd.check(model)?;
    cd.last = Family::Impact;
    super::impact::impact_dynamics_ws(model, data, &mut cd.impact, q, vminus)?;
    Ok(&cd.impact)
}

/// First-order derivatives of the impact dynamics (the results: `cd.impact()`).
///
/// # Errors
/// As [`impact_dynamics`].
pub fn impact_derivatives<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<&'a ImpactData> {
    cd.check(model)?;
    cd.last = Family::Impact;
    super::impact::impact_derivatives_ws(model, data, &mut cd.impact, q, vminus)?;
    Ok(&cd.impact)
}

/// First- and second-order derivatives of the impact dynamics (the second order:
/// `cd.impact().so()`); `cd` made by [`ContactData::with_second_order`].
///
/// # Errors
/// As [`impact_dynamics`]; [`Error::Workspace`] without dense second-order capacity.
pub fn impact_so_derivatives<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<&'a ImpactData> {
    if !cd.impact.has_so() {
        return Err(no_capacity(
            "impact_so_derivatives",
            "dense second-order",
            "ContactData::with_second_order",
        ));
    }
    cd.check(model)?;
    cd.last = Family::Impact;
    super::impact::impact_so_derivatives_ws(model, data, &mut cd.impact, q, vminus)?;
    Ok(&cd.impact)
}

/// The Hessians of `w_vᵀ q̇⁺ + w_λ̂ᵀ λ̂` of the impact dynamics (`cd.impact_contracted()`), with
/// the first-order derivatives (`cd.impact()`); `cd` made by [`ContactData::with_contracted`]
/// or [`ContactData::with_second_order`].
///
/// # Errors
/// As [`impact_dynamics`]; weights of the wrong length or not finite; [`Error::Workspace`]
/// without contracted capacity.
pub fn impact_so_contracted<'a>(
    model: &Model,
    data: &mut Data,
    cd: &'a mut ContactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
    w_vplus: &DVector<f64>,
    w_impulse: &DVector<f64>,
) -> Result<&'a ImpactContracted> {
    cd.check(model)?;
    let Some(ic) = cd.impact_c.as_mut() else {
        return Err(no_capacity(
            "impact_so_contracted",
            "contracted second-order",
            "ContactData::with_contracted",
        ));
    };
    cd.last = Family::Impact;
    super::impact::impact_so_contracted_ws(
        model,
        data,
        &mut cd.impact,
        ic,
        q,
        vminus,
        w_vplus,
        w_impulse,
    )?;
    Ok(ic)
}

/// First-order derivatives of constrained inverse dynamics at `(q, q̇, q̈, λ)`: fills
/// `data.tau()` (`= RNEA − J_cᵀλ`), `data.dtau_dq()`, `data.dtau_dv()`, `data.m()` and
/// `cd.jac()`.
///
/// # Errors
/// As [`Model::check_q`]; `v`, `a`, `lambda` of the wrong length or not finite; workspaces of
/// another model.
pub fn constrained_id_derivatives(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    lambda: &DVector<f64>,
) -> Result<()> {
    cd.check(model)?;
    cd.last = Family::ConstrainedId;
    super::external::constrained_id_derivatives_ws(model, data, &mut cd.id, q, v, a, lambda)
}

/// First- and second-order derivatives of constrained inverse dynamics: as
/// [`constrained_id_derivatives`], plus IDSVA-SOc into `data.id_so()` (whose `d2tau_dq2`
/// includes `−∂²(J_cᵀλ)/∂q²`; `d2tau_dv2`, `d2tau_dqdv` and `dm_dq` do not depend on `λ`);
/// `data` made by [`Data::with_second_order`].
///
/// # Errors
/// As [`constrained_id_derivatives`]; [`Error::Workspace`] without dense second-order capacity
/// in `data`.
#[allow(clippy::too_many_arguments)]
pub fn constrained_id_so_derivatives<'a>(
    model: &Model,
    data: &'a mut Data,
    cd: &mut ContactData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    lambda: &DVector<f64>,
) -> Result<&'a super::SoData> {
    cd.check(model)?;
    cd.last = Family::ConstrainedId;
    let f = "constrained_id_so_derivatives";
    data.with_part(Part::IdSo, f, "Data::with_second_order", |data, so| {
        super::external::constrained_id_so_derivatives_ws(
            model, data, &mut cd.id, so, q, v, a, lambda,
        )
    })?;
    data.part_or(Part::IdSo, f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deriv::{fd_so_contracted, fd_so_derivatives, id_so_derivatives};
    use crate::model::builtin;
    use crate::rng::Rng;
    use nalgebra::Vector3;

    fn feet(m: &Model) -> Vec<Contact> {
        ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]
            .iter()
            .map(|f| Contact::new(m, f, Vector3::zeros()))
            .collect::<Result<_>>()
            .unwrap()
    }

    /// The capacities: a call that needs more than the workspace was made with is an
    /// `Error::Workspace` naming the constructor; `reserve_*` adds it; a clone of a workspace
    /// with parts computes what the original computes (the parts are cloned, not shared or
    /// lost).
    #[test]
    fn capacities_errors_reserve_and_clone() {
        let m = builtin::quadruped();
        let mut rng = Rng::new(5);
        let q = m.random_configuration(&mut rng);
        let v = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let w = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let mut d = Data::new(&m);
        let e = id_so_derivatives(&m, &mut d, &q, &v, &v, None).unwrap_err();
        assert!(matches!(&e, Error::Workspace(s) if s.contains("Data::with_second_order")), "{e}");
        let e = fd_so_contracted(&m, &mut d, &q, &v, &v, &w).unwrap_err();
        assert!(matches!(&e, Error::Workspace(s) if s.contains("Data::with_contracted")), "{e}");
        d.reserve_contracted(&m).unwrap();
        assert!(d.has_contracted() && !d.has_second_order());
        fd_so_contracted(&m, &mut d, &q, &v, &v, &w).unwrap();
        d.reserve_second_order(&m).unwrap();
        let t = fd_so_derivatives(&m, &mut d, &q, &v, &v, None).unwrap().d2qdd_dq2().clone();
        let mut c = d.clone();
        let tc = fd_so_derivatives(&m, &mut c, &q, &v, &v, None).unwrap().d2qdd_dq2().clone();
        assert!(t.as_slice() == tc.as_slice());
        let fresh = id_so_derivatives(&m, &mut Data::with_second_order(&m), &q, &v, &v, None)
            .unwrap()
            .d2tau_dq2()
            .clone();
        let ours = id_so_derivatives(&m, &mut c, &q, &v, &v, None).unwrap().d2tau_dq2();
        assert!(ours.as_slice() == fresh.as_slice());

        let contacts = feet(&m);
        let mut cd = ContactData::new(&m, &contacts).unwrap();
        let (wl, tau) = (DVector::from_element(12, 0.5), DVector::zeros(m.nv()));
        let e = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap_err();
        assert!(
            matches!(&e, Error::Workspace(s) if s.contains("ContactData::with_second_order")),
            "{e}"
        );
        let e = impact_so_contracted(&m, &mut d, &mut cd, &q, &v, &w, &wl).unwrap_err();
        assert!(
            matches!(&e, Error::Workspace(s) if s.contains("ContactData::with_contracted")),
            "{e}"
        );
        cd.set_damping(1e-3).unwrap();
        cd.reserve_second_order(&m).unwrap();
        assert!(cd.has_second_order() && cd.has_contracted());
        // The damping survives the reservation.
        assert_eq!(cd.damping(), 1e-3);
        let k = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
        let lam = k.lambda().clone();
        let mut made = ContactData::with_second_order(&m, &contacts).unwrap();
        made.set_damping(1e-3).unwrap();
        let k2 = kkt_so_derivatives(&m, &mut d, &mut made, &q, &v, &tau).unwrap();
        assert!(k2.lambda().as_slice() == lam.as_slice());
        assert!(cd.jac().as_slice() == made.jac().as_slice());
        // A contact set of another model is refused, naming the type the caller made.
        let other = builtin::humanoid();
        let (mut od, qo) = (Data::new(&other), other.neutral());
        let zo = DVector::zeros(other.nv());
        let e = kkt_dynamics(&other, &mut od, &mut cd, &qo, &zo, &zo).unwrap_err();
        assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
        let e = cd.reserve_contracted(&other).unwrap_err();
        assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
        let e = Data::new(&m).reserve_second_order(&other).unwrap_err();
        assert!(matches!(e, Error::Workspace(_)), "{e}");
    }
}
