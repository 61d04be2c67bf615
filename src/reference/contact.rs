//! Generic reference contact dynamics: point-contact Jacobians and drifts, constrained inverse
//! dynamics, KKT (constrained forward) dynamics and impact dynamics, plus their `f64`
//! derivative oracles (first order with [`Dual64`], second order with [`HyperDual64`]).
//!
//! A contact ([`Contact`]) is a point fixed in a frame. Per contact `c`, rows `3c..3c+3` of the
//! contact Jacobian `J` are the **world-aligned** linear velocity of the point per unit `q̇`,
//! and `λ` (`3·nc`) stacks the world-frame forces applied **to the robot** at the points:
//!
//! * constrained inverse dynamics: `τ = M q̈ + b − Jᵀ λ` ([`constrained_rnea`]);
//! * KKT dynamics: `[M Jᵀ; J 0] [q̈; −λ] = [τ − b; −J̇ q̇]` ([`kkt`]);
//! * impact dynamics with restitution `e`: `[M Jᵀ; J 0] [q̇⁺; −λ̂] = [M q̇⁻; −e J q̇⁻]`
//!   ([`impact`]), i.e. `J q̇⁺ = −e J q̇⁻` (Newton restitution, Pinocchio's `r_coeff`; the notes
//!   print `+e`, which agrees for the usual `e = 0`).
//!
//! Everything is re-derived from the model description with the reference's own kinematics
//! (joint subspaces, poses, a body-frame velocity/acceleration recursion) and its dense
//! [`solve`]; nothing from the optimised algorithms is used. The contact point is read from the
//! [`Contact`]'s fields only (frame index and coordinates).
//!
//! Derivative conventions are those of [`super::derivatives`]: tangent derivatives in `q`
//! (`q ⊕ ε e_j`), tensors `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)` with nested perturbations
//! `(q ⊕ δ e_k) ⊕ ε e_j` for two `q` derivatives; `λ` is held fixed in the world frame when
//! differentiating the constrained inverse dynamics.

use super::derivatives::{eps, eps1, eps2, hessian, jacobian, nested_q, perturb_q, seeded};
use super::dynamics::{mass_matrix, nle, rnea, solve};
use super::kinematics::{forward_kinematics, parent_poses, subspace_column, subspace_mul};
use super::reduced::Reduced;
use super::spatial::{Pose, Sv, cst, lift_m3, lift_v3};
use super::{AdScalar, lift, real};
use crate::model::Model;
use crate::model::{Contact, ContactReference, ContactType};
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, Matrix3, Vector3};
use num_dual::{Dual64, HyperDual64};

// ---------------------------------------------------------------------------------------------
// Kinematics of the contact points
// ---------------------------------------------------------------------------------------------

/// The joint whose body carries the contact and the contact frame's placement in that joint's
/// (child) frame (frame placement composed with the contact's rotation and point).
fn body_pose<T: AdScalar>(model: &Model, contact: &Contact) -> (usize, Pose<T>) {
    let f = &model.frames[contact.frame];
    let local = Pose::new(lift_m3(&contact.rotation), lift_v3(&contact.point));
    (f.joint, Pose::<T>::lift(&f.placement).compose(&local))
}

/// Frame B's body and the frame-B contact frame's placement in its joint frame (two-frame
/// constraints only).
fn body_pose2<T: AdScalar>(model: &Model, contact: &Contact) -> (usize, Pose<T>) {
    let f = &model.frames[contact.frame2.expect("a two-frame constraint")];
    let local = Pose::new(lift_m3(&contact.rotation2), lift_v3(&contact.point2));
    (f.joint, Pose::<T>::lift(&f.placement).compose(&local))
}

/// The world placements of frame A's and frame B's contact frames of a two-frame constraint.
fn loop_poses<T: AdScalar>(
    model: &Model,
    world: &[Pose<T>],
    contact: &Contact,
) -> (Pose<T>, Pose<T>) {
    let (a, la) = body_pose::<T>(model, contact);
    let (b, lb) = body_pose2::<T>(model, contact);
    (world[a].compose(&la), world[b].compose(&lb))
}

/// Total number of constraint rows (3 per 3-D contact, 6 per 6-D contact).
fn dim(contacts: &[Contact]) -> usize {
    contacts.iter().map(|c| c.kind.dim()).sum()
}

/// Appends a contact's rows given the world-aligned angular and linear parts at the contact
/// point: `lin` (3-D) or `[ang; lin]` (6-D), rotated into the contact axes (`Rᵀ`) for `local`.
fn push_rows<T: AdScalar>(
    contact: &Contact,
    rc: &Matrix3<T>,
    ang: Vector3<T>,
    lin: Vector3<T>,
    out: &mut Vec<T>,
) {
    let (ang, lin) = match contact.reference {
        ContactReference::LocalWorldAligned => (ang, lin),
        ContactReference::Local => {
            let rt = rc.transpose();
            (&rt * ang, &rt * lin)
        }
    };
    if contact.kind == ContactType::D6 {
        out.extend(ang.iter().cloned());
    }
    out.extend(lin.iter().cloned());
}

/// Column `c` of joint `joint`'s motion subspace, in its child frame.
fn subspace_sv<T: AdScalar>(model: &Model, joint: usize, c: usize) -> Sv<T> {
    let (a, l) = subspace_column(&model.joints[joint], c);
    Sv::new(lift_v3(&Vector3::from(a)), lift_v3(&Vector3::from(l)))
}

