//! Reduced coordinates of a kinematic tree: the mimic constraints and the map `G` from the
//! reduced velocities to those of the full tree.
//!
//! A mimic joint (URDF `<mimic joint="ref" multiplier="m" offset="c"/>`) follows its reference
//! joint, `q_mimic = m · q_ref + c`, and has no degree of freedom of its own. The constant map
//! `G` (`nv_full × nv`) takes the reduced velocities to the full ones: row `f` of `G` is the
//! unit row of the reduced DoF of an independent DoF `f`, and `m` in the column of the
//! reference's DoF for a mimic DoF. Mimic and reference joints are one-DoF joints of one kind
//! (rotational: revolute or continuous; or prismatic), so that `q_full = expand(q)` (the
//! independent coordinates copied, `m · q_ref + c` for each mimic joint), `v_full = G v`,
//! `a_full = G a`, and `expand(q ⊕ δ) = expand(q) ⊕ G δ`.
//!
//! A linear coupling of several joints ([`LinearCoupling`], `q_joint = Σₖ cₖ · q_jₖ + c`, from
//! [`Model::with_linear_couplings`] or an MJCF `<equality><tendon>`) is the same with one entry
//! `cₖ` per term in the eliminated joint's row of `G` (stored by rows): everything below holds
//! for any constant `G` whose independent rows are unit rows.
//!
//! Every algorithm runs on such a model with the usual workspaces; its reduced-coordinate
//! implementation sits in the algorithm's own file (a `reduced` module beside the tree's code):
//! * the tangent derivatives of the reduced model are those of the full model times `G` for
//!   every `q`, `v` or `a` index;
//! * `τ = Gᵀ τ_full(q_full, G v, G a)` (the generalised forces of the reduced coordinates, by
//!   virtual work), `M = Gᵀ M_full G`, `∂τ/∂q = Gᵀ (∂τ_full/∂q) G`, `∂τ/∂v = Gᵀ (∂τ_full/∂v) G`;
//! * the second-order tensors are those of the full model contracted with `G` on each of their
//!   three indices (`∂M/∂q` too);
//! * forward dynamics `q̈ = M⁻¹(τ − Gᵀ b_full(q_full, G v))` by a dense `L D Lᵀ` factorisation
//!   (`M` is not tree-sparse) with the singularity test of the tree-sparse one (a pivot not
//!   positive and finite, or at most `1e-14` times the largest); its derivatives from the
//!   reduced inverse-dynamics derivatives at `a_full = G q̈`: `∂q̈/∂u = −M⁻¹ ∂τ/∂u`,
//!   `∂q̈/∂τ = M⁻¹`, and the second order by eq. eqn_FD_SO_43 with `∂M/∂q` above;
//! * the contracted second order: the adjoint `ζ` of the reduced residual, the full tree's
//!   contraction at `ζ_f = (G ζ₁, ζ₂)` reduced with `G`, no `nv³` tensor;
//! * frames and the centre of mass: the full tree's at `expand(q)`, `G v`, `G a`, Jacobians
//!   times `G`, Hessians contracted with `G` twice.
//!
//! External forces `fext` are those of the full model (one per joint of the full tree, mimic
//! joints included); contact frames are frames of the full tree.

use crate::error::{Error, Result};
use crate::model::{JointType, Model};
use crate::rng::Rng;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};

/// One mimic constraint `q[joint] = multiplier · q[reference] + offset` between two one-DoF
/// joints of the full model (indices of [`Model::names`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointCoupling {
    /// The mimic joint (it has no degree of freedom in the reduced model).
    pub joint: usize,
    /// The joint it follows (an independent joint).
    pub reference: usize,
    /// `m` in `q = m · q_ref + c` (URDF default 1).
    pub multiplier: f64,
    /// `c` in `q = m · q_ref + c` (URDF default 0).
    pub offset: f64,
}

