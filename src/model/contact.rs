//! Rigid contacts (Pinocchio's `RigidConstraintModel`): a contact frame fixed on a link, of type
//! [`ContactType::D3`] (a point: three translation rows) or [`ContactType::D6`] (the whole frame:
//! six rows `[angular; linear]`), expressed in a [`ContactReference`].
//!
//! Per contact `c`, with `ᵒM_c = (R, p)` the contact frame's world placement (`p` the point),
//! `ω`, `v_p` the angular velocity and the velocity of the body point at `p` (world axes), `α`
//! the angular acceleration, `a_p` the classical acceleration of that point and
//! `a_s = a_p − ω × v_p` its spatial (linear) acceleration, the constraint rows are
//!
//! | type | reference | velocity rows `J_c q̇` | acceleration rows `a_c = J_c q̈ + J̇_c q̇` (KKT) |
//! |---|---|---|---|
//! | `3d` | `local_world_aligned` | `v_p` | `a_p` |
//! | `3d` | `local` | `Rᵀ v_p` | `Rᵀ a_p` (the classical acceleration in contact axes) |
//! | `6d` | `local_world_aligned` | `[ω; v_p]` | `[α; a_s]` |
//! | `6d` | `local` | `Rᵀ[ω; v_p]` | `Rᵀ[α; a_s]` (the spatial acceleration of the frame) |
//!
//! A 6-D contact holds the spatial acceleration of the frame in both references (the
//! world-aligned rows are the local ones rotated by `R`, which is not the time derivative of the
//! world-aligned velocity rows `[ω; v_p]`: that would be `[α; a_p]`); a 3-D contact holds the
//! classical acceleration of the point. Pinocchio 4.1 does the same (checked by the generator
//! of the `contacts6d_*` fixtures).
//!
//! (Pinocchio's `CONTACT_3D` / `CONTACT_6D` in `LOCAL_WORLD_ALIGNED` / `LOCAL`; Pinocchio orders
//! the six rows `[linear; angular]`.) The contact force `λ_c` (3 or 6 rows, the same axes and
//! order) is applied **to the robot** at `p`: `τ + J_cᵀλ` is the joint force it adds.
//!
//! Baumgarte correction (Pinocchio's `corrector`): with gains `kp`, `kd` the KKT dynamics hold
//! `a_c + kd v_c + kp e_c = 0` instead of `a_c = 0`, `v_c = J_c q̇`, `e_c` the error of the contact
//! frame from a reference placement `ᵒM_ref = (R_ref, p_ref)` fixed in the world, taken as the
//! contact frame's placement at the `q` of the call (so `e_c = 0` there, and derivatives hold
//! `ᵒM_ref` fixed): `3d` `local_world_aligned`: `e = p − p_ref`; `3d` `local`: `Rᵀ(p − p_ref)`;
//! `6d` `local`: `e = log6(ᵒM_ref⁻¹ ᵒM_c)`; `6d` `local_world_aligned`: `e = diag(R, R) log6(ᵒM_ref⁻¹ ᵒM_c)`.
//! Impulses and constrained inverse dynamics do not use the gains.
//!
//! # World reference
//!
//! With [`Contact::world_ref`] set ([`Contact::with_reference_point`],
//! [`Contact::with_reference_placement`]) `ᵒM_ref` is that fixed placement instead, as
//! Crocoddyl's `ContactModel3D/6D` `xref` (3-D: only its translation `p_ref`), so `e_c ≠ 0` in
//! general: the KKT drift holds `kp e_c` and the first-order derivatives its exact
//! `q`-derivative (tangent `δ`, `J_ℓ` the local rows `Rᵀ[ω; v_p]` per unit `δ`, `ω_x` the
//! world angular velocity of DoF `x`): `3d` `local_world_aligned`: `J`; `3d` `local`:
//! `J + [e]× Rᵀω_x`; `6d` `local`: `Jlog6(ᵒM_ref⁻¹ ᵒM_c) J_ℓ`; `6d` `local_world_aligned`:
//! `diag(R, R) Jlog6 J_ℓ + [ω_x × e_ang; ω_x × e_lin]`. The second-order algorithms
//! (`kkt_so_derivatives`, `kkt_so_contracted`) refuse a contact with a world reference and
//! `kp ≠ 0`. Two-frame constraints take no world reference.
//!
//! # Two-frame constraints
//!
//! With [`Contact::frame2`] set ([`Contact::with_frame2`]) the constraint joins frame A (the
//! contact frame above, `(R₁, p₁)` on body `a`) to frame B (`(point2, rotation2)` in `frame2`'s
//! coordinates, `(R₂, p₂)` on body `b`): Pinocchio's `RigidConstraintModel(type, model, joint1,
//! placement1, joint2, placement2, reference)`. With `V`, `A` the world spatial velocities and
//! accelerations of the bodies and `R' = R₁ᵀ` (local) or `I` (world-aligned): `3d` rows
//! `R'(v_{p₁} − v_{p₂})` (accelerations `R'(a_{p₁} − a_{p₂})`, classical); `6d` rows the relative
//! motion `V_a − V_b` about `p₁` in frame A's axes (local) or the world's (world-aligned), whose
//! accelerations are `A_a − A_b` (world-aligned) and `¹X_o(A_a − A_b + (V_a − V_b) × V_b)`
//! (local, the time derivative of the velocity rows). `λ` acts on body `a` and `−λ` on body `b`
//! (3-D: forces at `p₁` and `p₂`; 6-D: a wrench at `p₁`), so `τ + J_cᵀλ` holds as for world
//! contacts. Baumgarte: `kd` on every loop; `kp` only on `3d` world-aligned loops, against the
//! actual error `e = p₁ − p₂` (placement 2 enters no other quantity). docs/conventions.md
//! lists the algorithms that take them.