/// Contact Jacobian given the world poses of the bodies (rows as in the module documentation).
fn jacobian_from_poses<T: AdScalar>(
    model: &Model,
    world: &[Pose<T>],
    contacts: &[Contact],
) -> Vec<Vec<T>> {
    let mut jac = vec![vec![T::zero(); model.nv]; dim(contacts)];
    let mut row0 = 0;
    for contact in contacts {
        if contact.is_loop() {
            loop_jacobian_rows(model, world, contact, row0, &mut jac);
            row0 += contact.kind.dim();
            continue;
        }
        let (body, local) = body_pose::<T>(model, contact);
        let pose = world[body].compose(&local);
        let p = pose.trans.clone();
        let mut j = body;
        while j > 0 {
            for col in 0..model.nvs[j] {
                // World motion subspace column [ω; v_O] (about the world origin), then the
                // velocity of the point p: v_O + ω × p.
                let s = world[j].act_motion(&subspace_sv::<T>(model, j, col));
                let vp = &s.lin + s.ang.cross(&p);
                let mut rows = Vec::with_capacity(6);
                push_rows(contact, &pose.rot, s.ang, vp, &mut rows);
                for (r, x) in rows.into_iter().enumerate() {
                    jac[row0 + r][model.idx_v[j] + col] = x;
                }
            }
            j = model.parents[j];
        }
        row0 += contact.kind.dim();
    }
    jac
}

/// A two-frame constraint's Jacobian rows `row0..` (added into the zero rows of `jac`): the
/// chain of frame A's body with sign `+1`, that of frame B's body with `−1` (DoFs on both
/// cancel for `6d`); a `3d` row takes each chain's subspace at its own point, a `6d` row
/// both at frame A's point (Pinocchio's two-joint `RigidConstraintModel`).
fn loop_jacobian_rows<T: AdScalar>(
    model: &Model,
    world: &[Pose<T>],
    contact: &Contact,
    row0: usize,
    jac: &mut [Vec<T>],
) {
    let (pa, pb) = loop_poses(model, world, contact);
    let chains = [
        (body_pose::<T>(model, contact).0, &pa.trans, 1.0),
        (body_pose2::<T>(model, contact).0, &pb.trans, -1.0),
    ];
    for (body, p, sign) in chains {
        let mut j = body;
        while j > 0 {
            for col in 0..model.nvs[j] {
                let s = world[j].act_motion(&subspace_sv::<T>(model, j, col));
                let at = if contact.kind == ContactType::D6 { &pa.trans } else { p };
                let vp = &s.lin + s.ang.cross(at);
                let mut rows = Vec::with_capacity(6);
                push_rows(contact, &pa.rot, s.ang * cst::<T>(sign), vp * cst::<T>(sign), &mut rows);
                for (r, x) in rows.into_iter().enumerate() {
                    let e = &mut jac[row0 + r][model.idx_v[j] + col];
                    *e = e.clone() + x;
                }
            }
            j = model.parents[j];
        }
    }
}

/// Contact drift `J̇ q̇` given the parent-relative and world poses of the bodies.
fn drift_from_poses<T: AdScalar>(
    model: &Model,
    xs: &[Pose<T>],
    world: &[Pose<T>],
    v: &[T],
    contacts: &[Contact],
) -> Vec<T> {
    let n = model.joints.len();
    let mut vel: Vec<Sv<T>> = vec![Sv::zero(); n];
    let mut acc: Vec<Sv<T>> = vec![Sv::zero(); n];
    for i in 1..n {
        let p = model.parents[i];
        let (b, m) = (model.idx_v[i], model.nvs[i]);
        let vj = subspace_mul(&model.joints[i], &v[b..b + m]);
        vel[i] = xs[i].inv_act_motion(&vel[p]).add(&vj);
        // q̈ = 0: a_i = X a_p + v_i × S q̇_i (S is constant in the child frame).
        acc[i] = xs[i].inv_act_motion(&acc[p]).add(&vel[i].cross_motion(&vj));
    }
    let mut out = Vec::with_capacity(dim(contacts));
    for contact in contacts {
        if contact.is_loop() {
            let (pa, pb) = loop_poses(model, world, contact);
            let (a, _) = body_pose::<T>(model, contact);
            let (b, _) = body_pose2::<T>(model, contact);
            // World spatial velocities and accelerations (about the world origin).
            let (va, aa) = (world[a].act_motion(&vel[a]), world[a].act_motion(&acc[a]));
            let (vb, ab) = (world[b].act_motion(&vel[b]), world[b].act_motion(&acc[b]));
            let classical = |v: &Sv<T>, acc: &Sv<T>, p: &Vector3<T>| {
                &acc.lin + acc.ang.cross(p) + v.ang.cross(&(&v.lin + v.ang.cross(p)))
            };
            if contact.kind == ContactType::D3 {
                let lin = classical(&va, &aa, &pa.trans) - classical(&vb, &ab, &pb.trans);
                push_rows(contact, &pa.rot, Vector3::zeros(), lin, &mut out);
            } else {
                let mut w = aa.sub(&ab);
                if contact.reference == ContactReference::Local {
                    w = w.add(&va.sub(&vb).cross_motion(&vb));
                }
                let lin = &w.lin + w.ang.cross(&pa.trans);
                push_rows(contact, &pa.rot, w.ang, lin, &mut out);
            }
            continue;
        }
        let (body, local) = body_pose::<T>(model, contact);
        let r = local.trans.clone();
        let (vb, ab) = (&vel[body], &acc[body]);
        let w = &vb.ang;
        // Spatial and classical accelerations of the body-fixed point r, body coordinates.
        let a_s = &ab.lin + ab.ang.cross(&r);
        let a_p = &a_s + w.cross(&(&vb.lin + w.cross(&r)));
        // 6-D rows hold the spatial acceleration of the frame, 3-D rows the classical one of
        // the point (Pinocchio's constraint accelerations).
        let rb = &world[body].rot;
        let lin = rb * if contact.kind == ContactType::D6 { a_s } else { a_p };
        push_rows(contact, &(rb * &local.rot), rb * &ab.ang, lin, &mut out);
    }
    out
}

