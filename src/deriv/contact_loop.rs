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

use super::contact_kin::{Base, D3, Dir, Dm, Geo, Path, Rows, at_point, rows};
use crate::spatial::Transform;

/// The two chains of a two-frame constraint.
#[derive(Clone, Debug, Default)]
pub(crate) struct Loop {
    /// Root path of frame A's body; `p`, `rot`: frame A's contact frame in the world.
    pub a: Path,
    /// Root path of frame B's body (empty: the world); `p`, `rot`: frame B's contact frame.
    pub b: Path,
    /// Frame B's body and its contact frame's placement in that body's frame.
    pub local_b: (usize, Transform),
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
