//! URDF loading.
//!
//! Conventions (shared with Pinocchio except where noted):
//!
//! * Joints are numbered depth-first from the root link, the child joints of each link in
//!   **document order** (Pinocchio, through urdfdom, visits siblings in alphabetical order of
//!   their joint names instead; the tree and every parent relation are the same).
//! * `fixed` joints are merged: the child link's inertia is lumped into the parent body (with the
//!   composed placement) and the child link stays addressable as a [`Frame`](super::Frame).
//! * Every link becomes a frame named after it; a link moved by a joint sits at that joint's child
//!   frame (identity placement).
//! * `continuous` → [`JointType::Continuous`] (nq = 1), `revolute` → [`JointType::Revolute`]
//!   (limits from `<limit lower upper>`), `prismatic` → [`JointType::Prismatic`], `floating` →
//!   [`JointType::FreeFlyer`], `planar` → [`JointType::Planar`] when its normal axis is `z` (or
//!   absent); anything else is an error.
//! * Limits. A revolute or prismatic joint's `<limit lower upper>` (each 0 when absent, as in
//!   urdfdom) become [`Model::lower`] and [`Model::upper`]; a joint without `<limit>` has
//!   `−∞`/`+∞`. **Reversed limits** (`lower > upper`) mean "not limited" (Bullet's reading,
//!   which simulator exports use on purpose): the joint loads with `−∞`/`+∞`, and a warning in
//!   [`Model::warnings`] names the file, the `<limit>`'s line and the joint. `lower == upper`
//!   (a zero-width range, e.g. `<limit effort=".." velocity=".."/>` without `lower` and
//!   `upper`) is kept as given, silently: no algorithm enforces limits, and
//!   [`Model::random_configuration`] (like `sodyn bench`'s states) samples such a joint as an
//!   unlimited one (revolute in `[−π, π]`, prismatic in `[−1, 1]`), as it does for reversed or
//!   absent limits. Limits are read from nothing else (continuous, floating and planar joints
//!   have none).
//! * Before the root element, the text may hold a UTF-8 byte-order mark, whitespace and blank
//!   lines, and an XML declaration `<?xml ...?>` after them (urdfdom and ROS tools accept that;
//!   so does the MJCF loader). Anything else before a declaration, such as a comment, is an
//!   error naming its line.
//! * With [`UrdfOptions::floating_base`], a free-flyer joint named `"root_joint"` is added in
//!   front of the root link; otherwise the root link is welded to the world (joint 0) and its
//!   inertia is stored in joint 0's slot, which the dynamics ignores.
//! * A link's `<inertial>` must have a finite, non-negative mass. Its rotational inertia about
//!   the centre of mass, principal moments `λ₁ ≤ λ₂ ≤ λ₃`, is read as follows:
//!   - **Round-off.** A principal moment that is negative by at most
//!     `max(INERTIA_ROUNDOFF_REL · λ₃, INERTIA_ROUNDOFF_ABS)` ([`INERTIA_ROUNDOFF_REL`] = `1e-12`
//!     of the largest moment, or [`INERTIA_ROUNDOFF_ABS`] = `1e-15` kg m²: CAD exports write
//!     `ixx="-5.42101e-20"` for zero) is taken as zero, the inertia being rebuilt from its
//!     principal axes. Silent, also with [`UrdfOptions::strict_inertia`].
//!   - The result must then be physical: positive semi-definite, and the triangle inequality
//!     `λ₁ + λ₂ ≥ λ₃`, both within round-off (the larger of `1e-9 max|λ|`, `1e-12` of the
//!     largest entry of the inertia about the frame origin, and `INERTIA_ROUNDOFF_ABS`). A link
//!     that is not is accepted silently when the body it is merged into by fixed joints is
//!     physical: real URDFs (hyq, anymal, tiago) put placeholder inertials (mass 1e-6 kg,
//!     every entry 1e-6 kg m²) on dummy links, and those only ever reach the dynamics summed
//!     into a heavier body.
//!   - Otherwise the body is not physical either. A body that is positive semi-definite but
//!     violates the triangle inequality (not a rigid body, but its contribution to the mass
//!     matrix is positive semi-definite; Pinocchio loads it) loads with a warning in
//!     [`Model::warnings`] naming the file, line and link (an error with
//!     [`UrdfOptions::strict_inertia`]). A body that is not positive semi-definite is an error
//!     (Pinocchio loads it, but its mass matrix may be indefinite).
//! * `<mimic>` joints are loaded as independent joints and recorded with
//!   [`ModelBuilder::set_mimic`] ([`Model::mimic`]). Without [`UrdfOptions::mimic`], a
//!   `<mimic>` naming an unknown joint (or the joint itself) is a warning, not an error: the
//!   joint loads as independent all the same, and nothing is recorded.
//! * With [`UrdfOptions::mimic`], each `<mimic joint multiplier offset>` (defaults 1 and 0) is
//!   checked and recorded as a constraint `q = multiplier · q_ref + offset` in
//!   [`Model::mimic_joints`]: the reference must be another joint of the file, not itself a
//!   mimic joint, and both must be one-DoF joints of one kind (`revolute`/`continuous`, or
//!   `prismatic`); anything else is an error naming the file, line and joint. The returned
//!   [`Model`] is then in reduced coordinates ([`Model::is_reduced`]): the mimic joints have no
//!   degrees of freedom, [`Model::nq`] and [`Model::nv`] count the independent coordinates,
//!   [`Model::full_tree`] is the tree with every joint independent, and every algorithm takes
//!   the model with its usual workspaces.
//! * Nothing is printed: warnings are returned in [`Model::warnings`] (the command-line tool
//!   prints them on standard error).
//! * `<visual>`, `<collision>`, `<transmission>`, `<gazebo>`, `<material>` and every other unknown
//!   element are ignored; `<link>` and `<joint>` are read only as direct children of `<robot>`.
//!
//! * At most [`MAX_URDF_DOFS`] degrees of freedom (free-flyer root included): the model and its
//!   workspaces take `O(nv²)` memory, so without a limit a file of a few hundred kilobytes (a
//!   chain of `floating` joints) could ask for gigabytes. Larger trees can be made with
//!   [`ModelBuilder`].
//!
//! Every failure is an [`Error::Model`] naming the file, the 1-based line, the element (e.g.
//! `joint "knee"`) and the reason.