fn check_lengths(model: &Model, q: usize, v: &[(&str, usize)]) {
    assert_eq!(q, model.nq(), "reference::contact: q has the wrong length");
    for (what, n) in v {
        assert_eq!(*n, model.nv(), "reference::contact: {what} has the wrong length");
    }
}

/// Contact Jacobian `J(q)` (`3·nc × nv`, rows of a `Vec`): rows `3c..3c+3` are the
/// world-aligned linear velocity of contact point `c` per unit `q̇`.
///
/// Column `k` of dof `k` of an ancestor joint `j` of the contact body is `S.lin + S.ang × p`,
/// with `S` the world-frame motion subspace column of the dof (about the world origin) and `p`
/// the world position of the point; other columns are zero.
///
/// # Panics
/// If `q` has the wrong length or a contact's frame index is out of range.
pub fn contact_jacobian<T: AdScalar>(model: &Model, q: &[T], contacts: &[Contact]) -> Vec<Vec<T>> {
    check_lengths(model, q.len(), &[]);
    if let Some(r) = Reduced::of(model) {
        // J_full(expand(q)) G, row by row as Gᵀ of the row.
        let jf = contact_jacobian(r.full, &r.expand_q(q), contacts);
        return jf.iter().map(|row| r.reduce_force(row)).collect();
    }
    jacobian_from_poses(model, &forward_kinematics(model, q), contacts)
}

/// Contact drift `J̇(q, q̇) q̇` (`3·nc`): the world-aligned classical acceleration of each contact
/// point at `q̈ = 0`, without gravity.
///
/// Computed by a body-frame recursion `v_i = ⁱX_p v_p + S q̇_i`,
/// `a_i = ⁱX_p a_p + v_i × S q̇_i`, then `a_point = a.lin + a.ang × r + ω × (v.lin + ω × r)` for
/// the point `r` in the body frame, rotated to the world.
///
/// # Panics
/// If `q` or `v` has the wrong length or a contact's frame index is out of range.
pub fn contact_drift<T: AdScalar>(model: &Model, q: &[T], v: &[T], contacts: &[Contact]) -> Vec<T> {
    check_lengths(model, q.len(), &[("v", v.len())]);
    if let Some(r) = Reduced::of(model) {
        // G is constant: J̇ q̇ of the full tree at expand(q), G q̇.
        return contact_drift(r.full, &r.expand_q(q), &r.expand_v(v), contacts);
    }
    let xs = parent_poses(model, q);
    let world = forward_kinematics(model, q);
    drift_from_poses(model, &xs, &world, v, contacts)
}

/// Constrained inverse dynamics `τ = rnea(q, v, a) − Jᵀ λ`, `λ` (`3·nc`) stacking the
/// world-frame forces applied to the robot at the contact points.
///
/// Computed through [`rnea`]'s external forces: contact `c` on body `m` contributes the
/// world-frame spatial force `[p × λ_c; λ_c]` (moment about the world origin) to `fext[m]`.
///
/// # Panics
/// If a slice length does not match the model and contacts.
pub fn constrained_rnea<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    a: &[T],
    contacts: &[Contact],
    lambda: &[T],
) -> Vec<T> {
    check_lengths(model, q.len(), &[("v", v.len()), ("a", a.len())]);
    assert_eq!(lambda.len(), dim(contacts), "reference::contact: lambda needs one entry per row");
    if let Some(r) = Reduced::of(model) {
        // Gᵀ (rnea_full − J_fullᵀ λ).
        let (qf, vf, af) = (r.expand_q(q), r.expand_v(v), r.expand_v(a));
        return r.reduce_force(&constrained_rnea(r.full, &qf, &vf, &af, contacts, lambda));
    }
    let world = forward_kinematics(model, q);
    let mut fext: Vec<[T; 6]> = vec![std::array::from_fn(|_| T::zero()); model.joints.len()];
    let mut row0 = 0;
    for contact in contacts {
        let (body, local) = body_pose::<T>(model, contact);
        let pose = world[body].compose(&local);
        let p = pose.trans.clone();
        let d = contact.kind.dim();
        let part = |o: usize| {
            Vector3::new(
                lambda[row0 + o].clone(),
                lambda[row0 + o + 1].clone(),
                lambda[row0 + o + 2].clone(),
            )
        };
        let (n, f) = if d == 6 { (part(0), part(3)) } else { (Vector3::zeros(), part(0)) };
        // World-aligned moment and force at p, then the spatial force about the world origin.
        let (n, f) = match contact.reference {
            ContactReference::LocalWorldAligned => (n, f),
            ContactReference::Local => (&pose.rot * n, &pose.rot * f),
        };
        if contact.is_loop() {
            // λ acts on frame A's body, −λ on frame B's: a 3-D force at each frame's own point,
            // a 6-D wrench at frame A's point (the transposed rows of `loop_jacobian_rows`).
            // (n, f) are already world-aligned (frame A's rotation is `pose.rot`).
            let (pa, pb) = loop_poses(model, &world, contact);
            let (a, _) = body_pose::<T>(model, contact);
            let (b, _) = body_pose2::<T>(model, contact);
            let fa = Sv::new(&n + pa.trans.cross(&f), f.clone());
            let at_b = if d == 6 { &pa.trans } else { &pb.trans };
            let fb = Sv::new(n + at_b.cross(&f), f).scale(&cst::<T>(-1.0));
            fext[a] = Sv::from_array(&fext[a]).add(&fa).to_array();
            if b > 0 {
                fext[b] = Sv::from_array(&fext[b]).add(&fb).to_array();
            }
            row0 += d;
            continue;
        }
        let fw = Sv::new(n + p.cross(&f), f);
        fext[body] = Sv::from_array(&fext[body]).add(&fw).to_array();
        row0 += d;
    }
    rnea(model, q, v, a, Some(&fext))
}

