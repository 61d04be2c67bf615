//! Kinematic derivatives of point contacts (world-aligned), first and second order, evaluated
//! per contact along its root path without `O(N⁴)` work.
//!
//! All quantities are world-frame and built from a few *base* quantities along the path of the
//! contact body `m`: the motion subspaces `S_x` (DoFs `x` of joints `⪯ m`), the body velocities
//! `V_j` and accelerations `A_j` (no gravity) of the joints `j ⪯ m`, and the contact point `p`.
//! Their derivatives along a tangent perturbation of `q_k` follow from the notes' identities
//! (J1, J6, J7, J8, J9 and `∂p/∂q_k = J_c(:, k)`):
//!
//! * `D S_x = [k ⪯ x] S_k × S_x`                                                     (J1)
//! * `D V_j = [k ⪯ j] S_k × (V_j − V_λ(k))`                                           (J2 / dv_eq)
//! * `D A_j = [k ⪯ j] ((A_λ(k) − A_j) × S_k + (V_λ(k) − V_j) × Ψ̇_k)`, `Ψ̇_k = V_λ(k) × S_k` (J6, J7)
//! * `D p = S_k.lin + S_k.ang × p`
//!
//! and along `q̇_k`: `D V_j = [k ⪯ j] S_k` (J8), `D A_j = [k ⪯ j](Ψ̇_k + Ṡ_k − V_j × S_k)` (J9).
//! A first derivative is an expression in base quantities; its second derivative is the same
//! expression evaluated with *dual* base quantities whose tangents follow these rules. This gives
//! `T[i][j][k] = ∂/∂x_k (∂y_i/∂u_j)` with the inner derivative first, as everywhere else.
//!
//! The second derivatives that the KKT and impact second order evaluate for every DoF pair or
//! triple are in closed form instead: `∂u_x/∂q_l = w_a × u_b` (`a` the ancestor of `x`, `l`)
//! differentiated once more ([`du_dq2`], [`djac_dq2`] for every contact type), running sums along
//! the path for `∂(J z)/∂q` ([`djz_dq_parts`]) and for `∂²a_p/∂q∂q̇` ([`dap_dqdv`]); the dual
//! evaluations remain for the contact accelerations along `q` ([`dap_dq`], `dacc_dq`).

use crate::spatial::Motion;
use nalgebra::{Matrix3, Vector3};
use std::ops::{Add, Mul, Neg, Sub};

/// A 3-vector with a tangent.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct D3 {
    pub v: Vector3<f64>,
    pub d: Vector3<f64>,
}

/// A motion vector with a tangent.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Dm {
    pub v: Motion,
    pub d: Motion,
}

impl D3 {
    #[inline]
    pub fn cross(&self, o: &D3) -> D3 {
        D3 { v: self.v.cross(&o.v), d: self.d.cross(&o.v) + self.v.cross(&o.d) }
    }
    #[inline]
    pub fn dot(&self, o: &Vector3<f64>) -> (f64, f64) {
        (self.v.dot(o), self.d.dot(o))
    }
}

impl Dm {
    #[inline]
    pub fn cross(&self, o: &Dm) -> Dm {
        Dm { v: self.v.cross(&o.v), d: self.d.cross(&o.v) + self.v.cross(&o.d) }
    }
    #[inline]
    pub fn ang(&self) -> D3 {
        D3 { v: self.v.ang, d: self.d.ang }
    }
    #[inline]
    pub fn lin(&self) -> D3 {
        D3 { v: self.v.lin, d: self.d.lin }
    }
}

macro_rules! dual_ops {
    ($t:ty) => {
        impl Add for $t {
            type Output = $t;
            #[inline]
            fn add(self, o: $t) -> $t {
                Self { v: self.v + o.v, d: self.d + o.d }
            }
        }
        impl Sub for $t {
            type Output = $t;
            #[inline]
            fn sub(self, o: $t) -> $t {
                Self { v: self.v - o.v, d: self.d - o.d }
            }
        }
        impl Neg for $t {
            type Output = $t;
            #[inline]
            fn neg(self) -> $t {
                Self { v: -self.v, d: -self.d }
            }
        }
        impl Mul<f64> for $t {
            type Output = $t;
            #[inline]
            fn mul(self, s: f64) -> $t {
                Self { v: self.v * s, d: self.d * s }
            }
        }
    };
}
dual_ops!(D3);
dual_ops!(Dm);