use super::joint::JointType;
use super::reduction::JointCoupling;
use super::tree::{Model, ModelBuilder, inertia_defect};
use crate::error::{Error, Result};
use crate::spatial::InertiaDefect;
use crate::spatial::{Inertia, Transform};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::Path;

/// Options of the URDF loader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UrdfOptions {
    /// Add a free-flyer joint named `"root_joint"` between the world and the root link
    /// (Pinocchio's `buildModelFromUrdf(path, JointModelFreeFlyer())`).
    pub floating_base: bool,
    /// Refuse a body inertia that violates the triangle inequality (see the module
    /// documentation): an error instead of a warning in [`Model::warnings`]. Moments negative
    /// by round-off are set to zero either way.
    pub strict_inertia: bool,
    /// Read `<mimic joint multiplier offset>` as a constraint `q = multiplier · q_ref + offset`
    /// (see the module documentation): every `<mimic>` is checked (an error otherwise) and
    /// recorded in [`Model::mimic_joints`]. The [`Model`] returned is in reduced coordinates
    /// (see [`Model::full_tree`]) when the file has a `<mimic>`: the mimic joints follow their
    /// references and have no degrees of freedom.
    pub mimic: bool,
}

/// Relative round-off tolerance of the URDF loader: a principal moment of a link's rotational
/// inertia that is negative by at most this fraction of the largest principal moment (or by
/// at most [`INERTIA_ROUNDOFF_ABS`]) is taken as zero.
pub const INERTIA_ROUNDOFF_REL: f64 = 1e-12;

pub use super::tree::INERTIA_ROUNDOFF_ABS;

/// `i_com` with its principal moments that are negative by round-off (see
/// [`INERTIA_ROUNDOFF_REL`], [`INERTIA_ROUNDOFF_ABS`]) set to zero, rebuilt from its principal
/// axes; `i_com` itself, bit for bit, when it has no such moment.
fn clear_roundoff(i_com: Matrix3<f64>) -> Matrix3<f64> {
    if !i_com.iter().all(|x| x.is_finite()) {
        return i_com;
    }
    let mut eig = SymmetricEigen::new(i_com);
    let tol = (INERTIA_ROUNDOFF_REL * eig.eigenvalues.max()).max(INERTIA_ROUNDOFF_ABS);
    let roundoff = |l: f64| l < 0.0 && l >= -tol;
    if !eig.eigenvalues.iter().any(|&l| roundoff(l)) {
        return i_com;
    }
    eig.eigenvalues.apply(|l| {
        if roundoff(*l) {
            *l = 0.0;
        }
    });
    let r = eig.recompose();
    (r + r.transpose()) * 0.5
}

/// Name of the free-flyer joint added by [`UrdfOptions::floating_base`] (Pinocchio's name).
pub const ROOT_JOINT_NAME: &str = "root_joint";

/// The largest number of degrees of freedom (`nv`, the root free-flyer's 6 included) that the
/// URDF loader accepts; a file with more is an [`Error::Model`] naming the joint that passes the
/// limit. The model's DoF-ancestor lists and every workspace ([`Data`](crate::algo::Data)) take
/// `O(nv²)` memory (a chain of `floating` joints costs 15 to 20 bytes of URDF per DoF), so the
/// limit bounds what a file can make the loader and the algorithms allocate: about 90 MB for
/// `Data` at the limit. Real robots have at most a few hundred DoFs (Talos: 50).
pub const MAX_URDF_DOFS: usize = 1024;

/// Loads a URDF file. Errors name the file (as given), line, element and reason; what loads
/// with a reservation (see the module documentation) is listed in [`Model::warnings`].
pub fn load_urdf_file(path: &Path, opts: &UrdfOptions) -> Result<Model> {
    let file = path.display().to_string();
    let xml = std::fs::read_to_string(path).map_err(|e| Error::Model {
        file: file.clone(),
        line: None,
        element: "file".into(),
        reason: format!("cannot read the file: {e}"),
    })?;
    load_urdf_str(&xml, &file, opts)
}

