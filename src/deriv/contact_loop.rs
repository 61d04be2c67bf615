//! Row kinematics of two-frame (closed-loop) constraints (`crate::model::Contact` with a
//! `frame2`), first order, in dual base quantities like the generic rows of `contact_kin`.
//!
//! Frame A's contact frame `(R₁, p₁)` sits on body `a`, frame B's `(R₂, p₂)` on body `b` (the
//! world for `b = 0`); `V`, `A` are world body velocities and accelerations (no gravity),
//! `σ_x = [x ⪯ a] − [x ⪯ b]`, `u_x^i = S_x.lin + S_x.ang × p_i`, `R' = R₁ᵀ` for `local` and
//! `I` for `local_world_aligned`. The rows (Pinocchio's `RigidConstraintModel` with two joints):
//!
//! | type | Jacobian column `x` | acceleration rows (KKT) |
//! |---|---|---|
//! | `3d` | `R'([x ⪯ a] u_x¹ − [x ⪯ b] u_x²)` | `R'(a_{p₁} − a_{p₂})`, classical point accelerations |
//! | `6d` `local_world_aligned` | `σ_x [S_x.ang; S_x.lin + S_x.ang × p₁]` | `W = A_a − A_b` at `p₁` |
//! | `6d` `local` | `σ_x ¹X_o S_x` | `¹X_o (A_a − A_b + (V_a − V_b) × V_b)` |
//!
//! (`¹X_o M = [R₁ᵀ M.ang; R₁ᵀ(M.lin + M.ang × p₁)]`.) A DoF's tangent acts on the quantities of
//! the chain(s) that hold it: each chain's base quantities are differentiated with the chain's
//! own direction (`Dir::None` when the DoF is off that chain), so the single-path rules of
//! [`Base`] stay valid.
//!
//! Second order: the inner derivatives along `q_l` (or `q̇_l`) are written out as expressions
//! in dual base quantities ([`loop_djac_col_dq`], [`loop_djz_dq_rows`], [`loop_dacc_dq`],
//! [`loop_dacc_dv`]), whose tangents along the outer direction are the second derivatives. A
//! chain's quantities move along `q_l` only if `l` is on that chain (`contact_kin`'s rules J1,
//! J2, J6, J7, J8, J9 on the chain), frame A's point `p₁` and rotation `R₁` with chain A,
//! `p₂` with chain B; `D(R₁ᵀ y) = R₁ᵀ(D y − w_l × y)` for `l` on chain A.
//!
//! The pair loops of the KKT and impact derivatives use closed forms instead of a dual
//! evaluation per pair: `∂(J_cᵀλ)/∂q` from the two chains' spatial forces ([`loop_djtl_dq`];
//! its tangent [`loop_djtl_dq2`] for `λ·∂²J_c/∂q²`) and `∂(J_c z)/∂q` from cumulative sums in
//! plain arithmetic ([`djz_dq_plain`]).

use super::contact_kin::{
    Base, D3, Dir, Dm, Geo, Path, Rows, acc_parts, at_point, d_acc_parts, d_rows, rows,
};
use crate::spatial::{Force, Motion, Transform};
use nalgebra::Vector3;

/// The two chains of a two-frame constraint.
#[derive(Clone, Debug, Default)]
pub(crate) struct Loop {
    /// Root path of frame A's body; `p`, `rot`: frame A's contact frame in the world.
    pub a: Path,
    /// Root path of frame B's body (empty: the world); `p`, `rot`: frame B's contact frame.
    pub b: Path,
    /// Frame B's body and its contact frame's placement in that body's frame.
    pub local_b: (usize, Transform),
    /// For each DoF of the union of both chains (ascending, the constraint's path in
    /// `ContactWs`): whether it is on chain A and on chain B ([`Loop::set_sides`]).
    pub on: Vec<(bool, bool)>,
}

