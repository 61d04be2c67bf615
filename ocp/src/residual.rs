//! Residuals `r(x, u)` of the costs (Crocoddyl's `ResidualModel*`) and their Jacobians
//! `R_x = ∂r/∂x` (`nr × ndx`, tangent space) and `R_u = ∂r/∂u` (`nr × nu`).
//!
//! | residual | `r` | `nr` |
//! |---|---|---|
//! | `State` | `x ⊖ x_ref` | `ndx` |
//! | `Control` | `u − u_ref` | `nu` |
//! | `JointEffort` | `τ_a − τ_ref`, `τ_a = u` the actuated joint torques | `nu` |
//! | `FramePlacement` | `log6(ᵒM_ref⁻¹ ᵒM_f)` (`[angular; linear]`) | 6 |
//! | `FrameTranslation` | `ᵒp_f − p_ref` | 3 |
//! | `FrameVelocity` | `v_f − v_ref` in LOCAL, WORLD or LOCAL_WORLD_ALIGNED (`[angular; linear]`) | 6 |
//! | `CoMPosition` | `c − c_ref` | 3 |
//! | `ContactForce` | `λ_c − λ_ref` (the contact's rows, its reference's axes) | 3 or 6 |
//! | `ContactCone` | `A λ_c` (Crocoddyl's linearised friction and wrench cones) | rows of `A` |
//!
//! `ContactForce` and `ContactCone` read the contact forces of the node's dynamics (the impulses
//! at an impulse node); at a node without dynamics (the terminal node) they read zero forces
//! with zero derivatives, as Crocoddyl's terminal `calc(x)` does.

use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX, Vector3};
use sodyn::algo::{
    Data, ReferenceFrame, center_of_mass, center_of_mass_jacobian, frame_jacobian, frame_placement,
    frame_velocity, frame_velocity_derivatives,
};
use sodyn::model::{Arg, Model, jlog6, log6};
use sodyn::spatial::{Motion, Transform};

use crate::linalg::gemm_nn;
use crate::state::{StateMultibody, StateScratch};

/// Which rows of the node's stacked contact forces a force residual reads.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactRows {
    /// The contact's name.
    pub name: String,
    /// Its first row in the stacked forces of the active contacts (`None`: inactive, zero).
    pub offset: Option<usize>,
    /// Its rows (3 or 6).
    pub dim: usize,
}

/// A residual.
#[derive(Clone, Debug, PartialEq)]
pub enum Residual {
    /// `x ⊖ x_ref`.
    State {
        /// The reference state (length `nx`).
        xref: DVector<f64>,
    },
    /// `u − u_ref`.
    Control {
        /// The reference control (length `nu`).
        uref: DVector<f64>,
    },
    /// `u − τ_ref` (the actuated joint torques of forward dynamics are the control).
    JointEffort {
        /// The reference torques (length `nu`).
        uref: DVector<f64>,
    },
    /// `log6(ᵒM_ref⁻¹ ᵒM_f)`.
    FramePlacement {
        /// The frame index.
        frame: usize,
        /// The reference placement.
        mref: Transform,
    },
    /// `ᵒp_f − p_ref`.
    FrameTranslation {
        /// The frame index.
        frame: usize,
        /// The reference position.
        pref: Vector3<f64>,
    },
    /// `v_f − v_ref`.
    FrameVelocity {
        /// The frame index.
        frame: usize,
        /// The reference velocity.
        vref: Motion,
        /// The reference frame of both.
        rf: ReferenceFrame,
    },
    /// `c − c_ref`.
    CoMPosition {
        /// The reference position.
        cref: Vector3<f64>,
    },
    /// `λ_c − λ_ref`.
    ContactForce {
        /// The contact's rows.
        contact: ContactRows,
        /// The reference force.
        fref: DVector<f64>,
    },
    /// `A λ_c`.
    ContactCone {
        /// The contact's rows.
        contact: ContactRows,
        /// The cone matrix (`nr × dim`).
        a: DMatrix<f64>,
    },
}

/// What a residual reads of its node, beyond `x` and `u`.
pub(crate) struct NodeView<'a> {
    pub model: &'a Model,
    pub state: &'a StateMultibody,
    pub data: &'a mut Data,
    pub sc: &'a mut StateScratch,
    pub x: &'a DVector<f64>,
    pub q: &'a DVector<f64>,
    pub v: &'a DVector<f64>,
    pub u: &'a DVector<f64>,
    /// Stacked contact forces with `∂λ/∂x`, `∂λ/∂u` (`None` at a node without dynamics).
    pub forces: Option<(&'a DVector<f64>, &'a DMatrix<f64>, &'a DMatrix<f64>)>,
}