/// Direction of the outer (tangent) derivative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Dir {
    /// No tangent (first-order evaluation).
    None,
    /// Tangent perturbation of `q_k` (DoF index).
    Q(usize),
    /// Perturbation of `q̇_k`.
    V(usize),
}

/// The root path of one contact body, with the base quantities.
#[derive(Clone, Debug, Default)]
pub(crate) struct Path {
    /// Joints from the root to the contact body (ascending), without the world.
    pub joints: Vec<usize>,
    /// DoFs on the path (ascending).
    pub dofs: Vec<usize>,
    /// For each DoF on the path: its joint.
    pub dof_joint: Vec<usize>,
    /// For each DoF on the path: the parent joint of its joint (0 = world).
    pub dof_parent: Vec<usize>,
    /// World contact point.
    pub p: Vector3<f64>,
    /// World rotation of the contact frame.
    pub rot: Matrix3<f64>,
}

/// Access to the base quantities of the current state (world frame).
pub(crate) struct Base<'a> {
    /// Motion subspaces per DoF.
    pub s: &'a [Motion],
    /// Body velocities per joint (index 0: world, zero).
    pub vel: &'a [Motion],
    /// Body accelerations per joint without gravity (index 0: zero).
    pub acc: &'a [Motion],
    /// DoF → joint.
    pub dof_joint: &'a [usize],
    /// Joint → parent.
    pub parents: &'a [usize],
}

impl Base<'_> {
    /// `S_x` with its tangent along `dir`.
    #[inline]
    pub fn s(&self, x: usize, dir: Dir) -> Dm {
        let v = self.s[x];
        let d = match dir {
            Dir::Q(k) if self.dof_joint[k] <= self.dof_joint[x] => self.s[k].cross(&v),
            _ => Motion::zero(),
        };
        Dm { v, d }
    }
    /// Velocity-like cumulative quantity `c_j` (velocities, or `Σ S z` sums) of joint `j`
    /// (on the path) with its tangent; `is_velocity` selects the `q̇` rule.
    #[inline]
    pub fn cum(&self, c: &[Motion], j: usize, dir: Dir, is_velocity: bool) -> Dm {
        let v = c[j];
        let d = match dir {
            Dir::Q(k) => {
                let jk = self.dof_joint[k];
                if j > 0 && jk <= j {
                    self.s[k].cross(&(v - c[self.parents[jk]]))
                } else {
                    Motion::zero()
                }
            }
            Dir::V(k) if is_velocity => {
                let jk = self.dof_joint[k];
                if j > 0 && jk <= j { self.s[k] } else { Motion::zero() }
            }
            _ => Motion::zero(),
        };
        Dm { v, d }
    }
    /// Body velocity `V_j`.
    #[inline]
    pub fn vel(&self, j: usize, dir: Dir) -> Dm {
        self.cum(self.vel, j, dir, true)
    }
    /// Body acceleration `A_j` (no gravity).
    #[inline]
    pub fn acc(&self, j: usize, dir: Dir) -> Dm {
        let v = self.acc[j];
        let d = match dir {
            Dir::Q(k) => {
                let jk = self.dof_joint[k];
                if j > 0 && jk <= j {
                    let lk = self.parents[jk];
                    let psid = self.vel[lk].cross(&self.s[k]);
                    (self.acc[lk] - v).cross(&self.s[k]) + (self.vel[lk] - self.vel[j]).cross(&psid)
                } else {
                    Motion::zero()
                }
            }
            Dir::V(k) => {
                let jk = self.dof_joint[k];
                if j > 0 && jk <= j {
                    let lk = self.parents[jk];
                    let sk = self.s[k];
                    self.vel[lk].cross(&sk) + self.vel[jk].cross(&sk) - self.vel[j].cross(&sk)
                } else {
                    Motion::zero()
                }
            }
            Dir::None => Motion::zero(),
        };
        Dm { v, d }
    }
    /// Contact point `p` with its tangent.
    #[inline]
    pub fn p(&self, p: &Vector3<f64>, dir: Dir) -> D3 {
        let d = match dir {
            Dir::Q(k) => self.s[k].lin + self.s[k].ang.cross(p),
            _ => Vector3::zeros(),
        };
        D3 { v: *p, d }
    }
}