/// The KKT matrix `[M Jᵀ; J 0]`.
fn kkt_matrix<T: AdScalar>(m: Vec<Vec<T>>, jac: &[Vec<T>]) -> Vec<Vec<T>> {
    let nv = m.len();
    let n = nv + jac.len();
    let mut k = vec![vec![T::zero(); n]; n];
    for (i, row) in m.into_iter().enumerate() {
        k[i][..nv].clone_from_slice(&row);
    }
    for (r, jr) in jac.iter().enumerate() {
        for (c, x) in jr.iter().enumerate() {
            k[nv + r][c] = x.clone();
            k[c][nv + r] = x.clone();
        }
    }
    k
}

/// Splits the solution `[x; −λ]` of a KKT system into `(x, λ)`.
fn split_solution<T: AdScalar>(mut sol: Vec<T>, nv: usize) -> (Vec<T>, Vec<T>) {
    let lambda = sol.split_off(nv).into_iter().map(|x| -x).collect();
    (sol, lambda)
}

/// KKT (contact-constrained forward) dynamics: solves
/// `[M Jᵀ; J 0] [q̈; −λ] = [τ − b; −J̇ q̇]` densely ([`solve`], partial pivoting) and returns
/// `(q̈, λ)`, `λ` being the world-frame contact forces applied to the robot, so that
/// `M q̈ + b = τ + Jᵀ λ` and `J q̈ + J̇ q̇ = 0`.
///
/// # Panics
/// If a slice length does not match the model, or the KKT matrix is singular (e.g. `J` without
/// full row rank).
pub fn kkt<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    tau: &[T],
    contacts: &[Contact],
) -> (Vec<T>, Vec<T>) {
    check_lengths(model, q.len(), &[("v", v.len()), ("tau", tau.len())]);
    if let Some(r) = Reduced::of(model) {
        // The full tree's drift and Baumgarte terms at expand(q), G q̇; J = J_full G.
        let (qf, vf) = (r.expand_q(q), r.expand_v(v));
        let world = forward_kinematics(r.full, &qf);
        let jf = jacobian_from_poses(r.full, &world, contacts);
        let mut drift = contact_drift(r.full, &qf, &vf, contacts);
        baumgarte(r.full, &qf, &vf, contacts, &world, &jf, &mut drift);
        let jac: Vec<Vec<T>> = jf.iter().map(|row| r.reduce_force(row)).collect();
        let b = nle(model, q, v);
        let mut rhs: Vec<T> = tau.iter().zip(b).map(|(t, b)| t.clone() - b).collect();
        rhs.extend(drift.into_iter().map(|x| -x));
        return split_solution(solve(kkt_matrix(mass_matrix(model, q), &jac), rhs), model.nv());
    }
    let xs = parent_poses(model, q);
    let world = forward_kinematics(model, q);
    let jac = jacobian_from_poses(model, &world, contacts);
    let mut drift = drift_from_poses(model, &xs, &world, v, contacts);
    baumgarte(model, q, v, contacts, &world, &jac, &mut drift);
    let b = nle(model, q, v);
    let mut rhs: Vec<T> = tau.iter().zip(b).map(|(t, b)| t.clone() - b).collect();
    rhs.extend(drift.into_iter().map(|x| -x));
    split_solution(solve(kkt_matrix(mass_matrix(model, q), &jac), rhs), model.nv())
}