use crate::error::{Error, Result};
use crate::model::Model;
use crate::spatial::Transform;
use nalgebra::{Matrix3, Vector3};

/// What a contact holds: a point (`3d`) or a whole frame (`6d`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ContactType {
    /// A point: three translation rows (Pinocchio's `CONTACT_3D`).
    #[default]
    D3,
    /// A frame: six rows `[angular; linear]` (Pinocchio's `CONTACT_6D`).
    D6,
}

impl ContactType {
    /// Parses `"3d"` or `"6d"`.
    ///
    /// # Errors
    /// [`Error::Argument`] listing the allowed values.
    pub fn parse(name: &str) -> Result<ContactType> {
        match name {
            "3d" | "3D" => Ok(ContactType::D3),
            "6d" | "6D" => Ok(ContactType::D6),
            _ => Err(Error::Argument {
                name: "type".into(),
                reason: format!("unknown contact type \"{name}\": use \"3d\" or \"6d\""),
            }),
        }
    }
    /// `"3d"` or `"6d"`.
    pub fn name(self) -> &'static str {
        match self {
            ContactType::D3 => "3d",
            ContactType::D6 => "6d",
        }
    }
    /// Rows of a contact of this type (3 or 6).
    pub fn dim(self) -> usize {
        match self {
            ContactType::D3 => 3,
            ContactType::D6 => 6,
        }
    }
}

/// The axes of a contact's rows (Pinocchio's `ReferenceFrame` for contacts).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ContactReference {
    /// The contact point, the world's axes (Pinocchio's `LOCAL_WORLD_ALIGNED`; the default).
    #[default]
    LocalWorldAligned,
    /// The contact frame's own origin and axes (Pinocchio's `LOCAL`).
    Local,
}

impl ContactReference {
    /// Parses `"local_world_aligned"` or `"local"`.
    ///
    /// # Errors
    /// [`Error::Argument`] listing the allowed values.
    pub fn parse(name: &str) -> Result<ContactReference> {
        match name {
            "local_world_aligned" => Ok(ContactReference::LocalWorldAligned),
            "local" => Ok(ContactReference::Local),
            _ => Err(Error::Argument {
                name: "reference".into(),
                reason: format!(
                    "unknown contact reference \"{name}\": use \"local_world_aligned\" or \"local\""
                ),
            }),
        }
    }
    /// `"local_world_aligned"` or `"local"`.
    pub fn name(self) -> &'static str {
        match self {
            ContactReference::LocalWorldAligned => "local_world_aligned",
            ContactReference::Local => "local",
        }
    }
}

