//! The oracle of the models in reduced coordinates (mimic joints,
//! [`Model::with_mimic_joints`](crate::model::Model::with_mimic_joints)): the reference dynamics
//! of the full tree composed with the mimic expansion, in any scalar.
//!
//! [`Reduced`] re-derives the reduced coordinates from the list of [`MimicJoint`]s and the
//! model's index tables alone (not from the reduction that a reduced [`Model`] carries): `q_full = expand(q)`
//! (independent coordinates copied, `m · q_ref + c` for each mimic joint), `v_full = G v`,
//! `τ = Gᵀ τ_full`. Its `f64` oracles differentiate these compositions with dual and
//! hyper-dual numbers, `q` in the tangent space of the reduced configuration
//! (`(q ⊕ δ_k) ⊕ ε_j` for the second order, as [`super::derivatives`]).

use super::contact::{baumgarte, constrained_rnea, contact_drift, contact_jacobian};
use super::derivatives::{eps, eps1, eps2, hessian, jacobian};
use super::dynamics::{rnea, rnea_with_gravity, solve};
use super::kinematics::{forward_kinematics, integrate};
use super::{AdScalar, lift};
use crate::model::MimicJoint;
use crate::model::{Contact, Model};
use crate::tensor::Tensor3;
use nalgebra::DMatrix;
use num_dual::{Dual64, HyperDual64};

/// A full model and its mimic constraints, seen in the reduced coordinates.
#[derive(Clone, Copy, Debug)]
pub struct Reduced<'a> {
    /// The full tree (every joint independent).
    pub full: &'a Model,
    /// The constraints.
    pub mimics: &'a [MimicJoint],
}