/// Adds the Baumgarte terms `kd J q̇ + kp e` to the contact rows `rows`, with the reference
/// placement [`Contact::world_ref`] or else the contact frame's placement at the real part of
/// `q` (fixed); `e` as in the
/// documentation of [`crate::model::Contact`]'s module.
pub(crate) fn baumgarte<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    contacts: &[Contact],
    world: &[Pose<T>],
    jac: &[Vec<T>],
    rows: &mut [T],
) {
    if !contacts.iter().any(|c| c.kp != 0.0 || c.kd != 0.0) {
        return;
    }
    let world_ref = forward_kinematics(model, &real(q));
    let mut row0 = 0;
    for contact in contacts {
        if contact.is_loop() {
            // e = p₁ − p₂ (3-D; Pinocchio's −translation of ¹M₂ rotated to the world).
            assert!(
                contact.kp == 0.0 || contact.kind == ContactType::D3,
                "reference::contact: kp on a 6-D two-frame constraint is not implemented"
            );
            let (pa, pb) = loop_poses(model, world, contact);
            let e = match contact.reference {
                ContactReference::LocalWorldAligned => &pa.trans - &pb.trans,
                ContactReference::Local => pa.rot.transpose() * (&pa.trans - &pb.trans),
            };
            for k in 0..contact.kind.dim() {
                let r = row0 + k;
                let jv =
                    jac[r].iter().zip(v).fold(T::zero(), |s, (j, x)| s + j.clone() * x.clone());
                let ek = if contact.kp != 0.0 { e[k].clone() * contact.kp } else { T::zero() };
                rows[r] = rows[r].clone() + jv * contact.kd + ek;
            }
            row0 += contact.kind.dim();
            continue;
        }
        let (body, local) = body_pose::<T>(model, contact);
        let pose = world[body].compose(&local);
        let (_, local0) = body_pose::<f64>(model, contact);
        // The fixed reference: the contact's world reference, or its placement at real(q).
        let (pose0, general) = match &contact.world_ref {
            Some(x) => (Pose { rot: x.rot, trans: x.trans }, true),
            None => (world_ref[body].compose(&local0), false),
        };
        let (rc, p) = (&pose.rot, &pose.trans);
        let dp = p - lift_v3(&pose0.trans);
        let mut e = Vec::with_capacity(6);
        match contact.kind {
            ContactType::D3 => {
                let e3 = match contact.reference {
                    ContactReference::LocalWorldAligned => dp,
                    ContactReference::Local => rc.transpose() * dp,
                };
                e.extend(e3.iter().cloned());
            }
            ContactType::D6 => {
                let r0t = lift_m3(&pose0.rot.transpose());
                let (phi, rho) = if general {
                    log6_general(&(&r0t * rc), &(r0t * dp))
                } else {
                    log6_near_identity(&(&r0t * rc), &(r0t * dp))
                };
                let (phi, rho) = match contact.reference {
                    ContactReference::Local => (phi, rho),
                    ContactReference::LocalWorldAligned => (rc * phi, rc * rho),
                };
                e.extend(phi.iter().cloned());
                e.extend(rho.iter().cloned());
            }
        }
        for (k, ek) in e.into_iter().enumerate() {
            let r = row0 + k;
            let jv = jac[r].iter().zip(v).fold(T::zero(), |s, (j, x)| s + j.clone() * x.clone());
            rows[r] = rows[r].clone() + jv * contact.kd + ek * contact.kp;
        }
        row0 += contact.kind.dim();
    }
}

/// `log6` of a placement `(R, t)` whose real part is the identity (the Baumgarte error at its
/// reference): `φ = 2 atan2(|v|, w) v/|v|` from the quaternion `(w, v)` of `R`, and
/// `ρ = (I − ½[φ]× + c(θ)[φ]×²) t` with `c = (1 − θ sin θ / (2(1 − cos θ)))/θ²`; `atan(x)/x` and
/// `c` by their series in `x²`, `θ²` (no square root of a zero real part), exact to rounding for
/// the first and second derivatives at the identity.
fn log6_near_identity<T: AdScalar>(r: &Matrix3<T>, t: &Vector3<T>) -> (Vector3<T>, Vector3<T>) {
    let tr = r[(0, 0)].clone() + r[(1, 1)].clone() + r[(2, 2)].clone();
    let w = (tr + cst::<T>(1.0)).sqrt() * cst::<T>(0.5);
    let four_w = w.clone() * cst::<T>(4.0);
    let v = Vector3::new(
        (r[(2, 1)].clone() - r[(1, 2)].clone()) / four_w.clone(),
        (r[(0, 2)].clone() - r[(2, 0)].clone()) / four_w.clone(),
        (r[(1, 0)].clone() - r[(0, 1)].clone()) / four_w,
    );
    let x2 = v.dot(&v) / (w.clone() * w.clone());
    // atan(x)/x = 1 − x²/3 + x⁴/5 − x⁶/7 + x⁸/9.
    let mut atan_over = cst::<T>(1.0 / 9.0);
    for c in [-1.0 / 7.0, 1.0 / 5.0, -1.0 / 3.0, 1.0] {
        atan_over = atan_over * x2.clone() + cst::<T>(c);
    }
    let phi = v * (atan_over * cst::<T>(2.0) / w);
    let th2 = phi.dot(&phi);
    let c = cst::<T>(1.0 / 12.0)
        + th2.clone() * cst::<T>(1.0 / 720.0)
        + th2.clone() * th2 * cst::<T>(1.0 / 30240.0);
    let pt = phi.cross(t);
    let rho = t - pt.clone() * cst::<T>(0.5) + phi.cross(&pt) * c;
    (phi, rho)
}