/// Point velocity of a motion `m` at point `p`: `m.lin + m.ang × p`.
#[inline]
pub(crate) fn at_point(m: &Dm, p: &D3) -> D3 {
    m.lin() + m.ang().cross(p)
}

/// The contact body's velocity `V_m`, acceleration `A_m` and contact point `p` with their
/// tangents along one direction, shared by [`dap_dq`] for every `l`.
pub(crate) struct BodyAt {
    vm: Dm,
    am: Dm,
    pp: D3,
}

impl BodyAt {
    /// Body `m`'s quantities at the point `p`, with tangent `dir`.
    #[inline]
    pub fn new(b: &Base, m: usize, p: &Vector3<f64>, dir: Dir) -> BodyAt {
        BodyAt { vm: b.vel(m, dir), am: b.acc(m, dir), pp: b.p(p, dir) }
    }
}

/// `∂a_p/∂q_l` (tangent) of the classical acceleration of the contact point of body `m`,
/// evaluated with tangent `dir` (the outer derivative; `at` made with the same `dir`).
pub(crate) fn dap_dq(b: &Base, at: &BodyAt, l: usize, dir: Dir) -> D3 {
    let jl = b.dof_joint[l];
    let ll = b.parents[jl];
    let sl = b.s(l, dir);
    let (vm, am, pp) = (at.vm, at.am, at.pp);
    let vl = b.vel(ll, dir);
    let al = b.acc(ll, dir);
    let psid = vl.cross(&sl);
    let dv = sl.cross(&(vm - vl)); // J2
    let da = (al - am).cross(&sl) + (vl - vm).cross(&psid); // J6 + J7
    let dp = at_point(&sl, &pp);
    let pdot = at_point(&vm, &pp);
    let dpdot = at_point(&dv, &pp) + vm.ang().cross(&dp);
    // a_p = A.lin + A.ang × p + ω × ṗ
    da.lin()
        + da.ang().cross(&pp)
        + am.ang().cross(&dp)
        + dv.ang().cross(&pdot)
        + vm.ang().cross(&dpdot)
}

/// `∂(λ·u_x)/∂q_l` for one contact force `λ` and path DoF `x`: the `(x, l)` entry of
/// `∂(J_cᵀλ)/∂q`, evaluated with tangent `dir`. Returns (value, tangent).
#[inline]
pub(crate) fn djtl_dq(
    b: &Base,
    p: &Vector3<f64>,
    lam: &Vector3<f64>,
    x: usize,
    l: usize,
    dir: Dir,
) -> (f64, f64) {
    let sx = b.s(x, dir);
    let sl = b.s(l, dir);
    let pp = b.p(p, dir);
    let dsx = if b.dof_joint[l] <= b.dof_joint[x] { sl.cross(&sx) } else { Dm::default() };
    let dp = at_point(&sl, &pp);
    // u_x = S_x.lin + S_x.ang × p
    (at_point(&dsx, &pp) + sx.ang().cross(&dp)).dot(lam)
}

/// A DoF `x` of a 3-D world-aligned point contact's path: `w = S_x.ang`, the point velocity
/// column `u = S_x.lin + S_x.ang × p` and `x`'s joint (path order: ancestors have lower index).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PointCol {
    pub w: Vector3<f64>,
    pub u: Vector3<f64>,
    pub joint: usize,
}

/// `∂/∂q_k (∂u_x/∂q_l)` in closed form for the DoFs `x`, `l`, `k` of one point contact's path.
/// With `(a, b) = (l, x)` if `l`'s joint is `x`'s or an ancestor, else `(x, l)`,
/// `∂u_x/∂q_l = w_a × u_b` (eq. J1 with `∂p/∂q_l = u_l`; see `point_jacobian_dq` in
/// `super::contact`), and along `q_k`: `D w_a = [k ⪯ a] w_k × w_a` (J1) and
/// `D u_b = w_k × u_b` if `k ⪯ b`, else `w_b × u_k`.
#[inline]
pub(crate) fn du_dq2(x: &PointCol, l: &PointCol, k: &PointCol) -> Vector3<f64> {
    let (a, b) = if l.joint <= x.joint { (l, x) } else { (x, l) };
    let du_b = if k.joint <= b.joint { k.w.cross(&b.u) } else { b.w.cross(&k.u) };
    let t = a.w.cross(&du_b);
    if k.joint <= a.joint { t + k.w.cross(&a.w).cross(&b.u) } else { t }
}

