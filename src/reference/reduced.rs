//! The mimic expansion of a model in reduced coordinates (mimic joints,
//! [`Model::with_mimic_joints`](crate::model::Model::with_mimic_joints)), as the oracle sees it.
//!
//! [`Reduced`] re-derives the reduced coordinates from the list of couplings
//! ([`LinearCoupling`]s: the mimic joints, [`crate::model::JointCoupling`], as one term, and the
//! couplings of several joints of [`Model::with_linear_couplings`]) and the model's index
//! tables alone (not from the reduction that a reduced [`Model`] carries): `q_full = expand(q)`
//! (independent coordinates copied, `Σ c · q_term + offset` for each eliminated joint),
//! `v_full = G v`, `τ = Gᵀ τ_full`. Every function of the oracle that takes a [`Model`] takes a
//! reduced one too, through these maps: its reference algorithms run on the full tree at
//! `expand(q)`, `G v`, `G a` and return the reduced quantities (`Gᵀ τ_full`, `J_full G`, …), and
//! its `f64` oracles differentiate those compositions, `q` in the tangent space of the reduced
//! configuration (`(q ⊕ δ_k) ⊕ ε_j` for the second order, as [`super::derivatives`]).

use super::AdScalar;
use crate::model::{LinearCoupling, Model};

/// A full model and its couplings (mimic joints and couplings of several joints), seen in the
/// reduced coordinates.
#[derive(Clone, Copy, Debug)]
pub struct Reduced<'a> {
    /// The full tree (every joint independent).
    pub full: &'a Model,
    /// The couplings (`q[joint] = Σ c q[term] + offset`; a mimic joint is one term).
    pub mimics: &'a [LinearCoupling],
}

impl<'a> Reduced<'a> {
    /// The oracle's view of `model` if it is in reduced coordinates
    /// ([`Model::is_reduced`]): its full tree and its couplings.
    pub fn of(model: &'a Model) -> Option<Self> {
        model
            .is_reduced()
            .then(|| Reduced { full: model.full_tree(), mimics: model.linear_couplings() })
    }
    /// The coupling of joint `i`, if it is an eliminated joint.
    fn mimic_of(&self, i: usize) -> Option<&LinearCoupling> {
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
                    let mut x = T::zero();
                    for &(j, c) in &mm.terms {
                        let (r, _) = lay[j].expect("term joints are independent");
                        x += q[r].clone() * c;
                    }
                    out[a] = x + mm.offset;
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
                    let mut x = T::zero();
                    for &(j, c) in &mm.terms {
                        let (_, r) = lay[j].expect("term joints are independent");
                        x += v[r].clone() * c;
                    }
                    out[a] = x;
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
                    for &(j, c) in &mm.terms {
                        let (_, r) = lay[j].expect("term joints are independent");
                        out[r] += f[a].clone() * c;
                    }
                }
                (None, None) => unreachable!(),
            }
        }
        out
    }
}