/// A linear coupling of several joints: `q[joint] = Σₖ cₖ · q[jₖ] + offset` for the terms
/// `(jₖ, cₖ)`, every joint a one-DoF (revolute, continuous or prismatic) joint of the full
/// model (indices of [`Model::names`]), the `jₖ` independent. The mimic constraint
/// ([`JointCoupling`]) is the case of one term; no term holds `joint` at `offset`. The MJCF
/// loader makes them from `<equality><tendon>` on fixed tendons.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearCoupling {
    /// The eliminated joint (it has no degree of freedom in the reduced model).
    pub joint: usize,
    /// `(joint index, coefficient)` of each independent joint it follows.
    pub terms: Vec<(usize, f64)>,
    /// The constant term.
    pub offset: f64,
}

impl From<JointCoupling> for LinearCoupling {
    fn from(c: JointCoupling) -> Self {
        LinearCoupling {
            joint: c.joint,
            terms: vec![(c.reference, c.multiplier)],
            offset: c.offset,
        }
    }
}

/// A model with mimic joints, in the reduced coordinates (see the documentation of
/// [`crate::mimic`]): the full tree ([`MimicModel::full`]) and the map `G`.
#[derive(Clone, Debug)]
pub struct MimicModel {
    pub(crate) full: Model,
    /// The single-term couplings (sorted by joint).
    pub(crate) mimics: Vec<JointCoupling>,
    /// Every coupling (sorted by joint).
    pub(crate) couplings: Vec<LinearCoupling>,
    pub(crate) nq: usize,
    pub(crate) nv: usize,
    /// `expand(q)`: full configuration coordinate `f` is `Σ q_val[e] q[q_idx[e]] + q_off[f]`
    /// over `e` in `q_ptr[f]..q_ptr[f + 1]`.
    pub(crate) q_ptr: Vec<usize>,
    pub(crate) q_idx: Vec<usize>,
    pub(crate) q_val: Vec<f64>,
    pub(crate) q_off: Vec<f64>,
    /// `G` by rows: row `f` has the entries `g_val[e]` in columns `g_idx[e]`, `e` in
    /// `g_ptr[f]..g_ptr[f + 1]`.
    pub(crate) g_ptr: Vec<usize>,
    pub(crate) g_idx: Vec<usize>,
    pub(crate) g_val: Vec<f64>,
    /// Whether a row of `G` has several entries.
    pub(crate) multi_term: bool,
    /// The full index of each reduced configuration coordinate / velocity coordinate.
    pub(crate) q_keep: Vec<usize>,
    pub(crate) v_keep: Vec<usize>,
    /// Per joint of the full model: its first reduced configuration and velocity indices, or
    /// `None` for a mimic joint.
    pub(crate) reduced_idx: Vec<Option<(usize, usize)>>,
    /// Identifies the model for the workspaces.
    pub(crate) key: u64,
    /// The configuration limits of the reduced coordinates (those of the independent
    /// coordinates of the full tree).
    pub(crate) lower: DVector<f64>,
    pub(crate) upper: DVector<f64>,
}

/// Whether a joint type can be a mimic or reference joint: `Some(true)` rotational, `Some(false)`
/// prismatic, `None` otherwise.
fn one_dof_kind(j: &JointType) -> Option<bool> {
    match j {
        JointType::Revolute { .. } | JointType::Continuous { .. } => Some(true),
        JointType::Prismatic { .. } => Some(false),
        _ => None,
    }
}