/// `log6` of a placement `(R, t)` with a rotation angle `θ` in `(0, π)` (a world reference:
/// in general not the identity): `φ = 2 atan(|v|/w) v/|v|` from the quaternion `(w, v)` of `R`
/// and `ρ` as in [`log6_near_identity`] with `c` in closed form; for a real angle below
/// `1e-3` the near-identity series instead.
fn log6_general<T: AdScalar>(r: &Matrix3<T>, t: &Vector3<T>) -> (Vector3<T>, Vector3<T>) {
    let tr = r[(0, 0)].clone() + r[(1, 1)].clone() + r[(2, 2)].clone();
    let w = (tr + cst::<T>(1.0)).sqrt() * cst::<T>(0.5);
    let four_w = w.clone() * cst::<T>(4.0);
    let v = Vector3::new(
        (r[(2, 1)].clone() - r[(1, 2)].clone()) / four_w.clone(),
        (r[(0, 2)].clone() - r[(2, 0)].clone()) / four_w.clone(),
        (r[(1, 0)].clone() - r[(0, 1)].clone()) / four_w,
    );
    let s = v.dot(&v).sqrt();
    if s.re() < 5e-4 {
        return log6_near_identity(r, t);
    }
    let th = (s.clone() / w).atan() * cst::<T>(2.0);
    let phi = v * (th.clone() / s);
    let th2 = th.clone() * th.clone();
    let c = (cst::<T>(1.0) - th.clone() * th.sin() / ((cst::<T>(1.0) - th.cos()) * cst::<T>(2.0)))
        / th2;
    let pt = phi.cross(t);
    let rho = t - pt.clone() * cst::<T>(0.5) + phi.cross(&pt) * c;
    (phi, rho)
}

/// Impact dynamics with restitution coefficient `e`: solves
/// `[M Jᵀ; J 0] [q̇⁺; −λ̂] = [M q̇⁻; −e J q̇⁻]` and returns `(q̇⁺, λ̂)`, `λ̂` being the world-frame
/// contact impulses applied to the robot: `M (q̇⁺ − q̇⁻) = Jᵀ λ̂` and `J q̇⁺ = −e J q̇⁻`.
///
/// # Panics
/// If a slice length does not match the model, or the KKT matrix is singular.
pub fn impact<T: AdScalar>(
    model: &Model,
    q: &[T],
    vminus: &[T],
    contacts: &[Contact],
    e: f64,
) -> (Vec<T>, Vec<T>) {
    check_lengths(model, q.len(), &[("vminus", vminus.len())]);
    let m = mass_matrix(model, q);
    let jac = contact_jacobian(model, q, contacts);
    let matvec = |a: &[Vec<T>]| -> Vec<T> {
        a.iter()
            .map(|row| row.iter().zip(vminus).fold(T::zero(), |s, (x, y)| s + x.clone() * y))
            .collect()
    };
    let mut rhs = matvec(&m);
    rhs.extend(matvec(&jac).into_iter().map(|x| x * (-e)));
    split_solution(solve(kkt_matrix(m, &jac), rhs), model.nv())
}

// ---------------------------------------------------------------------------------------------
// Derivative oracles
// ---------------------------------------------------------------------------------------------

/// Rows `from..from + n` of a matrix.
fn rows(m: &DMatrix<f64>, from: usize, n: usize) -> DMatrix<f64> {
    m.rows(from, n).into_owned()
}

/// The sub-tensor of rows `from..from + n`.
fn tensor_rows(t: &Tensor3, from: usize, n: usize) -> Tensor3 {
    let (_, n2, n3) = t.dims();
    Tensor3::from_fn(n, n2, n3, |i, j, k| t.get(from + i, j, k))
}

/// `∂τ/∂q` (`nv × nv`, tangent) of [`constrained_rnea`], `λ` fixed in the world frame.
///
/// # Panics
/// As [`constrained_rnea`].
pub fn d_constrained_rnea_dq(
    model: &Model,
    q: &[f64],
    v: &[f64],
    a: &[f64],
    contacts: &[Contact],
    lambda: &[f64],
) -> DMatrix<f64> {
    let (v, a, l) = (lift::<Dual64>(v), lift::<Dual64>(a), lift::<Dual64>(lambda));
    jacobian(model.nv(), model.nv(), |j| {
        let qd = perturb_q(model, &lift::<Dual64>(q), j, eps());
        constrained_rnea(model, &qd, &v, &a, contacts, &l)
    })
}

/// `∂τ/∂v` (`nv × nv`) of [`constrained_rnea`] (equal to that of [`rnea`]).
///
/// # Panics
/// As [`constrained_rnea`].
pub fn d_constrained_rnea_dv(
    model: &Model,
    q: &[f64],
    v: &[f64],
    a: &[f64],
    contacts: &[Contact],
    lambda: &[f64],
) -> DMatrix<f64> {
    let (qd, a, l) = (lift::<Dual64>(q), lift::<Dual64>(a), lift::<Dual64>(lambda));
    jacobian(model.nv(), model.nv(), |j| {
        constrained_rnea(model, &qd, &seeded(v, j, eps()), &a, contacts, &l)
    })
}

/// `T[(i, j, k)] = ∂/∂q_k (∂τ_i/∂q_j)` of [`constrained_rnea`] at `(q ⊕ δ_k) ⊕ ε_j` (tangent,
/// nested), `λ` fixed in the world frame.
///
/// # Panics
/// As [`constrained_rnea`].
pub fn d2_constrained_rnea_dq2(
    model: &Model,
    q: &[f64],
    v: &[f64],
    a: &[f64],
    contacts: &[Contact],
    lambda: &[f64],
) -> Tensor3 {
    let n = model.nv();
    let (v, a) = (lift::<HyperDual64>(v), lift::<HyperDual64>(a));
    let l = lift::<HyperDual64>(lambda);
    hessian(n, n, n, |j, k| {
        constrained_rnea(model, &nested_q(model, q, j, k), &v, &a, contacts, &l)
    })
}

