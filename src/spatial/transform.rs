//! Rigid transforms stored as rotation + translation.

use super::motion::{cross3, mat3_mul, mat3_tr_vec, mat3_vec};
use super::{Force, Inertia, Motion, skew};
use nalgebra::{Matrix3, Matrix6, Vector3};

/// Pose of a frame `b` in a frame `a` (`ᵃM_b`): `rot = ᵃR_b`, `trans` = origin of `b` in `a`.
///
/// Its action maps spatial vectors expressed in `b` to `a` (the matrix `ᵃX_b`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Rotation `ᵃR_b`.
    pub rot: Matrix3<f64>,
    /// Position of the origin of `b`, in `a`.
    pub trans: Vector3<f64>,
}

impl Default for Transform {
    fn default() -> Self {
        Self::identity()
    }
}

impl Transform {
    /// The identity transform.
    #[inline]
    pub fn identity() -> Self {
        Self { rot: Matrix3::identity(), trans: Vector3::zeros() }
    }
    /// From rotation and translation.
    #[inline]
    pub fn new(rot: Matrix3<f64>, trans: Vector3<f64>) -> Self {
        Self { rot, trans }
    }
    /// Pure translation.
    #[inline]
    pub fn from_translation(trans: Vector3<f64>) -> Self {
        Self { rot: Matrix3::identity(), trans }
    }
    /// From URDF-style roll-pitch-yaw (fixed axes X, Y, Z: `R = Rz(y) Ry(p) Rx(r)`) and translation.
    pub fn from_rpy_xyz(rpy: [f64; 3], xyz: [f64; 3]) -> Self {
        let (sr, cr) = rpy[0].sin_cos();
        let (sp, cp) = rpy[1].sin_cos();
        let (sy, cy) = rpy[2].sin_cos();
        let rot = Matrix3::new(
            cy * cp,
            cy * sp * sr - sy * cr,
            cy * sp * cr + sy * sr,
            sy * cp,
            sy * sp * sr + cy * cr,
            sy * sp * cr - cy * sr,
            -sp,
            cp * sr,
            cp * cr,
        );
        Self { rot, trans: Vector3::new(xyz[0], xyz[1], xyz[2]) }
    }
    /// Composition `ᵃM_c = ᵃM_b ᵇM_c`.
    #[inline]
    pub fn compose(&self, o: &Transform) -> Transform {
        Transform {
            rot: mat3_mul(&self.rot, &o.rot),
            trans: self.trans + mat3_vec(&self.rot, &o.trans),
        }
    }
    /// Inverse `ᵇM_a`.
    #[inline]
    pub fn inverse(&self) -> Transform {
        let rt = self.rot.transpose();
        Transform { rot: rt, trans: -(rt * self.trans) }
    }
    /// Maps a point of `b` to `a`.
    #[inline]
    pub fn act_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.trans
    }
    /// Motion vector in `b` → in `a` (`ᵃX_b m`).
    #[inline]
    pub fn act_motion(&self, m: &Motion) -> Motion {
        let ang = mat3_vec(&self.rot, &m.ang);
        Motion { ang, lin: mat3_vec(&self.rot, &m.lin) + cross3(&self.trans, &ang) }
    }
    /// Motion vector in `a` → in `b` (`ᵇX_a m`).
    #[inline]
    pub fn inv_act_motion(&self, m: &Motion) -> Motion {
        Motion {
            ang: mat3_tr_vec(&self.rot, &m.ang),
            lin: mat3_tr_vec(&self.rot, &(m.lin - cross3(&self.trans, &m.ang))),
        }
    }
    /// Force vector in `b` → in `a` (`ᵃX_b^* f`).
    #[inline]
    pub fn act_force(&self, f: &Force) -> Force {
        let lin = mat3_vec(&self.rot, &f.lin);
        Force { ang: mat3_vec(&self.rot, &f.ang) + cross3(&self.trans, &lin), lin }
    }
    /// Force vector in `a` → in `b`.
    #[inline]
    pub fn inv_act_force(&self, f: &Force) -> Force {
        Force {
            ang: mat3_tr_vec(&self.rot, &(f.ang - cross3(&self.trans, &f.lin))),
            lin: mat3_tr_vec(&self.rot, &f.lin),
        }
    }
    /// Spatial inertia expressed in `b` → expressed in `a`.
    #[inline]
    pub fn act_inertia(&self, i: &Inertia) -> Inertia {
        self.act_inertia_inline(i)
    }
    /// [`Self::act_inertia`], always inlined (for hot loops).
    #[inline(always)]
    pub(crate) fn act_inertia_inline(&self, i: &Inertia) -> Inertia {
        // Ī' = R Ī Rᵀ − [Rh]×[p]× − [p]×[Rh]× − m [p]×[p]×, with [a]×[b]× = b aᵀ − (a·b) 1,
        // i.e. Ī' = R Ī Rᵀ − p h'ᵀ − Rh pᵀ + (2 Rh·p + m p·p) 1 with h' = Rh + m p.
        let r = self.rot.as_slice(); // column-major: R_ij = r[i + 3j]
        let ib = i.rot.as_slice();
        let rh = mat3_vec(&self.rot, &i.h);
        let p = self.trans;
        let m = i.mass;
        let hn = rh + p * m;
        // T = R Ī (T_ik = Σ_l R_il Ī_lk), then the upper triangle of T Rᵀ.
        let mut t = [[0.0; 3]; 3];
        for (row, tr) in t.iter_mut().enumerate() {
            for (k, x) in tr.iter_mut().enumerate() {
                *x = r[row] * ib[3 * k] + r[row + 3] * ib[1 + 3 * k] + r[row + 6] * ib[2 + 3 * k];
            }
        }
        let diag = 2.0 * rh.dot(&p) + m * p.norm_squared();
        let (pa, ha, ra) = ([p.x, p.y, p.z], [hn.x, hn.y, hn.z], [rh.x, rh.y, rh.z]);
        let mut s = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in a..3 {
                let x = t[a][0] * r[b] + t[a][1] * r[b + 3] + t[a][2] * r[b + 6]
                    - pa[a] * ha[b]
                    - ra[a] * pa[b];
                s[a][b] = x;
                s[b][a] = x;
            }
            s[a][a] += diag;
        }
        #[rustfmt::skip]
        let rot = Matrix3::new(
            s[0][0], s[0][1], s[0][2],
            s[1][0], s[1][1], s[1][2],
            s[2][0], s[2][1], s[2][2],
        );
        Inertia { mass: m, h: hn, rot }
    }
    /// Spatial inertia expressed in `a` → expressed in `b`.
    pub fn inv_act_inertia(&self, i: &Inertia) -> Inertia {
        self.inverse().act_inertia(i)
    }
    /// The 6×6 motion transform `ᵃX_b = [[R, 0], [p×R, R]]`.
    pub fn motion_matrix(&self) -> Matrix6<f64> {
        let mut x = Matrix6::zeros();
        x.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rot);
        x.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.rot);
        x.fixed_view_mut::<3, 3>(3, 0).copy_from(&(skew(&self.trans) * self.rot));
        x
    }
}
