//! IDSVA-SO: second-order partial derivatives of inverse dynamics and `∂M/∂q`, rebuilt from the
//! per-DoF expressions of the notes' section "Efficient Implementation" (cases 1A–2C w.r.t. `q`,
//! A–E w.r.t. `q̇`, 1A–2C cross, 1A–2C for `∂M/∂q`). Ground frame, cost `O(N d²)`.
//!
//! Loop structure: `i` over bodies backwards (composites of `i` complete), `p` over the DoFs of
//! `i`; `j` up the ancestor chain of `i` (`j ⪯ i`), `t` over its DoFs; `k` up the chain of `j`
//! (`k ⪯ j`), `r` over its DoFs. Index names below follow the notes.

use super::id_fo::{accumulate_to_parent, add_armature, backward_step_fo, forward_pass_world};
use crate::algo::Data;
use crate::algo::data::Part;
use crate::algo::internal::check_fext;
use crate::error::Result;
use crate::model::{Model, check_vec};
use crate::simd::F64x4;
use crate::spatial::{Force, Motion};
use crate::tensor::Tensor3;
use nalgebra::{DVector, Matrix6, Vector3};

/// Second-order inverse-dynamics derivatives, `nv×nv×nv` each, `T[(i, j, k)]` as documented on
/// the getters. Allocated once in a [`crate::algo::Data`] made by
/// [`Data::with_second_order`](crate::algo::Data::with_second_order); only [`id_so_derivatives`]
/// writes them, and
/// it writes every entry that is not structurally zero (entries whose DoFs are not all on one
/// root path stay zero from construction).
#[derive(Clone, Debug)]
pub struct SoData {
    d2tau_dq2: Tensor3,
    d2tau_dv2: Tensor3,
    d2tau_dqdv: Tensor3,
    /// `n×n×n`, or `0×0×0` in the workspaces of [`SoData::without_dm_dq`].
    dm_dq: Tensor3,
    /// Upper halves only (the workspaces of [`SoData::upper_halves`]): the entries `(i, j, k)`
    /// with `j > k` of `∂²τ/∂q̇²`, those of `∂²τ/∂q²` with `j > k` whose DoFs `j` and `k` belong
    /// to different joints, and those of `∂²τ/∂q∂q̇` with `root[j]`, are never written (they
    /// stay zero); and `∂²τ/∂q∂q̇` is stored by blocks of eight pages (see [`qv_offset`]), not
    /// column-major.
    upper: bool,
    /// As `Data::dtau_dq_off_path`, for `d2tau_dq2`.
    pub(crate) d2tau_dq2_off_path: bool,
    /// `root[j]`: DoF `j` belongs to a joint attached to the world.
    root: Vec<bool>,
    /// Per DoF, contiguous: `[S, Ψ̇, Ψ̈, Ψ̇ + Ṡ]` (ground frame), refreshed on every call.
    dof: Vec<[V6; 4]>,
    /// DoFs of the strict ancestor joints of joint `j`: `anc_dofs[anc_start[j]..anc_start[j + 1]]`.
    anc_dofs: Vec<usize>,
    anc_start: Vec<usize>,
    /// The tree this workspace was built for (checked on every call).
    parents: Vec<usize>,
    nvs: Vec<usize>,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced tensors,
    /// which the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::id_so::reduced::MimicSoData>>,
}