impl Loop {
    /// Frame A's body.
    pub fn body_a(&self) -> usize {
        *self.a.joints.last().expect("frame A is on a moving body")
    }
    /// Frame B's body (0: the world).
    pub fn body_b(&self) -> usize {
        self.b.joints.last().copied().unwrap_or(0)
    }
    /// Fills [`Loop::on`] for `dofs`, the union of both chains' DoFs (ascending).
    pub fn set_sides(&mut self, dofs: &[usize]) {
        self.on = dofs.iter().map(|&x| (self.in_a(x), self.in_b(x))).collect();
    }
    #[inline]
    fn in_a(&self, x: usize) -> bool {
        self.a.dofs.binary_search(&x).is_ok()
    }
    #[inline]
    fn in_b(&self, x: usize) -> bool {
        self.b.dofs.binary_search(&x).is_ok()
    }
    /// The directions of A's and B's chains for `dir`.
    #[inline]
    fn dirs(&self, dir: Dir) -> (Dir, Dir) {
        match dir {
            Dir::Q(k) | Dir::V(k) => (
                if self.in_a(k) { dir } else { Dir::None },
                if self.in_b(k) { dir } else { Dir::None },
            ),
            Dir::None => (Dir::None, Dir::None),
        }
    }
}

/// Jacobian column of DoF `x` (on either chain) with its tangent along `dir`.
pub(crate) fn loop_jac_col(b: &Base, geo: Geo, lp: &Loop, x: usize, dir: Dir) -> Rows {
    let (da, db) = lp.dirs(dir);
    let (ia, ib) = (lp.in_a(x), lp.in_b(x));
    let sx = b.s(x, if ia { da } else { db });
    let pa = b.p(&lp.a.p, da);
    let ra = b.rot(&lp.a.rot, da);
    if geo.six {
        let sigma = f64::from(u8::from(ia)) - f64::from(u8::from(ib));
        let w = sx * sigma;
        rows(geo, &ra, w.ang(), at_point(&w, &pa))
    } else {
        let pb = b.p(&lp.b.p, db);
        let mut lin = D3::default();
        if ia {
            lin = lin + at_point(&sx, &pa);
        }
        if ib {
            lin = lin - at_point(&sx, &pb);
        }
        rows(geo, &ra, D3::default(), lin)
    }
}

/// The acceleration rows (module documentation) at the current base accelerations (with the
/// `q̈` they hold), with their tangent along `dir`.
pub(crate) fn loop_acc_rows(b: &Base, geo: Geo, lp: &Loop, dir: Dir) -> Rows {
    let (da, db) = lp.dirs(dir);
    let (ma, mb) = (lp.body_a(), lp.body_b());
    let (va, aa, pa) = (b.vel(ma, da), b.acc(ma, da), b.p(&lp.a.p, da));
    let (vb, ab) = (b.vel(mb, db), b.acc(mb, db));
    let ra = b.rot(&lp.a.rot, da);
    if geo.six {
        let mut w = aa - ab;
        if geo.local {
            w = w + (va - vb).cross(&vb);
        }
        rows(geo, &ra, w.ang(), at_point(&w, &pa))
    } else {
        let pb = b.p(&lp.b.p, db);
        let acc = |v: &Dm, a: &Dm, p: &D3| at_point(a, p) + v.ang().cross(&at_point(v, p));
        rows(geo, &ra, D3::default(), acc(&va, &aa, &pa) - acc(&vb, &ab, &pb))
    }
}

/// One chain's body velocity `V`, acceleration `A` (no gravity) and contact point `p`, or
/// their inner derivatives along one direction (all zero for a DoF off the chain).
#[derive(Clone, Copy, Debug, Default)]
struct Side {
    v: Dm,
    a: Dm,
    p: D3,
}

impl Loop {
    /// The two chains' quantities with the tangents of their directions `(da, db)`.
    #[inline]
    fn sides(&self, b: &Base, (da, db): (Dir, Dir)) -> (Side, Side) {
        let (ma, mb) = (self.body_a(), self.body_b());
        let sa = Side { v: b.vel(ma, da), a: b.acc(ma, da), p: b.p(&self.a.p, da) };
        let sb = Side { v: b.vel(mb, db), a: b.acc(mb, db), p: b.p(&self.b.p, db) };
        (sa, sb)
    }
}