impl MimicModel {
    /// The reduced model of `full` with the constraints `mimics`.
    ///
    /// # Errors
    /// [`Error::Build`] naming the joint if a constraint names a joint index that does not
    /// exist or the world, a joint mimics itself, a joint is constrained twice, a reference
    /// joint is itself a mimic joint, either joint is not a one-DoF revolute, continuous or
    /// prismatic joint, the two are not of one kind (both rotational or both prismatic), or
    /// the multiplier or offset is not finite.
    pub fn new(full: Model, mimics: &[JointCoupling]) -> Result<Self> {
        // The constraints name joints of the full tree.
        let full = match &full.reduction {
            Some(r) => r.full.clone(),
            None => full,
        };
        let nj = full.njoints();
        let name = |i: usize| full.names()[i].clone();
        let mut is_mimic = vec![false; nj];
        for (k, m) in mimics.iter().enumerate() {
            let bad = |why: String| Err(Error::Build(format!("mimic constraint {k}: {why}")));
            if m.joint == 0 || m.joint >= nj {
                return bad(format!("joint index {} is not a moving joint of the model", m.joint));
            }
            let who = format!("joint \"{}\" (index {})", name(m.joint), m.joint);
            if m.reference == 0 || m.reference >= nj {
                return bad(format!(
                    "{who}: reference joint index {} is not a moving joint of the model",
                    m.reference
                ));
            }
            if m.reference == m.joint {
                return bad(format!("{who} cannot mimic itself"));
            }
            if is_mimic[m.joint] {
                return bad(format!("{who} is constrained twice"));
            }
            is_mimic[m.joint] = true;
            let (kj, kr) =
                (one_dof_kind(&full.joints()[m.joint]), one_dof_kind(&full.joints()[m.reference]));
            let rname = name(m.reference);
            match (kj, kr) {
                (None, _) => {
                    return bad(format!(
                        "{who} is {}: a mimic joint must be revolute, continuous or prismatic",
                        full.joints()[m.joint].name()
                    ));
                }
                (_, None) => {
                    return bad(format!(
                        "{who}: the reference joint \"{rname}\" is {}, not a revolute, \
                         continuous or prismatic joint",
                        full.joints()[m.reference].name()
                    ));
                }
                (Some(a), Some(b)) if a != b => {
                    return bad(format!(
                        "{who} is {} and its reference joint \"{rname}\" {}: both must be \
                         rotational (revolute, continuous) or both prismatic",
                        full.joints()[m.joint].name(),
                        full.joints()[m.reference].name()
                    ));
                }
                _ => {}
            }
            if !m.multiplier.is_finite() || !m.offset.is_finite() {
                return bad(format!(
                    "{who}: multiplier {} and offset {} must be finite",
                    m.multiplier, m.offset
                ));
            }
        }
        for (k, m) in mimics.iter().enumerate() {
            if is_mimic[m.reference] {
                return Err(Error::Build(format!(
                    "mimic constraint {k}: joint \"{}\" (index {}): the reference joint \"{}\" is \
                     itself a mimic joint",
                    name(m.joint),
                    m.joint,
                    name(m.reference)
                )));
            }
        }
        let couplings: Vec<LinearCoupling> = mimics.iter().map(|&m| m.into()).collect();
        Ok(Self::build(full, couplings))
    }

    /// The reduced model of `full` with the linear couplings `couplings`.
    ///
    /// # Errors
    /// [`Error::Build`] naming the coupling (`coupling K`) and the joint if a coupling names a
    /// joint index that does not exist or the world, a joint is constrained twice, a joint is a
    /// term of its own coupling or twice a term of one coupling, a joint is not a one-DoF
    /// revolute, continuous or prismatic joint, a term's joint is itself eliminated by a
    /// coupling, or a coefficient or the offset is not finite.
    pub fn with_couplings(full: Model, couplings: &[LinearCoupling]) -> Result<Self> {
        let full = match &full.reduction {
            Some(r) => r.full.clone(),
            None => full,
        };
        let nj = full.njoints();
        let name = |i: usize| full.names()[i].clone();
        let mut eliminated = vec![false; nj];
        for (k, c) in couplings.iter().enumerate() {
            let bad = |why: String| Error::Build(format!("coupling {k}: {why}"));
            let scalar = |j: usize, what: &str| -> Result<()> {
                if j == 0 || j >= nj {
                    return Err(bad(format!(
                        "{what} index {j} is not a moving joint of the model"
                    )));
                }
                if one_dof_kind(&full.joints()[j]).is_none() {
                    return Err(bad(format!(
                        "{what} \"{}\" (index {j}) is {}: a coupled joint must be revolute, \
                         continuous or prismatic",
                        name(j),
                        full.joints()[j].name()
                    )));
                }
                Ok(())
            };
            scalar(c.joint, "joint")?;
            let who = format!("joint \"{}\" (index {})", name(c.joint), c.joint);
            if eliminated[c.joint] {
                return Err(bad(format!("{who} is constrained twice")));
            }
            eliminated[c.joint] = true;
            if !c.offset.is_finite() {
                return Err(bad(format!("{who}: offset {} must be finite", c.offset)));
            }
            for (t, &(j, x)) in c.terms.iter().enumerate() {
                scalar(j, "term joint")?;
                if j == c.joint {
                    return Err(bad(format!("{who} is a term of its own coupling")));
                }
                if c.terms[..t].iter().any(|&(i, _)| i == j) {
                    return Err(bad(format!("{who}: joint \"{}\" is twice a term", name(j))));
                }
                if !x.is_finite() {
                    return Err(bad(format!(
                        "{who}: the coefficient {x} of joint \"{}\" must be finite",
                        name(j)
                    )));
                }
            }
        }
        for (k, c) in couplings.iter().enumerate() {
            if let Some(&(j, _)) = c.terms.iter().find(|&&(j, _)| eliminated[j]) {
                return Err(Error::Build(format!(
                    "coupling {k}: joint \"{}\" (index {}): the term joint \"{}\" is itself \
                     eliminated by a coupling",
                    name(c.joint),
                    c.joint,
                    name(j)
                )));
            }
        }
        Ok(Self::build(full, couplings.to_vec()))
    }