impl Reduced<'_> {
    /// The constraint of joint `i`, if it is a mimic joint.
    fn mimic_of(&self, i: usize) -> Option<&MimicJoint> {
        self.mimics.iter().find(|m| m.joint == i)
    }
    /// Reduced `(idx_q, idx_v)` of each joint (`None` for a mimic joint), and `(nq, nv)`.
    fn layout(&self) -> (Vec<Option<(usize, usize)>>, usize, usize) {
        let m = self.full;
        let (mut nq, mut nv) = (0, 0);
        let mut out = vec![None; m.njoints()];
        for (i, o) in out.iter_mut().enumerate().skip(1) {
            if self.mimic_of(i).is_none() {
                *o = Some((nq, nv));
                nq += m.nqs()[i];
                nv += m.nvs()[i];
            }
        }
        (out, nq, nv)
    }
    /// Reduced configuration dimension.
    pub fn nq(&self) -> usize {
        self.layout().1
    }
    /// Reduced velocity dimension.
    pub fn nv(&self) -> usize {
        self.layout().2
    }
    /// `expand(q)`.
    pub fn expand_q<T: AdScalar>(&self, q: &[T]) -> Vec<T> {
        let m = self.full;
        let (lay, ..) = self.layout();
        let mut out = vec![T::zero(); m.nq()];
        for i in 1..m.njoints() {
            let a = m.idx_q()[i];
            match (lay[i], self.mimic_of(i)) {
                (Some((r, _)), _) => out[a..a + m.nqs()[i]].clone_from_slice(&q[r..r + m.nqs()[i]]),
                (None, Some(mm)) => {
                    let (r, _) = lay[mm.reference].expect("reference joints are independent");
                    out[a] = q[r].clone() * mm.multiplier + mm.offset;
                }
                (None, None) => unreachable!(),
            }
        }
        out
    }
    /// `G v`.
    pub fn expand_v<T: AdScalar>(&self, v: &[T]) -> Vec<T> {
        let m = self.full;
        let (lay, ..) = self.layout();
        let mut out = vec![T::zero(); m.nv()];
        for i in 1..m.njoints() {
            let a = m.idx_v()[i];
            match (lay[i], self.mimic_of(i)) {
                (Some((_, r)), _) => out[a..a + m.nvs()[i]].clone_from_slice(&v[r..r + m.nvs()[i]]),
                (None, Some(mm)) => {
                    let (_, r) = lay[mm.reference].expect("reference joints are independent");
                    out[a] = v[r].clone() * mm.multiplier;
                }
                (None, None) => unreachable!(),
            }
        }
        out
    }
    /// `Gᵀ f`.
    pub fn reduce_force<T: AdScalar>(&self, f: &[T]) -> Vec<T> {
        let m = self.full;
        let (lay, _, nv) = self.layout();
        let mut out = vec![T::zero(); nv];
        for i in 1..m.njoints() {
            let a = m.idx_v()[i];
            match (lay[i], self.mimic_of(i)) {
                (Some((_, r)), _) => {
                    for c in 0..m.nvs()[i] {
                        out[r + c] += f[a + c].clone();
                    }
                }
                (None, Some(mm)) => {
                    let (_, r) = lay[mm.reference].expect("reference joints are independent");
                    out[r] += f[a].clone() * mm.multiplier;
                }
                (None, None) => unreachable!(),
            }
        }
        out
    }
    /// `q ⊕ δ` in the reduced coordinates: the independent coordinates of
    /// `expand(q) ⊕ G δ`.
    pub fn integrate<T: AdScalar>(&self, q: &[T], delta: &[T]) -> Vec<T> {
        let m = self.full;
        let qf = integrate(m, &self.expand_q(q), &self.expand_v(delta));
        let (lay, nq, _) = self.layout();
        let mut out = vec![T::zero(); nq];
        for i in 1..m.njoints() {
            if let Some((r, _)) = lay[i] {
                let a = m.idx_q()[i];
                out[r..r + m.nqs()[i]].clone_from_slice(&qf[a..a + m.nqs()[i]]);
            }
        }
        out
    }
    /// Inverse dynamics `Gᵀ τ_full(expand(q), G v, G a)` (reference RNEA of the full model).
    pub fn rnea<T: AdScalar>(&self, q: &[T], v: &[T], a: &[T]) -> Vec<T> {
        let tf = rnea(self.full, &self.expand_q(q), &self.expand_v(v), &self.expand_v(a), None);
        self.reduce_force(&tf)
    }
    /// The reduced mass matrix by unit reduced accelerations (zero velocity and gravity).
    pub fn mass_matrix<T: AdScalar>(&self, q: &[T]) -> Vec<Vec<T>> {
        let n = self.nv();
        let qf = self.expand_q(q);
        let zero = vec![T::zero(); self.full.nv()];
        let mut m = vec![vec![T::zero(); n]; n];
        for j in 0..n {
            let mut e = vec![T::zero(); n];
            e[j] = T::one();
            let col = rnea_with_gravity(self.full, &qf, &zero, &self.expand_v(&e), None, false);
            for (i, x) in self.reduce_force(&col).into_iter().enumerate() {
                m[i][j] = x;
            }
        }
        m
    }
    /// Forward dynamics `M⁻¹(τ − rnea(q, v, 0))` by a dense solve.
    pub fn aba<T: AdScalar>(&self, q: &[T], v: &[T], tau: &[T]) -> Vec<T> {
        let zero = vec![T::zero(); self.nv()];
        let b = self.rnea(q, v, &zero);
        let rhs: Vec<T> = tau.iter().zip(b).map(|(t, b)| t.clone() - b).collect();
        solve(self.mass_matrix(q), rhs)
    }
    fn perturb<T: AdScalar>(&self, q: &[T], j: usize, d: T) -> Vec<T> {
        let mut delta = vec![T::zero(); self.nv()];
        delta[j] = d;
        self.integrate(q, &delta)
    }
    fn nested(&self, q: &[f64], j: usize, k: usize) -> Vec<HyperDual64> {
        let q1 = self.perturb(&lift::<HyperDual64>(q), k, eps2());
        self.perturb(&q1, j, eps1())
    }

    /// `∂τ/∂q` (tangent).
    pub fn d_rnea_dq(&self, q: &[f64], v: &[f64], a: &[f64]) -> DMatrix<f64> {
        let n = self.nv();
        let (v, a) = (lift::<Dual64>(v), lift::<Dual64>(a));
        jacobian(n, n, |j| self.rnea(&self.perturb(&lift::<Dual64>(q), j, eps()), &v, &a))
    }
    /// `∂τ/∂v`.
    pub fn d_rnea_dv(&self, q: &[f64], v: &[f64], a: &[f64]) -> DMatrix<f64> {
        let n = self.nv();
        let (qd, a) = (lift::<Dual64>(q), lift::<Dual64>(a));
        jacobian(n, n, |j| self.rnea(&qd, &seeded(v, j, eps()), &a))
    }
    /// `∂q̈/∂q` (tangent).
    pub fn d_aba_dq(&self, q: &[f64], v: &[f64], tau: &[f64]) -> DMatrix<f64> {
        let n = self.nv();
        let (v, t) = (lift::<Dual64>(v), lift::<Dual64>(tau));
        jacobian(n, n, |j| self.aba(&self.perturb(&lift::<Dual64>(q), j, eps()), &v, &t))
    }
    /// `∂q̈/∂v`.
    pub fn d_aba_dv(&self, q: &[f64], v: &[f64], tau: &[f64]) -> DMatrix<f64> {
        let n = self.nv();
        let (qd, t) = (lift::<Dual64>(q), lift::<Dual64>(tau));
        jacobian(n, n, |j| self.aba(&qd, &seeded(v, j, eps()), &t))
    }
    /// `∂q̈/∂τ`.
    pub fn d_aba_dtau(&self, q: &[f64], v: &[f64], tau: &[f64]) -> DMatrix<f64> {
        let n = self.nv();
        let (qd, vd) = (lift::<Dual64>(q), lift::<Dual64>(v));
        jacobian(n, n, |j| self.aba(&qd, &vd, &seeded(tau, j, eps())))
    }
    /// `∂²τ/∂q²` (nested tangent).
    pub fn d2_rnea_dq2(&self, q: &[f64], v: &[f64], a: &[f64]) -> Tensor3 {
        let n = self.nv();
        let (v, a) = (lift::<HyperDual64>(v), lift::<HyperDual64>(a));
        hessian(n, n, n, |j, k| self.rnea(&self.nested(q, j, k), &v, &a))
    }
    /// `∂²τ/∂v²`.
    pub fn d2_rnea_dv2(&self, q: &[f64], v: &[f64], a: &[f64]) -> Tensor3 {
        let n = self.nv();
        let (qh, a) = (lift::<HyperDual64>(q), lift::<HyperDual64>(a));
        hessian(n, n, n, |j, k| {
            let mut vh = seeded(v, j, eps1());
            vh[k] += eps2();
            self.rnea(&qh, &vh, &a)
        })
    }
    /// `∂/∂v_k (∂τ_i/∂q_j)`.
    pub fn d2_rnea_dqdv(&self, q: &[f64], v: &[f64], a: &[f64]) -> Tensor3 {
        let n = self.nv();
        let a = lift::<HyperDual64>(a);
        hessian(n, n, n, |j, k| {
            let qh = self.perturb(&lift::<HyperDual64>(q), j, eps1());
            self.rnea(&qh, &seeded(v, k, eps2()), &a)
        })
    }
    /// `∂M_ij/∂q_k` (tangent).
    #[allow(non_snake_case)]
    pub fn dM_dq(&self, q: &[f64]) -> Tensor3 {
        let n = self.nv();
        let mut t = Tensor3::zeros(n, n, n);
        for k in 0..n {
            let m = self.mass_matrix(&self.perturb(&lift::<Dual64>(q), k, eps()));
            for (i, row) in m.iter().enumerate() {
                for (j, x) in row.iter().enumerate() {
                    t.set(i, j, k, x.eps);
                }
            }
        }
        t
    }
    /// `M(q) x = Gᵀ rnea_full(expand(q), 0, G x)` without gravity (the reduced mass matrix
    /// times `x`, for IDFOZA and IDSOZA).
    pub fn mass_times<T: AdScalar>(&self, q: &[T], x: &[T]) -> Vec<T> {
        let qf = self.expand_q(q);
        let zero = vec![T::zero(); self.full.nv()];
        let f = rnea_with_gravity(self.full, &qf, &zero, &self.expand_v(x), None, false);
        self.reduce_force(&f)
    }
    /// `∂(M x)/∂q` (tangent; the oracle of [`crate::deriv::idfoza`] on a reduced model).
    pub fn d_mass_times_dq(&self, q: &[f64], x: &[f64]) -> DMatrix<f64> {
        let n = self.nv();
        let xd = lift::<Dual64>(x);
        jacobian(n, n, |j| self.mass_times(&self.perturb(&lift::<Dual64>(q), j, eps()), &xd))
    }
    /// `∂²(M x)/∂q²` (nested tangent; the oracle of [`crate::deriv::idsoza`] on a reduced model).
    pub fn d2_mass_times_dq2(&self, q: &[f64], x: &[f64]) -> Tensor3 {
        let n = self.nv();
        let xh = lift::<HyperDual64>(x);
        hessian(n, n, n, |j, k| self.mass_times(&self.nested(q, j, k), &xh))
    }
    /// `∂²q̈/∂q²` (nested tangent).
    pub fn d2_aba_dq2(&self, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
        let n = self.nv();
        let (v, t) = (lift::<HyperDual64>(v), lift::<HyperDual64>(tau));
        hessian(n, n, n, |j, k| self.aba(&self.nested(q, j, k), &v, &t))
    }
    /// `∂²q̈/∂v²`.
    pub fn d2_aba_dv2(&self, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
        let n = self.nv();
        let (qh, t) = (lift::<HyperDual64>(q), lift::<HyperDual64>(tau));
        hessian(n, n, n, |j, k| {
            let mut vh = seeded(v, j, eps1());
            vh[k] += eps2();
            self.aba(&qh, &vh, &t)
        })
    }
    /// `∂/∂v_k (∂q̈_i/∂q_j)`.
    pub fn d2_aba_dqdv(&self, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
        let n = self.nv();
        let t = lift::<HyperDual64>(tau);
        hessian(n, n, n, |j, k| {
            let qh = self.perturb(&lift::<HyperDual64>(q), j, eps1());
            self.aba(&qh, &seeded(v, k, eps2()), &t)
        })
    }
    /// `∂(M⁻¹)_ij/∂q_k`.
    pub fn d2_aba_dtaudq(&self, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
        let n = self.nv();
        let vh = lift::<HyperDual64>(v);
        hessian(n, n, n, |j, k| {
            let qh = self.perturb(&lift::<HyperDual64>(q), k, eps2());
            self.aba(&qh, &vh, &seeded(tau, j, eps1()))
        })
    }
}

