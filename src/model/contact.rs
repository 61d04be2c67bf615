//! Point contacts: a point fixed in a frame (a URDF link, possibly merged by a fixed joint).
//! The contact Jacobian stacks, per contact `c`, the world-aligned linear velocity of the point
//! (rows `3c..3c+3`); `λ` stacks the world-frame contact forces applied to the robot.
//!
//! Baumgarte correction (Pinocchio's `corrector`): with gains `kp`, `kd` the KKT dynamics hold
//! `a_c + kd v_c + kp e_c = 0` instead of `a_c = 0`, `a_c`, `v_c` the point's world-aligned
//! classical acceleration and velocity, `e_c = p_c(q) − p_ref` its position error from a
//! reference point fixed in the world, taken as the point's position at the `q` of the call
//! (so `e_c = 0` there, and derivatives hold `p_ref` fixed). Impulses and constrained inverse
//! dynamics do not use the gains.

use crate::error::{Error, Result};
use crate::model::Model;
use nalgebra::Vector3;

/// A point contact: a point given in the coordinates of a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Contact {
    /// Frame index in `model.frames()`.
    pub frame: usize,
    /// Point in the frame's coordinates.
    pub point: Vector3<f64>,
    /// Baumgarte position gain `kp ≥ 0` (default 0).
    pub kp: f64,
    /// Baumgarte velocity gain `kd ≥ 0` (default 0).
    pub kd: f64,
}

impl Contact {
    /// A contact at `point` (frame coordinates) of the frame named `frame`.
    pub fn new(model: &Model, frame: &str, point: Vector3<f64>) -> Result<Contact> {
        let id = model.frame_id(frame)?;
        if let Some(index) = point.iter().position(|x| !x.is_finite()) {
            return Err(Error::NotFinite { what: format!("point of contact \"{frame}\""), index });
        }
        Ok(Contact { frame: id, point, kp: 0.0, kd: 0.0 })
    }
    /// The same contact with Baumgarte gains `kp`, `kd` (module documentation).
    ///
    /// # Errors
    /// [`Error::Argument`] if a gain is negative or not finite.
    pub fn with_baumgarte(mut self, kp: f64, kd: f64) -> Result<Contact> {
        self.kp = kp;
        self.kd = kd;
        self.check_gains()?;
        Ok(self)
    }
    /// Checks that the gains are finite and non-negative.
    ///
    /// # Errors
    /// [`Error::Argument`] naming the gain and its value.
    pub fn check_gains(&self) -> Result<()> {
        for (name, g) in [("kp", self.kp), ("kd", self.kd)] {
            if !(g.is_finite() && g >= 0.0) {
                return Err(Error::Argument {
                    name: name.into(),
                    reason: format!("Baumgarte gain {name} = {g}: must be finite and >= 0"),
                });
            }
        }
        Ok(())
    }
    /// Whether the contact has a nonzero Baumgarte gain.
    pub fn has_baumgarte(&self) -> bool {
        self.kp != 0.0 || self.kd != 0.0
    }
    /// The joint whose body carries the contact, and the point in that joint's frame.
    ///
    /// # Panics
    /// If [`Contact::frame`] is not a frame index of `model` (a contact made for another model;
    /// [`crate::deriv::ContactData::new`] checks it and returns an error instead).
    pub fn body_point(&self, model: &Model) -> (usize, Vector3<f64>) {
        let f = &model.frames[self.frame];
        (f.joint, f.placement.act_point(&self.point))
    }
}