/// Loads a URDF from a string; `source_name` is used as the file name in error messages.
pub fn load_urdf_str(xml: &str, source_name: &str, opts: &UrdfOptions) -> Result<Model> {
    let text = XmlText::new(xml);
    let doc = text.parse(source_name)?;
    let p = Parser { doc: &doc, file: source_name, warnings: Default::default() };
    p.load(opts)
}

/// An XML text ready for `roxmltree`, which accepts an XML declaration only at the very start
/// (after a byte-order mark): when the declaration follows whitespace or blank lines (accepted
/// by urdfdom's tinyxml2 and by ROS tools), the declaration is moved in front of that
/// whitespace. Every byte after the declaration keeps its offset, so the lines of nodes and of
/// errors are those of the file; an error inside the declaration is reported at its own line.
/// Anything but whitespace before a declaration is left to `roxmltree`'s error (e.g.
/// `unexpected XML declaration at 3:1`). Shared by the URDF and MJCF loaders.
pub(crate) struct XmlText<'a> {
    text: std::borrow::Cow<'a, str>,
    /// Lines of the moved declaration (`1 +` its line breaks), 0 if nothing moved.
    decl_lines: u32,
    /// Line breaks in the whitespace in front of the moved declaration.
    shift: u32,
}

impl<'a> XmlText<'a> {
    pub(crate) fn new(xml: &'a str) -> Self {
        let unmoved = XmlText { text: xml.into(), decl_lines: 0, shift: 0 };
        let body = xml.strip_prefix('\u{FEFF}').unwrap_or(xml);
        let bom = &xml[..xml.len() - body.len()];
        let is_space = |c: char| matches!(c, ' ' | '\t' | '\r' | '\n');
        let rest = body.trim_start_matches(is_space);
        let ws = &body[..body.len() - rest.len()];
        let is_decl = rest.strip_prefix("<?xml").is_some_and(|r| r.starts_with(is_space));
        if ws.is_empty() || !is_decl {
            return unmoved;
        }
        let Some(end) = rest.find("?>") else {
            return unmoved; // roxmltree reports the unterminated declaration
        };
        let (decl, after) = rest.split_at(end + 2);
        let count = |s: &str| u32::try_from(s.matches('\n').count()).unwrap_or(u32::MAX);
        XmlText {
            text: format!("{bom}{decl}{ws}{after}").into(),
            decl_lines: 1 + count(decl),
            shift: count(ws),
        }
    }

    /// The text to parse (and to take positions in).
    pub(crate) fn text(&self) -> &str {
        &self.text
    }

    /// Parses the text; a malformed one is an [`Error::Model`] naming `file` and the line.
    pub(crate) fn parse(&self, file: &str) -> Result<Document<'_>> {
        Document::parse(&self.text).map_err(|e| {
            let (row, mut reason) = (e.pos().row, format!("malformed XML: {e}"));
            let line = if row <= self.decl_lines { row + self.shift } else { row };
            if line != row {
                reason = reason.replacen(&format!(" at {row}:"), &format!(" at {line}:"), 1);
            }
            Error::Model { file: file.into(), line: Some(line), element: "XML".into(), reason }
        })
    }
}

/// A parsed `<link>`.
struct Link<'a, 'i> {
    name: String,
    node: Node<'a, 'i>,
    /// Inertia expressed in the link frame (zero without `<inertial>`).
    inertia: Inertia,
    /// A rotational inertia that is not positive semi-definite or violates the triangle
    /// inequality: position of its `<inertia>` element and the description.
    defect: Option<(usize, String)>,
}

/// What a joint becomes.
#[derive(Clone, Copy, Debug)]
enum Kind {
    Fixed,
    Movable(JointType),
}

/// A parsed `<joint>`.
struct Joint<'a, 'i> {
    name: String,
    node: Node<'a, 'i>,
    kind: Kind,
    origin: Transform,
    parent: usize,
    child: usize,
    /// `(lower, upper)` for revolute/prismatic joints with a `<limit>`.
    limits: Option<(f64, f64)>,
    /// Mimicked joint name and the position of the `<mimic>` element.
    mimic: Option<(String, usize)>,
    /// `<mimic>`'s `multiplier` and `offset` (defaults 1 and 0), read with
    /// [`UrdfOptions::mimic`] only.
    mimic_coeffs: (f64, f64),
}

struct Parser<'d, 'a, 'i> {
    doc: &'d Document<'i>,
    file: &'a str,
    /// Warnings so far, in the format of [`Error::Model`]'s message.
    warnings: std::cell::RefCell<Vec<String>>,
}

fn child_elem<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.is_element() && c.tag_name().name() == tag)
}

fn attr_node<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<roxmltree::Attribute<'a, 'i>> {
    node.attributes().find(|a| a.name() == name)
}

impl<'d, 'a, 'i> Parser<'d, 'a, 'i> {
    /// An [`Error::Model`] at byte position `pos`.
    fn err(&self, pos: usize, element: &str, reason: impl Into<String>) -> Error {
        Error::Model {
            file: self.file.into(),
            line: Some(self.doc.text_pos_at(pos).row),
            element: element.into(),
            reason: reason.into(),
        }
    }