/// Contact dynamics in the reduced coordinates (the oracle of [`crate::deriv::kkt_derivatives`]
/// and [`crate::deriv::constrained_id_derivatives`] on a reduced model).
impl Reduced<'_> {
    /// `J(expand(q)) G` (rows of a `Vec`), the contact Jacobian of the reduced coordinates.
    pub fn contact_jacobian<T: AdScalar>(&self, q: &[T], contacts: &[Contact]) -> Vec<Vec<T>> {
        let jf = contact_jacobian(self.full, &self.expand_q(q), contacts);
        jf.iter().map(|row| self.reduce_force(row)).collect()
    }
    /// Constrained inverse dynamics `Gᵀ constrained_rnea(expand(q), G v, G a, λ)`.
    pub fn constrained_rnea<T: AdScalar>(
        &self,
        q: &[T],
        v: &[T],
        a: &[T],
        contacts: &[Contact],
        lambda: &[T],
    ) -> Vec<T> {
        let (qf, vf, af) = (self.expand_q(q), self.expand_v(v), self.expand_v(a));
        self.reduce_force(&constrained_rnea(self.full, &qf, &vf, &af, contacts, lambda))
    }
    /// KKT dynamics `[M Jrᵀ; Jr 0] [q̈; −λ] = [τ − b; −γ]` in the reduced coordinates
    /// (`Jr = J G`, `γ` the full tree's drift with its Baumgarte terms at `(expand(q), G v)`),
    /// solved densely; returns `(q̈, λ)`.
    pub fn kkt<T: AdScalar>(
        &self,
        q: &[T],
        v: &[T],
        tau: &[T],
        contacts: &[Contact],
    ) -> (Vec<T>, Vec<T>) {
        let (qf, vf) = (self.expand_q(q), self.expand_v(v));
        let jf = contact_jacobian(self.full, &qf, contacts);
        let mut gamma = contact_drift(self.full, &qf, &vf, contacts);
        let world = forward_kinematics(self.full, &qf);
        baumgarte(self.full, &qf, &vf, contacts, &world, &jf, &mut gamma);
        let jr: Vec<Vec<T>> = jf.iter().map(|row| self.reduce_force(row)).collect();
        let n = self.nv();
        let zero = vec![T::zero(); n];
        let b = self.rnea(q, v, &zero);
        let mut k = vec![vec![T::zero(); n + jr.len()]; n + jr.len()];
        for (i, row) in self.mass_matrix(q).into_iter().enumerate() {
            k[i][..n].clone_from_slice(&row);
        }
        for (r, row) in jr.iter().enumerate() {
            for (c, x) in row.iter().enumerate() {
                k[n + r][c] = x.clone();
                k[c][n + r] = x.clone();
            }
        }
        let mut rhs: Vec<T> = tau.iter().zip(b).map(|(t, b)| t.clone() - b).collect();
        rhs.extend(gamma.into_iter().map(|x| -x));
        let mut sol = solve(k, rhs);
        let lambda = sol.split_off(n).into_iter().map(|x| -x).collect();
        (sol, lambda)
    }
    fn kkt_stacked<T: AdScalar>(&self, q: &[T], v: &[T], tau: &[T], c: &[Contact]) -> Vec<T> {
        let (mut qdd, lambda) = self.kkt(q, v, tau, c);
        qdd.extend(lambda);
        qdd
    }
    /// First-order derivatives of [`Reduced::kkt`]: `[∂q̈/∂x; ∂λ/∂x]` (`(nv + m) × nv`) for
    /// `x` = `q` (tangent), `v`, `τ`.
    pub fn kkt_fo(
        &self,
        q: &[f64],
        v: &[f64],
        tau: &[f64],
        contacts: &[Contact],
    ) -> [DMatrix<f64>; 3] {
        let n = self.nv();
        let nout = n + contacts.iter().map(|c| c.dim()).sum::<usize>();
        let (qd, vd, td) = (lift::<Dual64>(q), lift::<Dual64>(v), lift::<Dual64>(tau));
        [
            jacobian(nout, n, |j| {
                self.kkt_stacked(&self.perturb(&qd, j, eps()), &vd, &td, contacts)
            }),
            jacobian(nout, n, |j| self.kkt_stacked(&qd, &seeded(v, j, eps()), &td, contacts)),
            jacobian(nout, n, |j| self.kkt_stacked(&qd, &vd, &seeded(tau, j, eps()), contacts)),
        ]
    }
    /// Second-order derivatives of [`Reduced::kkt`]: `[q̈; λ]` rows (`(nv + m) × nv × nv`) of
    /// `∂²/∂q²` (nested tangent), `∂²/∂v²`, `∂/∂v_k(∂/∂q_j)`, `∂/∂q_k(∂/∂τ_j)`.
    pub fn kkt_so(&self, q: &[f64], v: &[f64], tau: &[f64], contacts: &[Contact]) -> [Tensor3; 4] {
        let n = self.nv();
        let nout = n + contacts.iter().map(|c| c.dim()).sum::<usize>();
        let (qh, vh, th) =
            (lift::<HyperDual64>(q), lift::<HyperDual64>(v), lift::<HyperDual64>(tau));
        [
            hessian(nout, n, n, |j, k| self.kkt_stacked(&self.nested(q, j, k), &vh, &th, contacts)),
            hessian(nout, n, n, |j, k| {
                let mut vjk = seeded(v, j, eps1());
                vjk[k] += eps2();
                self.kkt_stacked(&qh, &vjk, &th, contacts)
            }),
            hessian(nout, n, n, |j, k| {
                let qj = self.perturb(&qh, j, eps1());
                self.kkt_stacked(&qj, &seeded(v, k, eps2()), &th, contacts)
            }),
            hessian(nout, n, n, |j, k| {
                let qk = self.perturb(&qh, k, eps2());
                self.kkt_stacked(&qk, &vh, &seeded(tau, j, eps1()), contacts)
            }),
        ]
    }
    /// Impact dynamics in the reduced coordinates: `[M Jrᵀ; Jr 0] [q̇⁺; −λ̂] = [M q̇⁻; −e Jr q̇⁻]`
    /// solved densely; returns `(q̇⁺, λ̂)`.
    pub fn impact<T: AdScalar>(
        &self,
        q: &[T],
        vminus: &[T],
        contacts: &[Contact],
        e: f64,
    ) -> (Vec<T>, Vec<T>) {
        let n = self.nv();
        let jr = self.contact_jacobian(q, contacts);
        let mm = self.mass_matrix(q);
        let matvec = |a: &[Vec<T>]| -> Vec<T> {
            a.iter()
                .map(|row| row.iter().zip(vminus).fold(T::zero(), |s, (x, y)| s + x.clone() * y))
                .collect()
        };
        let mut rhs = matvec(&mm);
        rhs.extend(matvec(&jr).into_iter().map(|x| x * (-e)));
        let mut k = vec![vec![T::zero(); n + jr.len()]; n + jr.len()];
        for (i, row) in mm.into_iter().enumerate() {
            k[i][..n].clone_from_slice(&row);
        }
        for (r, row) in jr.iter().enumerate() {
            for (c, x) in row.iter().enumerate() {
                k[n + r][c] = x.clone();
                k[c][n + r] = x.clone();
            }
        }
        let mut sol = solve(k, rhs);
        let impulse = sol.split_off(n).into_iter().map(|x| -x).collect();
        (sol, impulse)
    }
    /// First-order derivatives of [`Reduced::impact`]: `[∂q̇⁺/∂x; ∂λ̂/∂x]` for `x` = `q`
    /// (tangent), `q̇⁻`.
    pub fn impact_fo(
        &self,
        q: &[f64],
        vminus: &[f64],
        contacts: &[Contact],
        e: f64,
    ) -> [DMatrix<f64>; 2] {
        let n = self.nv();
        let nout = n + contacts.iter().map(|c| c.dim()).sum::<usize>();
        let (qd, vd) = (lift::<Dual64>(q), lift::<Dual64>(vminus));
        let stacked = |q: &[Dual64], v: &[Dual64]| {
            let (mut a, b) = self.impact(q, v, contacts, e);
            a.extend(b);
            a
        };
        [
            jacobian(nout, n, |j| stacked(&self.perturb(&qd, j, eps()), &vd)),
            jacobian(nout, n, |j| stacked(&qd, &seeded(vminus, j, eps()))),
        ]
    }
    /// Second-order derivatives of [`Reduced::impact`]: `[q̇⁺; λ̂]` rows of `∂²/∂q²` (nested
    /// tangent) and `∂/∂q̇⁻_k (∂/∂q_j)`.
    pub fn impact_so(
        &self,
        q: &[f64],
        vminus: &[f64],
        contacts: &[Contact],
        e: f64,
    ) -> [Tensor3; 2] {
        let n = self.nv();
        let nout = n + contacts.iter().map(|c| c.dim()).sum::<usize>();
        let (qh, vh) = (lift::<HyperDual64>(q), lift::<HyperDual64>(vminus));
        let stacked = |q: &[HyperDual64], v: &[HyperDual64]| {
            let (mut a, b) = self.impact(q, v, contacts, e);
            a.extend(b);
            a
        };
        [
            hessian(nout, n, n, |j, k| stacked(&self.nested(q, j, k), &vh)),
            hessian(nout, n, n, |j, k| {
                let qj = self.perturb(&qh, j, eps1());
                stacked(&qj, &seeded(vminus, k, eps2()))
            }),
        ]
    }
    /// `∂τ/∂q`, `∂τ/∂v` of [`Reduced::constrained_rnea`] (`λ` fixed).
    pub fn d_constrained_rnea(
        &self,
        q: &[f64],
        v: &[f64],
        a: &[f64],
        contacts: &[Contact],
        lambda: &[f64],
    ) -> [DMatrix<f64>; 2] {
        let n = self.nv();
        let (qd, vd, ad, ld) =
            (lift::<Dual64>(q), lift::<Dual64>(v), lift::<Dual64>(a), lift::<Dual64>(lambda));
        [
            jacobian(n, n, |j| {
                self.constrained_rnea(&self.perturb(&qd, j, eps()), &vd, &ad, contacts, &ld)
            }),
            jacobian(n, n, |j| {
                self.constrained_rnea(&qd, &seeded(v, j, eps()), &ad, contacts, &ld)
            }),
        ]
    }
    /// `∂²τ/∂q²` of [`Reduced::constrained_rnea`] (`λ` fixed; nested tangent).
    pub fn d2_constrained_rnea_dq2(
        &self,
        q: &[f64],
        v: &[f64],
        a: &[f64],
        contacts: &[Contact],
        lambda: &[f64],
    ) -> Tensor3 {
        let n = self.nv();
        let (vh, ah, lh) =
            (lift::<HyperDual64>(v), lift::<HyperDual64>(a), lift::<HyperDual64>(lambda));
        hessian(n, n, n, |j, k| {
            self.constrained_rnea(&self.nested(q, j, k), &vh, &ah, contacts, &lh)
        })
    }
}

/// `x` lifted, plus `e_j · d`.
fn seeded<T: AdScalar>(x: &[f64], j: usize, d: T) -> Vec<T> {
    let mut out = lift::<T>(x);
    out[j] += d;
    out
}