impl SoData {
    /// Workspace for `model`.
    pub(crate) fn new(model: &Model) -> Self {
        Self::build(model, true, false)
    }
    /// Workspace for `model` that does not compute `∂M/∂q` (its [`SoData::dm_dq`] is an empty
    /// `0×0×0` tensor): for the callers that only need the three `∂²τ` tensors (forward,
    /// contact and impact second-order derivatives), sparing the `nv³` writes of `∂M/∂q`.
    pub(crate) fn without_dm_dq(model: &Model) -> Self {
        Self::build(model, false, false)
    }
    /// As [`SoData::without_dm_dq`], and IDSVA-SO writes only the upper halves of the two
    /// tensors that are symmetric in `(j, k)`: the entries `(i, j, k)` with `j ≤ k` of
    /// `∂²τ/∂q̇²`, and those of `∂²τ/∂q²` with `j ≤ k` or `j` and `k` DoFs of one joint (which
    /// need not commute); and the columns `j` of `∂²τ/∂q∂q̇` but those of the DoFs of joints
    /// attached to the world (which vanish: `τ` depends on such a `q_j` only through gravity
    /// and the external forces, neither of which depends on `q̇`). The others stay zero. For
    /// the forward-dynamics derivatives, whose products read only those columns: IDSVA-SO's
    /// scattered writes are a large part of its memory traffic once its tensors no longer fit
    /// in the cache. Its `∂²τ/∂q∂q̇` is stored by blocks of eight pages (see [`qv_offset`]).
    pub(crate) fn upper_halves(model: &Model) -> Self {
        Self::build(model, false, true)
    }
    fn build(model: &Model, with_dm_dq: bool, upper: bool) -> Self {
        if let Some(r) = &model.reduction {
            let mut so = Self::build(crate::model::tree::shell_model(), with_dm_dq, upper);
            so.red = Some(Box::new(crate::deriv::id_so::reduced::MimicSoData::new(r)));
            return so;
        }
        let n = model.nv;
        let nd = if with_dm_dq { n } else { 0 };
        let mut anc_dofs = vec![];
        let mut anc_start = vec![0];
        for j in 0..model.njoints() {
            if j > 0 {
                let mut k = model.parents[j];
                while k > 0 {
                    anc_dofs.extend(model.idx_v[k]..model.idx_v[k] + model.nvs[k]);
                    k = model.parents[k];
                }
            }
            anc_start.push(anc_dofs.len());
        }
        Self {
            d2tau_dq2: Tensor3::zeros(n, n, n),
            d2tau_dv2: Tensor3::zeros(n, n, n),
            d2tau_dqdv: Tensor3::zeros(n, n, n),
            dm_dq: Tensor3::zeros(nd, nd, nd),
            upper,
            d2tau_dq2_off_path: false,
            root: (0..n).map(|k| model.parents[model.dof_joint[k]] == 0).collect(),
            dof: vec![[[0.0; 6]; 4]; n],
            anc_dofs,
            anc_start,
            parents: model.parents.clone(),
            nvs: model.nvs.clone(),
            red: None,
        }
    }
    /// Checks that this workspace was built for `model` (same tree and degrees of freedom).
    pub fn check(&self, model: &Model) -> Result<()> {
        match (&model.reduction, &self.red) {
            (Some(r), Some(so)) => so.check(r),
            (Some(_), None) | (None, Some(_)) => Err(crate::error::Error::Workspace(format!(
                "SoData was made for a model {} mimic joints, model \"{}\" {}; make it with \
                 SoData::new for this model",
                if self.red.is_some() { "with" } else { "without" },
                model.name(),
                if self.red.is_some() { "has none" } else { "is in reduced coordinates" },
            ))),
            (None, None) => self.check_tree(model),
        }
    }
    /// [`SoData::check`] for the algorithms of the tree: an error for a reduced model.
    pub(crate) fn check_tree(&self, model: &Model) -> Result<()> {
        if model.reduction.is_some() || self.red.is_some() {
            return Err(crate::error::Error::Workspace(format!(
                "model \"{}\" is in reduced coordinates (mimic joints): this function takes \
                 the full tree (Model::full_tree) and its own workspaces",
                model.name()
            )));
        }
        let n = model.nv;
        if self.parents.len() == model.parents.len()
            && (self.parents != model.parents || self.nvs != model.nvs)
        {
            return Err(crate::error::Error::Build(format!(
                "SoData (workspace built for another model): same number of joints ({}) but a \
                 different joint tree; make it with SoData::new for model \"{}\"",
                model.njoints(),
                model.name
            )));
        }
        if self.parents != model.parents || self.nvs != model.nvs || self.dof.len() != n {
            return Err(crate::error::Error::Dimension {
                what: "SoData (workspace built for another model): joints".into(),
                expected: model.njoints(),
                got: self.parents.len(),
            });
        }
        let dm_ok = self.dm_dq.dims() == (n, n, n) || self.dm_dq.dims() == (0, 0, 0);
        for t in [&self.d2tau_dq2, &self.d2tau_dv2, &self.d2tau_dqdv] {
            if t.dims() != (n, n, n) || !dm_ok {
                return Err(crate::error::Error::Dimension {
                    what: "SoData (workspace built for another model): nv".into(),
                    expected: n,
                    got: t.dims().0,
                });
            }
        }
        Ok(())
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂τ_i/∂q_j)` (tangent space; not symmetric in `j, k` within a
    /// multi-DoF joint).
    pub fn d2tau_dq2(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2tau_dq2(),
            None => &self.d2tau_dq2,
        }
    }
    pub(crate) fn d2tau_dq2_mut(&mut self) -> &mut Tensor3 {
        &mut self.d2tau_dq2
    }
    /// `T[(i, j, k)] = ∂²τ_i/∂q̇_j∂q̇_k`.
    pub fn d2tau_dv2(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2tau_dv2(),
            None => &self.d2tau_dv2,
        }
    }
    /// `T[(i, j, k)] = ∂/∂q̇_k (∂τ_i/∂q_j)`.
    pub fn d2tau_dqdv(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2tau_dqdv(),
            None => &self.d2tau_dqdv,
        }
    }
    /// `T[(i, j, k)] = ∂M_ij/∂q_k`. Empty (`0×0×0`) in the workspace inside
    /// [`FdSoData`](super::FdSoData), whose forward-dynamics derivatives do not need it.
    pub fn dm_dq(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.dm_dq(),
            None => &self.dm_dq,
        }
    }
}

/// Second-order derivatives of inverse dynamics at `(q, q̇, q̈)` (IDSVA-SO), into `data` made by
/// [`Data::with_second_order`] (returned, and `data.id_so()` later). Also computes the
/// first-order ones (`data.dtau_dq`, `data.dtau_dv`, `data.m`, `data.tau`) in the same pass.
///
/// # Errors
/// As [`crate::algo::rnea`]; [`crate::Error::Workspace`] for a `data` of another model or
/// without dense second-order capacity.
pub fn id_so_derivatives<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a SoData> {
    data.with_part(
        Part::IdSo,
        "id_so_derivatives",
        "Data::with_second_order",
        |data, so: &mut SoData| id_so_derivatives_ws(model, data, so, q, v, a, fext),
    )?;
    data.part_or(Part::IdSo, "id_so_derivatives")
}

/// [`id_so_derivatives`] with its workspace part passed apart (the crate's callers that hold it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn id_so_derivatives_ws(
    model: &Model,
    data: &mut Data,
    so: &mut SoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let so = crate::algo::data::reduced::reduced_ws(&mut so.red, "SoData", model)?;
        return crate::deriv::id_so::reduced::id_so_derivatives(
            r,
            data.reduced(model)?,
            so,
            q,
            v,
            a,
            fext,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_fext(model, fext)?;
    so.check_tree(model)?;
    id_so_unchecked(model, data, so, q, v, a, fext, -model.gravity);
    Ok(())
}

/// IDSVA-SO without input checks, with base acceleration `a0` (`−a_g`, or zero for IDSOZA).
#[allow(clippy::too_many_arguments)]
pub(crate) fn id_so_unchecked(
    model: &Model,
    data: &mut Data,
    so: &mut SoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
    a0: Motion,
) {
    if std::mem::take(&mut data.dtau_dq_off_path) {
        data.dtau_dq.fill(0.0);
    }
    if std::mem::take(&mut so.d2tau_dq2_off_path) {
        so.d2tau_dq2.as_mut_slice().fill(0.0);
    }
    forward_pass_world(model, data, q, v, a, fext, a0);
    fill_dof(data, so);
    let n = model.nv;
    let SoData {
        d2tau_dq2,
        d2tau_dv2,
        d2tau_dqdv,
        dm_dq,
        upper,
        root,
        dof,
        anc_dofs,
        anc_start,
        ..
    } = so;
    let (qq, vv, qv, dm) = (
        d2tau_dq2.as_mut_slice(),
        d2tau_dv2.as_mut_slice(),
        d2tau_dqdv.as_mut_slice(),
        dm_dq.as_mut_slice(),
    );
    let with_dm = dm.len() == n * n * n;
    let ws = SoWs { dof, anc_dofs, anc_start, root };
    match (with_dm, *upper) {
        // (Upper-half workspaces have no ∂M/∂q.)
        (true, _) => {
            backward_pass(model, data, &ws, &mut Store::<true, false> { n, qq, vv, qv, dm })
        }
        (false, false) => {
            backward_pass(model, data, &ws, &mut Store::<false, false> { n, qq, vv, qv, dm })
        }
        (false, true) => {
            backward_pass(model, data, &ws, &mut Store::<false, true> { n, qq, vv, qv, dm })
        }
    }
    // The armature: τ and M only (its second derivatives are zero).
    add_armature(model, data, a);
}

/// The per-DoF vectors `[S, Ψ̇, Ψ̈, Ψ̇ + Ṡ]` of the forward pass, for the backward pass.
fn fill_dof(data: &Data, so: &mut SoData) {
    for (c, d) in so.dof.iter_mut().enumerate() {
        let ps = data.psid[c] + data.sdot[c];
        *d = [v6m(&data.s_world[c]), v6m(&data.psid[c]), v6m(&data.psidd[c]), v6m(&ps)];
    }
}

/// The backward pass of IDSVA-SO (second order into `sink`, first order into `data`).
fn backward_pass<S: Sink>(model: &Model, data: &mut Data, ws: &SoWs<'_>, sink: &mut S) {
    for i in (1..model.njoints()).rev() {
        backward_step_so(model, data, ws, sink, i);
        backward_step_fo(model, data, i);
        accumulate_to_parent(model, data, i);
    }
}

/// A spatial vector as plain components `[ang; lin]` (motion or force).
type V6 = [f64; 6];
/// A 6×6 matrix stored by columns: `m[c][r]`.
type M6 = [[f64; 6]; 6];

#[inline(always)]
fn v6m(m: &Motion) -> V6 {
    [m.ang.x, m.ang.y, m.ang.z, m.lin.x, m.lin.y, m.lin.z]
}

#[inline(always)]
fn v6f(f: &Force) -> V6 {
    [f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z]
}

/// `α a + β b`.
#[inline(always)]
fn lin2(alpha: f64, a: &V6, beta: f64, b: &V6) -> V6 {
    let mut o = [0.0; 6];
    for r in 0..6 {
        o[r] = alpha * a[r] + beta * b[r];
    }
    o
}

#[inline(always)]
fn add(a: &V6, b: &V6) -> V6 {
    let mut o = [0.0; 6];
    for r in 0..6 {
        o[r] = a[r] + b[r];
    }
    o
}

/// `a × b` of 3-vectors stored at `a[oa..oa + 3]`, `b[ob..ob + 3]`.
#[inline(always)]
fn x3(a: &V6, oa: usize, b: &V6, ob: usize) -> [f64; 3] {
    [
        a[oa + 1] * b[ob + 2] - a[oa + 2] * b[ob + 1],
        a[oa + 2] * b[ob] - a[oa] * b[ob + 2],
        a[oa] * b[ob + 1] - a[oa + 1] * b[ob],
    ]
}

/// `m ×* f` (eq. cross_f_defn); also `f ×̄* m` (eq. crff_oper).
#[inline(always)]
fn crf(m: &V6, f: &V6) -> V6 {
    let (a, b, c) = (x3(m, 0, f, 0), x3(m, 3, f, 3), x3(m, 0, f, 3));
    [a[0] + b[0], a[1] + b[1], a[2] + b[2], c[0], c[1], c[2]]
}

/// `M x` (columns `m[c]`).
#[inline(always)]
fn mv<V: F64x4>(m: &M6, x: &V6) -> V6 {
    V::mat6_vec(m, x)
}

/// `Mᵀ x` (columns `m[r]`).
#[inline(always)]
fn mtv<V: F64x4>(m: &M6, x: &V6) -> V6 {
    V::mat6_tr_vec(m, x)
}

#[inline(always)]
fn transpose(m: &M6) -> M6 {
    let mut o = [[0.0; 6]; 6];
    for c in 0..6 {
        for r in 0..6 {
            o[c][r] = m[r][c];
        }
    }
    o
}

/// `α A + β B + γ C`.
#[inline(always)]
fn lin3m(alpha: f64, a: &M6, beta: f64, b: &M6, gamma: f64, c: &M6) -> M6 {
    let mut o = [[0.0; 6]; 6];
    for j in 0..6 {
        for r in 0..6 {
            o[j][r] = alpha * a[j][r] + beta * b[j][r] + gamma * c[j][r];
        }
    }
    o
}

/// `x ×* M`, column by column.
#[inline(always)]
fn crf_cols(x: &V6, m: &M6) -> M6 {
    let mut o = [[0.0; 6]; 6];
    for c in 0..6 {
        o[c] = crf(x, &m[c]);
    }
    o
}

#[inline(always)]
fn m6(m: &Matrix6<f64>) -> M6 {
    let s = m.as_slice();
    let mut o = [[0.0; 6]; 6];
    for c in 0..6 {
        o[c].copy_from_slice(&s[6 * c..6 * c + 6]);
    }
    o
}

/// Per-DoF operators of body `i` (DoF `p`), all ground frame.
struct IOps {
    s: V6,  // S_i
    t1: V6, // I^C_i S_i
    t2: V6, // B^Cᵀ_i S_i
    a: M6,  // 2(B(I^C_i, Ψ̇_i) + S_i×* B^C_i − B^C_i S_i×)
    c: M6,  // S_i×* I^C_i − I^C_i S_i×  (symmetric)
    g: V6,  // 2B^C_i Ψ̇_i + I^C_i Ψ̈_i + f^C_i ×̄* S_i
    t4: V6, // 2B^C_i S_i + I^C_i(Ψ̇_i + Ṡ_i)
}

/// The operators of DoF `dof = [S, Ψ̇, Ψ̈, Ψ̇ + Ṡ]` with composite inertia `ic`, Coriolis matrix
/// `bc` and force `fc`. With `P = S×* I` and `I` symmetric, `I S× = −Pᵀ`, so
/// `C = S×* I − I S× = P + Pᵀ`, and `2B(I, m) = m×* I − I m× + (I m)×̄*` (eq. bkm_term_defn);
/// likewise `−B S× = (S×* Bᵀ)ᵀ`. No 6×6 products.
#[inline(always)]
fn i_ops<V: F64x4>(ic: &M6, bc: &M6, bct: &M6, fc: &V6, dof: &[V6; 4]) -> IOps {
    let [s, psid, psidd, ps] = dof;
    let t1 = mv::<V>(ic, s);
    let p = crf_cols(s, ic);
    let pt = transpose(&p);
    let c = lin3m(1.0, &p, 1.0, &pt, 0.0, &p);
    let pp = crf_cols(psid, ic);
    let ppt = transpose(&pp);
    let ip = mv::<V>(ic, psid);
    let rp = m6(&Force::new(Vector3::new(ip[0], ip[1], ip[2]), Vector3::new(ip[3], ip[4], ip[5]))
        .crff_matrix());
    let sb = crf_cols(s, bc);
    let qbt = transpose(&crf_cols(s, bct));
    // 2B(I, Ψ̇) = P' + P'ᵀ + (IΨ̇)×̄*
    let b2 = lin3m(1.0, &pp, 1.0, &ppt, 1.0, &rp);
    let a = lin3m(1.0, &b2, 2.0, &sb, 2.0, &qbt);
    let bpsid = mv::<V>(bc, psid);
    let g = add(&lin2(2.0, &bpsid, 1.0, &mv::<V>(ic, psidd)), &crf(s, fc));
    let t4 = lin2(2.0, &mv::<V>(bc, s), 1.0, &mv::<V>(ic, ps));
    IOps { s: *s, t1, t2: mtv::<V>(bc, s), a, c, g, t4 }
}

/// `t[idx] = x` without a bounds check in release builds: every index written by IDSVA-SO is
/// built from DoF indices `< nv` of an `nv×nv×nv` tensor (checked in debug builds).
#[inline(always)]
fn set(t: &mut [f64], idx: usize, x: f64) {
    debug_assert!(idx < t.len());
    // SAFETY: idx = i + n (j + n k) with i, j, k < n and t.len() = n³ (see `SoData::new`).
    unsafe { *t.get_unchecked_mut(idx) = x }
}

/// The rows `fs` stored column by column: `out[c][r] = fs[r][c]`.
#[inline(always)]
fn rows6<const R: usize>(fs: [&V6; R]) -> [[f64; R]; 6] {
    let mut o = [[0.0; R]; 6];
    for c in 0..6 {
        for r in 0..R {
            o[c][r] = fs[r][c];
        }
    }
    o
}

/// `Σ_c rows[c][r] x[c]` for every row `r`.
#[inline(always)]
fn matvec<V: F64x4, const R: usize>(rows: &[[f64; R]; 6], x: &V6) -> [f64; R] {
    V::rows6_vec(rows, x)
}

/// Flat offset of `(i, j, k)` in an `n×n×n` column-major tensor.
#[inline(always)]
fn at(n: usize, i: usize, j: usize, k: usize) -> usize {
    i + n * (j + n * k)
}

/// Offset of `(i, j, k)` in an `n×n×n` tensor stored by blocks of eight pages `k` (the last
/// block holding the `w = n − k8 ≤ 8` pages left), the pages of a block interleaved:
/// `n² k8 + (k − k8) + w (i + n j)` with `k8 = 8 ⌊k/8⌋` and `w = min(8, n − k8)`. The layout of
/// `∂²τ/∂q∂q̇` in [`SoData::upper_halves`] workspaces: the eight values `(i, j, k8..k8 + w)` are
/// contiguous, as the products of the forward-dynamics derivatives read them.
#[inline(always)]
pub(crate) fn qv_offset(n: usize, i: usize, j: usize, k: usize) -> usize {
    let k8 = k & !7;
    let w = (n - k8).min(8);
    n * n * k8 + (k - k8) + w * (i + n * j)
}

/// The backward step compiled for AVX2/FMA (the 6-vector kernels vectorise 4 wide).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn backward_step_so_avx2<S: Sink>(
    model: &Model,
    data: &Data,
    ws: &SoWs<'_>,
    sink: &mut S,
    i: usize,
) {
    backward_step_so_body::<crate::simd::Avx4, S>(model, data, ws, sink, i)
}

/// One backward step of IDSVA-SO into `sink`, with the AVX2/FMA kernels where the CPU has them.
fn backward_step_so<S: Sink>(model: &Model, data: &Data, ws: &SoWs<'_>, sink: &mut S, i: usize) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        return unsafe { backward_step_so_avx2(model, data, ws, sink, i) };
    }
    backward_step_so_portable(model, data, ws, sink, i)
}

/// The backward step with the portable lanes (out of line).
#[inline(never)]
fn backward_step_so_portable<S: Sink>(
    model: &Model,
    data: &Data,
    ws: &SoWs<'_>,
    sink: &mut S,
    i: usize,
) {
    backward_step_so_body::<[f64; 4], S>(model, data, ws, sink, i)
}

/// The model-constant and per-DoF vectors of IDSVA-SO's backward pass (from a [`SoData`]).
#[derive(Clone, Copy)]
struct SoWs<'a> {
    dof: &'a [[V6; 4]],
    anc_dofs: &'a [usize],
    anc_start: &'a [usize],
    root: &'a [bool],
}

/// Where IDSVA-SO's entries `(i, j, k)` go as they are produced ([`Store`]: into the tensors,
/// full or upper halves, with or without `∂M/∂q`). Every entry that is not structurally zero
/// reaches the sink exactly once.
trait Sink {
    /// Also produce `∂M/∂q`.
    const DM: bool;
    /// Upper halves only (see [`SoData::upper_halves`]).
    const UP: bool;
    /// `∂/∂q_k (∂τ_i/∂q_j) = x`, given as `i`, `jk = j + n k` and the offset `i + n jk` (each
    /// sink uses what it needs; the call sites compute them from loop invariants).
    fn qq(&mut self, i: usize, jk: usize, at: usize, x: f64);
    /// `∂²τ_i/∂q̇_j∂q̇_k = x` (arguments as for `qq`).
    fn vv(&mut self, i: usize, jk: usize, at: usize, x: f64);
    /// `∂/∂q̇_k (∂τ_i/∂q_j) = x`.
    fn qv(&mut self, i: usize, j: usize, k: usize, x: f64);
    /// `∂M_ij/∂q_k = x` (arguments as for `qq`).
    fn dm(&mut self, i: usize, jk: usize, at: usize, x: f64);
}

/// Stores into the `n×n×n` tensors (`∂²τ/∂q∂q̇` by blocks of eight pages with `UP`).
struct Store<'a, const DM: bool, const UP: bool> {
    n: usize,
    qq: &'a mut [f64],
    vv: &'a mut [f64],
    qv: &'a mut [f64],
    dm: &'a mut [f64],
}

impl<const DM: bool, const UP: bool> Sink for Store<'_, DM, UP> {
    const DM: bool = DM;
    const UP: bool = UP;
    #[inline(always)]
    fn qq(&mut self, _i: usize, _jk: usize, at: usize, x: f64) {
        set(self.qq, at, x)
    }
    #[inline(always)]
    fn vv(&mut self, _i: usize, _jk: usize, at: usize, x: f64) {
        set(self.vv, at, x)
    }
    #[inline(always)]
    fn qv(&mut self, i: usize, j: usize, k: usize, x: f64) {
        let o = if UP { qv_offset(self.n, i, j, k) } else { at(self.n, i, j, k) };
        set(self.qv, o, x)
    }
    #[inline(always)]
    fn dm(&mut self, _i: usize, _jk: usize, at: usize, x: f64) {
        set(self.dm, at, x)
    }
}

/// One backward step of IDSVA-SO for body `i`: every entry `(i, j, k)` of the four tensors goes
/// to `sink` once, as it is produced. With
/// `S::DM`, also `∂M/∂q`; with `S::UP`, the lower-half entries of `∂²τ/∂q²` and `∂²τ/∂q̇²` and
/// the `∂²τ/∂q∂q̇` columns of root DoFs are skipped (see [`SoData::upper_halves`]; DoFs are
/// numbered depth-first, so an ancestor's are smaller).
#[inline(always)]
fn backward_step_so_body<V: F64x4, S: Sink>(
    model: &Model,
    data: &Data,
    ws: &SoWs<'_>,
    sink: &mut S,
    i: usize,
) {
    let n = model.nv;
    let SoWs { dof, anc_dofs, anc_start, root } = *ws;
    let ic = m6(&data.ic_world[i].matrix());
    let bc = m6(&data.bc[i]);
    let bct = transpose(&bc);
    let fc = v6f(&data.ofc[i]);
    let dofs = |j: usize| model.idx_v[j]..model.idx_v[j] + model.nvs[j];
    let anc = |j: usize| &anc_dofs[anc_start[j]..anc_start[j + 1]];
    for ip in dofs(i) {
        let o = i_ops::<V>(&ic, &bc, &bct, &fc, &dof[ip]);
        let mut j = i;
        while j > 0 {
            let j_is_i = j == i;
            // A joint attached to the world has Ψ̇ = v_λ × S = 0 (eq. psidot_psidotdot_defn,
            // v_0 = 0): the products with its Ψ̇ are skipped.
            let j_root = model.parents[j] == 0;
            // Upper halves: no ∂²τ/∂q∂q̇ columns of root DoFs (here those of joint j).
            let skip_j = S::UP && j_root;
            for jt in dofs(j) {
                let [sj, psidj, psiddj, psj] = &dof[jt];
                // B(I^C_i, S_i) = ½(C + R) and B(I^C_i, S_i)ᵀ = ½(C − R), with R x = x ×* (I^C_i S_i)
                // antisymmetric (eq. crff_oper): every B(I^C_i, S_i) product is C x ± x ×* t1.
                let z = [0.0; 6];
                let (c_s, c_dd, c_p) =
                    (mv::<V>(&o.c, sj), mv::<V>(&o.c, psiddj), mv::<V>(&o.c, psj));
                let a_s = mv::<V>(&o.a, sj);
                let (c_d, a_d, d_t1) = if j_root {
                    (z, z, z)
                } else {
                    (mv::<V>(&o.c, psidj), mv::<V>(&o.a, psidj), crf(psidj, &o.t1))
                };
                // q–q 1A/2A terms: z1 · Ψ̇_k + z2 · Ψ̈_k
                let z2 = crf(sj, &o.t1);
                let x_t2 = crf(sj, &o.t2);
                // z1 = −2B(I^C_i,S_i)ᵀΨ̇_j + 2 S_j×*(B^Cᵀ_i S_i); the cross-1B vector
                // h1 = −2B(I^C_i,S_i)Ψ̇_j + 2Ψ̇_j×*(I^C_i S_i) + 2 S_j×*(B^Cᵀ_i S_i) is the same vector.
                let z1: V6 = std::array::from_fn(|r| d_t1[r] - c_d[r] + 2.0 * x_t2[r]);
                let h1 = z1;
                // q̇–q̇: u = −2 B(I^C_i,S_i)ᵀ S_j
                let u: V6 = std::array::from_fn(|r| z2[r] - c_s[r]);
                // q–q 1B: w · S_k
                let w = add(&add(&a_d, &c_dd), &crf(sj, &o.g));
                // cross 2B: e = 2B(I^C_i,S_i)Ψ̇_j + S_j×* t4
                let x_t4 = crf(sj, &o.t4);
                let e: V6 = std::array::from_fn(|r| c_d[r] + d_t1[r] + x_t4[r]);
                // C is symmetric: Cᵀ S_j = C S_j.
                let csj = c_s;
                // Per-(j, t) vectors for the cases with j ≺ i (or the D case at j = i).
                let (y1, x, f2c) = if j_is_i {
                    // D S_j = S_i×*(I^C_i S_j) + S_j ×* (I^C_i S_i)
                    let ics = mv::<V>(&ic, sj);
                    (z, add(&crf(&o.s, &ics), &z2), z)
                } else {
                    // 2B(I^C_i,S_i) S_j = C S_j + S_j ×* t1
                    (mtv::<V>(&o.a, sj), add(&c_s, &z2), add(&a_s, &c_p))
                };
                let y2 = csj;
                // All dot products with one k as small matrix–vector products (rows below),
                // which vectorise. Dotted with S_k: w, u, h1, e, z2, (x | D S_j), y1, f2c, C S_j.
                let rs = rows6([&w, &u, &h1, &e, &z2, &x, &y1, &f2c, &csj]);
                // Dotted with Ψ̇_k: z1, u, y1; with Ψ̈_k and Ψ̇_k + Ṡ_k: z2, y2.
                let rd = rows6([&z1, &u, &y1]);
                let rz = rows6([&z2, &y2]);
                // j = k block (same joint): 1A only, B (v–v) and 1A cross; j ≺ i adds 1C/1E/2A/2C.
                for kr in dofs(j) {
                    let [sk, psidk, psiddk, psk] = &dof[kr];
                    let ds = matvec::<V, _>(&rs, sk);
                    // Ψ̇_k = 0 on a root joint (above).
                    let dp = if j_root { [0.0; 3] } else { matvec::<V, _>(&rd, psidk) };
                    let ddd = matvec::<V, _>(&rz, psiddk);
                    sink.qq(ip, jt + n * kr, at(n, ip, jt, kr), dp[0] + ddd[0]); // 1A
                    if !S::UP || jt <= kr {
                        sink.vv(ip, jt + n * kr, at(n, ip, jt, kr), -ds[8]); // B: −S_jᵀ C S_k
                    }
                    let val = dp[1]; // cross 1A
                    if !skip_j {
                        sink.qv(ip, kr, jt, val);
                    }
                    if !j_is_i {
                        let dpk = matvec::<V, _>(&rz, psk);
                        let v1c = dp[2] + ddd[1]; // q–q 1C/2C
                        sink.qq(jt, kr + n * ip, at(n, jt, kr, ip), v1c);
                        if !S::UP {
                            sink.qq(jt, ip + n * kr, at(n, jt, ip, kr), v1c); // column ip > kr, other joints
                        }
                        let v1e = -ds[1]; // v–v 1E/2E
                        sink.vv(jt, kr + n * ip, at(n, jt, kr, ip), v1e);
                        if !S::UP {
                            sink.vv(jt, ip + n * kr, at(n, jt, ip, kr), v1e);
                        }
                        if !skip_j {
                            sink.qv(jt, kr, ip, -val); // cross 2A
                        }
                        sink.qv(jt, ip, kr, ds[6] + dpk[1]); // cross 1C
                        if S::DM {
                            let vm = ds[8]; // ∂M 1C/2C
                            sink.dm(kr, jt + n * ip, at(n, kr, jt, ip), vm);
                            sink.dm(jt, kr + n * ip, at(n, jt, kr, ip), vm);
                        }
                    }
                }
                // Strict ancestors k ≺ j.
                let (o_ij, o_i_j, o_ji) = (ip + n * n * jt, ip + n * jt, jt * n);
                let (njt, nip) = (n * jt, n * ip);
                for &kr in anc(j) {
                    debug_assert!(kr < dof.len());
                    // SAFETY: the ancestor lists hold DoF indices < nv (`SoData::new`, checked
                    // against the model by `SoData::check`).
                    let [sk, psidk, psiddk, psk] = unsafe { dof.get_unchecked(kr) };
                    // SAFETY: kr < nv = root.len() (as for `dof` above).
                    let k_root = unsafe { *root.get_unchecked(kr) };
                    let ds = matvec::<V, _>(&rs, sk);
                    // Ψ̇_k = 0 on a root joint (above).
                    let dp = if k_root { [0.0; 3] } else { matvec::<V, _>(&rd, psidk) };
                    let ddd = matvec::<V, _>(&rz, psiddk);
                    let dpk = matvec::<V, _>(&rz, psk);
                    let (nk, nnk) = (n * kr, n * n * kr);
                    // ∂²τ/∂q²: 1A + 2A mirror, 1B (+ 2B mirror if j ≺ i)
                    let val = dp[0] + ddd[0];
                    sink.qq(ip, kr + njt, o_ij + nk, val); // (ip, kr, jt)
                    if !S::UP {
                        sink.qq(ip, jt + nk, ip + n * jt + nnk, val); // (ip, jt, kr)
                    }
                    let wval = ds[0];
                    if !S::UP || j_is_i {
                        sink.qq(kr, ip + njt, kr + n * ip + n * n * jt, wval); // (kr, ip, jt)
                    }
                    // ∂²τ/∂q̇²: 1A + 2A mirror
                    let uval = ds[1];
                    if !S::UP {
                        sink.vv(ip, jt + nk, o_i_j + nnk, uval); // (ip, jt, kr)
                    }
                    sink.vv(ip, kr + njt, o_ij + nk, uval); // (ip, kr, jt)
                    // cross: 1A, 1B, 2B
                    let cval = dp[1];
                    // Upper halves: no ∂²τ/∂q∂q̇ columns of root DoFs.
                    let skip_k = S::UP && k_root;
                    if !skip_k {
                        sink.qv(ip, kr, jt, cval);
                    }
                    sink.qv(ip, jt, kr, ds[2] + dpk[0]);
                    sink.qv(kr, jt, ip, ds[3]);
                    if S::DM {
                        // ∂M/∂q 1B + 2B mirror
                        sink.dm(kr, ip + njt, kr + n * ip + n * n * jt, ds[4]); // (kr, ip, jt)
                        sink.dm(ip, kr + njt, o_ij + nk, ds[4]); // (ip, kr, jt)
                    }
                    if j_is_i {
                        // v–v D (k ≺ j = i)
                        if !S::UP || ip <= jt {
                            sink.vv(kr, ip + njt, kr + n * ip + n * n * jt, ds[5]); // (kr, ip, jt)
                        }
                    } else {
                        sink.qq(kr, jt + nip, kr + o_ji + n * n * ip, wval); // 1B mirror (2B): (kr, jt, ip)
                        let v1c = dp[2] + ddd[1]; // q–q 1C/2C
                        sink.qq(jt, kr + nip, jt + nk + n * n * ip, v1c); // (jt, kr, ip)
                        if !S::UP {
                            sink.qq(jt, ip + nk, jt + n * ip + nnk, v1c); // (jt, ip, kr)
                            sink.vv(kr, ip + njt, kr + n * ip + n * n * jt, ds[5]); // v–v 1C/2C: (kr, ip, jt)
                        }
                        sink.vv(kr, jt + nip, kr + o_ji + n * n * ip, ds[5]); // (kr, jt, ip)
                        sink.vv(jt, kr + nip, jt + nk + n * n * ip, -uval); // v–v 1E/2E: (jt, kr, ip)
                        if !S::UP {
                            sink.vv(jt, ip + nk, jt + n * ip + nnk, -uval); // (jt, ip, kr)
                        }
                        if !skip_k {
                            sink.qv(jt, kr, ip, -cval); // cross 2A
                        }
                        sink.qv(jt, ip, kr, ds[6] + dpk[1]); // cross 1C
                        sink.qv(kr, ip, jt, ds[7]); // cross 2C
                        if S::DM {
                            sink.dm(kr, jt + nip, kr + o_ji + n * n * ip, ds[8]); // ∂M 1C/2C: (kr, jt, ip)
                            sink.dm(jt, kr + nip, jt + nk + n * n * ip, ds[8]); // (jt, kr, ip)
                        }
                    }
                }
            }
            j = model.parents[j];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::random_tree;
    use crate::rng::Rng;

    /// The upper-half workspace (`SoData::upper_halves`) writes exactly the entries of the full
    /// one in its upper halves (bit for bit, same code), and nothing else: on random trees with
    /// joints of every kind (multi-DoF ones included, whose `∂²τ/∂q²` blocks are not
    /// symmetric) and a free-flyer, the other entries stay zero although they are not
    /// structurally zero (checked: each tree has some).
    #[test]
    fn upper_halves_write_exactly_the_upper_entries() {
        let mut rng = Rng::new(5);
        let (mut total_joint_lower, mut root_qv) = (0, 0);
        for seed in 1..9 {
            let m = random_tree(8, seed, seed % 2 == 0);
            let n = m.nv;
            let q = m.random_configuration(&mut rng);
            let v = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let a = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let (mut d, mut full, mut up) =
                (Data::new(&m), SoData::new(&m), SoData::upper_halves(&m));
            id_so_derivatives_ws(&m, &mut d, &mut full, &q, &v, &a, None).unwrap();
            id_so_derivatives_ws(&m, &mut d, &mut up, &q, &v, &a, None).unwrap();
            let joint = |j: usize| m.dof_joint[j];
            let qv_max = full.d2tau_dqdv().as_slice().iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let (mut lower_nonzero, mut joint_lower) = (0, 0);
            for (i, j, k) in (0..n * n * n).map(|x| (x % n, x / n % n, x / (n * n))) {
                let keep_qq = j <= k || joint(j) == joint(k);
                let (fq, uq) = (full.d2tau_dq2()[(i, j, k)], up.d2tau_dq2()[(i, j, k)]);
                assert_eq!(uq, if keep_qq { fq } else { 0.0 }, "∂²τ/∂q² {i} {j} {k}");
                let (fv, uv) = (full.d2tau_dv2()[(i, j, k)], up.d2tau_dv2()[(i, j, k)]);
                assert_eq!(uv, if j <= k { fv } else { 0.0 }, "∂²τ/∂q̇² {i} {j} {k}");
                let fx = full.d2tau_dqdv()[(i, j, k)];
                let ux = up.d2tau_dqdv().as_slice()[qv_offset(n, i, j, k)];
                let root = m.parents[joint(j)] == 0;
                assert_eq!(ux, if root { 0.0 } else { fx }, "∂²τ/∂q∂q̇ {i} {j} {k}");
                // The left-out columns vanish (up to rounding).
                if root {
                    assert!(fx.abs() < 1e-12 * (1.0 + qv_max), "{i} {j} {k}");
                    root_qv += 1;
                }
                lower_nonzero +=
                    usize::from(!keep_qq && fq != 0.0) + usize::from(j > k && fv != 0.0);
                joint_lower += usize::from(j > k && joint(j) == joint(k) && fq != 0.0);
            }
            assert!(lower_nonzero > 0, "tree {seed}: no non-zero lower-half entry");
            total_joint_lower += joint_lower;
            assert_eq!(up.dm_dq().dims(), (0, 0, 0));
        }
        // Some multi-DoF joint blocks below the diagonal (kept) were exercised.
        assert!(total_joint_lower > 0 && root_qv > 0);
    }

    /// The entries of `∂²τ/∂q∂q̇` that the upper-half workspace writes are exactly the `(i, j, k)`
    /// with `i`, `j` and `k` pairwise related (on one root path) and `j` not a DoF of a joint
    /// attached to the world: the forward-dynamics products add their `∂M/∂q` terms to the
    /// others' lanes and overwrite the rest (see `fd::so_products`), which is right only if no
    /// other entry is ever written. Checked by filling the tensor with NaN first, on random
    /// trees with joints of every kind.
    #[test]
    fn upper_halves_write_exactly_the_chain_entries_of_the_cross_tensor() {
        let mut rng = Rng::new(6);
        for seed in 1..9 {
            let m = random_tree(8, seed, seed % 2 == 1);
            let n = m.nv;
            let related = |a: usize, b: usize| {
                m.dof_joint[a] == m.dof_joint[b]
                    || m.ancestors_of_dof(a).contains(&b)
                    || m.ancestors_of_dof(b).contains(&a)
            };
            let q = m.random_configuration(&mut rng);
            let v = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let a = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let (mut d, mut up) = (Data::new(&m), SoData::upper_halves(&m));
            up.d2tau_dqdv.as_mut_slice().fill(f64::NAN);
            id_so_derivatives_ws(&m, &mut d, &mut up, &q, &v, &a, None).unwrap();
            for (i, j, k) in (0..n * n * n).map(|x| (x % n, x / n % n, x / (n * n))) {
                let chain = related(i, j) && related(i, k) && related(j, k);
                let root = m.parents[m.dof_joint[j]] == 0;
                let written = !up.d2tau_dqdv.as_slice()[qv_offset(n, i, j, k)].is_nan();
                assert_eq!(written, chain && !root, "tree {seed}: entry ({i}, {j}, {k})");
            }
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::prepare;
    use crate::deriv::SoData;
    use crate::error::{Error, Result};
    use crate::model::reduction::MimicModel;
    use crate::spatial::Force;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector};

    use crate::deriv::id_fo::reduced::reduce_fo;

    /// Workspace and results of the second-order algorithms of a [`MimicModel`] (layout
    /// `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)`, `nv × nv × nv`).
    #[derive(Clone, Debug)]
    pub struct MimicSoData {
        pub(crate) full: SoData,
        pub(crate) d2tau_dq2: Tensor3,
        pub(crate) d2tau_dv2: Tensor3,
        pub(crate) d2tau_dqdv: Tensor3,
        pub(crate) dm_dq: Tensor3,
        pub(crate) d2qdd_dq2: Tensor3,
        pub(crate) d2qdd_dv2: Tensor3,
        pub(crate) d2qdd_dqdv: Tensor3,
        pub(crate) d2qdd_dtaudq: Tensor3,
        /// Scratch: `∂M/∂q_k X[:, j]` at `(·, j, k)`.
        pub(crate) y: Tensor3,
        /// Scratch: one `nv × nv` page.
        pub(crate) page: DMatrix<f64>,
        pub(crate) key: u64,
    }

    impl MimicSoData {
        /// Workspace for `model`.
        pub fn new(model: &MimicModel) -> Self {
            let n = model.nv;
            let t = || Tensor3::zeros(n, n, n);
            Self {
                full: SoData::new(&model.full),
                d2tau_dq2: t(),
                d2tau_dv2: t(),
                d2tau_dqdv: t(),
                dm_dq: t(),
                d2qdd_dq2: t(),
                d2qdd_dv2: t(),
                d2qdd_dqdv: t(),
                d2qdd_dtaudq: t(),
                y: t(),
                page: DMatrix::zeros(n, n),
                key: model.key,
            }
        }
        pub(crate) fn check(&self, model: &MimicModel) -> Result<()> {
            if self.key != model.key || self.page.nrows() != model.nv {
                return Err(Error::Workspace(format!(
                    "SoData was made for another model; make it with SoData::new for the \
                     reduced model \"{}\"",
                    model.name()
                )));
            }
            Ok(())
        }
        /// `∂²τ/∂q²`: `T[(i, j, k)] = ∂/∂q_k (∂τ_i/∂q_j)`.
        pub fn d2tau_dq2(&self) -> &Tensor3 {
            &self.d2tau_dq2
        }
        /// `∂²τ/∂v²`.
        pub fn d2tau_dv2(&self) -> &Tensor3 {
            &self.d2tau_dv2
        }
        /// `T[(i, j, k)] = ∂/∂v_k (∂τ_i/∂q_j)`.
        pub fn d2tau_dqdv(&self) -> &Tensor3 {
            &self.d2tau_dqdv
        }
        /// `T[(i, j, k)] = ∂M_ij/∂q_k`.
        pub fn dm_dq(&self) -> &Tensor3 {
            &self.dm_dq
        }
        /// `∂²q̈/∂q²`.
        pub fn d2qdd_dq2(&self) -> &Tensor3 {
            &self.d2qdd_dq2
        }
        /// `∂²q̈/∂v²`.
        pub fn d2qdd_dv2(&self) -> &Tensor3 {
            &self.d2qdd_dv2
        }
        /// `T[(i, j, k)] = ∂/∂v_k (∂q̈_i/∂q_j)`.
        pub fn d2qdd_dqdv(&self) -> &Tensor3 {
            &self.d2qdd_dqdv
        }
        /// `T[(i, j, k)] = ∂(M⁻¹)_ij/∂q_k`.
        pub fn d2qdd_dtaudq(&self) -> &Tensor3 {
            &self.d2qdd_dtaudq
        }
    }

    /// Second-order inverse-dynamics derivatives at `(q, v, a)` (the full model's
    /// [`crate::deriv::id_so_derivatives`] contracted with `G`): the tensors of `so` and the
    /// first-order results in `data` (as [`id_derivatives`]).
    ///
    /// # Errors
    /// As [`rnea`], or an `so` made for another model.
    pub fn id_so_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        so: &mut MimicSoData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<()> {
        so.check(model)?;
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        id_so_reduced(model, data, so, fext)
    }

    pub(crate) fn id_so_reduced(
        model: &MimicModel,
        data: &mut MimicData,
        so: &mut MimicSoData,
        fext: Option<&[Force]>,
    ) -> Result<()> {
        crate::deriv::id_so::id_so_derivatives_ws(
            &model.full,
            &mut data.full,
            &mut so.full,
            &data.q,
            &data.v,
            &data.a,
            fext,
        )?;
        reduce_fo(model, data);
        model.reduce_tensor(so.full.d2tau_dq2(), &mut so.d2tau_dq2);
        model.reduce_tensor(so.full.d2tau_dv2(), &mut so.d2tau_dv2);
        model.reduce_tensor(so.full.d2tau_dqdv(), &mut so.d2tau_dqdv);
        model.reduce_tensor(so.full.dm_dq(), &mut so.dm_dq);
        Ok(())
    }
}