    /// The reduction of checked couplings.
    fn build(full: Model, mut couplings: Vec<LinearCoupling>) -> Self {
        let nj = full.njoints();
        let key = {
            use std::hash::{Hash, Hasher};
            let mut h = std::collections::hash_map::DefaultHasher::new();
            (full.nq(), full.nv(), full.parents()).hash(&mut h);
            let mut sorted: Vec<&LinearCoupling> = couplings.iter().collect();
            sorted.sort_by_key(|c| c.joint);
            for c in sorted {
                (c.joint, c.offset.to_bits()).hash(&mut h);
                for &(j, x) in &c.terms {
                    (j, x.to_bits()).hash(&mut h);
                }
            }
            h.finish()
        };
        couplings.sort_by_key(|c| c.joint);
        let mut of = vec![None; nj];
        for (k, c) in couplings.iter().enumerate() {
            of[c.joint] = Some(k);
        }
        // Reduced indices of the independent joints, in the order of the full model.
        let mut reduced_idx = vec![None; nj];
        let (mut nq, mut nv) = (0, 0);
        let (mut q_keep, mut v_keep) = (Vec::new(), Vec::new());
        reduced_idx[0] = Some((0, 0));
        for i in 1..nj {
            if of[i].is_some() {
                continue;
            }
            reduced_idx[i] = Some((nq, nv));
            q_keep.extend(full.idx_q()[i]..full.idx_q()[i] + full.nqs()[i]);
            v_keep.extend(full.idx_v()[i]..full.idx_v()[i] + full.nvs()[i]);
            nq += full.nqs()[i];
            nv += full.nvs()[i];
        }
        let (mut q_ptr, mut q_idx, mut q_val) = (vec![0], Vec::new(), Vec::new());
        let mut q_off = vec![0.0; full.nq()];
        let (mut g_ptr, mut g_idx, mut g_val) = (vec![0], Vec::new(), Vec::new());
        for i in 1..nj {
            match of[i] {
                None => {
                    let (rq, rv) = reduced_idx[i].expect("an independent joint");
                    for c in 0..full.nqs()[i] {
                        q_idx.push(rq + c);
                        q_val.push(1.0);
                        q_ptr.push(q_idx.len());
                    }
                    for c in 0..full.nvs()[i] {
                        g_idx.push(rv + c);
                        g_val.push(1.0);
                        g_ptr.push(g_idx.len());
                    }
                }
                Some(k) => {
                    // One-DoF joints: one configuration and one velocity coordinate each.
                    let c = &couplings[k];
                    for &(j, x) in &c.terms {
                        let (rq, rv) = reduced_idx[j].expect("a term joint is independent");
                        q_idx.push(rq);
                        q_val.push(x);
                        g_idx.push(rv);
                        g_val.push(x);
                    }
                    q_off[full.idx_q()[i]] = c.offset;
                    q_ptr.push(q_idx.len());
                    g_ptr.push(g_idx.len());
                }
            }
        }
        let mimics = couplings
            .iter()
            .filter(|c| c.terms.len() == 1)
            .map(|c| JointCoupling {
                joint: c.joint,
                reference: c.terms[0].0,
                multiplier: c.terms[0].1,
                offset: c.offset,
            })
            .collect();
        let lower = DVector::from_iterator(nq, q_keep.iter().map(|&f| full.lower[f]));
        let upper = DVector::from_iterator(nq, q_keep.iter().map(|&f| full.upper[f]));
        let multi_term = couplings.iter().any(|c| c.terms.len() > 1);
        Self {
            full,
            mimics,
            couplings,
            nq,
            nv,
            q_ptr,
            q_idx,
            q_val,
            q_off,
            g_ptr,
            g_idx,
            g_val,
            multi_term,
            q_keep,
            v_keep,
            reduced_idx,
            key,
            lower,
            upper,
        }
    }