/// Inner derivative along `q_l` (`l` on the chain of `s`, the root path of its body) with the
/// chain's outer direction `dir`: `D V = S_l × (V − V_λ)` (J2),
/// `D A = (A_λ − A) × S_l + (V_λ − V) × Ψ̇_l` (J6, J7), `D p = S_l.lin + S_l.ang × p`.
#[inline]
fn side_dq(b: &Base, s: &Side, l: usize, dir: Dir) -> Side {
    let ll = b.parents[b.dof_joint[l]];
    let sl = b.s(l, dir);
    let (vl, al) = (b.vel(ll, dir), b.acc(ll, dir));
    let psid = vl.cross(&sl);
    Side {
        v: sl.cross(&(s.v - vl)),
        a: (al - s.a).cross(&sl) + (vl - s.v).cross(&psid),
        p: at_point(&sl, &s.p),
    }
}

/// Inner derivative along `q̇_l` (`l` on the chain of `s`): `D V = S_l` (J8),
/// `D A = (V_λ + V_l − V) × S_l` (J9), `D p = 0`.
#[inline]
fn side_dv(b: &Base, s: &Side, l: usize, dir: Dir) -> Side {
    let jl = b.dof_joint[l];
    let sl = b.s(l, dir);
    let (vl, vj) = (b.vel(b.parents[jl], dir), b.vel(jl, dir));
    Side { v: sl, a: vl.cross(&sl) + vj.cross(&sl) - s.v.cross(&sl), p: D3::default() }
}

/// The inner derivative of the acceleration rows (module documentation) from the chains'
/// quantities `sa`, `sb`, their inner derivatives `dsa`, `dsb` and `wl` (`S_l.ang` for `l` on
/// chain A, which turns `R₁`; zero otherwise).
fn d_acc_rows(geo: Geo, ra: &super::contact_kin::D33, sides: [&Side; 4], wl: &D3) -> Rows {
    let [sa, sb, dsa, dsb] = sides;
    if geo.six {
        let (mut w, mut dw) = (sa.a - sb.a, dsa.a - dsb.a);
        if geo.local {
            let rel = sa.v - sb.v;
            w = w + rel.cross(&sb.v);
            dw = dw + (dsa.v - dsb.v).cross(&sb.v) + rel.cross(&dsb.v);
        }
        let base = (w.ang(), at_point(&w, &sa.p));
        let d = (dw.ang(), at_point(&dw, &sa.p) + w.ang().cross(&dsa.p));
        d_rows(geo, ra, base, d, wl)
    } else {
        let la = acc_parts(geo, &sa.v, &sa.a, &sa.p).1;
        let lb = acc_parts(geo, &sb.v, &sb.a, &sb.p).1;
        let dla = d_acc_parts(geo, &sa.v, &sa.a, &sa.p, &dsa.v, &dsa.a, &dsa.p).1;
        let dlb = d_acc_parts(geo, &sb.v, &sb.a, &sb.p, &dsb.v, &dsb.a, &dsb.p).1;
        d_rows(geo, ra, (D3::default(), la - lb), (D3::default(), dla - dlb), wl)
    }
}

/// `∂a_c/∂q_l` of the acceleration rows (module documentation) at the current base
/// accelerations, with its tangent along `dir`.
pub(crate) fn loop_dacc_dq(b: &Base, geo: Geo, lp: &Loop, l: usize, dir: Dir) -> Rows {
    let (da, db) = lp.dirs(dir);
    let (sa, sb) = lp.sides(b, (da, db));
    let ra = b.rot(&lp.a.rot, da);
    let (dsa, wl) = if lp.in_a(l) {
        (side_dq(b, &sa, l, da), b.s(l, da).ang())
    } else {
        (Side::default(), D3::default())
    };
    let dsb = if lp.in_b(l) { side_dq(b, &sb, l, db) } else { Side::default() };
    d_acc_rows(geo, &ra, [&sa, &sb, &dsa, &dsb], &wl)
}

/// `∂a_c/∂q̇_l` of the acceleration rows, with its tangent along `dir`.
pub(crate) fn loop_dacc_dv(b: &Base, geo: Geo, lp: &Loop, l: usize, dir: Dir) -> Rows {
    let (da, db) = lp.dirs(dir);
    let (sa, sb) = lp.sides(b, (da, db));
    let ra = b.rot(&lp.a.rot, da);
    let dsa = if lp.in_a(l) { side_dv(b, &sa, l, da) } else { Side::default() };
    let dsb = if lp.in_b(l) { side_dv(b, &sb, l, db) } else { Side::default() };
    d_acc_rows(geo, &ra, [&sa, &sb, &dsa, &dsb], &D3::default())
}