/// `∂u_x/∂q_l = w_a × u_b` (see [`du_dq2`]).
#[inline]
pub(crate) fn du_dq(x: &PointCol, l: &PointCol) -> Vector3<f64> {
    if l.joint <= x.joint { l.w.cross(&x.u) } else { x.w.cross(&l.u) }
}

/// `∂w_x/∂q_l = [l ⪯ x] w_l × w_x` (eq. J1).
#[inline]
fn dw_dq(x: &PointCol, l: &PointCol) -> Vector3<f64> {
    if l.joint <= x.joint { l.w.cross(&x.w) } else { Vector3::zeros() }
}

/// `∂/∂q_k (∂J_x/∂q_l)` in closed form for the DoFs `x`, `l`, `k` of one contact's path, as
/// world-axis `(angular, linear)` parts `(a, b)`: the contact's rows are `(a, b)` for world
/// axes and `(Rᵀa, Rᵀb)` for local axes. World axes: `J_x = (w_x, u_x)`, so
/// `D_k D_l w_x = [l ⪯ x]([k ⪯ l] (w_k × w_l) × w_x + [k ⪯ x] w_l × (w_k × w_x))` and
/// `D_k D_l u_x` is [`du_dq2`]. Local axes (`D_l Rᵀ = −Rᵀ [w_l]×`): with `y_x = (w_x, u_x)`,
/// `e = D_l y_x − w_l × y_x`, the parts are `D_k e − w_k × e` with
/// `D_k e = D_k D_l y_x − (D_k w_l) × y_x − w_l × D_k y_x`.
#[inline]
pub(crate) fn djac_dq2(
    local: bool,
    x: &PointCol,
    l: &PointCol,
    k: &PointCol,
) -> (Vector3<f64>, Vector3<f64>) {
    let dd_lin = du_dq2(x, l, k);
    let dwl = if k.joint <= l.joint { k.w.cross(&l.w) } else { Vector3::zeros() };
    let dd_ang =
        if l.joint <= x.joint { dwl.cross(&x.w) + l.w.cross(&dw_dq(x, k)) } else { dwl * 0.0 };
    if !local {
        return (dd_ang, dd_lin);
    }
    let (e_ang, e_lin) = (dw_dq(x, l) - l.w.cross(&x.w), du_dq(x, l) - l.w.cross(&x.u));
    let de_ang = dd_ang - dwl.cross(&x.w) - l.w.cross(&dw_dq(x, k));
    let de_lin = dd_lin - dwl.cross(&x.u) - l.w.cross(&du_dq(x, k));
    (de_ang - k.w.cross(&e_ang), de_lin - k.w.cross(&e_lin))
}

/// A contact's weights `λ` (`[n; f]` for 6-D, `f` for 3-D, in the contact's axes) as
/// world-axis `(n, f)`, so that `λ · rows = n·a + f·b` for [`djac_dq2`]'s parts.
#[inline]
pub(crate) fn world_weights(
    geo: Geo,
    r: &Matrix3<f64>,
    lam: &[f64],
) -> (Vector3<f64>, Vector3<f64>) {
    let part = |i: usize| Vector3::new(lam[i], lam[i + 1], lam[i + 2]);
    let (n, f) = if geo.six { (part(0), part(3)) } else { (Vector3::zeros(), part(0)) };
    if geo.local { (r * n, r * f) } else { (n, f) }
}

/// Running sums along one point contact's path for [`dap_dqdv`]: with `N` path DoFs at
/// positions `t` (path order) and `q̇` their velocities, `pw[t] = Σ_{s<t} q̇_s w_s`,
/// `pu[t] = Σ_{s<t} q̇_s u_s` (`N + 1` each), and the positions `jb[t]..je[t]` of `t`'s joint.
pub(crate) struct PathSums<'a> {
    pub cols: &'a [PointCol],
    pub pw: &'a [Vector3<f64>],
    pub pu: &'a [Vector3<f64>],
    pub jb: &'a [usize],
    pub je: &'a [usize],
}

