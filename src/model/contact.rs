//! Point contacts: a point fixed in a frame (a URDF link, possibly merged by a fixed joint).
//! The contact Jacobian stacks, per contact `c`, the world-aligned linear velocity of the point
//! (rows `3c..3c+3`); `λ` stacks the world-frame contact forces applied to the robot.

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
}

impl Contact {
    /// A contact at `point` (frame coordinates) of the frame named `frame`.
    pub fn new(model: &Model, frame: &str, point: Vector3<f64>) -> Result<Contact> {
        let id = model.frame_id(frame)?;
        if let Some(index) = point.iter().position(|x| !x.is_finite()) {
            return Err(Error::NotFinite { what: format!("point of contact \"{frame}\""), index });
        }
        Ok(Contact { frame: id, point })
    }
    /// The joint whose body carries the contact, and the point in that joint's frame.
    pub fn body_point(&self, model: &Model) -> (usize, Vector3<f64>) {
        let f = &model.frames[self.frame];
        (f.joint, f.placement.act_point(&self.point))
    }
}