/// `∂J_x/∂q_l` of the Jacobian column of DoF `x` ([`loop_jac_col`]), with its tangent along
/// `dir`: `D S_x = [l ⪯ x] S_l × S_x` (J1; `l ⪯ x` puts `l` on every chain that holds `x`),
/// `D p_i = u_l^i` for `l` on chain `i`, `D R₁ = [w_l]× R₁` for `l` on chain A.
pub(crate) fn loop_djac_col_dq(
    b: &Base,
    geo: Geo,
    lp: &Loop,
    x: usize,
    l: usize,
    dir: Dir,
) -> Rows {
    let (da, db) = lp.dirs(dir);
    let (ia, ib) = (lp.in_a(x), lp.in_b(x));
    let (la, lb) = (lp.in_a(l), lp.in_b(l));
    let anc = b.dof_joint[l] <= b.dof_joint[x];
    let pa = b.p(&lp.a.p, da);
    let ra = b.rot(&lp.a.rot, da);
    let (wl, dpa) = if la {
        let sl = b.s(l, da);
        (sl.ang(), at_point(&sl, &pa))
    } else {
        (D3::default(), D3::default())
    };
    // S_x and its inner derivative, differentiated along chain `d`'s direction (`on`: `l` on
    // that chain).
    let col = |d: Dir, on: bool| {
        let sx = b.s(x, d);
        let dsx = if on && anc { b.s(l, d).cross(&sx) } else { Dm::default() };
        (sx, dsx)
    };
    if geo.six {
        if ia == ib {
            return (D3::default(), D3::default());
        }
        let (sx, dsx) = if ia { col(da, la) } else { col(db, lb) };
        let sigma = if ia { 1.0 } else { -1.0 };
        let (w, dw) = (sx * sigma, dsx * sigma);
        let base = (w.ang(), at_point(&w, &pa));
        let d = (dw.ang(), at_point(&dw, &pa) + w.ang().cross(&dpa));
        d_rows(geo, &ra, base, d, &wl)
    } else {
        let (mut lin, mut dlin) = (D3::default(), D3::default());
        if ia {
            let (sx, dsx) = col(da, la);
            lin = lin + at_point(&sx, &pa);
            dlin = dlin + at_point(&dsx, &pa) + sx.ang().cross(&dpa);
        }
        if ib {
            let pb = b.p(&lp.b.p, db);
            let (sx, dsx) = col(db, lb);
            let dpb = if lb { at_point(&b.s(l, db), &pb) } else { D3::default() };
            lin = lin - at_point(&sx, &pb);
            dlin = dlin - (at_point(&dsx, &pb) + sx.ang().cross(&dpb));
        }
        d_rows(geo, &ra, (D3::default(), lin), (D3::default(), dlin), &wl)
    }
}

/// `∂(J_c z)/∂q_l` of the constraint's rows for the cumulative sums `zc`
/// (`Z_j = Σ_{x ⪯ j} S_x z_x` on both chains, `zc[0] = 0`), with its tangent along `dir`:
/// `J_c z` is the rows of `Z_a − Z_b` at `p₁` (6-D) or `R'(Z_a.lin + Z_a.ang × p₁ − Z_b.lin −
/// Z_b.ang × p₂)` (3-D), and along `q_l` on a chain, `D Z = S_l × (Z − Z_λ)`, `D p = u_l`.
pub(crate) fn loop_djz_dq_rows(
    b: &Base,
    geo: Geo,
    lp: &Loop,
    zc: &[crate::spatial::Motion],
    l: usize,
    dir: Dir,
) -> Rows {
    let (da, db) = lp.dirs(dir);
    let (ma, mb) = (lp.body_a(), lp.body_b());
    let (za, zb) = (b.cum(zc, ma, da, false), b.cum(zc, mb, db, false));
    let pa = b.p(&lp.a.p, da);
    let ra = b.rot(&lp.a.rot, da);
    let ll = b.parents[b.dof_joint[l]];
    let dz = |z: &Dm, d: Dir| {
        let sl = b.s(l, d);
        (sl.cross(&(*z - b.cum(zc, ll, d, false))), sl)
    };
    let (dza, wl, dpa) = if lp.in_a(l) {
        let (dza, sl) = dz(&za, da);
        (dza, sl.ang(), at_point(&sl, &pa))
    } else {
        (Dm::default(), D3::default(), D3::default())
    };
    let (dzb, slb) = if lp.in_b(l) { dz(&zb, db) } else { (Dm::default(), Dm::default()) };
    if geo.six {
        let (w, dw) = (za - zb, dza - dzb);
        let base = (w.ang(), at_point(&w, &pa));
        let d = (dw.ang(), at_point(&dw, &pa) + w.ang().cross(&dpa));
        d_rows(geo, &ra, base, d, &wl)
    } else {
        let pb = b.p(&lp.b.p, db);
        let dpb = at_point(&slb, &pb);
        let lin = at_point(&za, &pa) - at_point(&zb, &pb);
        let dlin = at_point(&dza, &pa) + za.ang().cross(&dpa)
            - (at_point(&dzb, &pb) + zb.ang().cross(&dpb));
        d_rows(geo, &ra, (D3::default(), lin), (D3::default(), dlin), &wl)
    }
}