/// Fills the sums of [`PathSums`] for `cols` with velocities `qd[t]` (the slices at least
/// `N + 1`, `N + 1`, `N`, `N` long).
pub(crate) fn fill_path_sums(
    cols: &[PointCol],
    qd: impl Fn(usize) -> f64,
    pw: &mut [Vector3<f64>],
    pu: &mut [Vector3<f64>],
    jb: &mut [usize],
    je: &mut [usize],
) {
    let nt = cols.len();
    pw[0] = Vector3::zeros();
    pu[0] = Vector3::zeros();
    for (t, c) in cols.iter().enumerate() {
        pw[t + 1] = pw[t] + c.w * qd(t);
        pu[t + 1] = pu[t] + c.u * qd(t);
    }
    let mut t = 0;
    while t < nt {
        let mut e = t + 1;
        while e < nt && cols[e].joint == cols[t].joint {
            e += 1;
        }
        jb[t..e].fill(t);
        je[t..e].fill(e);
        t = e;
    }
}

/// `∂/∂q_l (∂a_p/∂q̇_k)` of a 3-D world-aligned point contact (positions `tl`, `tk` on its path)
/// in closed form. With `a_p = J q̈ + Σ_{x,y} q̇_x q̇_y ∂u_x/∂q_y`,
/// `∂a_p/∂q̇_k = A × u_k + w_k × B` where `A = 2 Σ_{y ≺ k} q̇_y w_y + Σ_{y ~ k} q̇_y w_y` and
/// `B = 2 Σ_{y ≻ k} q̇_y u_y + Σ_{y ~ k} q̇_y u_y` (`~`: of `k`'s joint), so
/// `∂/∂q_l = (∂A/∂q_l) × u_k + A × ∂u_k/∂q_l + ∂w_k/∂q_l × B + w_k × ∂B/∂q_l`, each sum's
/// derivative (eq. J1, [`du_dq2`]) a difference of the running sums: the path is a chain, so
/// `l ⪯ y` selects the positions from `l`'s joint on.
pub(crate) fn dap_dqdv(s: &PathSums, tl: usize, tk: usize) -> Vector3<f64> {
    let n = s.cols.len();
    let (cl, ck) = (&s.cols[tl], &s.cols[tk]);
    let (bl, bk, ek) = (s.jb[tl], s.jb[tk], s.je[tk]);
    let sw = |a: usize, b: usize| if a < b { s.pw[b] - s.pw[a] } else { Vector3::zeros() };
    let su = |a: usize, b: usize| if a < b { s.pu[b] - s.pu[a] } else { Vector3::zeros() };
    let a = sw(0, bk) * 2.0 + sw(bk, ek);
    let b = su(ek, n) * 2.0 + su(bk, ek);
    let l_anc_k = cl.joint <= ck.joint;
    // ∂A/∂q_l = w_l × Σ_{l ⪯ y} α_y q̇_y w_y.
    let da = cl.w.cross(&(sw(bl, bk) * 2.0 + if l_anc_k { sw(bk, ek) } else { Vector3::zeros() }));
    // ∂B/∂q_l = w_l × Σ_{l ⪯ y} β_y q̇_y u_y + (Σ_{y ≺ l} β_y q̇_y w_y) × u_l.
    let su_l = su(ek.max(bl), n) * 2.0 + su(bk.max(bl), ek);
    let sw_l = sw(ek, bl) * 2.0 + sw(bk, ek.min(bl));
    let db = cl.w.cross(&su_l) + sw_l.cross(&cl.u);
    let dwk = if l_anc_k { cl.w.cross(&ck.w) } else { Vector3::zeros() };
    da.cross(&ck.u) + a.cross(&du_dq(ck, cl)) + dwk.cross(&b) + ck.w.cross(&db)
}

