//! Shared workspace of the contact algorithms: contact paths, the contact Jacobian, the
//! Delassus factorisation and the block inverse of the KKT matrix
//! `R = [[M, −J_cᵀ], [J_c, 0]]` (unknowns `(q̈, λ)` or `(q̇⁺, λ̂)`), and the product terms
//! `G(z)` of the second-order implicit-function formulas.

use super::contact_kin::{Base, Dir, Path, djtl_dq, djz_dq};
use super::zero::idfoza_core;
use crate::algo::internal::ltl_solve_in_place;
use crate::algo::{Contact, Data};
use crate::error::{Error, Result};
use crate::linalg::gemm;
use crate::model::Model;
use crate::spatial::Motion;
use nalgebra::{DMatrix, DVector, Vector3};

/// Workspace for a fixed set of point contacts on one model (allocated once).
#[derive(Clone, Debug)]
pub struct ContactData {
    /// The contacts.
    pub contacts: Vec<Contact>,
    pub(crate) paths: Vec<Path>,
    pub(crate) acc: Vec<Motion>,
    pub(crate) zc: Vec<Motion>,
    /// Contact Jacobian `J_c` (`3 nc × nv`), world-aligned point velocities.
    pub jac: DMatrix<f64>,
    /// Drift `J̇_c q̇` (classical point accelerations at `q̈ = 0`), when computed.
    pub drift: DVector<f64>,
    pub(crate) y: DMatrix<f64>,
    pub(crate) lam: DMatrix<f64>,
    pub(crate) del: DMatrix<f64>,
    pub(crate) yl: DMatrix<f64>,
    pub(crate) rhs: DVector<f64>,
    pub(crate) sol: DVector<f64>,
    pub(crate) rinv: DMatrix<f64>,
    pub(crate) g: DMatrix<f64>,
    pub(crate) zmat: DMatrix<f64>,
    /// Regularisation `μ ≥ 0` added to the Delassus matrix `J M⁻¹ Jᵀ` (default 0: a
    /// rank-deficient contact set is an error). With `μ > 0` the solve is damped:
    /// `(J M⁻¹ Jᵀ + μ I) λ = …`, and all derivatives are those of the damped system.
    pub damping: f64,
}

impl ContactData {
    /// Workspace for `contacts` on `model`. A contact on the fixed world is an error.
    pub fn new(model: &Model, contacts: &[Contact]) -> Result<Self> {
        let n = model.nv;
        let m = 3 * contacts.len();
        let mut paths = Vec::with_capacity(contacts.len());
        for c in contacts {
            if c.frame >= model.frames.len() {
                return Err(Error::Unknown {
                    kind: "frame index".into(),
                    name: c.frame.to_string(),
                });
            }
            let (body, _) = c.body_point(model);
            if body == 0 {
                return Err(Error::Singular {
                    what: "contact set".into(),
                    detail: format!(
                        "contact on frame \"{}\" is attached to the fixed world: it constrains nothing",
                        model.frames[c.frame].name
                    ),
                });
            }
            let mut joints = vec![];
            let mut j = body;
            while j > 0 {
                joints.push(j);
                j = model.parents[j];
            }
            joints.reverse();
            let mut path = Path { joints, ..Path::default() };
            for &j in &path.joints {
                for x in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
                    path.dofs.push(x);
                    path.dof_joint.push(j);
                    path.dof_parent.push(model.parents[j]);
                }
            }
            paths.push(path);
        }
        Ok(Self {
            contacts: contacts.to_vec(),
            paths,
            acc: vec![Motion::zero(); model.njoints()],
            zc: vec![Motion::zero(); model.njoints()],
            jac: DMatrix::zeros(m, n),
            drift: DVector::zeros(m),
            y: DMatrix::zeros(n, m),
            lam: DMatrix::zeros(m, m),
            del: DMatrix::zeros(m, m),
            yl: DMatrix::zeros(n, m),
            rhs: DVector::zeros(n + m),
            sol: DVector::zeros(n + m),
            rinv: DMatrix::zeros(n + m, n + m),
            g: DMatrix::zeros(n + m, n),
            zmat: DMatrix::zeros(n, n),
            damping: 0.0,
        })
    }

    /// Number of constraint rows `3 nc`.
    pub fn dim(&self) -> usize {
        3 * self.contacts.len()
    }

    /// Contact body of contact `c`.
    pub(crate) fn body(&self, c: usize) -> usize {
        *self.paths[c].joints.last().expect("non-empty path")
    }

    /// Contact names for error messages.
    fn names(&self, model: &Model) -> String {
        self.contacts
            .iter()
            .map(|c| format!("\"{}\"", model.frames[c.frame].name))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Base quantities of the current state (after `forward_pass_world` and [`update_points`]).
pub(crate) fn base<'a>(model: &'a Model, data: &'a Data, cd: &'a ContactData) -> Base<'a> {
    Base {
        s: &data.s_world,
        vel: &data.ov,
        acc: &cd.acc,
        dof_joint: &model.dof_joint,
        parents: &model.parents,
    }
}