/// `λ·∂J_x/∂q_l` (the `(x, l)` entry of `∂(J_cᵀλ)/∂q`) for every pair of DoFs `x`, `l` of the
/// constraint's path `dofs` (the union of both chains, joints `dof_joint`, sides [`Loop::on`]),
/// passed to `f(x, l, e)`, in closed form from the world subspaces `s`. With `(n, f)` the
/// weights `λ` in world axes (`R₁λ` for `local`) and the spatial forces about the world origin
/// `F_A = [n + p₁ × f; f]`, `F_B = [n + p_B × f; f]` (`p_B = p₁` for 6-D, `p₂` for 3-D; `n = 0`
/// for 3-D), the module documentation's rows give `(J_cᵀλ)_x = [x ∈ A] S_x·F_A − [x ∈ B] S_x·F_B`
/// (6-D: the common DoFs cancel). Along `q_l`: `D S_x = [l ⪯ x] S_l × S_x` (J1, `l` then on
/// `x`'s chain) with `(S_l × S_x)·F = −S_x·(S_l ×* F)`; `R₁` turns and `p₁` moves with chain A
/// (`D(R₁y) = w_l × R₁y`, `D p₁ = u_l¹` for `l ∈ A`), `p₂` with chain B (`D p₂ = u_l²` for
/// `l ∈ B`), so `D F_X = [D n + D p_X × f + p_X × D f; D f]`. The entry is
/// `[x ∈ A] S_x·(D F_A − [l ⪯ x] S_l ×* F_A) − [x ∈ B] S_x·(D F_B − [l ⪯ x] S_l ×* F_B)`:
/// per `l` two forces of each kind, per pair at most two dot products.
pub(crate) fn loop_djtl_dq(
    s: &[Motion],
    geo: Geo,
    lp: &Loop,
    (dofs, dof_joint): (&[usize], &[usize]),
    lam: &[f64],
    mut f: impl FnMut(usize, usize, f64),
) {
    let (n, fw) = super::contact_kin::world_weights(geo, &lp.a.rot, lam);
    let p1 = lp.a.p;
    let pb = if geo.six { p1 } else { lp.b.p };
    let fa = Force { ang: n + p1.cross(&fw), lin: fw };
    let fb = Force { ang: n + pb.cross(&fw), lin: fw };
    let zero = Force { ang: Vector3::zeros(), lin: Vector3::zeros() };
    assert!(dofs.len() == dof_joint.len() && lp.on.len() == dofs.len());
    for (il, &l) in dofs.iter().enumerate() {
        let (la, lb) = lp.on[il];
        let jl = dof_joint[il];
        let sl = s[l];
        let (w, v) = (sl.ang, sl.lin);
        let (dn, df) = if geo.local && la {
            (w.cross(&n), w.cross(&fw))
        } else {
            (Vector3::zeros(), Vector3::zeros())
        };
        let dpa = if la { v + w.cross(&p1) } else { Vector3::zeros() };
        let dpb = if geo.six {
            dpa
        } else if lb {
            v + w.cross(&pb)
        } else {
            Vector3::zeros()
        };
        let dfa = Force { ang: dn + dpa.cross(&fw) + p1.cross(&df), lin: df };
        let dfb = Force { ang: dn + dpb.cross(&fw) + pb.cross(&df), lin: df };
        // D F − S_l ×* F for x below l on its chain.
        let ga = if la { dfa - sl.cross_force(&fa) } else { zero };
        let gb = if lb { dfb - sl.cross_force(&fb) } else { zero };
        for (ix, &x) in dofs.iter().enumerate() {
            let (xa, xb) = lp.on[ix];
            if geo.six && xa == xb {
                continue;
            }
            let (sx, anc) = (s[x], jl <= dof_joint[ix]);
            let mut e = 0.0;
            if xa {
                e += sx.dot(if la && anc { &ga } else { &dfa });
            }
            if xb {
                e -= sx.dot(if lb && anc { &gb } else { &dfb });
            }
            f(x, l, e);
        }
    }
}