/// A rigid contact: a contact frame (`rotation`, `point`) given in the coordinates of a model
/// frame, its type, reference and Baumgarte gains (module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Contact {
    /// Frame index in `model.frames()`.
    pub frame: usize,
    /// Origin of the contact frame (the contact point) in the frame's coordinates.
    pub point: Vector3<f64>,
    /// Orientation of the contact frame in the frame's coordinates (identity by default; it
    /// matters for the `local` reference and for `6d` contacts).
    pub rotation: Matrix3<f64>,
    /// `3d` (a point) or `6d` (the whole frame).
    pub kind: ContactType,
    /// Axes of the rows: `local_world_aligned` (default) or `local`.
    pub reference: ContactReference,
    /// Baumgarte position gain `kp ≥ 0` (default 0).
    pub kp: f64,
    /// Baumgarte velocity gain `kd ≥ 0` (default 0).
    pub kd: f64,
    /// Frame B of a two-frame (closed-loop) constraint, an index in `model.frames()`; `None`
    /// (the default) for a contact with the fixed world. (Module documentation, "Two-frame
    /// constraints".)
    pub frame2: Option<usize>,
    /// Origin of the frame-B contact frame in `frame2`'s coordinates (zero by default).
    pub point2: Vector3<f64>,
    /// Orientation of the frame-B contact frame in `frame2`'s coordinates (identity by default;
    /// only the placement error of a `6d` constraint uses it).
    pub rotation2: Matrix3<f64>,
    /// A reference placement fixed in the world for the position gain `kp` (Crocoddyl's
    /// `xref`; `None`, the default: the contact frame's placement at the `q` of each call, so
    /// the position error is zero there). A `3d` contact uses only its translation (the point
    /// `xref`). Module documentation, "World reference".
    pub world_ref: Option<Transform>,
}