/// `∂(J z)/∂q_l` for every DoF `l` (position `t` in `cols`, the columns of one contact's path
/// in path order, with `z_x`), world-aligned at the contact point, passed to
/// `f(t, ang, lin)`: with the closed form of [`du_dq2`]'s inner derivative,
/// `Σ_x z_x ∂u_x/∂q_l = w_l × Σ_{x ⪰ l} z_x u_x + (Σ_{x ≺ l} z_x w_x) × u_l` and
/// `Σ_x z_x ∂w_x/∂q_l = w_l × Σ_{x ⪰ l} z_x w_x` (`⪰`: `x`'s joint is `l`'s or a
/// descendant), by running sums along the path.
#[inline]
pub(crate) fn djz_dq_parts(
    cols: impl Iterator<Item = (PointCol, f64)> + Clone,
    mut f: impl FnMut(usize, Vector3<f64>, Vector3<f64>),
) {
    let (mut su, mut sw) = cols
        .clone()
        .fold((Vector3::zeros(), Vector3::zeros()), |(u, w), (c, z)| (u + c.u * z, w + c.w * z));
    let mut pw = Vector3::zeros();
    // The DoFs of one joint (consecutive) see the same sums.
    let (mut su_next, mut sw_next, mut pw_next, mut joint) = (su, sw, pw, usize::MAX);
    for (t, (c, z)) in cols.enumerate() {
        if c.joint != joint {
            (su, sw, pw, joint) = (su_next, sw_next, pw_next, c.joint);
        }
        f(t, c.w.cross(&sw), c.w.cross(&su) + pw.cross(&c.u));
        su_next -= c.u * z;
        sw_next -= c.w * z;
        pw_next += c.w * z;
    }
}

// ---------------------------------------------------------------------------------------------
// Generic contacts: 6-D contacts and the local reference (module documentation of
// `crate::model::Contact`). A contact's rows are formed from world-aligned angular and linear
// parts at the contact point, rotated into the contact axes (`Rᵀ`) for `local`; `R` turns with
// the body: `D R = [w_l]× R` along `q_l` (`w_l = S_l.ang`, `l` on the path), so
// `D(Rᵀ y) = Rᵀ (D y − w_l × y)`. As above, first derivatives are written as expressions in
// dual base quantities, whose tangents give the second derivatives.
// ---------------------------------------------------------------------------------------------

/// A 3×3 matrix with a tangent (the contact frame's world rotation).
#[derive(Clone, Copy, Debug)]
pub(crate) struct D33 {
    pub v: Matrix3<f64>,
    pub d: Matrix3<f64>,
}

impl D33 {
    /// `Rᵀ y` with its tangent.
    #[inline]
    fn tr_mul(&self, y: &D3) -> D3 {
        D3 { v: self.v.tr_mul(&y.v), d: self.d.tr_mul(&y.v) + self.v.tr_mul(&y.d) }
    }
}

/// Shape of a contact's rows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Geo {
    /// Six rows `[angular; linear]` (otherwise three linear rows).
    pub six: bool,
    /// Contact axes (otherwise world axes).
    pub local: bool,
    /// A two-frame (closed-loop) constraint (`super::contact_loop`).
    pub two: bool,
}

impl Geo {
    /// The shape of `c`'s rows.
    pub fn of(c: &crate::model::Contact) -> Geo {
        Geo {
            six: c.kind == crate::model::ContactType::D6,
            local: c.reference == crate::model::ContactReference::Local,
            two: c.frame2.is_some(),
        }
    }
    /// A 3-D world-aligned point (the specialised code paths).
    #[inline]
    pub fn is_point(self) -> bool {
        !self.six && !self.local && !self.two
    }
    /// Number of rows.
    #[inline]
    pub fn dim(self) -> usize {
        if self.six { 6 } else { 3 }
    }
}

/// A contact's rows `(angular, linear)` (the angular part unused for 3-D contacts).
pub(crate) type Rows = (D3, D3);

impl Base<'_> {
    /// The contact frame's world rotation `R` with its tangent.
    #[inline]
    pub fn rot(&self, r: &Matrix3<f64>, dir: Dir) -> D33 {
        let d = match dir {
            Dir::Q(k) => {
                let w = self.s[k].ang;
                Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0) * r
            }
            _ => Matrix3::zeros(),
        };
        D33 { v: *r, d }
    }
}