/// `∂(J_c z)/∂q_l` for every DoF `l` of a constraint's path (position `il`, DoF `dofs[il]`,
/// parent joint `dof_parent[il]`, sides `on(il)`), passed to `f(l, rows)` (`rows[..dim]`), in
/// plain arithmetic from the cumulative sums `zc` (`Z_j = Σ_{x ⪯ j} S_x z_x`, `zc[0] = 0`) and
/// the world subspaces `s`: the value and inner derivative of [`loop_djz_dq_rows`] without a
/// tangent. Frame A `(R₁, p₁)` on body `ma`, frame B's point `p₂` on body `mb` (0 for a world
/// contact, whose rows are then those of `contact_kin`'s generic contacts). `J_c z` is the rows
/// of `W = Z_a − Z_b` at `p₁` (6-D) or `Z_a.lin + Z_a.ang × p₁ − Z_b.lin − Z_b.ang × p₂` (3-D),
/// in `R₁`'s axes for `local`; along `q_l`: `D Z = S_l × (Z − Z_λ)` on `l`'s chains,
/// `D p_i = u_l^i`, `D(R₁ᵀ y) = R₁ᵀ(D y − w_l × y)` for `l` on chain A.
#[allow(clippy::too_many_arguments)]
pub(crate) fn djz_dq_plain(
    s: &[Motion],
    geo: Geo,
    (ma, p1, r1): (usize, &Vector3<f64>, &nalgebra::Matrix3<f64>),
    (mb, p2): (usize, &Vector3<f64>),
    (dofs, dof_parent): (&[usize], &[usize]),
    on: impl Fn(usize) -> (bool, bool),
    zc: &[Motion],
    mut f: impl FnMut(usize, &[f64; 6]),
) {
    let (za, zb) = (zc[ma], zc[mb]);
    let wv = za - zb;
    let (y_ang, y_lin) = if geo.six {
        (wv.ang, wv.lin + wv.ang.cross(p1))
    } else {
        (Vector3::zeros(), za.lin + za.ang.cross(p1) - zb.lin - zb.ang.cross(p2))
    };
    let z3 = Vector3::zeros();
    let mut out = [0.0; 6];
    for (il, &l) in dofs.iter().enumerate() {
        let (la, lb) = on(il);
        let sl = s[l];
        let zl = zc[dof_parent[il]];
        let dza = if la { sl.cross(&(za - zl)) } else { Motion::zero() };
        let dzb = if lb { sl.cross(&(zb - zl)) } else { Motion::zero() };
        let dp1 = if la { sl.lin + sl.ang.cross(p1) } else { z3 };
        let (mut d_ang, mut d_lin) = if geo.six {
            let dw = dza - dzb;
            (dw.ang, dw.lin + dw.ang.cross(p1) + wv.ang.cross(&dp1))
        } else {
            let dp2 = if lb { sl.lin + sl.ang.cross(p2) } else { z3 };
            let a = dza.lin + dza.ang.cross(p1) + za.ang.cross(&dp1);
            (z3, a - (dzb.lin + dzb.ang.cross(p2) + zb.ang.cross(&dp2)))
        };
        if geo.local {
            let wl = if la { sl.ang } else { z3 };
            d_lin = r1.tr_mul(&(d_lin - wl.cross(&y_lin)));
            if geo.six {
                d_ang = r1.tr_mul(&(d_ang - wl.cross(&y_ang)));
            }
        }
        if geo.six {
            out[..3].copy_from_slice(d_ang.as_slice());
            out[3..6].copy_from_slice(d_lin.as_slice());
        } else {
            out[..3].copy_from_slice(d_lin.as_slice());
        }
        f(l, &out);
    }
}