impl Contact {
    /// A 3-D point contact at `point` (frame coordinates) of the frame named `frame`, in the
    /// `local_world_aligned` reference.
    ///
    /// # Errors
    /// [`Error::Unknown`] for an unknown frame, [`Error::NotFinite`] for a non-finite point.
    pub fn new(model: &Model, frame: &str, point: Vector3<f64>) -> Result<Contact> {
        let id = model.frame_id(frame)?;
        if let Some(index) = point.iter().position(|x| !x.is_finite()) {
            return Err(Error::NotFinite { what: format!("point of contact \"{frame}\""), index });
        }
        Ok(Contact {
            frame: id,
            point,
            rotation: Matrix3::identity(),
            kind: ContactType::D3,
            reference: ContactReference::LocalWorldAligned,
            kp: 0.0,
            kd: 0.0,
            frame2: None,
            point2: Vector3::zeros(),
            rotation2: Matrix3::identity(),
            world_ref: None,
        })
    }
    /// A 6-D contact holding the frame named `frame` at `placement` (in the frame's coordinates;
    /// `None`: the frame itself), in the `local_world_aligned` reference.
    ///
    /// # Errors
    /// [`Error::Unknown`] for an unknown frame, [`Error::NotFinite`] for a non-finite placement.
    pub fn new_6d(model: &Model, frame: &str, placement: Option<&Transform>) -> Result<Contact> {
        let c = Contact::new(model, frame, Vector3::zeros())?;
        let c = Contact { kind: ContactType::D6, ..c };
        match placement {
            Some(p) => c.with_placement(model, p),
            None => Ok(c),
        }
    }
    /// The same contact with the contact frame at `placement` in the model frame's coordinates.
    ///
    /// # Errors
    /// [`Error::NotFinite`] for a non-finite entry; [`Error::Argument`] for a rotation block
    /// that is not a rotation (`RᵀR ≠ I` or `det R ≠ 1` beyond `1e-9`).
    pub fn with_placement(mut self, model: &Model, placement: &Transform) -> Result<Contact> {
        let name = &model.frames[self.frame.min(model.frames.len().saturating_sub(1))].name;
        check_placement(placement, &format!("placement of contact \"{name}\""))?;
        self.point = placement.trans;
        self.rotation = placement.rot;
        Ok(self)
    }
    /// The same constraint closed on frame B, the frame named `frame2` of the robot, with the
    /// frame-B contact frame at `placement2` in `frame2`'s coordinates (`None`: the frame
    /// itself; a `3d` constraint uses only its translation, `point2`). The constraint then
    /// joins the two contact frames instead of holding frame A in the world (module
    /// documentation, "Two-frame constraints").
    ///
    /// # Errors
    /// [`Error::Unknown`] for an unknown frame; [`Error::NotFinite`] or [`Error::Argument`] for
    /// a bad placement (as [`Contact::with_placement`]); [`Error::Argument`] if both frames are
    /// on the same body (bodies merged by fixed joints are one body), or frame A is on the
    /// world.
    pub fn with_frame2(
        mut self,
        model: &Model,
        frame2: &str,
        placement2: Option<&Transform>,
    ) -> Result<Contact> {
        let id = model.frame_id(frame2)?;
        if let Some(p) = placement2 {
            check_placement(p, &format!("placement2 of contact \"{frame2}\""))?;
            self.point2 = p.trans;
            self.rotation2 = p.rot;
        }
        self.frame2 = Some(id);
        if self.world_ref.is_some() {
            return Err(Error::Argument {
                name: "frame2".into(),
                reason: "a contact with a world reference (xref) cannot be a two-frame constraint"
                    .into(),
            });
        }
        if let Some(reason) = self.loop_problem(model) {
            return Err(Error::Argument { name: "frame2".into(), reason });
        }
        Ok(self)
    }
    /// Whether this is a two-frame (closed-loop) constraint.
    pub fn is_loop(&self) -> bool {
        self.frame2.is_some()
    }
    /// What is wrong with this two-frame constraint on `model`, `None` if nothing is (or if it
    /// is a world contact); an index out of the model's frames is a problem too.
    pub(crate) fn loop_problem(&self, model: &Model) -> Option<String> {
        let f2 = self.frame2?;
        let n = model.frames.len();
        let (Some(fa), Some(fb)) = (model.frames.get(self.frame), model.frames.get(f2)) else {
            return Some(format!(
                "frame index {} or frame2 index {f2} is out of range (the model has {n} frames)",
                self.frame
            ));
        };
        if fa.joint == fb.joint {
            return Some(format!(
                "frames \"{}\" and \"{}\" are on the same body \"{}\": the constraint \
                 between them constrains nothing",
                fa.name,
                fb.name,
                model.names.get(fa.joint).map_or("?", |s| s.as_str())
            ));
        }
        if fa.joint == 0 {
            return Some(format!(
                "frame \"{}\" (frame A) is on the fixed world: give the world frame as frame2 \
                 instead",
                fa.name
            ));
        }
        None
    }
    /// The joint whose body carries frame B (0: the world) and the frame-B contact frame's
    /// placement in that joint's frame.
    ///
    /// # Panics
    /// If [`Contact::frame2`] is `None` or not a frame index of `model`.
    pub fn body_placement2(&self, model: &Model) -> (usize, Transform) {
        let f = &model.frames[self.frame2.expect("a two-frame constraint")];
        (f.joint, f.placement.compose(&Transform::new(self.rotation2, self.point2)))
    }
    /// The same `3d` contact with the position gain acting against the point `xref` fixed in
    /// the world (Crocoddyl's `ContactModel3D` `xref`; module documentation, "World
    /// reference").
    ///
    /// # Errors
    /// [`Error::NotFinite`] for a non-finite point; [`Error::Argument`] for a `6d` contact (use
    /// [`Contact::with_reference_placement`]) or a two-frame constraint.
    pub fn with_reference_point(mut self, model: &Model, xref: Vector3<f64>) -> Result<Contact> {
        let name = &model.frames[self.frame.min(model.frames.len().saturating_sub(1))].name;
        if let Some(index) = xref.iter().position(|x| !x.is_finite()) {
            return Err(Error::NotFinite { what: format!("xref of contact \"{name}\""), index });
        }
        if self.kind != ContactType::D3 {
            return Err(Error::Argument {
                name: format!("xref of contact \"{name}\""),
                reason: "a 6d contact takes a reference placement \
                         (Contact::with_reference_placement), not a point"
                    .into(),
            });
        }
        self.world_ref = Some(Transform::new(Matrix3::identity(), xref));
        self.check_world_ref(name)?;
        Ok(self)
    }
    /// The same `6d` contact with the position gain acting against the placement `xref` fixed
    /// in the world (Crocoddyl's `ContactModel6D` `xref`; module documentation, "World
    /// reference").
    ///
    /// # Errors
    /// [`Error::NotFinite`] or [`Error::Argument`] for a bad placement (as
    /// [`Contact::with_placement`]); [`Error::Argument`] for a `3d` contact (use
    /// [`Contact::with_reference_point`]) or a two-frame constraint.
    pub fn with_reference_placement(mut self, model: &Model, xref: &Transform) -> Result<Contact> {
        let name = &model.frames[self.frame.min(model.frames.len().saturating_sub(1))].name;
        check_placement(xref, &format!("xref of contact \"{name}\""))?;
        if self.kind != ContactType::D6 {
            return Err(Error::Argument {
                name: format!("xref of contact \"{name}\""),
                reason: "a 3d contact takes a reference point (Contact::with_reference_point), \
                         not a placement"
                    .into(),
            });
        }
        self.world_ref = Some(*xref);
        self.check_world_ref(name)?;
        Ok(self)
    }
    /// A world reference on a two-frame constraint is an error.
    fn check_world_ref(&self, name: &str) -> Result<()> {
        if self.world_ref.is_some() && self.is_loop() {
            return Err(Error::Argument {
                name: format!("xref of contact \"{name}\""),
                reason: "a two-frame constraint takes no world reference".into(),
            });
        }
        Ok(())
    }
    /// The same contact with rows in `reference`.
    pub fn with_reference(mut self, reference: ContactReference) -> Contact {
        self.reference = reference;
        self
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
    /// Number of constraint rows: 3 or 6.
    pub fn dim(&self) -> usize {
        self.kind.dim()
    }
    /// Whether this is a 3-D contact in the `local_world_aligned` reference (a world-aligned
    /// point: the specialised code paths of the contact algorithms).
    pub fn is_point_lwa(&self) -> bool {
        self.kind == ContactType::D3 && self.reference == ContactReference::LocalWorldAligned
    }
    /// The contact frame's placement in the model frame's coordinates.
    pub fn placement(&self) -> Transform {
        Transform::new(self.rotation, self.point)
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
    /// The joint whose body carries the contact, and the contact frame's placement in that
    /// joint's frame.
    ///
    /// # Panics
    /// As [`Contact::body_point`].
    pub fn body_placement(&self, model: &Model) -> (usize, Transform) {
        let f = &model.frames[self.frame];
        (f.joint, f.placement.compose(&self.placement()))
    }
}

/// Checks that `placement` is finite and its rotation block a rotation (`what` names it).
fn check_placement(placement: &Transform, what: &str) -> Result<()> {
    let what = what.to_string();
    if let Some(index) = placement.trans.iter().position(|x| !x.is_finite()) {
        return Err(Error::NotFinite { what, index });
    }
    if let Some(index) = placement.rot.iter().position(|x| !x.is_finite()) {
        return Err(Error::NotFinite { what, index: 3 + index });
    }
    let r = &placement.rot;
    if (r.transpose() * r - Matrix3::identity()).amax() > 1e-9
        || (r.determinant() - 1.0).abs() > 1e-9
    {
        return Err(Error::Argument {
            name: what,
            reason: "the rotation block is not a rotation matrix".into(),
        });
    }
    Ok(())
}

/// A description of contact `i` for messages: `contacts[i] ("frame", 6d)`.
pub(crate) fn contact_label(model: &Model, contacts: &[Contact], i: usize) -> String {
    let c = &contacts[i];
    let name = model.frames.get(c.frame).map_or("?", |f| f.name.as_str());
    match c.frame2 {
        Some(f2) => {
            let name2 = model.frames.get(f2).map_or("?", |f| f.name.as_str());
            format!("contacts[{i}] (\"{name}\" to \"{name2}\", {})", c.kind.name())
        }
        None => format!("contacts[{i}] (\"{name}\", {})", c.kind.name()),
    }
}

/// A structurally redundant contact set: a body held by a 6-D contact that carries another
/// contact (two 6-D contacts on one body, or a 3-D contact on a 6-D-held body). Returns the
/// message naming the first such pair, `None` for a set without such a pair. (Bodies merged by
/// fixed joints are one body.)
pub(crate) fn redundancy(model: &Model, contacts: &[Contact]) -> Option<String> {
    let body = |c: &Contact| model.frames[c.frame].joint;
    for (i, ci) in contacts.iter().enumerate() {
        if ci.kind != ContactType::D6 || ci.is_loop() {
            continue;
        }
        for (j, cj) in contacts.iter().enumerate() {
            if j != i && !cj.is_loop() && body(cj) == body(ci) {
                let (a, b) = (i.min(j), i.max(j));
                return Some(format!(
                    "{} and {} are on the same body \"{}\", which the 6-D contact already holds: \
                     the set is redundant",
                    contact_label(model, contacts, a),
                    contact_label(model, contacts, b),
                    model.names.get(body(ci)).map_or("?", |s| s.as_str())
                ));
            }
        }
    }
    None
}