    /// The non-zero entries `(column, value)` of row `f` of `G` (`f < full().nv()`).
    #[inline]
    pub(crate) fn g_row(&self, f: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.g_ptr[f]..self.g_ptr[f + 1];
        self.g_idx[r.clone()].iter().copied().zip(self.g_val[r].iter().copied())
    }

    /// The model name.
    pub fn name(&self) -> &str {
        self.full.name()
    }
    /// The map `G` (`full().nv() × nv()`), `v_full = G v`, as a dense matrix (allocates).
    pub fn g(&self) -> DMatrix<f64> {
        let mut g = DMatrix::zeros(self.full.nv(), self.nv);
        for f in 0..self.full.nv() {
            for (c, x) in self.g_row(f) {
                g[(f, c)] = x;
            }
        }
        g
    }
    /// `q_full = expand(q)` into `out` (length `full().nq()`). Lengths are not checked.
    pub fn expand_q_into(&self, q: &[f64], out: &mut [f64]) {
        for (f, (o, &c)) in out.iter_mut().zip(&self.q_off).enumerate() {
            let r = self.q_ptr[f]..self.q_ptr[f + 1];
            let mut s = 0.0;
            for (&i, &m) in self.q_idx[r.clone()].iter().zip(&self.q_val[r]) {
                s += m * q[i];
            }
            *o = s + c;
        }
    }
    /// `v_full = G v` into `out` (length `full().nv()`). Lengths are not checked.
    pub fn expand_v_into(&self, v: &[f64], out: &mut [f64]) {
        for (f, o) in out.iter_mut().enumerate() {
            let mut s = 0.0;
            for (r, m) in self.g_row(f) {
                s += m * v[r];
            }
            *o = s;
        }
    }
    /// `y = Gᵀ x` (`x` of length `full().nv()`, `y` of length `nv()`). Lengths are not checked.
    pub fn reduce_force_into(&self, x: &[f64], y: &mut [f64]) {
        y.fill(0.0);
        for (f, &xf) in x.iter().enumerate() {
            for (r, m) in self.g_row(f) {
                y[r] += m * xf;
            }
        }
    }
    /// `expand(q)` (allocates).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`].
    pub fn expand_q(&self, q: &DVector<f64>) -> Result<DVector<f64>> {
        self.check_q(q)?;
        let mut out = DVector::zeros(self.full.nq());
        self.expand_q_into(q.as_slice(), out.as_mut_slice());
        Ok(out)
    }
    /// The reduced coordinates of a full configuration: its independent coordinates (the mimic
    /// joints' values are dropped, not checked).
    ///
    /// # Errors
    /// [`Error::Dimension`] if `q_full.len() != full().nq()`.
    pub fn reduce_q(&self, q_full: &DVector<f64>) -> Result<DVector<f64>> {
        if q_full.len() != self.full.nq() {
            return Err(Error::Dimension {
                what: "q_full".into(),
                expected: self.full.nq(),
                got: q_full.len(),
            });
        }
        Ok(DVector::from_iterator(self.nq, self.q_keep.iter().map(|&f| q_full[f])))
    }
    /// The neutral configuration (each mimic joint then sits at its offset).
    pub fn neutral(&self) -> DVector<f64> {
        self.select_q(&self.full.neutral())
    }
    /// A random valid configuration: that of [`Model::random_configuration`] of the full model,
    /// its independent coordinates.
    pub fn random_configuration(&self, rng: &mut Rng) -> DVector<f64> {
        self.select_q(&self.full.random_configuration(rng))
    }
    pub(crate) fn select_q(&self, q_full: &DVector<f64>) -> DVector<f64> {
        DVector::from_iterator(self.nq, self.q_keep.iter().map(|&f| q_full[f]))
    }
    pub(crate) fn select_v(&self, v_full: &DVector<f64>) -> DVector<f64> {
        DVector::from_iterator(self.nv, self.v_keep.iter().map(|&f| v_full[f]))
    }
    /// `q ⊕ δ` in the reduced coordinates (joint by joint, as [`Model::integrate`]).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`] and [`MimicModel::check_v`] (`"delta"`).
    pub fn integrate(&self, q: &DVector<f64>, delta: &DVector<f64>) -> Result<DVector<f64>> {
        let qf = self.expand_q(q)?;
        self.check_v("delta", delta)?;
        let mut df = DVector::zeros(self.full.nv());
        self.expand_v_into(delta.as_slice(), df.as_mut_slice());
        Ok(self.select_q(&self.full.integrate(&qf, &df)?))
    }
    /// `q₁ ⊖ q₀` in the reduced coordinates (the inverse of [`MimicModel::integrate`]).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`] for `q0` and `q1`.
    pub fn difference(&self, q0: &DVector<f64>, q1: &DVector<f64>) -> Result<DVector<f64>> {
        let q0f = self.expand_q(q0)?;
        let q1f = self.expand_q(q1).map_err(|e| match e {
            Error::Dimension { expected, got, .. } => {
                Error::Dimension { what: "q1".into(), expected, got }
            }
            Error::NotFinite { index, .. } => Error::NotFinite { what: "q1".into(), index },
            e => e,
        })?;
        Ok(self.select_v(&self.full.difference(&q0f, &q1f)?))
    }
    /// [`MimicModel::d_integrate`] into `out` (`nv × nv`; every entry written).
    ///
    /// # Errors
    /// As [`MimicModel::d_integrate`]; `out` not `nv × nv`.
    pub fn d_integrate_into(
        &self,
        q: &DVector<f64>,
        delta: &DVector<f64>,
        arg: crate::model::Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        self.check_q(q)?;
        self.check_v("delta", delta)?;
        self.lie_blocks(out, |j, a, b, blk| {
            let (n, m) = (self.full.nqs()[j], self.full.nvs()[j]);
            self.full.joints()[j].d_integrate(
                &q.as_slice()[a..a + n],
                &delta.as_slice()[b..b + m],
                arg,
                blk,
            );
        })
    }
    /// [`MimicModel::d_difference`] into `out` (`nv × nv`; every entry written).
    ///
    /// # Errors
    /// As [`MimicModel::d_difference`]; `out` not `nv × nv`.
    pub fn d_difference_into(
        &self,
        q0: &DVector<f64>,
        q1: &DVector<f64>,
        arg: crate::model::Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        self.check_q(q0)?;
        self.check_q(q1).map_err(|e| match e {
            Error::Dimension { expected, got, .. } => {
                Error::Dimension { what: "q1".into(), expected, got }
            }
            Error::NotFinite { index, .. } => Error::NotFinite { what: "q1".into(), index },
            e => e,
        })?;
        self.lie_blocks(out, |j, a, _, blk| {
            let n = self.full.nqs()[j];
            self.full.joints()[j].d_difference(
                &q0.as_slice()[a..a + n],
                &q1.as_slice()[a..a + n],
                arg,
                blk,
            );
        })
    }
    /// `q₁ ⊖ q₀` into `out` (length `nv`) without allocating: joint by joint over the
    /// independent joints (their reduced coordinates are those of the full tree).
    ///
    /// # Errors
    /// As [`MimicModel::difference`]; `out` not of length `nv`.
    pub(crate) fn difference_into(
        &self,
        q0: &DVector<f64>,
        q1: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        self.check_q(q0)?;
        self.check_q(q1).map_err(|e| match e {
            Error::Dimension { expected, got, .. } => {
                Error::Dimension { what: "q1".into(), expected, got }
            }
            Error::NotFinite { index, .. } => Error::NotFinite { what: "q1".into(), index },
            e => e,
        })?;
        if out.len() != self.nv {
            return Err(Error::Dimension { what: "out".into(), expected: self.nv, got: out.len() });
        }
        for j in 1..self.full.njoints() {
            if let Some((a, b)) = self.reduced_idx[j] {
                let (n, m) = (self.full.nqs()[j], self.full.nvs()[j]);
                self.full.joints()[j].difference(
                    &q0.as_slice()[a..a + n],
                    &q1.as_slice()[a..a + n],
                    &mut out.as_mut_slice()[b..b + m],
                );
            }
        }
        Ok(())
    }
    /// Zeroes `out` (checked `nv × nv`) and writes the diagonal block of each independent joint
    /// `j` from `block(j, reduced idx_q, reduced idx_v, column-major nv_j × nv_j)`.
    pub(crate) fn lie_blocks(
        &self,
        out: &mut DMatrix<f64>,
        mut block: impl FnMut(usize, usize, usize, &mut [f64]),
    ) -> Result<()> {
        if out.shape() != (self.nv, self.nv) {
            return Err(Error::Dimension {
                what: "out (nv × nv) rows × cols".into(),
                expected: self.nv * self.nv,
                got: out.nrows() * out.ncols(),
            });
        }
        out.fill(0.0);
        let mut blk = [0.0; 36];
        for j in 1..self.full.njoints() {
            if let Some((a, b)) = self.reduced_idx[j] {
                let m = self.full.nvs()[j];
                block(j, a, b, &mut blk);
                for c in 0..m {
                    for r in 0..m {
                        out[(b + r, b + c)] = blk[c * m + r];
                    }
                }
            }
        }
        Ok(())
    }
    /// Checks a reduced configuration: length `nq`, finite, unit quaternions (the last naming
    /// the joint).
    ///
    /// # Errors
    /// [`Error::Dimension`], [`Error::NotFinite`] (reduced index) or
    /// [`Error::InvalidConfiguration`].
    pub fn check_q(&self, q: &DVector<f64>) -> Result<()> {
        crate::model::check_vec("q", q, self.nq)?;
        for i in 1..self.full.njoints() {
            if let Some((a, _)) = self.reduced_idx[i] {
                let n = self.full.nqs()[i];
                self.full.joints()[i].check_configuration(&q.as_slice()[a..a + n]).map_err(
                    |reason| Error::InvalidConfiguration {
                        joint: self.full.names()[i].clone(),
                        reason: format!("{reason} (q indices {a}..{})", a + n),
                    },
                )?;
            }
        }
        Ok(())
    }
    /// Checks a velocity-sized vector: length `nv`, finite.
    ///
    /// # Errors
    /// [`Error::Dimension`] or [`Error::NotFinite`] naming `what`.
    pub fn check_v(&self, what: &str, x: &DVector<f64>) -> Result<()> {
        crate::model::check_vec(what, x, self.nv)
    }
    /// `out = Gᵀ x G` (`x`: `full().nv()` square, `out`: `nv()` square); exactly symmetric
    /// for an exactly symmetric `x` (the upper triangle mirrored: with several entries in a
    /// row of `G` the two triangles are sums in different orders).
    pub(crate) fn reduce_matrix(&self, x: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        out.fill(0.0);
        let nf = self.full.nv();
        let (xs, n) = (x.as_slice(), self.nv);
        let os = out.as_mut_slice();
        for b in 0..nf {
            for (cb, mb) in self.g_row(b) {
                for a in 0..nf {
                    for (ca, ma) in self.g_row(a) {
                        os[ca + n * cb] += ma * mb * xs[a + nf * b];
                    }
                }
            }
        }
        if self.multi_term {
            let symmetric = (0..nf).all(|b| (0..b).all(|a| xs[a + nf * b] == xs[b + nf * a]));
            if symmetric {
                for c in 0..n {
                    for r in 0..c {
                        os[c + n * r] = os[r + n * c];
                    }
                }
            }
        }
    }
    /// `out[r, s, t] = Σ G[i, r] G[j, s] G[k, t] x[i, j, k]`.
    pub(crate) fn reduce_tensor(&self, x: &Tensor3, out: &mut Tensor3) {
        out.fill(0.0);
        let nf = self.full.nv();
        let n = self.nv;
        let xs = x.as_slice();
        let os = out.as_mut_slice();
        for k in 0..nf {
            for (ck, mk) in self.g_row(k) {
                for j in 0..nf {
                    for (cj, mj) in self.g_row(j) {
                        let m = mk * mj;
                        let src = &xs[nf * (j + nf * k)..nf * (j + nf * k + 1)];
                        let dst = n * (cj + n * ck);
                        for (i, &xi) in src.iter().enumerate() {
                            for (ci, mi) in self.g_row(i) {
                                os[dst + ci] += m * mi * xi;
                            }
                        }
                    }
                }
            }
        }
    }
}