/// Rows from world-aligned parts.
#[inline]
pub(crate) fn rows(geo: Geo, r: &D33, ang: D3, lin: D3) -> Rows {
    if geo.local { (r.tr_mul(&ang), r.tr_mul(&lin)) } else { (ang, lin) }
}

/// Inner derivative along `q_l` of the rows of world-aligned parts `(ang, lin)` with inner
/// derivatives `(dang, dlin)`; `wl` = `S_l.ang` (dual).
#[inline]
pub(crate) fn d_rows(geo: Geo, r: &D33, (ang, lin): Rows, (dang, dlin): Rows, wl: &D3) -> Rows {
    if geo.local {
        (r.tr_mul(&(dang - wl.cross(&ang))), r.tr_mul(&(dlin - wl.cross(&lin))))
    } else {
        (dang, dlin)
    }
}

/// `y · (ang, lin)` for the contact's force `lam` (`[n; f]` for 6-D, `f` for 3-D).
#[inline]
pub(crate) fn rows_dot(geo: Geo, (ang, lin): &Rows, lam: &[f64]) -> (f64, f64) {
    if geo.six {
        let (n, f) = (Vector3::new(lam[0], lam[1], lam[2]), Vector3::new(lam[3], lam[4], lam[5]));
        let (a, b) = (ang.dot(&n), lin.dot(&f));
        (a.0 + b.0, a.1 + b.1)
    } else {
        lin.dot(&Vector3::new(lam[0], lam[1], lam[2]))
    }
}

/// Writes the rows (value or tangent) into `out[0..dim]`.
#[inline]
pub(crate) fn put_rows(geo: Geo, (ang, lin): &Rows, tangent: bool, out: &mut [f64]) {
    let (a, l) = if tangent { (&ang.d, &lin.d) } else { (&ang.v, &lin.v) };
    if geo.six {
        out[..3].copy_from_slice(a.as_slice());
        out[3..6].copy_from_slice(l.as_slice());
    } else {
        out[..3].copy_from_slice(l.as_slice());
    }
}

/// Jacobian column of DoF `x`: rows of `(S_x.ang, S_x.lin + S_x.ang × p)`.
pub(crate) fn jac_col(
    b: &Base,
    geo: Geo,
    r: &Matrix3<f64>,
    p: &Vector3<f64>,
    x: usize,
    dir: Dir,
) -> Rows {
    let sx = b.s(x, dir);
    let pp = b.p(p, dir);
    rows(geo, &b.rot(r, dir), sx.ang(), at_point(&sx, &pp))
}

/// `∂/∂q_l` of the Jacobian column of DoF `x` (path DoFs `x`, `l`): `D S_x = [l ⪯ x] S_l × S_x`
/// (J1), `D p = u_l`.
pub(crate) fn djac_col_dq(
    b: &Base,
    geo: Geo,
    r: &Matrix3<f64>,
    p: &Vector3<f64>,
    x: usize,
    l: usize,
    dir: Dir,
) -> Rows {
    let sx = b.s(x, dir);
    let sl = b.s(l, dir);
    let pp = b.p(p, dir);
    let dsx = if b.dof_joint[l] <= b.dof_joint[x] { sl.cross(&sx) } else { Dm::default() };
    let ul = at_point(&sl, &pp);
    let base = (sx.ang(), at_point(&sx, &pp));
    let d = (dsx.ang(), at_point(&dsx, &pp) + sx.ang().cross(&ul));
    d_rows(geo, &b.rot(r, dir), base, d, &sl.ang())
}

/// World-aligned acceleration parts of body `m`'s contact frame: `(α, a_s)` for 6-D (spatial),
/// `(α, a_p)` for 3-D (classical), from `V_m`, `A_m`, `p` (and the inner derivatives given
/// `D V`, `D A`, `D p`).
#[inline]
pub(crate) fn acc_parts(geo: Geo, vm: &Dm, am: &Dm, pp: &D3) -> Rows {
    let a_s = at_point(am, pp);
    if geo.six {
        (am.ang(), a_s)
    } else {
        let w = vm.ang();
        (am.ang(), a_s + w.cross(&at_point(vm, pp)))
    }
}