/// Buffers of one residual.
#[derive(Clone, Debug)]
pub struct ResidualData {
    /// `r`.
    pub r: DVector<f64>,
    /// `∂r/∂x`.
    pub rx: DMatrix<f64>,
    /// `∂r/∂u`.
    pub ru: DMatrix<f64>,
    pub(crate) j6a: Matrix6xX<f64>,
    j6b: Matrix6xX<f64>,
    j3: Matrix3xX<f64>,
}

impl Residual {
    /// Crocoddyl's class name of this residual.
    pub fn name(&self) -> &'static str {
        match self {
            Residual::State { .. } => "ResidualModelState",
            Residual::Control { .. } => "ResidualModelControl",
            Residual::JointEffort { .. } => "ResidualModelJointEffort",
            Residual::FramePlacement { .. } => "ResidualModelFramePlacement",
            Residual::FrameTranslation { .. } => "ResidualModelFrameTranslation",
            Residual::FrameVelocity { .. } => "ResidualModelFrameVelocity",
            Residual::CoMPosition { .. } => "ResidualModelCoMPosition",
            Residual::ContactForce { .. } => "ResidualModelContactForce",
            Residual::ContactCone { .. } => "ResidualModelContactCone",
        }
    }
    /// The residual's length.
    pub fn nr(&self, ndx: usize, nu: usize) -> usize {
        match self {
            Residual::State { .. } => ndx,
            Residual::Control { .. } | Residual::JointEffort { .. } => nu,
            Residual::FramePlacement { .. } | Residual::FrameVelocity { .. } => 6,
            Residual::FrameTranslation { .. } | Residual::CoMPosition { .. } => 3,
            Residual::ContactForce { contact, .. } => contact.dim,
            Residual::ContactCone { a, .. } => a.nrows(),
        }
    }
    /// The reference as a flat vector, in the layout [`Residual::set_reference`] takes; `None`
    /// for `ContactCone`, which has none.
    pub fn reference(&self) -> Option<DVector<f64>> {
        Some(match self {
            Residual::State { xref } => xref.clone(),
            Residual::Control { uref } | Residual::JointEffort { uref } => uref.clone(),
            Residual::FramePlacement { mref, .. } => {
                let mut v = DVector::zeros(12);
                v.rows_mut(0, 3).copy_from(&mref.trans);
                for i in 0..3 {
                    for j in 0..3 {
                        v[3 + 3 * i + j] = mref.rot[(i, j)];
                    }
                }
                v
            }
            Residual::FrameTranslation { pref: p, .. } | Residual::CoMPosition { cref: p } => {
                DVector::from_column_slice(p.as_slice())
            }
            Residual::FrameVelocity { vref, .. } => {
                DVector::from_iterator(6, vref.ang.iter().chain(vref.lin.iter()).copied())
            }
            Residual::ContactForce { fref, .. } => fref.clone(),
            Residual::ContactCone { .. } => return None,
        })
    }
    /// Replaces the reference (a receding-horizon update without rebuilding the problem):
    ///
    /// | residual | `value` |
    /// |---|---|
    /// | `State` | `x_ref` (`nx`) |
    /// | `Control`, `JointEffort` | `u_ref` (`nu`) |
    /// | `FramePlacement` | `[p; R₀₀, R₀₁, …, R₂₂]` (translation, then the rotation row by row: 12) |
    /// | `FrameTranslation`, `CoMPosition` | the point (3) |
    /// | `FrameVelocity` | `[ω; v]` (6) |
    /// | `ContactForce` | `λ_ref` (the contact's 3 or 6 rows) |
    ///
    /// # Errors
    /// A message if `value` has the wrong length or a non-finite entry, a state reference has a
    /// non-unit quaternion, a placement's rotation is not one (`RᵀR ≠ I` or `det R ≠ 1` beyond
    /// 1e-9), or the residual is a `ContactCone` (no reference); the residual is then unchanged.
    pub fn set_reference(
        &mut self,
        value: &[f64],
        state: &StateMultibody,
    ) -> std::result::Result<(), String> {
        let expected = match self {
            Residual::State { xref } => xref.len(),
            Residual::Control { uref } | Residual::JointEffort { uref } => uref.len(),
            Residual::FramePlacement { .. } => 12,
            Residual::FrameTranslation { .. } | Residual::CoMPosition { .. } => 3,
            Residual::FrameVelocity { .. } => 6,
            Residual::ContactForce { fref, .. } => fref.len(),
            Residual::ContactCone { .. } => {
                return Err(format!("a {} has no reference", self.name()));
            }
        };
        if value.len() != expected {
            return Err(format!("reference of length {} (expected {expected})", value.len()));
        }
        if let Some(i) = value.iter().position(|v| !v.is_finite()) {
            return Err(format!("reference entry {i} is {}", value[i]));
        }
        let v3 = |k: usize| Vector3::new(value[k], value[k + 1], value[k + 2]);
        match self {
            Residual::State { xref } => {
                let x = DVector::from_column_slice(value);
                state.check_x("reference", &x).map_err(|e| e.message)?;
                *xref = x;
            }
            Residual::Control { uref } | Residual::JointEffort { uref } => {
                uref.copy_from_slice(value);
            }
            Residual::FramePlacement { mref, .. } => {
                let r = nalgebra::Matrix3::from_row_slice(&value[3..12]);
                let e = (r.transpose() * r - nalgebra::Matrix3::identity()).amax();
                if e > 1e-9 || (r.determinant() - 1.0).abs() > 1e-9 {
                    return Err("reference rotation is not a rotation matrix (RᵀR ≠ I or \
                                det R ≠ 1 beyond 1e-9)"
                        .into());
                }
                *mref = Transform::new(r, v3(0));
            }
            Residual::FrameTranslation { pref: p, .. } | Residual::CoMPosition { cref: p } => {
                *p = v3(0);
            }
            Residual::FrameVelocity { vref, .. } => *vref = Motion::new(v3(0), v3(3)),
            Residual::ContactForce { fref, .. } => fref.copy_from_slice(value),
            Residual::ContactCone { .. } => unreachable!("refused above"),
        }
        Ok(())
    }
    /// Whether `r` depends on `u` (so it is zero-derivative at a node without control).
    pub fn depends_on_u(&self) -> bool {
        matches!(
            self,
            Residual::Control { .. }
                | Residual::JointEffort { .. }
                | Residual::ContactForce { .. }
                | Residual::ContactCone { .. }
        )
    }
    /// Whether `r` depends on `x` (Crocoddyl's `q_dependent || v_dependent`): costs that do
    /// not are skipped at a node without control.
    pub fn depends_on_x(&self) -> bool {
        !matches!(self, Residual::Control { .. } | Residual::JointEffort { .. })
    }
    /// How many leading columns of `R_x` can be nonzero: `nv` for residuals of `q` only, `2 nv`
    /// otherwise (the cost derivatives skip the zero blocks).
    pub fn x_cols(&self, nv: usize) -> usize {
        match self {
            Residual::FramePlacement { .. }
            | Residual::FrameTranslation { .. }
            | Residual::CoMPosition { .. } => nv,
            _ => 2 * nv,
        }
    }
    /// Buffers for this residual.
    pub fn create_data(&self, nv: usize, nu: usize) -> ResidualData {
        let nr = self.nr(2 * nv, nu);
        let mut rx = DMatrix::zeros(nr, 2 * nv);
        if let Residual::State { .. } = self {
            // R_x = blockdiag(∂(q ⊖ q_ref)/∂q, I): `calc_diff` writes only the first block.
            rx.view_mut((nv, nv), (nv, nv)).fill_diagonal(1.0);
        }
        ResidualData {
            r: DVector::zeros(nr),
            rx,
            ru: DMatrix::zeros(nr, nu),
            j6a: Matrix6xX::zeros(nv),
            j6b: Matrix6xX::zeros(nv),
            j3: Matrix3xX::zeros(nv),
        }
    }

    /// `r` into `rd.r`.
    pub(crate) fn calc(&self, rd: &mut ResidualData, n: &mut NodeView<'_>) -> sodyn::Result<()> {
        match self {
            Residual::State { xref } => n.state.diff(xref, n.x, &mut rd.r),
            Residual::Control { uref } | Residual::JointEffort { uref } => {
                rd.r.copy_from(n.u);
                rd.r -= uref;
            }
            Residual::FramePlacement { frame, mref } => {
                let omf = frame_placement(n.model, n.data, n.q, *frame)?;
                let e = log6(&mref.inverse().compose(&omf));
                rd.r.rows_mut(0, 3).copy_from(&e.ang);
                rd.r.rows_mut(3, 3).copy_from(&e.lin);
            }
            Residual::FrameTranslation { frame, pref } => {
                let omf = frame_placement(n.model, n.data, n.q, *frame)?;
                rd.r.copy_from(&(omf.trans - pref));
            }
            Residual::FrameVelocity { frame, vref, rf } => {
                let vf = frame_velocity(n.model, n.data, n.q, n.v, *frame, *rf)?;
                rd.r.rows_mut(0, 3).copy_from(&(vf.ang - vref.ang));
                rd.r.rows_mut(3, 3).copy_from(&(vf.lin - vref.lin));
            }
            Residual::CoMPosition { cref } => {
                let c = center_of_mass(n.model, n.data, n.q)?;
                rd.r.copy_from(&(c - cref));
            }
            Residual::ContactForce { contact, fref } => {
                match (n.forces, contact.offset) {
                    (Some((f, _, _)), Some(o)) => {
                        rd.r.copy_from(&f.rows(o, contact.dim));
                        rd.r -= fref;
                    }
                    (Some(_), None) => {
                        rd.r.fill(0.0);
                        rd.r -= fref;
                    }
                    // A node without dynamics: Crocoddyl's `calc(x)` sets r = 0.
                    (None, _) => rd.r.fill(0.0),
                }
            }
            Residual::ContactCone { contact, a } => match (n.forces, contact.offset) {
                (Some((f, _, _)), Some(o)) => rd.r.gemv(1.0, a, &f.rows(o, contact.dim), 0.0),
                _ => rd.r.fill(0.0),
            },
        }
        Ok(())
    }

    /// `R_x`, `R_u` into `rd` (after [`Residual::calc`] at the same point).
    pub(crate) fn calc_diff(
        &self,
        rd: &mut ResidualData,
        n: &mut NodeView<'_>,
    ) -> sodyn::Result<()> {
        let nv = n.model.nv();
        match self {
            Residual::State { xref } => {
                // The other blocks of R_x (zero, and I for the velocities) are set at creation.
                n.state.jdiff_q(n.sc, xref, n.x, Arg::Second);
                rd.rx.view_mut((0, 0), (nv, nv)).copy_from(&n.sc.jq);
            }
            Residual::Control { .. } | Residual::JointEffort { .. } => {
                rd.ru.as_mut_slice().fill(0.0);
                rd.ru.fill_diagonal(1.0);
            }
            Residual::FramePlacement { frame, mref } => {
                frame_jacobian(n.model, n.data, n.q, *frame, ReferenceFrame::Local, &mut rd.j6a)?;
                // The Jacobian's kinematics pass left the frame's joint placement in `data`:
                // `⁰M_f` from it (what `frame_placement` computes), without a second pass.
                let f = &n.model.frames()[*frame];
                let omf = n.data.o_m_i()[f.joint].compose(&f.placement);
                let jl = jlog6(&mref.inverse().compose(&omf));
                rd.rx.as_mut_slice().fill(0.0);
                let mut rq = rd.rx.view_mut((0, 0), (6, nv));
                gemm_nn(&mut rq, 1.0, &jl, &rd.j6a, 0.0);
            }
            Residual::FrameTranslation { frame, .. } => {
                frame_jacobian(
                    n.model,
                    n.data,
                    n.q,
                    *frame,
                    ReferenceFrame::LocalWorldAligned,
                    &mut rd.j6a,
                )?;
                rd.rx.as_mut_slice().fill(0.0);
                rd.rx.view_mut((0, 0), (3, nv)).copy_from(&rd.j6a.rows(3, 3));
            }
            Residual::FrameVelocity { frame, rf, .. } => {
                frame_velocity_derivatives(
                    n.model,
                    n.data,
                    n.q,
                    n.v,
                    *frame,
                    *rf,
                    &mut rd.j6a,
                    &mut rd.j6b,
                )?;
                rd.rx.view_mut((0, 0), (6, nv)).copy_from(&rd.j6a);
                rd.rx.view_mut((0, nv), (6, nv)).copy_from(&rd.j6b);
            }
            Residual::CoMPosition { .. } => {
                center_of_mass_jacobian(n.model, n.data, n.q, &mut rd.j3)?;
                rd.rx.as_mut_slice().fill(0.0);
                rd.rx.view_mut((0, 0), (3, nv)).copy_from(&rd.j3);
            }
            Residual::ContactForce { contact, .. } => match (n.forces, contact.offset) {
                (Some((_, dx, du)), Some(o)) => {
                    rd.rx.copy_from(&dx.rows(o, contact.dim));
                    rd.ru.copy_from(&du.rows(o, contact.dim));
                }
                _ => {
                    rd.rx.as_mut_slice().fill(0.0);
                    rd.ru.as_mut_slice().fill(0.0);
                }
            },
            Residual::ContactCone { contact, a } => match (n.forces, contact.offset) {
                (Some((_, dx, du)), Some(o)) => {
                    gemm_nn(&mut rd.rx, 1.0, a, &dx.rows(o, contact.dim), 0.0);
                    gemm_nn(&mut rd.ru, 1.0, a, &du.rows(o, contact.dim), 0.0);
                }
                _ => {
                    rd.rx.as_mut_slice().fill(0.0);
                    rd.ru.as_mut_slice().fill(0.0);
                }
            },
        }
        Ok(())
    }
}
