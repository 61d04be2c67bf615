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

use crate::spatial::Motion;
use nalgebra::Vector3;
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

/// `∂a_p/∂q_l` (tangent) of the classical acceleration of the contact point of body `m`,
/// evaluated with tangent `dir` (the outer derivative).
pub(crate) fn dap_dq(b: &Base, m: usize, p: &Vector3<f64>, l: usize, dir: Dir) -> D3 {
    let jl = b.dof_joint[l];
    let ll = b.parents[jl];
    let sl = b.s(l, dir);
    let vm = b.vel(m, dir);
    let am = b.acc(m, dir);
    let vl = b.vel(ll, dir);
    let al = b.acc(ll, dir);
    let pp = b.p(p, dir);
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

/// `∂a_p/∂q̇_l`, evaluated with tangent `dir`.
pub(crate) fn dap_dv(b: &Base, m: usize, p: &Vector3<f64>, l: usize, dir: Dir) -> D3 {
    let jl = b.dof_joint[l];
    let ll = b.parents[jl];
    let sl = b.s(l, dir);
    let vm = b.vel(m, dir);
    let vl = b.vel(ll, dir);
    let vj = b.vel(jl, dir);
    let pp = b.p(p, dir);
    let dv = sl; // J8
    let da = vl.cross(&sl) + vj.cross(&sl) - vm.cross(&sl); // J9
    let pdot = at_point(&vm, &pp);
    let dpdot = at_point(&dv, &pp);
    da.lin() + da.ang().cross(&pp) + dv.ang().cross(&pdot) + vm.ang().cross(&dpdot)
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

/// `∂(J z)/∂q_l` at one contact, where `zc` holds the cumulative sums `Z_j = Σ_{x ⪯ j} S_x z_x`
/// per joint; evaluated with tangent `dir`.
pub(crate) fn djz_dq(
    b: &Base,
    zc: &[Motion],
    m: usize,
    p: &Vector3<f64>,
    l: usize,
    dir: Dir,
) -> D3 {
    let jl = b.dof_joint[l];
    let sl = b.s(l, dir);
    let zm = b.cum(zc, m, dir, false);
    let zl = b.cum(zc, b.parents[jl], dir, false);
    let pp = b.p(p, dir);
    let dz = sl.cross(&(zm - zl));
    at_point(&dz, &pp) + zm.ang().cross(&at_point(&sl, &pp))
}