#[inline]
#[allow(clippy::too_many_arguments)]
pub(crate) fn d_acc_parts(geo: Geo, vm: &Dm, am: &Dm, pp: &D3, dv: &Dm, da: &Dm, dp: &D3) -> Rows {
    let da_s = at_point(da, pp) + am.ang().cross(dp);
    if geo.six {
        (da.ang(), da_s)
    } else {
        let w = vm.ang();
        let vp = at_point(vm, pp);
        let dvp = at_point(dv, pp) + w.cross(dp);
        (da.ang(), da_s + dv.ang().cross(&vp) + w.cross(&dvp))
    }
}

/// The contact acceleration rows of body `m`'s contact (current `A_m`, i.e. with the `q̈` of
/// the base quantities).
pub(crate) fn acc_rows(
    b: &Base,
    geo: Geo,
    r: &Matrix3<f64>,
    m: usize,
    p: &Vector3<f64>,
    dir: Dir,
) -> Rows {
    let (vm, am, pp) = (b.vel(m, dir), b.acc(m, dir), b.p(p, dir));
    let (ang, lin) = acc_parts(geo, &vm, &am, &pp);
    rows(geo, &b.rot(r, dir), ang, lin)
}

/// `∂a_c/∂q_l` of the contact acceleration rows (J2, J6, J7; `D p = u_l`, `D R = [w_l]× R`).
pub(crate) fn dacc_dq(
    b: &Base,
    geo: Geo,
    r: &Matrix3<f64>,
    m: usize,
    p: &Vector3<f64>,
    l: usize,
    dir: Dir,
) -> Rows {
    let jl = b.dof_joint[l];
    let ll = b.parents[jl];
    let sl = b.s(l, dir);
    let (vm, am, pp) = (b.vel(m, dir), b.acc(m, dir), b.p(p, dir));
    let (vl, al) = (b.vel(ll, dir), b.acc(ll, dir));
    let psid = vl.cross(&sl);
    let dv = sl.cross(&(vm - vl));
    let da = (al - am).cross(&sl) + (vl - vm).cross(&psid);
    let dp = at_point(&sl, &pp);
    let base = acc_parts(geo, &vm, &am, &pp);
    let d = d_acc_parts(geo, &vm, &am, &pp, &dv, &da, &dp);
    d_rows(geo, &b.rot(r, dir), base, d, &sl.ang())
}

/// `∂a_c/∂q̇_l` of the contact acceleration rows (J8, J9).
pub(crate) fn dacc_dv(
    b: &Base,
    geo: Geo,
    r: &Matrix3<f64>,
    m: usize,
    p: &Vector3<f64>,
    l: usize,
    dir: Dir,
) -> Rows {
    let jl = b.dof_joint[l];
    let ll = b.parents[jl];
    let sl = b.s(l, dir);
    let (vm, am, pp) = (b.vel(m, dir), b.acc(m, dir), b.p(p, dir));
    let (vl, vj) = (b.vel(ll, dir), b.vel(jl, dir));
    let da = vl.cross(&sl) + vj.cross(&sl) - vm.cross(&sl);
    let d = d_acc_parts(geo, &vm, &am, &pp, &sl, &da, &D3::default());
    let rr = b.rot(r, dir);
    if geo.local { (rr.tr_mul(&d.0), rr.tr_mul(&d.1)) } else { d }
}

/// `∂(J_c z)/∂q_l` of a contact's rows, `zc` the cumulative sums `Z_j = Σ_{x ⪯ j} S_x z_x`:
/// `D Z_m = S_l × (Z_m − Z_λ)`, `D p = u_l`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn djz_dq_rows(
    b: &Base,
    geo: Geo,
    r: &Matrix3<f64>,
    zc: &[Motion],
    m: usize,
    p: &Vector3<f64>,
    l: usize,
    dir: Dir,
) -> Rows {
    let jl = b.dof_joint[l];
    let sl = b.s(l, dir);
    let zm = b.cum(zc, m, dir, false);
    let zl = b.cum(zc, b.parents[jl], dir, false);
    let pp = b.p(p, dir);
    let dz = sl.cross(&(zm - zl));
    let base = (zm.ang(), at_point(&zm, &pp));
    let d = (dz.ang(), at_point(&dz, &pp) + zm.ang().cross(&at_point(&sl, &pp)));
    d_rows(geo, &b.rot(r, dir), base, d, &sl.ang())
}