/// First-order derivatives of the KKT dynamics [`kkt`] (rows: outputs, columns: inputs;
/// tangent in `q`).
#[derive(Clone, Debug, PartialEq)]
pub struct KktFo {
    /// `∂q̈/∂q` (`nv × nv`).
    pub dqdd_dq: DMatrix<f64>,
    /// `∂q̈/∂v` (`nv × nv`).
    pub dqdd_dv: DMatrix<f64>,
    /// `∂q̈/∂τ` (`nv × nv`).
    pub dqdd_dtau: DMatrix<f64>,
    /// `∂λ/∂q` (`3·nc × nv`).
    pub dlambda_dq: DMatrix<f64>,
    /// `∂λ/∂v` (`3·nc × nv`).
    pub dlambda_dv: DMatrix<f64>,
    /// `∂λ/∂τ` (`3·nc × nv`).
    pub dlambda_dtau: DMatrix<f64>,
}

/// Second-order derivatives of the KKT dynamics [`kkt`]: tensors
/// `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)` (`y` = `q̈` (`nv`) or `λ` (`3·nc`)).
#[derive(Clone, Debug, PartialEq)]
pub struct KktSo {
    /// `∂/∂q_k (∂q̈_i/∂q_j)` at `(q ⊕ δ_k) ⊕ ε_j`.
    pub d2qdd_dq2: Tensor3,
    /// `∂²q̈_i/∂v_j∂v_k`.
    pub d2qdd_dv2: Tensor3,
    /// `∂/∂v_k (∂q̈_i/∂q_j)`.
    pub d2qdd_dqdv: Tensor3,
    /// `∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub d2qdd_dtaudq: Tensor3,
    /// `∂/∂q_k (∂λ_i/∂q_j)` at `(q ⊕ δ_k) ⊕ ε_j`.
    pub d2lambda_dq2: Tensor3,
    /// `∂²λ_i/∂v_j∂v_k`.
    pub d2lambda_dv2: Tensor3,
    /// `∂/∂v_k (∂λ_i/∂q_j)`.
    pub d2lambda_dqdv: Tensor3,
    /// `∂/∂q_k (∂λ_i/∂τ_j)`.
    pub d2lambda_dtaudq: Tensor3,
}

/// `[q̈; λ]` of [`kkt`] as one vector.
fn kkt_stacked<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    tau: &[T],
    contacts: &[Contact],
) -> Vec<T> {
    let (mut qdd, lambda) = kkt(model, q, v, tau, contacts);
    qdd.extend(lambda);
    qdd
}

/// First-order derivatives of [`kkt`] w.r.t. `q` (tangent), `v` and `τ` (forward-mode AD).
///
/// # Panics
/// As [`kkt`].
pub fn kkt_fo(model: &Model, q: &[f64], v: &[f64], tau: &[f64], contacts: &[Contact]) -> KktFo {
    let (nv, nout) = (model.nv(), model.nv() + dim(contacts));
    let (qd, vd, taud) = (lift::<Dual64>(q), lift::<Dual64>(v), lift::<Dual64>(tau));
    let dq = jacobian(nout, nv, |j| {
        kkt_stacked(model, &perturb_q(model, &qd, j, eps()), &vd, &taud, contacts)
    });
    let dv = jacobian(nout, nv, |j| kkt_stacked(model, &qd, &seeded(v, j, eps()), &taud, contacts));
    let dtau =
        jacobian(nout, nv, |j| kkt_stacked(model, &qd, &vd, &seeded(tau, j, eps()), contacts));
    let nl = nout - nv;
    KktFo {
        dqdd_dq: rows(&dq, 0, nv),
        dqdd_dv: rows(&dv, 0, nv),
        dqdd_dtau: rows(&dtau, 0, nv),
        dlambda_dq: rows(&dq, nv, nl),
        dlambda_dv: rows(&dv, nv, nl),
        dlambda_dtau: rows(&dtau, nv, nl),
    }
}

/// Second-order derivatives of [`kkt`] (hyper-dual AD; `nv²` KKT solves per tensor pair).
///
/// # Panics
/// As [`kkt`].
pub fn kkt_so(model: &Model, q: &[f64], v: &[f64], tau: &[f64], contacts: &[Contact]) -> KktSo {
    let (n, nout) = (model.nv(), model.nv() + dim(contacts));
    let (qh, vh, tauh) = (lift::<HyperDual64>(q), lift::<HyperDual64>(v), lift::<HyperDual64>(tau));
    let dq2 = hessian(nout, n, n, |j, k| {
        kkt_stacked(model, &nested_q(model, q, j, k), &vh, &tauh, contacts)
    });
    let dv2 = hessian(nout, n, n, |j, k| {
        let mut vjk = seeded(v, j, eps1());
        vjk[k] += eps2();
        kkt_stacked(model, &qh, &vjk, &tauh, contacts)
    });
    let dqdv = hessian(nout, n, n, |j, k| {
        let qj = perturb_q(model, &qh, j, eps1());
        kkt_stacked(model, &qj, &seeded(v, k, eps2()), &tauh, contacts)
    });
    let dtaudq = hessian(nout, n, n, |j, k| {
        let qk = perturb_q(model, &qh, k, eps2());
        kkt_stacked(model, &qk, &vh, &seeded(tau, j, eps1()), contacts)
    });
    let nl = nout - n;
    KktSo {
        d2qdd_dq2: tensor_rows(&dq2, 0, n),
        d2qdd_dv2: tensor_rows(&dv2, 0, n),
        d2qdd_dqdv: tensor_rows(&dqdv, 0, n),
        d2qdd_dtaudq: tensor_rows(&dtaudq, 0, n),
        d2lambda_dq2: tensor_rows(&dq2, n, nl),
        d2lambda_dv2: tensor_rows(&dv2, n, nl),
        d2lambda_dqdv: tensor_rows(&dqdv, n, nl),
        d2lambda_dtaudq: tensor_rows(&dtaudq, n, nl),
    }
}