impl MimicModel {
    /// `out[(u, c0 + l)] += s Σ_{f, i} G[f, u] G[i, l] g[(i, f)]`: the transpose of
    /// `Gᵀ g_top G` (`g_top` the first `nv_f` rows of `g`, `nv_f` columns).
    pub(crate) fn add_top_t(&self, g: &DMatrix<f64>, s: f64, out: &mut DMatrix<f64>, c0: usize) {
        let nf = self.full.nv();
        for f in 0..nf {
            for (u, gf) in self.g_row(f) {
                let gu = s * gf;
                for i in 0..nf {
                    for (ci, gi) in self.g_row(i) {
                        out[(u, c0 + ci)] += gu * gi * g[(i, f)];
                    }
                }
            }
        }
    }
    /// `out[(u, c0 + r)] += s Σ_f G[f, u] g[(nf + r, f)]` for `r < m`: the transpose of
    /// `g_bottom G`.
    pub(crate) fn add_bottom_t(
        &self,
        g: &DMatrix<f64>,
        m: usize,
        s: f64,
        out: &mut DMatrix<f64>,
        c0: usize,
    ) {
        let nf = self.full.nv();
        for f in 0..nf {
            for (u, gf) in self.g_row(f) {
                let gu = s * gf;
                for r in 0..m {
                    out[(u, c0 + r)] += gu * g[(nf + r, f)];
                }
            }
        }
    }
}