/// A spatial force (or motion) with a tangent, as `(ang, lin)`.
type DF = (D3, D3);

/// `S ×* F = [w × F.ang + v × F.lin; w × F.lin]` with tangents.
#[inline]
fn cross_force(s: &Dm, f: &DF) -> DF {
    let (w, v) = (s.ang(), s.lin());
    (w.cross(&f.0) + v.cross(&f.1), w.cross(&f.1))
}

/// The tangent of `S·F`.
#[inline]
fn dot_d(s: &Dm, f: &DF) -> f64 {
    s.d.ang.dot(&f.0.v) + s.v.ang.dot(&f.0.d) + s.d.lin.dot(&f.1.v) + s.v.lin.dot(&f.1.d)
}

/// `λ·∂²J_x/∂q_l∂q_k` (inner `l`, outer `k`) for every pair of DoFs `x`, `l` of the constraint's
/// path, passed to `f(x, l, e)`: the tangent along `q_k` of [`loop_djtl_dq`]'s closed form,
/// evaluated with dual base quantities (`S_x`, `S_l`, `p₁`, `p₂` and `R₁λ` with their
/// tangents on the chains that hold `k`; the indicators `[l ⪯ x]` are fixed).
pub(crate) fn loop_djtl_dq2(
    b: &Base,
    geo: Geo,
    lp: &Loop,
    (dofs, dof_joint): (&[usize], &[usize]),
    lam: &[f64],
    k: usize,
    mut f: impl FnMut(usize, usize, f64),
) {
    let (da, db) = lp.dirs(Dir::Q(k));
    let part = |i: usize| Vector3::new(lam[i], lam[i + 1], lam[i + 2]);
    let (n0, f0) = if geo.six { (part(0), part(3)) } else { (Vector3::zeros(), part(0)) };
    let z3 = D3::default();
    let (n, fw) = if geo.local {
        let r = b.rot(&lp.a.rot, da);
        (D3 { v: r.v * n0, d: r.d * n0 }, D3 { v: r.v * f0, d: r.d * f0 })
    } else {
        (D3 { v: n0, d: Vector3::zeros() }, D3 { v: f0, d: Vector3::zeros() })
    };
    let p1 = b.p(&lp.a.p, da);
    let pb = if geo.six { p1 } else { b.p(&lp.b.p, db) };
    let fa: DF = (n + p1.cross(&fw), fw);
    let fb: DF = (n + pb.cross(&fw), fw);
    assert!(dofs.len() == dof_joint.len() && lp.on.len() == dofs.len());
    for (il, &l) in dofs.iter().enumerate() {
        let (la, lb) = lp.on[il];
        let jl = dof_joint[il];
        let sl = b.s(l, if la { da } else { db });
        let (w, v) = (sl.ang(), sl.lin());
        let (dn, df) = if geo.local && la { (w.cross(&n), w.cross(&fw)) } else { (z3, z3) };
        let dpa = if la { v + w.cross(&p1) } else { z3 };
        let dpb = if geo.six {
            dpa
        } else if lb {
            v + w.cross(&pb)
        } else {
            z3
        };
        let dfa: DF = (dn + dpa.cross(&fw) + p1.cross(&df), df);
        let dfb: DF = (dn + dpb.cross(&fw) + pb.cross(&df), df);
        let sub = |x: DF, y: DF| (x.0 - y.0, x.1 - y.1);
        let ga = if la { sub(dfa, cross_force(&sl, &fa)) } else { (z3, z3) };
        let gb = if lb { sub(dfb, cross_force(&sl, &fb)) } else { (z3, z3) };
        for (ix, &x) in dofs.iter().enumerate() {
            let (xa, xb) = lp.on[ix];
            if geo.six && xa == xb {
                continue;
            }
            let sx = b.s(x, if xa { da } else { db });
            let anc = jl <= dof_joint[ix];
            let mut e = 0.0;
            if xa {
                e += dot_d(&sx, if la && anc { &ga } else { &dfa });
            }
            if xb {
                e -= dot_d(&sx, if lb && anc { &gb } else { &dfb });
            }
            f(x, l, e);
        }
    }
}