/// First-order derivatives of the impact dynamics [`impact`] (rows: outputs, columns: inputs;
/// tangent in `q`).
#[derive(Clone, Debug, PartialEq)]
pub struct ImpactFo {
    /// `∂q̇⁺/∂q` (`nv × nv`).
    pub dvplus_dq: DMatrix<f64>,
    /// `∂q̇⁺/∂q̇⁻` (`nv × nv`; Pinocchio stores this minus the identity).
    pub dvplus_dvminus: DMatrix<f64>,
    /// `∂λ̂/∂q` (`3·nc × nv`).
    pub dimpulse_dq: DMatrix<f64>,
    /// `∂λ̂/∂q̇⁻` (`3·nc × nv`).
    pub dimpulse_dvminus: DMatrix<f64>,
}

/// Second-order derivatives of the impact dynamics [`impact`]: tensors
/// `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)`. The second derivatives w.r.t. `q̇⁻` twice vanish
/// identically (the outputs are linear in `q̇⁻`).
#[derive(Clone, Debug, PartialEq)]
pub struct ImpactSo {
    /// `∂/∂q_k (∂q̇⁺_i/∂q_j)` at `(q ⊕ δ_k) ⊕ ε_j`.
    pub d2vplus_dq2: Tensor3,
    /// `∂/∂q̇⁻_k (∂q̇⁺_i/∂q_j)`.
    pub d2vplus_dqdvminus: Tensor3,
    /// `∂/∂q_k (∂λ̂_i/∂q_j)` at `(q ⊕ δ_k) ⊕ ε_j`.
    pub d2impulse_dq2: Tensor3,
    /// `∂/∂q̇⁻_k (∂λ̂_i/∂q_j)`.
    pub d2impulse_dqdvminus: Tensor3,
}

/// `[q̇⁺; λ̂]` of [`impact`] as one vector.
fn impact_stacked<T: AdScalar>(
    model: &Model,
    q: &[T],
    vminus: &[T],
    contacts: &[Contact],
    e: f64,
) -> Vec<T> {
    let (mut vplus, impulse) = impact(model, q, vminus, contacts, e);
    vplus.extend(impulse);
    vplus
}

/// First-order derivatives of [`impact`] w.r.t. `q` (tangent) and `q̇⁻`.
///
/// # Panics
/// As [`impact`].
pub fn impact_fo(
    model: &Model,
    q: &[f64],
    vminus: &[f64],
    contacts: &[Contact],
    e: f64,
) -> ImpactFo {
    let (nv, nout) = (model.nv(), model.nv() + dim(contacts));
    let (qd, vd) = (lift::<Dual64>(q), lift::<Dual64>(vminus));
    let dq = jacobian(nout, nv, |j| {
        impact_stacked(model, &perturb_q(model, &qd, j, eps()), &vd, contacts, e)
    });
    let dv =
        jacobian(nout, nv, |j| impact_stacked(model, &qd, &seeded(vminus, j, eps()), contacts, e));
    let nl = nout - nv;
    ImpactFo {
        dvplus_dq: rows(&dq, 0, nv),
        dvplus_dvminus: rows(&dv, 0, nv),
        dimpulse_dq: rows(&dq, nv, nl),
        dimpulse_dvminus: rows(&dv, nv, nl),
    }
}

/// Second-order derivatives of [`impact`] (hyper-dual AD).
///
/// # Panics
/// As [`impact`].
pub fn impact_so(
    model: &Model,
    q: &[f64],
    vminus: &[f64],
    contacts: &[Contact],
    e: f64,
) -> ImpactSo {
    let (n, nout) = (model.nv(), model.nv() + dim(contacts));
    let (qh, vh) = (lift::<HyperDual64>(q), lift::<HyperDual64>(vminus));
    let dq2 = hessian(nout, n, n, |j, k| {
        impact_stacked(model, &nested_q(model, q, j, k), &vh, contacts, e)
    });
    let dqdv = hessian(nout, n, n, |j, k| {
        let qj = perturb_q(model, &qh, j, eps1());
        impact_stacked(model, &qj, &seeded(vminus, k, eps2()), contacts, e)
    });
    let nl = nout - n;
    ImpactSo {
        d2vplus_dq2: tensor_rows(&dq2, 0, n),
        d2vplus_dqdvminus: tensor_rows(&dqdv, 0, n),
        d2impulse_dq2: tensor_rows(&dq2, n, nl),
        d2impulse_dqdvminus: tensor_rows(&dqdv, n, nl),
    }
}