/// World contact points, accelerations without gravity and the Jacobian, from the current
/// `o_m_i`, `s_world`, `oa` (with base acceleration `a0`).
pub(crate) fn update_points(model: &Model, data: &Data, cd: &mut ContactData, a0: Motion) {
    for j in 0..model.njoints() {
        cd.acc[j] = if j == 0 { Motion::zero() } else { data.oa[j] - a0 };
    }
    cd.jac.fill(0.0);
    for (c, contact) in cd.contacts.iter().enumerate() {
        let (body, local) = contact.body_point(model);
        let p = data.o_m_i[body].act_point(&local);
        cd.paths[c].p = p;
        for &x in &cd.paths[c].dofs {
            let s = data.s_world[x];
            let u = s.lin + s.ang.cross(&p);
            for r in 0..3 {
                cd.jac[(3 * c + r, x)] = u[r];
            }
        }
    }
}

/// Classical accelerations of the contact points (stacked) from the current `ov` and `acc`.
pub(crate) fn point_accelerations(data: &Data, cd: &ContactData, out: &mut DVector<f64>) {
    for (c, path) in cd.paths.iter().enumerate() {
        let m = cd.body(c);
        let (v, a, p) = (data.ov[m], cd.acc[m], path.p);
        let pdot = v.lin + v.ang.cross(&p);
        let acc = a.lin + a.ang.cross(&p) + v.ang.cross(&pdot);
        for r in 0..3 {
            out[3 * c + r] = acc[r];
        }
    }
}