impl MimicModel {
    /// `out = x G` for a `R × full().nv()` matrix `x` (`out`: `R × nv()`).
    pub(crate) fn reduce_cols<R: nalgebra::Dim, S1, S2>(
        &self,
        x: &nalgebra::Matrix<f64, R, nalgebra::Dyn, S1>,
        out: &mut nalgebra::Matrix<f64, R, nalgebra::Dyn, S2>,
    ) where
        S1: nalgebra::storage::Storage<f64, R, nalgebra::Dyn>,
        S2: nalgebra::storage::StorageMut<f64, R, nalgebra::Dyn>,
    {
        out.fill(0.0);
        for f in 0..self.full.nv() {
            for (c, m) in self.g_row(f) {
                for r in 0..x.nrows() {
                    out[(r, c)] += m * x[(r, f)];
                }
            }
        }
    }
    /// Checks a frame index of the full tree.
    pub(crate) fn check_frame(&self, frame: usize) -> Result<()> {
        let n = self.full.frames().len();
        if frame >= n {
            return Err(Error::Argument {
                name: "frame".into(),
                reason: format!("frame index {frame} out of range (the model has {n} frames)"),
            });
        }
        Ok(())
    }
}

impl MimicModel {
    /// `out[r, c, k] = Σ G[f, c] G[g, k] t[r, f, g]` (`t`: `R × nv_full × nv_full`).
    pub(crate) fn reduce_tensor_cols(&self, t: &Tensor3, out: &mut Tensor3) {
        out.fill(0.0);
        let nf = self.full.nv();
        let rows = t.dims().0;
        for g in 0..nf {
            for (cg, mg) in self.g_row(g) {
                for f in 0..nf {
                    for (cf, mf) in self.g_row(f) {
                        let m = mf * mg;
                        for r in 0..rows {
                            out[(r, cf, cg)] += m * t[(r, f, g)];
                        }
                    }
                }
            }
        }
    }
}