    /// Records a warning at byte position `pos` (`FILE:LINE: ELEMENT: REASON`).
    fn warn(&self, pos: usize, element: &str, reason: impl std::fmt::Display) {
        let line = self.line(pos);
        self.warnings.borrow_mut().push(format!("{}:{line}: {element}: {reason}", self.file));
    }

    fn line(&self, pos: usize) -> u32 {
        self.doc.text_pos_at(pos).row
    }

    /// Converts a builder error into a located model error.
    fn wrap(&self, pos: usize, element: &str) -> impl Fn(Error) -> Error + '_ {
        let element = element.to_string();
        move |e| match e {
            Error::Build(s) => self.err(pos, &element, s),
            other => other,
        }
    }

    /// `n` whitespace-separated finite numbers from attribute `name` of `node`, or `None` if the
    /// attribute is absent.
    fn numbers(&self, node: Node, name: &str, n: usize, element: &str) -> Result<Option<Vec<f64>>> {
        let Some(a) = attr_node(node, name) else {
            return Ok(None);
        };
        let tag = node.tag_name().name();
        let pos = a.range().start;
        let text = a.value();
        let mut out = Vec::with_capacity(n);
        for tok in text.split_whitespace() {
            let x: f64 = tok.parse().map_err(|_| {
                self.err(
                    pos,
                    element,
                    format!("<{tag}> attribute {name}=\"{text}\": \"{tok}\" is not a number"),
                )
            })?;
            if !x.is_finite() {
                return Err(self.err(
                    pos,
                    element,
                    format!("<{tag}> attribute {name}=\"{text}\": \"{tok}\" is not finite"),
                ));
            }
            out.push(x);
        }
        if out.len() != n {
            let what = if n == 1 { "1 number".to_string() } else { format!("{n} numbers") };
            return Err(self.err(
                pos,
                element,
                format!(
                    "<{tag}> attribute {name}=\"{text}\": expected {what}, found {}",
                    out.len()
                ),
            ));
        }
        Ok(Some(out))
    }

    /// A required scalar attribute.
    fn scalar(&self, node: Node, name: &str, element: &str) -> Result<f64> {
        match self.numbers(node, name, 1, element)? {
            Some(v) => Ok(v[0]),
            None => Err(self.err(
                node.range().start,
                element,
                format!("<{}> has no {name} attribute", node.tag_name().name()),
            )),
        }
    }

    /// An optional scalar attribute with a default.
    fn scalar_or(&self, node: Node, name: &str, default: f64, element: &str) -> Result<f64> {
        Ok(self.numbers(node, name, 1, element)?.map_or(default, |v| v[0]))
    }

    /// A 3-vector attribute, `None` if absent.
    fn vec3(&self, node: Node, name: &str, element: &str) -> Result<Option<Vector3<f64>>> {
        Ok(self.numbers(node, name, 3, element)?.map(|v| Vector3::new(v[0], v[1], v[2])))
    }

    /// The `<origin xyz rpy>` child of `node` (identity if absent).
    fn origin(&self, node: Node, element: &str) -> Result<Transform> {
        let Some(o) = child_elem(node, "origin") else {
            return Ok(Transform::identity());
        };
        let xyz = self.vec3(o, "xyz", element)?.unwrap_or_else(Vector3::zeros);
        let rpy = self.vec3(o, "rpy", element)?.unwrap_or_else(Vector3::zeros);
        Ok(Transform::from_rpy_xyz([rpy.x, rpy.y, rpy.z], [xyz.x, xyz.y, xyz.z]))
    }

    /// The required `name` attribute of a `<link>`/`<joint>`/`<robot>`.
    fn name(&self, node: Node) -> Result<String> {
        let tag = node.tag_name().name();
        match node.attribute("name") {
            Some(n) if !n.is_empty() => Ok(n.to_string()),
            Some(_) => {
                Err(self.err(node.range().start, &format!("<{tag}>"), "empty name attribute"))
            }
            None => {
                Err(self.err(node.range().start, &format!("<{tag}>"), "missing name attribute"))
            }
        }
    }

    /// Inertia of a link in the link frame from its `<inertial>` (zero if absent), and the
    /// rotational-inertia defect if any (decided later, against the merged body).
    fn inertial(&self, link: Node, element: &str) -> Result<(Inertia, Option<(usize, String)>)> {
        let Some(inl) = child_elem(link, "inertial") else {
            return Ok((Inertia::zero(), None));
        };
        let origin = self.origin(inl, element)?;
        let Some(mass_node) = child_elem(inl, "mass") else {
            return Err(self.err(inl.range().start, element, "<inertial> has no <mass>"));
        };
        let mass = self.scalar(mass_node, "value", element)?;
        if mass < 0.0 {
            let pos =
                attr_node(mass_node, "value").map_or(mass_node.range().start, |a| a.range().start);
            return Err(self.err(pos, element, format!("negative mass {mass}")));
        }
        let Some(inn) = child_elem(inl, "inertia") else {
            return Err(self.err(inl.range().start, element, "<inertial> has no <inertia>"));
        };
        let mut c = [0.0; 6];
        for (k, name) in ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"].iter().enumerate() {
            c[k] = self.scalar(inn, name, element)?;
        }
        let [ixx, ixy, ixz, iyy, iyz, izz] = c;
        let i_com = clear_roundoff(Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz));
        let defect = inertia_defect(&Inertia::from_com(mass, Vector3::zeros(), i_com)).map(|d| {
            (
                inn.range().start,
                format!("invalid inertial (ixx={ixx} ixy={ixy} ixz={ixz} iyy={iyy} iyz={iyz} izz={izz}): {d}"),
            )
        });
        let r = origin.rot;
        Ok((Inertia::from_com(mass, origin.trans, r * i_com * r.transpose()), defect))
    }

    /// Joint type (with normalised axis) of a `<joint>`.
    fn joint_kind(&self, node: Node, element: &str) -> Result<Kind> {
        let Some(ty) = node.attribute("type") else {
            return Err(self.err(node.range().start, element, "missing type attribute"));
        };
        let type_pos = attr_node(node, "type").map_or(node.range().start, |a| a.range().start);
        let axis_node = child_elem(node, "axis");
        let axis_raw = match axis_node {
            Some(a) => self.vec3(a, "xyz", element)?,
            None => None,
        };
        let unit_axis = || -> Result<Vector3<f64>> {
            let a = axis_raw.unwrap_or_else(Vector3::x);
            let n = a.norm();
            if !n.is_finite() || n <= 1e-12 {
                let pos = axis_node.map_or(node.range().start, |x| x.range().start);
                let what = if n.is_finite() { "zero" } else { "a non-finite" };
                return Err(self.err(
                    pos,
                    element,
                    format!("axis [{} {} {}] has {what} length", a.x, a.y, a.z),
                ));
            }
            Ok(a / n)
        };
        Ok(match ty {
            "fixed" => Kind::Fixed,
            "revolute" => Kind::Movable(JointType::Revolute { axis: unit_axis()? }),
            "continuous" => Kind::Movable(JointType::Continuous { axis: unit_axis()? }),
            "prismatic" => Kind::Movable(JointType::Prismatic { axis: unit_axis()? }),
            "floating" => Kind::Movable(JointType::FreeFlyer),
            "planar" => {
                if axis_raw.is_some() {
                    let a = unit_axis()?;
                    if (a - Vector3::z()).norm() > 1e-9 {
                        return Err(self.err(
                            axis_node.map_or(type_pos, |x| x.range().start),
                            element,
                            format!(
                                "unsupported joint type \"planar\" with normal axis [{} {} {}]: only \
                                 planar joints normal to z (axis \"0 0 1\" or no <axis>) are supported",
                                a.x, a.y, a.z
                            ),
                        ));
                    }
                }
                Kind::Movable(JointType::Planar)
            }
            other => {
                return Err(self.err(
                    type_pos,
                    element,
                    format!(
                        "unknown or unsupported joint type \"{other}\" (expected fixed, revolute, \
                         continuous, prismatic, floating or planar)"
                    ),
                ));
            }
        })
    }

    fn load(&self, opts: &UrdfOptions) -> Result<Model> {
        let robot = self.doc.root_element();
        let tag = robot.tag_name().name();
        if tag != "robot" {
            return Err(self.err(
                robot.range().start,
                &format!("<{tag}>"),
                format!("the root element is <{tag}>, expected <robot>"),
            ));
        }
        let robot_name = self.name(robot)?;
        let robot_elem = format!("robot \"{robot_name}\"");

        // Links.
        let mut links: Vec<Link> = Vec::new();
        let mut link_index: HashMap<String, usize> = HashMap::new();
        for node in robot.children().filter(|c| c.is_element() && c.tag_name().name() == "link") {
            let name = self.name(node)?;
            let element = format!("link \"{name}\"");
            if let Some(&prev) = link_index.get(&name) {
                return Err(self.err(
                    node.range().start,
                    &element,
                    format!(
                        "duplicate link name (first defined at line {})",
                        self.line(links[prev].node.range().start)
                    ),
                ));
            }
            if name == "universe" {
                return Err(self.err(
                    node.range().start,
                    &element,
                    "the link name \"universe\" is reserved for the world frame",
                ));
            }
            let (inertia, defect) = self.inertial(node, &element)?;
            link_index.insert(name.clone(), links.len());
            links.push(Link { name, node, inertia, defect });
        }
        if links.is_empty() {
            return Err(self.err(robot.range().start, &robot_elem, "no <link> elements"));
        }

        // Joints.
        let mut joints: Vec<Joint> = Vec::new();
        let mut joint_index: HashMap<String, usize> = HashMap::new();
        // Degrees of freedom so far, checked against MAX_URDF_DOFS joint by joint.
        let mut nv = if opts.floating_base { JointType::FreeFlyer.nv() } else { 0 };
        for node in robot.children().filter(|c| c.is_element() && c.tag_name().name() == "joint") {
            let name = self.name(node)?;
            let element = format!("joint \"{name}\"");
            let pos = node.range().start;
            if let Some(&prev) = joint_index.get(&name) {
                return Err(self.err(
                    pos,
                    &element,
                    format!(
                        "duplicate joint name (first defined at line {})",
                        self.line(joints[prev].node.range().start)
                    ),
                ));
            }
            let kind = self.joint_kind(node, &element)?;
            if let Kind::Movable(t) = kind {
                nv += t.nv();
                if nv > MAX_URDF_DOFS {
                    return Err(self.err(
                        pos,
                        &element,
                        format!(
                            "the model has more than {MAX_URDF_DOFS} degrees of freedom (the \
                             loader's limit, MAX_URDF_DOFS{}): {nv} up to this joint",
                            if opts.floating_base {
                                ", the floating base's 6 included"
                            } else {
                                ""
                            }
                        ),
                    ));
                }
            }
            if let Kind::Movable(_) = kind
                && (name == "universe" || (opts.floating_base && name == ROOT_JOINT_NAME))
            {
                return Err(self.err(
                    pos,
                    &element,
                    format!("the joint name \"{name}\" is reserved"),
                ));
            }
            let origin = self.origin(node, &element)?;
            let mut ends = [0usize; 2];
            for (k, which) in ["parent", "child"].iter().enumerate() {
                let Some(e) = child_elem(node, which) else {
                    return Err(self.err(pos, &element, format!("missing <{which}> element")));
                };
                let Some(l) = e.attribute("link") else {
                    return Err(self.err(
                        e.range().start,
                        &element,
                        format!("<{which}> has no link attribute"),
                    ));
                };
                let Some(&li) = link_index.get(l) else {
                    return Err(self.err(
                        e.range().start,
                        &element,
                        format!("{which} link \"{l}\" is not defined"),
                    ));
                };
                ends[k] = li;
            }
            let limits = match kind {
                Kind::Movable(JointType::Revolute { .. } | JointType::Prismatic { .. }) => {
                    match child_elem(node, "limit") {
                        // URDF defaults: lower = upper = 0 when the attributes are absent.
                        Some(l) => {
                            let lo = self.scalar_or(l, "lower", 0.0, &element)?;
                            let hi = self.scalar_or(l, "upper", 0.0, &element)?;
                            if lo > hi {
                                // Bullet's convention, used on purpose by simulator exports.
                                self.warn(
                                    l.range().start,
                                    &element,
                                    format!(
                                        "<limit lower=\"{lo}\" upper=\"{hi}\">: lower > upper, \
                                         read as \"not limited\": loaded without limits"
                                    ),
                                );
                                None
                            } else {
                                Some((lo, hi))
                            }
                        }
                        None => None,
                    }
                }
                _ => None,
            };
            let mimic = match (kind, child_elem(node, "mimic")) {
                (Kind::Movable(_), Some(m)) => match m.attribute("joint") {
                    Some(j) if !j.is_empty() => Some((j.to_string(), m.range().start)),
                    _ => {
                        return Err(self.err(
                            m.range().start,
                            &element,
                            "<mimic> has no joint attribute",
                        ));
                    }
                },
                _ => None,
            };
            let mimic_coeffs = match (opts.mimic, kind, child_elem(node, "mimic")) {
                (true, Kind::Movable(_), Some(m)) => (
                    self.scalar_or(m, "multiplier", 1.0, &element)?,
                    self.scalar_or(m, "offset", 0.0, &element)?,
                ),
                _ => (1.0, 0.0),
            };
            joint_index.insert(name.clone(), joints.len());
            joints.push(Joint {
                name,
                node,
                kind,
                origin,
                parent: ends[0],
                child: ends[1],
                limits,
                mimic,
                mimic_coeffs,
            });
        }

        // Topology: one parent joint per link, one root, no cycle.
        let mut parent_joint: Vec<Option<usize>> = vec![None; links.len()];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
        for (ji, j) in joints.iter().enumerate() {
            if let Some(prev) = parent_joint[j.child] {
                return Err(self.err(
                    j.node.range().start,
                    &format!("joint \"{}\"", j.name),
                    format!(
                        "link \"{}\" already has the parent joint \"{}\" (line {}): a link can have \
                         only one parent joint",
                        links[j.child].name,
                        joints[prev].name,
                        self.line(joints[prev].node.range().start)
                    ),
                ));
            }
            parent_joint[j.child] = Some(ji);
            children[j.parent].push(ji);
        }
        // With `opts.mimic`, every <mimic> must define a constraint the reduced model can use.
        if opts.mimic {
            self.check_mimics(&joints, &joint_index)?;
        }
        // A <mimic> naming an unknown joint or the joint itself: a warning, and not recorded
        // (the joint is independent either way).
        for j in joints.iter_mut() {
            let Some((of, pos)) = &j.mimic else { continue };
            let what = if !joint_index.contains_key(of) {
                format!("the unknown joint \"{of}\"")
            } else if of == &j.name {
                "the joint itself".to_string()
            } else {
                continue;
            };
            self.warn(
                *pos,
                &format!("joint \"{}\"", j.name),
                format!("<mimic> refers to {what}: ignored, the joint is loaded as independent"),
            );
            j.mimic = None;
        }
        let roots: Vec<usize> = (0..links.len()).filter(|&l| parent_joint[l].is_none()).collect();
        if roots.len() > 1 {
            let list = roots
                .iter()
                .map(|&l| {
                    format!(
                        "\"{}\" (line {})",
                        links[l].name,
                        self.line(links[l].node.range().start)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ");
            let second = &links[roots[1]];
            return Err(self.err(
                second.node.range().start,
                &format!("link \"{}\"", second.name),
                format!(
                    "{} root links (links that are no joint's child): {list}; a URDF must be a \
                     single tree",
                    roots.len()
                ),
            ));
        }
        if roots.is_empty() {
            // Every link has a parent: follow parents from the first link into a cycle.
            return Err(self.cycle_error(&links, &joints, &parent_joint, 0));
        }
        let root = roots[0];

        // Depth-first walk: siblings in document order.
        let mut b = ModelBuilder::new(&robot_name);
        let root_elem = format!("link \"{}\"", links[root].name);
        let root_pos = links[root].node.range().start;
        let root_body = if opts.floating_base {
            b.add_joint(0, ROOT_JOINT_NAME, JointType::FreeFlyer, Transform::identity())
                .map_err(self.wrap(root_pos, &root_elem))?
        } else {
            0
        };
        // Model joint index of each movable joint, by name.
        let mut b_names: HashMap<&str, usize> = HashMap::new();
        // (body joint, placement of the link frame in the body frame), per link.
        let mut at: Vec<Option<(usize, Transform)>> = vec![None; links.len()];
        at[root] = Some((root_body, Transform::identity()));
        // Links in depth-first order.
        let mut order: Vec<usize> = vec![root];
        b.add_frame(&links[root].name, root_body, Transform::identity())
            .map_err(self.wrap(root_pos, &root_elem))?;
        b.append_inertia(root_body, &Transform::identity(), &links[root].inertia)
            .map_err(self.wrap(root_pos, &root_elem))?;
        let mut stack: Vec<usize> = children[root].iter().rev().copied().collect();
        while let Some(ji) = stack.pop() {
            let j = &joints[ji];
            let element = format!("joint \"{}\"", j.name);
            let pos = j.node.range().start;
            let (pbody, pplace) =
                at[j.parent].expect("parent link visited before its child joints");
            let place = pplace.compose(&j.origin);
            let child_at = match j.kind {
                Kind::Fixed => (pbody, place),
                Kind::Movable(t) => {
                    let id =
                        b.add_joint(pbody, &j.name, t, place).map_err(self.wrap(pos, &element))?;
                    b_names.insert(j.name.as_str(), id);
                    if let Some((lo, hi)) = j.limits {
                        b.set_limits(id, &[lo], &[hi]).map_err(self.wrap(pos, &element))?;
                    }
                    if let Some((of, _)) = &j.mimic {
                        b.set_mimic(id, of);
                    }
                    (id, Transform::identity())
                }
            };
            let child = &links[j.child];
            let cpos = child.node.range().start;
            let celem = format!("link \"{}\"", child.name);
            at[j.child] = Some(child_at);
            order.push(j.child);
            b.add_frame(&child.name, child_at.0, child_at.1).map_err(self.wrap(cpos, &celem))?;
            b.append_inertia(child_at.0, &child_at.1, &child.inertia)
                .map_err(self.wrap(cpos, &celem))?;
            stack.extend(children[j.child].iter().rev().copied());
        }
        // Links not reached from the root lie on a cycle (each link has at most one parent).
        if let Some(l) = at.iter().position(|a| a.is_none()) {
            return Err(self.cycle_error(&links, &joints, &parent_joint, l));
        }
        let mut mimics = Vec::new();
        if opts.mimic {
            for j in &joints {
                let Some((of, _)) = &j.mimic else { continue };
                let id = |n: &str| b_names.get(n).copied().expect("movable joints are in the tree");
                mimics.push(JointCoupling {
                    joint: id(&j.name),
                    reference: id(of),
                    multiplier: j.mimic_coeffs.0,
                    offset: j.mimic_coeffs.1,
                });
            }
            mimics.sort_by_key(|m| m.joint);
        }
        let mut model = b.build_unchecked();
        model.mimic_joints = mimics;
        self.check_body_inertias(&model, &links, &at, &order, opts.strict_inertia)?;
        model.validate().map_err(|e| Error::Model {
            file: self.file.to_string(),
            line: None,
            element: format!("robot \"{}\"", model.name),
            reason: e.to_string(),
        })?;
        model.warnings = self.warnings.take();
        if !model.mimic_joints.is_empty() {
            let mimics = std::mem::take(&mut model.mimic_joints);
            let reduced = model.with_mimic_joints(&mimics).map_err(|e| Error::Model {
                file: self.file.to_string(),
                line: None,
                element: format!("robot \"{}\"", model.name),
                reason: e.to_string(),
            })?;
            return Ok(reduced);
        }
        Ok(model)
    }

    /// The checks of [`UrdfOptions::mimic`]: each `<mimic>` names another joint of the file
    /// that is not itself a mimic joint, and both are one-DoF joints of one kind (rotational:
    /// `revolute` or `continuous`; or `prismatic`).
    fn check_mimics(&self, joints: &[Joint], joint_index: &HashMap<String, usize>) -> Result<()> {
        let rot = |k: Kind| match k {
            Kind::Movable(JointType::Revolute { .. } | JointType::Continuous { .. }) => Some(true),
            Kind::Movable(JointType::Prismatic { .. }) => Some(false),
            _ => None,
        };
        let type_of = |j: &Joint| j.node.attribute("type").unwrap_or("").to_string();
        for j in joints {
            let Some((of, pos)) = &j.mimic else { continue };
            let element = format!("joint \"{}\"", j.name);
            let fail = |why: String| {
                Err(self.err(*pos, &element, format!("<mimic joint=\"{of}\">: {why}")))
            };
            let Some(&r) = joint_index.get(of) else {
                return fail(format!("\"{of}\" is not a joint of the file"));
            };
            let reference = &joints[r];
            if reference.name == j.name {
                return fail("a joint cannot mimic itself".into());
            }
            if reference.mimic.is_some() {
                return fail(format!(
                    "the reference joint \"{of}\" (line {}) is itself a mimic joint",
                    self.line(reference.node.range().start)
                ));
            }
            let Some(kj) = rot(j.kind) else {
                return fail(format!(
                    "a mimic joint must be revolute, continuous or prismatic, not {}",
                    type_of(j)
                ));
            };
            match rot(reference.kind) {
                None => {
                    return fail(format!(
                        "the reference joint \"{of}\" (line {}) is {}, not a revolute, continuous \
                         or prismatic joint",
                        self.line(reference.node.range().start),
                        type_of(reference)
                    ));
                }
                Some(kr) if kr != kj => {
                    return fail(format!(
                        "a {} joint cannot mimic the {} joint \"{of}\" (line {}): both must be \
                         rotational (revolute, continuous) or both prismatic",
                        type_of(j),
                        type_of(reference),
                        self.line(reference.node.range().start)
                    ));
                }
                Some(_) => {}
            }
        }
        Ok(())
    }

    /// A link whose own rotational inertia is not physical is an error unless the body it is
    /// merged into (by fixed joints) is physical: real URDFs use placeholder inertials on dummy
    /// links (e.g. mass 1e-6 kg with all six entries 1e-6 kg m²) that only ever reach the
    /// dynamics summed into a heavier body. A body that is not physical always contains such a
    /// link (physical inertias are closed under rigid placement and addition); the first one in
    /// depth-first order is reported. Unless `strict`, a body that only violates the triangle
    /// inequality (it is positive semi-definite) gives a warning for each such link instead.
    fn check_body_inertias(
        &self,
        model: &Model,
        links: &[Link],
        at: &[Option<(usize, Transform)>],
        order: &[usize],
        strict: bool,
    ) -> Result<()> {
        for &l in order {
            let Some((pos, reason)) = &links[l].defect else {
                continue;
            };
            let body = at[l].map_or(0, |a| a.0);
            if let Some(d) = inertia_defect(&model.inertias[body]) {
                let merged: Vec<String> = order
                    .iter()
                    .filter(|&&k| at[k].map(|a| a.0) == Some(body))
                    .map(|&k| format!("\"{}\"", links[k].name))
                    .collect();
                let body_desc = if merged.len() > 1 {
                    format!(
                        "; the body of joint \"{}\" (links {} merged) is not physical either: {d}",
                        model.names[body],
                        merged.join(", ")
                    )
                } else {
                    String::new()
                };
                let element = format!("link \"{}\"", links[l].name);
                if strict || !matches!(d, InertiaDefect::TriangleInequality(_)) {
                    return Err(self.err(*pos, &element, format!("{reason}{body_desc}")));
                }
                self.warn(
                    *pos,
                    &element,
                    format!(
                        "{reason}{body_desc}; loaded all the same, as the body's inertia is \
                         positive semi-definite (strict_inertia makes this an error)"
                    ),
                );
            }
        }
        Ok(())
    }

    /// Error for the cycle reached by following parent joints from link `start`.
    fn cycle_error(
        &self,
        links: &[Link],
        joints: &[Joint],
        parent_joint: &[Option<usize>],
        start: usize,
    ) -> Error {
        // Walk up until a link repeats; that link is on the cycle.
        let mut seen = vec![false; links.len()];
        let mut l = start;
        while !seen[l] {
            seen[l] = true;
            match parent_joint[l] {
                Some(j) => l = joints[j].parent,
                None => break, // Not expected: a parentless link reaches no cycle.
            }
        }
        let first = l;
        let mut path = vec![format!("link \"{}\"", links[first].name)];
        // The cycle's joint that comes last in the document is reported (it closes the loop).
        let mut last_joint: Option<usize> = None;
        while let Some(j) = parent_joint[l] {
            if last_joint
                .is_none_or(|k| joints[k].node.range().start < joints[j].node.range().start)
            {
                last_joint = Some(j);
            }
            l = joints[j].parent;
            path.push(format!("joint \"{}\"", joints[j].name));
            path.push(format!("link \"{}\"", links[l].name));
            if l == first {
                break;
            }
        }
        // Report in parent → child direction.
        path.reverse();
        let j = last_joint.unwrap_or(0);
        self.err(
            joints[j].node.range().start,
            &format!("joint \"{}\"", joints[j].name),
            format!("kinematic cycle: {}", path.join(" -> ")),
        )
    }
}