/// With `data.ltl` (factor of `M`) and `data.minv`, computes `Y = M⁻¹Jᵀ`, `Λ = (J Y + μI)⁻¹` and
/// `R⁻¹ = [[M⁻¹ − YΛYᵀ, YΛ], [−ΛYᵀ, Λ]]`. A rank-deficient contact set is an error naming the
/// contacts (unless damped).
pub(crate) fn factor_kkt(model: &Model, data: &Data, cd: &mut ContactData) -> Result<()> {
    let n = model.nv;
    let m = cd.dim();
    cd.y.tr_copy_from(&cd.jac);
    for mut col in cd.y.column_iter_mut() {
        ltl_solve_in_place(model, &data.ltl, col.as_mut_slice());
    }
    // Delassus matrix J M⁻¹ Jᵀ (+ μ I), symmetrised, factorised in place (L in the lower part).
    gemm(1.0, &cd.jac, &cd.y, 0.0, &mut cd.del);
    for c in 0..m {
        for r in 0..c {
            let x = 0.5 * (cd.del[(r, c)] + cd.del[(c, r)]);
            cd.del[(r, c)] = x;
            cd.del[(c, r)] = x;
        }
        cd.del[(c, c)] += cd.damping;
    }
    let scale = (0..m).map(|i| cd.del[(i, i)].abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    if !cholesky_inverse_in_place(&mut cd.del, &mut cd.lam, 1e-11 * scale) {
        return Err(Error::Singular {
            what: "contact set".into(),
            detail: format!(
                "the Delassus matrix J M⁻¹ Jᵀ of contacts {} is rank deficient (dependent or \
                 redundant constraints); set ContactData::damping > 0 for a regularised solve",
                cd.names(model)
            ),
        });
    }
    gemm(1.0, &cd.y, &cd.lam, 0.0, &mut cd.yl);
    // top-left block M⁻¹ − (YΛ) Yᵀ (m is small: a direct loop).
    for c in 0..n {
        for r in 0..n {
            let mut x = data.minv[(r, c)];
            for l in 0..m {
                x -= cd.yl[(r, l)] * cd.y[(c, l)];
            }
            cd.rinv[(r, c)] = x;
        }
    }
    cd.rinv.view_mut((0, n), (n, m)).copy_from(&cd.yl);
    for r in 0..m {
        for c in 0..n {
            cd.rinv[(n + r, c)] = -cd.yl[(c, r)];
        }
    }
    cd.rinv.view_mut((n, n), (m, m)).copy_from(&cd.lam);
    Ok(())
}

/// Cholesky factorisation of the symmetric `a` in place (lower triangle) and its inverse into
/// `inv`, without allocating. `false` if a pivot `l_ii²` is not above `tol`.
fn cholesky_inverse_in_place(a: &mut DMatrix<f64>, inv: &mut DMatrix<f64>, tol: f64) -> bool {
    let m = a.nrows();
    for j in 0..m {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if d.is_nan() || d <= tol {
            return false;
        }
        let l = d.sqrt();
        a[(j, j)] = l;
        for i in j + 1..m {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / l;
        }
    }
    // inv = L⁻ᵀ L⁻¹, column by column: solve L y = e_c, then Lᵀ x = y.
    for c in 0..m {
        for i in 0..m {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in 0..i {
                s -= a[(i, k)] * inv[(k, c)];
            }
            inv[(i, c)] = s / a[(i, i)];
        }
        for i in (0..m).rev() {
            let mut s = inv[(i, c)];
            for k in i + 1..m {
                s -= a[(k, i)] * inv[(k, c)];
            }
            inv[(i, c)] = s / a[(i, i)];
        }
    }
    true
}

/// Subtracts `∂(J_cᵀ λ)/∂q` (λ: `3 nc` world forces) from `out` (`nv×nv`, `[x][l]`).
pub(crate) fn sub_djtl_dq(
    model: &Model,
    data: &Data,
    cd: &ContactData,
    lambda: &[f64],
    out: &mut DMatrix<f64>,
) {
    let b = base(model, data, cd);
    for (c, path) in cd.paths.iter().enumerate() {
        let lam = Vector3::new(lambda[3 * c], lambda[3 * c + 1], lambda[3 * c + 2]);
        for &x in &path.dofs {
            for &l in &path.dofs {
                out[(x, l)] -= djtl_dq(&b, &path.p, &lam, x, l, Dir::None).0;
            }
        }
    }
}

/// `G(z)` (columns `l`): `[IDFOZA(z₁) − ∂(Jᵀz₂)/∂q ; ∂(J z₁)/∂q]`, `z = (z₁, z₂)` of length
/// `nv + 3 nc`. Needs the composite inertias of the current `q` in `data`. Writes `cd.g`.
pub(crate) fn g_matrix(model: &Model, data: &mut Data, cd: &mut ContactData, z: &[f64]) {
    let n = model.nv;
    g_matrix_split(model, data, cd, &z[..n], &z[n..], &z[..n]);
}

/// `G` with separate vectors: `[IDFOZA(z_m) − ∂(Jᵀz₂)/∂q ; ∂(J z_j)/∂q]`.
pub(crate) fn g_matrix_split(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactData,
    z_m: &[f64],
    z2: &[f64],
    z: &[f64],
) {
    let n = model.nv;
    idfoza_core(model, data, z_m, &mut cd.zmat);
    cd.g.view_mut((0, 0), (n, n)).copy_from(&cd.zmat);
    let mut g = std::mem::replace(&mut cd.g, DMatrix::zeros(0, 0));
    sub_djtl_dq_rows(model, data, cd, z2, &mut g);
    // ∂(J z₁)/∂q rows: cumulative Z_j = Σ_{x ⪯ j} S_x z_x along the path.
    let mut zc = std::mem::take(&mut cd.zc);
    for (c, path) in cd.paths.iter().enumerate() {
        for &j in &path.joints {
            let parent = model.parents[j];
            let mut zj = if parent == 0 { Motion::zero() } else { zc[parent] };
            let iv = model.idx_v[j];
            for (s, zx) in data.s_world[iv..iv + model.nvs[j]].iter().zip(&z[iv..iv + model.nvs[j]])
            {
                zj += *s * *zx;
            }
            zc[j] = zj;
        }
        zc[0] = Motion::zero();
        let b = base(model, data, cd);
        let m = cd.body(c);
        for &l in &path.dofs {
            let r = djz_dq(&b, &zc, m, &path.p, l, Dir::None).v;
            for k in 0..3 {
                g[(n + 3 * c + k, l)] = r[k];
            }
        }
    }
    cd.zc = zc;
    cd.g = g;
}

/// Rows `0..nv` of `g`: subtract `∂(Jᵀ z₂)/∂q`.
fn sub_djtl_dq_rows(
    model: &Model,
    data: &Data,
    cd: &ContactData,
    z2: &[f64],
    g: &mut DMatrix<f64>,
) {
    let b = base(model, data, cd);
    for (c, path) in cd.paths.iter().enumerate() {
        let lam = Vector3::new(z2[3 * c], z2[3 * c + 1], z2[3 * c + 2]);
        if lam == Vector3::zeros() {
            continue;
        }
        for &x in &path.dofs {
            for &l in &path.dofs {
                g[(x, l)] -= djtl_dq(&b, &path.p, &lam, x, l, Dir::None).0;
            }
        }
    }
    let _ = model;
}
