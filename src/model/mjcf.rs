//! MJCF (MuJoCo XML) loading: the subset of MJCF that defines a kinematic tree and its masses.
//!
//! Read (MuJoCo's XML reference is the specification; MuJoCo 4.0 is the oracle of the tests):
//!
//! * `<mujoco model>` (the model name; `"MuJoCo Model"` without it), every `<worldbody>`, and
//!   `<include file>` anywhere (the included file's top-level element is dropped and its
//!   children take the place of the `<include>`; the path is relative to the directory of the
//!   main file, or to the `base_dir` given with a string; in an included file, a path that
//!   does not exist there is taken relative to the including file's directory, as MuJoCo does).
//! * `<compiler>`: `angle` (`degree`, MuJoCo's default, or `radian`), `eulerseq`, `autolimits`,
//!   `inertiafromgeom` (`true`, `false`, `auto`), `inertiagrouprange`, `boundmass`,
//!   `boundinertia`, `balanceinertia`, `settotalmass`; `coordinate="global"`
//!   (removed from MuJoCo in 2.3.3) is an error; `alignfree="true"` is an error (unsupported).
//! * `<option gravity>` and `<option><flag gravity="disable"/></option>`.
//!   `discardvisual` (a visual geom with mass is an error with `inertiafromgeom="true"`, as in
//!   MuJoCo; otherwise no effect) and `fusestatic` (no effect: static bodies are merged anyway).
//! * `<default>` classes as MuJoCo reads them: the root class `main`, which every top-level
//!   `<default>` (unnamed, `class="main"` or `class=""`) updates; nested classes (a copy of
//!   their parent when read, names unique in the model), `class` and `childclass` (on `<body>`
//!   and `<frame>`); what MuJoCo refuses is an error (see `docs/mjcf.md`).
//! * `<tendon>`: `<fixed>` and `<spatial>` tendons are recorded ([`Model::tendons`], see
//!   [`Tendon`]), checked as MuJoCo checks them, with one warning that they do not enter the
//!   dynamics (except as the couplings of an `<equality><tendon>`, below); a nonzero tendon
//!   `armature` (which MuJoCo adds to `M`) is an error.
//! * `<body pos quat|axisangle|euler|xyaxes|zaxis>`, `<frame>` (a placement of its children),
//!   `<inertial pos orientation mass diaginertia|fullinertia>`, `<joint>` of type `hinge`,
//!   `slide`, `ball` and `free`, `<freejoint>`, `<geom>` (for inertias) and named `<site>`s (as
//!   frames).
//!
//! Conventions (see also `docs/conventions.md`, section MJCF):
//!
//! * Joints are numbered in MuJoCo's order (bodies depth-first in document order, the joints
//!   of a body in document order), so sodyn's velocity coordinates are MuJoCo's `dof`s in the
//!   same order, and its configuration coordinates MuJoCo's `qpos` in the same order.
//! * A hinge or slide joint's coordinate is MuJoCo's `qpos` (its `ref` is folded into the
//!   joint placement). A hinge or ball joint with `pos` rotates about that point: its sodyn
//!   frame sits at `pos`, and what follows it is placed back by `−pos`. Several joints in one
//!   body are chained in document order as MuJoCo composes them.
//! * A ball joint is [`JointType::Spherical`]: MuJoCo's `qpos` `[w x y z]` is sodyn's
//!   `[x y z w]`; the velocity (angular velocity in the body frame) is the same.
//! * A free joint is [`JointType::FreeFlyer`] on the world, at the identity: sodyn's
//!   `q = [p; x y z w]` is MuJoCo's `qpos = [p; w x y z]` reordered; sodyn's `v = [ω; Rᵀṗ]`
//!   (body frame) where MuJoCo's `qvel = [ṗ; ω]` (world-frame linear velocity first); forces
//!   map likewise, `τ = [τ_ω; Rᵀ τ_p]`.
//! * Bodies without a joint are welded to their parent: their inertia is merged into the
//!   moving body they are welded to, and each named body and named site is a
//!   [`Frame`](super::Frame). Unnamed joints are named `joint<i>` (`i` is MuJoCo's joint
//!   index; `_` appended while the name is taken).
//! * Inertias follow MuJoCo: `<inertial>` if the body has one (with `inertiafromgeom="auto"`,
//!   the default), otherwise the sum of its geoms' (`sphere`, `capsule`, `ellipsoid`,
//!   `cylinder`, `box`; `mass` or `density` (default 1000); `fromto`; geoms outside
//!   `inertiagrouprange` are left out). A mesh, height field or SDF geom (or a primitive
//!   sized from a mesh) that would contribute to a moving body's inertia is an error naming
//!   the body (give it an `<inertial>`); in a static body it does not matter. A body with
//!   joints needs, with the bodies welded to it, a positive mass and moments. Then
//!   `boundmass`, `boundinertia`, `balanceinertia`, and `settotalmass`. A body with joints,
//!   with the bodies welded to it, must have positive mass and principal moments (MuJoCo's
//!   rule); negative masses, densities or sizes, a non-physical `<inertial>`, and a plane in a
//!   moving body are errors.
//! * `<equality>` (each constraint with `active="false"`, own or from its class, is skipped;
//!   `solref`, `solimp` and `torquescale` are ignored: the constraints are rigid):
//!   `<connect body1 body2 anchor>` is a 3-D two-frame constraint ([`Model::constraints`]):
//!   frame A at `anchor` in body1's frame, frame B at the point of body2 where the anchor is at
//!   MuJoCo's reference configuration `qpos0` (hinges and slides at their `ref`, ball joints at
//!   the identity, free joints at their body's pose); `<weld body1 body2 anchor relpose>` a 6-D
//!   one: frame B at `anchor` in body2's frame, frame A at `relpose · anchor` in body1's frame
//!   (`relpose`, `pos` then `quat`, the pose of body2 in body1; by default, or with a zero
//!   quaternion, the relative pose at `qpos0`). A missing body2, or `"world"`, is the world
//!   (frame `"universe"`); with body1 on the world, frame A is body2's side. `<joint joint1
//!   joint2 polycoef>` with a linear polynomial (`q1 − q1₀ = c0 + c1 (q2 − q2₀)`, `₀` at
//!   `qpos0`) is a mimic constraint: the model is in reduced coordinates
//!   ([`Model::with_mimic_joints`]). `<tendon tendon1 tendon2 polycoef>` on fixed tendons
//!   (`L = Σ coef · q`) with a linear polynomial is the constraint `L1 − L1₀ = c0 + c1 (L2 −
//!   L2₀)` (`L1 − L1₀ = c0` without tendon2), linear in the joint coordinates: with one, every
//!   `<joint>` and `<tendon>` coupling is eliminated in document order, each eliminating
//!   tendon1's last joint with a nonzero net coefficient (else tendon2's last; joint1, else
//!   joint2, for a `<joint>`) after the joints eliminated before it are replaced by their
//!   expressions, into couplings of several joints ([`Model::with_linear_couplings`]). A
//!   non-linear polynomial, a `<joint>` without joint2, a constraint between sites, an unknown
//!   body, joint or tendon, a spatial tendon, a coupling that is dependent on or inconsistent
//!   with those before it, both frames on one body, and every other element (`<flex>`, …) are
//!   errors naming the element and its line.
//! * Joint `damping`, `stiffness`, `frictionloss`, actuators, contacts, sensors and every
//!   element irrelevant to the rigid-body dynamics are ignored;
//!   a nonzero body `gravcomp` is ignored with a warning in [`Model::warnings`]. A joint's
//!   `armature` (with the class defaults; none for a `<freejoint>`, as in MuJoCo) is the
//!   armature of each of its DoFs ([`Model::armature`]); a negative one is an error. On a
//!   `<joint type="free">` it loads with a warning: MuJoCo's armature acts on its own
//!   free-joint coordinates `[ṗ_world; ω]`, sodyn's on `[ω; v_body]`, so `M` agrees but `τ`
//!   differs by `armature · (ω × v)` in the translation rows. Limits (`range` of limited hinge and slide joints) are
//!   recorded as data.
//! * Elements that would add bodies or degrees of freedom that sodyn cannot represent
//!   (`<composite>`, `<flexcomp>`, `<replicate>`, `<attach>`) are errors.
//!
//! Every failure is an [`Error::Model`] naming the file (the included file for an element read
//! from one), the 1-based line, the element and the reason. At most [`MAX_URDF_DOFS`] degrees
//! of freedom, and elements nested at most a hundred levels deeper than that.

use super::joint::JointType;
use super::tree::{Model, ModelBuilder, inertia_defect};
use super::urdf::{MAX_URDF_DOFS, ROOT_JOINT_NAME};
use crate::error::{Error, Result};
use crate::spatial::{Inertia, Transform};
use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// Options of the MJCF loader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MjcfOptions {
    /// Add a free-flyer joint named `"root_joint"` in front of the `<worldbody>`'s only body
    /// (which must have no joint of its own); the body is placed at the joint's frame, as a
    /// MuJoCo `<freejoint>` would place it. An MJCF `<freejoint>` (or `<joint type="free">`)
    /// is a free-flyer itself and needs no option.
    pub floating_base: bool,
}

pub use super::tendon::{SpatialWrap, Tendon, TendonPath};

/// Where an equality element is: its file, line and element description.
type Loc = (Rc<str>, u32, String);

/// `(joint index, coefficient)` pairs.
type Terms = Vec<(usize, f64)>;

/// A linear equality constraint `Σ terms = rhs` on one-DoF joints (joint index, coefficient),
/// and the joints to eliminate by it, in order of preference.
struct LinearRow {
    terms: Vec<(usize, f64)>,
    rhs: f64,
    prefer: Vec<usize>,
}

/// The `<equality>` constraints: two-frame constraints, the `<joint>` couplings as mimic
/// constraints, and (when a `<tendon>` coupling is present, empty otherwise) every linear
/// constraint in document order.
struct Equalities {
    contacts: Vec<super::Contact>,
    mimics: Vec<(Loc, super::JointCoupling)>,
    rows: Vec<(Loc, LinearRow)>,
}

/// "mimic constraint K: REASON" of [`Model::with_mimic_joints`] as the error of the K-th
/// `<joint>` equality.
fn mimic_error(e: Error, lines: &[Loc]) -> Error {
    let Error::Build(full) = &e else { return e };
    let (k, msg) = full
        .strip_prefix("mimic constraint ")
        .and_then(|r| r.split_once(": "))
        .and_then(|(n, why)| Some((n.parse::<usize>().ok()?, why.to_string())))
        .unwrap_or((0, full.clone()));
    match lines.get(k).or(lines.first()) {
        Some((file, line, element)) => model_err(file, *line, element, msg),
        None => e,
    }
}

/// Gauss–Jordan elimination of linear joint constraints, in document order: each constraint,
/// with the joints eliminated before it replaced by their expressions, eliminates the first
/// joint of its preference list (for a tendon coupling, tendon1's joints from the last, then
/// tendon2's) whose net coefficient is not zero (else the last such joint of the model); the
/// expressions before it are updated. Returns each eliminated joint as a coupling on the
/// independent joints, with the element that eliminated it.
///
/// # Errors
/// A constraint whose net coefficients all vanish (relative to `1e-12` of the largest): it
/// follows from those before it (dependent) or contradicts them (inconsistent), an error
/// naming the element and its line.
fn eliminate(rows: Vec<(Loc, LinearRow)>) -> Result<Vec<(Loc, super::LinearCoupling)>> {
    // Eliminated joint → (its terms on independent joints, offset), with its element.
    let mut exprs: Vec<(usize, Terms, f64, Loc)> = Vec::new();
    for (loc, row) in rows {
        let scale = row.terms.iter().fold(0.0f64, |m, t| m.max(t.1.abs()));
        let mut terms: Vec<(usize, f64)> = Vec::new();
        let mut rhs = row.rhs;
        let add = |terms: &mut Vec<(usize, f64)>, j: usize, x: f64| match terms
            .iter_mut()
            .find(|t| t.0 == j)
        {
            Some(t) => t.1 += x,
            None => terms.push((j, x)),
        };
        for &(j, a) in &row.terms {
            match exprs.iter().find(|e| e.0 == j) {
                Some((_, et, eo, _)) => {
                    for &(i, x) in et {
                        add(&mut terms, i, a * x);
                    }
                    rhs -= a * eo;
                }
                None => add(&mut terms, j, a),
            }
        }
        let tol = 1e-12 * scale.max(f64::MIN_POSITIVE);
        terms.retain(|t| t.1.abs() > tol);
        let (file, line, element) = &loc;
        if terms.is_empty() {
            let why = if rhs.abs() <= 1e-12 * (1.0 + row.rhs.abs()) {
                "its joints' net coefficients cancel, with the equality constraints before it:                  the constraint is dependent (it follows from them and constrains nothing)"
                    .to_string()
            } else {
                format!(
                    "its joints' net coefficients cancel, with the equality constraints before                      it, and it requires 0 = {rhs}: the constraint set is inconsistent"
                )
            };
            return Err(model_err(file, *line, element, why));
        }
        let pivot = row
            .prefer
            .iter()
            .copied()
            .find(|&j| terms.iter().any(|t| t.0 == j))
            .unwrap_or_else(|| terms.iter().map(|t| t.0).max().expect("not empty"));
        let ap = terms.iter().find(|t| t.0 == pivot).expect("a term").1;
        // q_p = (rhs − Σ_{j≠p} a_j q_j) / a_p.
        let mut expr: Vec<(usize, f64)> =
            terms.iter().filter(|t| t.0 != pivot).map(|&(j, a)| (j, -a / ap)).collect();
        expr.sort_by_key(|t| t.0);
        let off = rhs / ap;
        for (_, et, eo, _) in exprs.iter_mut() {
            if let Some(k) = et.iter().position(|t| t.0 == pivot) {
                let x = et.remove(k).1;
                for &(j, y) in &expr {
                    match et.iter_mut().find(|t| t.0 == j) {
                        Some(t) => t.1 += x * y,
                        None => et.push((j, x * y)),
                    }
                }
                et.retain(|t| t.1 != 0.0);
                et.sort_by_key(|t| t.0);
                *eo += x * off;
            }
        }
        exprs.push((pivot, expr, off, loc));
    }
    Ok(exprs
        .into_iter()
        .map(|(joint, terms, offset, loc)| (loc, super::LinearCoupling { joint, terms, offset }))
        .collect())
}

/// Nesting limit of `<include>` (an include cycle is reported before it).
const MAX_INCLUDE_DEPTH: usize = 32;

/// Size limit of an included file (bytes).
const MAX_INCLUDE_BYTES: u64 = 256 << 20;

/// Nesting limit of elements (bodies in bodies): the loader is recursive, and a chain of
/// [`MAX_URDF_DOFS`] bodies with a joint each needs a little more than that.
const MAX_NESTING: usize = MAX_URDF_DOFS + 100;

/// Loads an MJCF file. `<include>` paths are relative to the file's directory.
pub fn load_mjcf_file(path: &Path, opts: &MjcfOptions) -> Result<Model> {
    let file = path.display().to_string();
    let xml = std::fs::read_to_string(path).map_err(|e| Error::Model {
        file: file.clone(),
        line: None,
        element: "file".into(),
        reason: format!("cannot read the file: {e}"),
    })?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let canon = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    load(&xml, &file, &dir, Some(canon), opts)
}

/// Loads an MJCF document from a string; `source_name` is used as the file name in messages
/// and `<include>` paths are relative to `base_dir`.
pub fn load_mjcf_str(
    xml: &str,
    source_name: &str,
    base_dir: &Path,
    opts: &MjcfOptions,
) -> Result<Model> {
    load(xml, source_name, base_dir, None, opts)
}

impl Model {
    /// Loads an MJCF (MuJoCo XML) file with the default [`MjcfOptions`]; see the
    /// [`mjcf`](super::mjcf) module for what is read.
    ///
    /// # Errors
    /// [`Error::Model`] naming the file, line, element and reason.
    pub fn from_mjcf(path: impl AsRef<Path>) -> Result<Model> {
        load_mjcf_file(path.as_ref(), &MjcfOptions::default())
    }

    /// Loads an MJCF document from a string (`<include>` paths relative to `base_dir`; the
    /// file name in messages is `<string>`), with the default [`MjcfOptions`].
    ///
    /// # Errors
    /// [`Error::Model`] naming the line, element and reason.
    pub fn from_mjcf_str(xml: &str, base_dir: impl AsRef<Path>) -> Result<Model> {
        load_mjcf_str(xml, "<string>", base_dir.as_ref(), &MjcfOptions::default())
    }
}

// ---------------------------------------------------------------------------------------------
// An owned element tree with `<include>` expanded and every position resolved to file:line.

#[derive(Debug)]
struct Attr {
    name: String,
    value: String,
    line: u32,
}

#[derive(Debug)]
struct El {
    tag: String,
    attrs: Vec<Attr>,
    children: Vec<El>,
    file: Rc<str>,
    line: u32,
}

impl El {
    fn attr(&self, name: &str) -> Option<&Attr> {
        self.attrs.iter().find(|a| a.name == name)
    }
    fn elems<'s>(&'s self, tag: &'s str) -> impl Iterator<Item = &'s El> + 's {
        self.children.iter().filter(move |c| c.tag == tag)
    }
}

fn model_err(file: &str, line: u32, element: &str, reason: impl Into<String>) -> Error {
    Error::Model {
        file: file.into(),
        line: Some(line),
        element: element.into(),
        reason: reason.into(),
    }
}

struct Reader<'a> {
    base_dir: &'a Path,
    /// Canonical paths of the files being included (cycle detection).
    stack: Vec<PathBuf>,
    /// Element nesting depth so far (included files' elements count at their `<include>`).
    level: usize,
}

/// Byte offsets of the line starts of a text: the line of a position in `O(log n)`
/// (`roxmltree`'s `text_pos_at` scans the text, which made loading quadratic in its size).
struct Lines(Vec<usize>);

impl Lines {
    fn new(text: &str) -> Self {
        Lines(std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect())
    }
    /// The 1-based line of byte position `pos`.
    fn line(&self, pos: usize) -> u32 {
        u32::try_from(self.0.partition_point(|&s| s <= pos)).unwrap_or(u32::MAX)
    }
}

impl Reader<'_> {
    /// Parses `xml` (named `file`) into an owned tree, expanding `<include>`.
    fn parse(&mut self, xml: &str, file: &str, depth: usize) -> Result<El> {
        // Whitespace before the XML declaration: as in URDF (`urdf::XmlText`).
        let text = super::urdf::XmlText::new(xml);
        let (doc, xml) = (text.parse(file)?, text.text());
        let file: Rc<str> = file.into();
        let lines = Lines::new(xml);
        let root = doc.root_element();
        let mut children = Vec::new();
        self.convert_children(&lines, root, &file, depth, &mut children)?;
        Ok(El {
            tag: root.tag_name().name().to_string(),
            attrs: attrs_of(&lines, root),
            children,
            line: lines.line(root.range().start),
            file,
        })
    }

    fn convert_children(
        &mut self,
        lines: &Lines,
        node: roxmltree::Node,
        file: &Rc<str>,
        depth: usize,
        out: &mut Vec<El>,
    ) -> Result<()> {
        self.level += 1;
        for c in node.children().filter(|c| c.is_element()) {
            let line = lines.line(c.range().start);
            if self.level > MAX_NESTING {
                return Err(model_err(
                    file,
                    line,
                    &format!("<{}>", c.tag_name().name()),
                    format!("elements nested more than {MAX_NESTING} deep"),
                ));
            }
            if c.tag_name().name() == "include" {
                self.include(c, file, line, depth, out)?;
                continue;
            }
            let mut children = Vec::new();
            self.convert_children(lines, c, file, depth, &mut children)?;
            out.push(El {
                tag: c.tag_name().name().to_string(),
                attrs: attrs_of(lines, c),
                children,
                file: file.clone(),
                line,
            });
        }
        self.level -= 1;
        Ok(())
    }

    fn include(
        &mut self,
        node: roxmltree::Node,
        file: &Rc<str>,
        line: u32,
        depth: usize,
        out: &mut Vec<El>,
    ) -> Result<()> {
        let Some(name) = node.attribute("file") else {
            return Err(model_err(file, line, "<include>", "missing file attribute"));
        };
        let element = format!("<include file=\"{name}\">");
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(model_err(
                file,
                line,
                &element,
                format!("<include> nested more than {MAX_INCLUDE_DEPTH} deep"),
            ));
        }
        // Relative to the main file's directory (MuJoCo's rule), else, in an included file,
        // relative to that file's directory (MuJoCo's fallback).
        let mut path = self.base_dir.join(name);
        if depth > 0
            && !path.exists()
            && let Some(dir) = Path::new(&**file).parent()
            && dir.join(name).exists()
        {
            path = dir.join(name);
        }
        // Only regular files of a bounded size (not /dev/zero, a FIFO or a directory).
        match std::fs::metadata(&path) {
            Ok(md) if !md.is_file() => {
                return Err(model_err(
                    file,
                    line,
                    &element,
                    format!("the included path {} is not a regular file", path.display()),
                ));
            }
            Ok(md) if md.len() > MAX_INCLUDE_BYTES => {
                return Err(model_err(
                    file,
                    line,
                    &element,
                    format!(
                        "the included file {} has {} bytes, more than the loader's limit of {}",
                        path.display(),
                        md.len(),
                        MAX_INCLUDE_BYTES
                    ),
                ));
            }
            _ => {}
        }
        let xml = std::fs::read_to_string(&path).map_err(|e| {
            model_err(
                file,
                line,
                &element,
                format!("cannot read the included file {}: {e}", path.display()),
            )
        })?;
        let canon = std::fs::canonicalize(&path).unwrap_or_else(|_| path.clone());
        if self.stack.contains(&canon) {
            return Err(model_err(
                file,
                line,
                &element,
                format!("include cycle: {} includes itself", path.display()),
            ));
        }
        self.stack.push(canon);
        let root = self.parse(&xml, &path.display().to_string(), depth + 1)?;
        self.stack.pop();
        out.extend(root.children);
        Ok(())
    }
}

fn attrs_of(lines: &Lines, node: roxmltree::Node) -> Vec<Attr> {
    node.attributes()
        .map(|a| Attr {
            name: a.name().to_string(),
            value: a.value().to_string(),
            line: lines.line(a.range().start),
        })
        .collect()
}

fn load(
    xml: &str,
    file: &str,
    base_dir: &Path,
    canon: Option<PathBuf>,
    opts: &MjcfOptions,
) -> Result<Model> {
    let mut reader = Reader { base_dir, stack: canon.into_iter().collect(), level: 0 };
    let root = reader.parse(xml, file, 0)?;
    if root.tag != "mujoco" {
        return Err(model_err(
            &root.file,
            root.line,
            &format!("<{}>", root.tag),
            format!("the root element is <{}>, expected <mujoco>", root.tag),
        ));
    }
    let mut p = Loader::new(&root)?;
    p.build(&root, opts)
}

// ---------------------------------------------------------------------------------------------
// Compiler settings and default classes.

#[derive(Clone, Copy, PartialEq, Eq)]
enum FromGeom {
    True,
    False,
    Auto,
}

struct Compiler {
    degree: bool,
    /// Axis (0..3) and intrinsic (lower case) flag of each Euler rotation.
    eulerseq: [(usize, bool); 3],
    autolimits: bool,
    inertiafromgeom: FromGeom,
    group_range: (i64, i64),
    boundmass: f64,
    boundinertia: f64,
    balanceinertia: bool,
    settotalmass: f64,
    discardvisual: bool,
}

impl Default for Compiler {
    fn default() -> Self {
        Self {
            degree: true,
            eulerseq: [(0, true), (1, true), (2, true)],
            autolimits: true,
            inertiafromgeom: FromGeom::Auto,
            group_range: (0, 5),
            boundmass: 0.0,
            boundinertia: 0.0,
            balanceinertia: false,
            settotalmass: -1.0,
            discardvisual: false,
        }
    }
}

/// A default class: per element tag, its attributes (inherited ones included).
#[derive(Clone, Default)]
struct Class {
    attrs: HashMap<String, Vec<Rc<Attr>>>,
}

/// One body of the tree, as read (before merging).
struct Body {
    name: Option<String>,
    file: Rc<str>,
    line: u32,
    /// Index of the parent body in `bodies` (`None`: the world).
    parent: Option<usize>,
    /// Pose in the parent body's frame.
    pose: Transform,
    joints: Vec<Jnt>,
    /// Inertia in the body frame (`None`: unknown, a static body with a mesh geom).
    inertia: Option<Inertia>,
    /// Named sites, posed in the body frame.
    sites: Vec<Site>,
}

/// A named site: name, pose (in its body's frame), line and file.
type Site = (String, Transform, u32, Rc<str>);

#[derive(Clone, Copy, PartialEq)]
enum JKind {
    Hinge,
    Slide,
    Ball,
    Free,
}

struct Jnt {
    name: Option<String>,
    kind: JKind,
    pos: Vector3<f64>,
    axis: Vector3<f64>,
    refpos: f64,
    range: Option<(f64, f64)>,
    /// `armature` (with the class defaults; 0 for a `<freejoint>`), on each of its DoFs.
    armature: f64,
    file: Rc<str>,
    line: u32,
}

struct Loader {
    comp: Compiler,
    classes: HashMap<String, Class>,
    warnings: Vec<String>,
    bodies: Vec<Body>,
}

/// `"FILE:LINE"`-located helpers.
fn err_at(el: &El, element: &str, reason: impl Into<String>) -> Error {
    model_err(&el.file, el.line, element, reason)
}

fn parse_numbers(el: &El, a: &Attr, element: &str, min: usize, max: usize) -> Result<Vec<f64>> {
    let mut out = Vec::with_capacity(max);
    let bad = |what: String| {
        model_err(
            &el.file,
            a.line,
            element,
            format!("<{}> attribute {}=\"{}\": {what}", el.tag, a.name, a.value),
        )
    };
    for tok in a.value.split_whitespace() {
        let x: f64 = tok.parse().map_err(|_| bad(format!("\"{tok}\" is not a number")))?;
        if !x.is_finite() {
            return Err(bad(format!("\"{tok}\" is not finite")));
        }
        out.push(x);
    }
    if out.len() < min || out.len() > max {
        let what = if min == max {
            if min == 1 { "1 number".to_string() } else { format!("{min} numbers") }
        } else {
            format!("{min} to {max} numbers")
        };
        return Err(bad(format!("expected {what}, found {}", out.len())));
    }
    Ok(out)
}

fn quat_wxyz(w: f64, x: f64, y: f64, z: f64) -> Option<UnitQuaternion<f64>> {
    let q = nalgebra::Quaternion::new(w, x, y, z);
    let n = q.norm();
    (n > 1e-12 && n.is_finite()).then(|| UnitQuaternion::from_quaternion(q))
}

/// The rotation taking `e_z` to the unit vector along `v` by the shortest arc (a half turn
/// about `e_x` when `v` points along `−e_z`, as MuJoCo does).
fn z_to(v: &Vector3<f64>) -> UnitQuaternion<f64> {
    let v = v.normalize();
    let c = Vector3::z().cross(&v);
    let s = c.norm();
    if s < 1e-14 {
        return if v.z > 0.0 {
            UnitQuaternion::identity()
        } else {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        };
    }
    let angle = s.atan2(v.z);
    UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(c / s), angle)
}

fn unit_transform(q: &UnitQuaternion<f64>, p: Vector3<f64>) -> Transform {
    Transform::new(*q.to_rotation_matrix().matrix(), p)
}

fn parse_bool(el: &El, a: &Attr, element: &str) -> Result<bool> {
    match a.value.as_str() {
        "true" => Ok(true),
        "false" => Ok(false),
        v => Err(model_err(
            &el.file,
            a.line,
            element,
            format!("<{}> attribute {}=\"{v}\": expected true or false", el.tag, a.name),
        )),
    }
}

impl Loader {
    fn new(root: &El) -> Result<Self> {
        let mut l = Loader {
            comp: Compiler::default(),
            classes: HashMap::new(),
            warnings: Vec::new(),
            bodies: Vec::new(),
        };
        for c in root.elems("compiler") {
            l.compiler(c)?;
        }
        // MuJoCo's root class is "main": every top-level <default> (unnamed, or named "main"
        // or "") configures it, the later ones on top of the earlier ones.
        l.classes.insert("main".into(), Class::default());
        for d in root.elems("default") {
            if let Some(a) = d.attr("class")
                && !a.value.is_empty()
                && a.value != "main"
            {
                return Err(model_err(
                    &d.file,
                    a.line,
                    &format!("<default class=\"{}\">", a.value),
                    "a top-level <default> configures the root class \"main\", which cannot be \
                     renamed (MuJoCo refuses it too): give it no class attribute or class=\"main\"",
                ));
            }
            l.default_class(d, "main".into(), None)?;
        }
        Ok(l)
    }

    fn compiler(&mut self, c: &El) -> Result<()> {
        let e = "<compiler>";
        for a in &c.attrs {
            let bad = |what: &str| {
                model_err(
                    &c.file,
                    a.line,
                    e,
                    format!("attribute {}=\"{}\": {what}", a.name, a.value),
                )
            };
            let num = || -> Result<f64> { Ok(parse_numbers(c, a, e, 1, 1)?[0]) };
            match a.name.as_str() {
                "angle" => {
                    self.comp.degree = match a.value.as_str() {
                        "degree" => true,
                        "radian" => false,
                        _ => return Err(bad("expected degree or radian")),
                    }
                }
                "eulerseq" => {
                    let chars: Vec<char> = a.value.chars().collect();
                    if chars.len() != 3 {
                        return Err(bad("expected 3 characters from xyzXYZ"));
                    }
                    for (k, ch) in chars.iter().enumerate() {
                        let axis = match ch.to_ascii_lowercase() {
                            'x' => 0,
                            'y' => 1,
                            'z' => 2,
                            _ => return Err(bad("expected 3 characters from xyzXYZ")),
                        };
                        self.comp.eulerseq[k] = (axis, ch.is_ascii_lowercase());
                    }
                }
                "autolimits" => self.comp.autolimits = parse_bool(c, a, e)?,
                "inertiafromgeom" => {
                    self.comp.inertiafromgeom = match a.value.as_str() {
                        "true" => FromGeom::True,
                        "false" => FromGeom::False,
                        "auto" => FromGeom::Auto,
                        _ => return Err(bad("expected true, false or auto")),
                    }
                }
                "inertiagrouprange" => {
                    let v = parse_numbers(c, a, e, 2, 2)?;
                    if v.iter().any(|x| x.fract() != 0.0) {
                        return Err(bad("expected 2 integers"));
                    }
                    self.comp.group_range = (v[0] as i64, v[1] as i64);
                }
                "boundmass" => self.comp.boundmass = num()?,
                "boundinertia" => self.comp.boundinertia = num()?,
                "settotalmass" => self.comp.settotalmass = num()?,
                "balanceinertia" => self.comp.balanceinertia = parse_bool(c, a, e)?,
                "discardvisual" => self.comp.discardvisual = parse_bool(c, a, e)?,
                "fusestatic" => {
                    // Static bodies are merged into their parents anyway; their names stay
                    // frames.
                    parse_bool(c, a, e)?;
                }
                "coordinate" => match a.value.as_str() {
                    "local" => {}
                    "global" => {
                        return Err(bad(
                            "global coordinates are not supported (MuJoCo dropped them in \
                             2.3.3; convert the model to local coordinates)",
                        ));
                    }
                    _ => return Err(bad("expected local")),
                },
                "alignfree" if parse_bool(c, a, e)? => {
                    return Err(bad(
                        "aligning free joints with the inertial frame is not supported",
                    ));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Reads `<default>` element `d` as class `name`, a child of class `parent` (`None`: the
    /// root class "main", which a top-level `<default>` updates). Class names are unique
    /// across the whole tree; a class starts as a copy of its parent's at this point.
    fn default_class(&mut self, d: &El, name: String, parent: Option<&str>) -> Result<()> {
        let element = format!("<default class=\"{name}\">");
        let mut class = match parent {
            None => self.classes.remove(&name).unwrap_or_default(),
            Some(_) if self.classes.contains_key(&name) => {
                let line = d.attr("class").map_or(d.line, |a| a.line);
                return Err(model_err(
                    &d.file,
                    line,
                    &element,
                    format!(
                        "default class \"{name}\" is defined twice (class names are unique in \
                         the whole model, \"main\" is the root class; MuJoCo refuses it too)"
                    ),
                ));
            }
            Some(p) => self.classes[p].clone(),
        };
        let mut seen: HashSet<&str> = HashSet::new();
        for c in d.children.iter().filter(|c| c.tag != "default") {
            if !DEFAULT_ELEMENTS.contains(&c.tag.as_str()) {
                return Err(err_at(
                    c,
                    &format!("<{}>", c.tag),
                    format!(
                        "<{}> cannot be in a <default> (MuJoCo refuses it too; {element} may \
                         hold {})",
                        c.tag,
                        DEFAULT_ELEMENTS.join(", ")
                    ),
                ));
            }
            if !seen.insert(&c.tag) {
                return Err(err_at(
                    d,
                    &element,
                    format!(
                        "a second <{}> (line {}): a class holds one of each element (MuJoCo \
                         refuses it too)",
                        c.tag, c.line
                    ),
                ));
            }
            let entry = class.attrs.entry(c.tag.clone()).or_default();
            for a in &c.attrs {
                let mut value = a.value.clone();
                // A partial size keeps the inherited entries after it (MuJoCo reads `size`
                // into the inherited vector).
                if a.name == "size"
                    && let Some(old) = entry.iter().find(|b| b.name == "size")
                {
                    let new: Vec<&str> = a.value.split_whitespace().collect();
                    let inherited: Vec<&str> = old.value.split_whitespace().collect();
                    if new.len() < inherited.len() {
                        value = new
                            .iter()
                            .chain(&inherited[new.len()..])
                            .copied()
                            .collect::<Vec<_>>()
                            .join(" ");
                    }
                }
                let a = Rc::new(Attr { name: a.name.clone(), value, line: a.line });
                // An orientation given here replaces the inherited one of another form.
                if ORIENT.contains(&a.name.as_str()) {
                    entry.retain(|b| !ORIENT.contains(&b.name.as_str()));
                }
                entry.retain(|b| b.name != a.name);
                entry.push(a);
            }
        }
        self.classes.insert(name.clone(), class);
        for c in d.elems("default") {
            let cn = c.attr("class").map_or("", |a| a.value.as_str());
            if cn.is_empty() {
                return Err(err_at(
                    c,
                    "<default>",
                    "a nested <default> needs a non-empty class attribute (MuJoCo refuses it too)",
                ));
            }
            self.default_class(c, cn.to_string(), Some(&name))?;
        }
        Ok(())
    }

    /// The class of element `el`: its `class` attribute, else the inherited `childclass`.
    fn class_of<'s>(&'s self, el: &El, childclass: &'s str, element: &str) -> Result<&'s Class> {
        let name = el.attr("class").map_or(childclass, |a| a.value.as_str());
        self.classes
            .get(name)
            .ok_or_else(|| err_at(el, element, format!("unknown default class \"{name}\"")))
    }

    fn warn(&mut self, file: &str, line: u32, element: &str, reason: impl std::fmt::Display) {
        self.warnings.push(format!("{file}:{line}: {element}: {reason}"));
    }

    fn angle(&self, x: f64) -> f64 {
        if self.comp.degree { x.to_radians() } else { x }
    }

    /// The orientation of `el` from its own attributes, else from those of its class
    /// (`class`), identity if none.
    fn orientation(
        &self,
        el: &El,
        class: Option<&Class>,
        element: &str,
    ) -> Result<UnitQuaternion<f64>> {
        let own: Vec<&Attr> =
            el.attrs.iter().filter(|a| ORIENT.contains(&a.name.as_str())).collect();
        if own.len() > 1 {
            return Err(err_at(
                el,
                element,
                format!(
                    "several orientations given ({}); give one of quat, axisangle, euler, \
                     xyaxes, zaxis",
                    own.iter().map(|a| a.name.as_str()).collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        let a: &Attr = match own.first() {
            Some(a) => a,
            None => match class
                .and_then(|c| c.attrs.get(&el.tag))
                .and_then(|v| v.iter().find(|b| ORIENT.contains(&b.name.as_str())))
            {
                Some(a) => a,
                None => return Ok(UnitQuaternion::identity()),
            },
        };
        let zero = |what: &str| {
            model_err(
                &el.file,
                a.line,
                element,
                format!("<{}> attribute {}=\"{}\": {what}", el.tag, a.name, a.value),
            )
        };
        Ok(match a.name.as_str() {
            "quat" => {
                let v = parse_numbers(el, a, element, 4, 4)?;
                quat_wxyz(v[0], v[1], v[2], v[3]).ok_or_else(|| zero("zero quaternion"))?
            }
            "axisangle" => {
                let v = parse_numbers(el, a, element, 4, 4)?;
                let axis = Vector3::new(v[0], v[1], v[2]);
                if axis.norm() < 1e-12 {
                    return Err(zero("zero axis"));
                }
                UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_normalize(axis),
                    self.angle(v[3]),
                )
            }
            "euler" => {
                let v = parse_numbers(el, a, element, 3, 3)?;
                let mut q = UnitQuaternion::identity();
                for (k, &(axis, intrinsic)) in self.comp.eulerseq.iter().enumerate() {
                    let r = UnitQuaternion::from_axis_angle(
                        &nalgebra::Unit::new_unchecked(Vector3::from_fn(|i, _| {
                            if i == axis { 1.0 } else { 0.0 }
                        })),
                        self.angle(v[k]),
                    );
                    q = if intrinsic { q * r } else { r * q };
                }
                q
            }
            "xyaxes" => {
                let v = parse_numbers(el, a, element, 6, 6)?;
                let x = Vector3::new(v[0], v[1], v[2]);
                let y = Vector3::new(v[3], v[4], v[5]);
                if x.norm() < 1e-12 {
                    return Err(zero("zero x axis"));
                }
                let x = x.normalize();
                let y = y - x * x.dot(&y);
                if y.norm() < 1e-12 {
                    return Err(zero("y axis parallel to the x axis"));
                }
                let y = y.normalize();
                let z = x.cross(&y);
                UnitQuaternion::from_matrix(&Matrix3::from_columns(&[x, y, z]))
            }
            "zaxis" => {
                let v = parse_numbers(el, a, element, 3, 3)?;
                let z = Vector3::new(v[0], v[1], v[2]);
                if z.norm() < 1e-12 {
                    return Err(zero("zero axis"));
                }
                z_to(&z)
            }
            _ => unreachable!("ORIENT lists the orientation attributes"),
        })
    }

    /// The placement of a geom or site in its body (or frame): from `fromto` (the midpoint,
    /// `z` along `from − to` as MuJoCo does; with the half length) when given by the element,
    /// or by its class and the element gives no `pos` or orientation; else `pos` and the
    /// orientation.
    fn pose(&self, el: &El, class: &Class, element: &str) -> Result<(Transform, Option<f64>)> {
        let fromto = self.nums(el, class, "fromto", 6, element)?;
        let own_fromto = el.attr("fromto").is_some();
        let own_pose =
            el.attr("pos").is_some() || el.attrs.iter().any(|a| ORIENT.contains(&a.name.as_str()));
        match fromto {
            Some(f) if own_fromto || !own_pose => {
                let (a, b) = (Vector3::new(f[0], f[1], f[2]), Vector3::new(f[3], f[4], f[5]));
                let len = (b - a).norm();
                if len < 1e-12 {
                    return Err(err_at(el, element, "fromto has zero length"));
                }
                Ok((unit_transform(&z_to(&(a - b)), (a + b) / 2.0), Some(len / 2.0)))
            }
            _ => {
                let q = self.orientation(el, Some(class), element)?;
                let p = self.vec3(el, class, "pos", element)?.unwrap_or_default();
                Ok((unit_transform(&q, p), None))
            }
        }
    }

    /// Attribute `name` of `el`, else of its class.
    fn get<'s>(&self, el: &'s El, class: &'s Class, name: &str) -> Option<&'s Attr> {
        el.attr(name).or_else(|| {
            class.attrs.get(&el.tag).and_then(|v| v.iter().find(|a| a.name == name)).map(|a| &**a)
        })
    }

    /// `n` numbers of attribute `name` (own or class), `None` if absent.
    fn nums(
        &self,
        el: &El,
        class: &Class,
        name: &str,
        n: usize,
        element: &str,
    ) -> Result<Option<Vec<f64>>> {
        match self.get(el, class, name) {
            Some(a) => Ok(Some(parse_numbers(el, a, element, n, n)?)),
            None => Ok(None),
        }
    }

    fn vec3(
        &self,
        el: &El,
        class: &Class,
        name: &str,
        element: &str,
    ) -> Result<Option<Vector3<f64>>> {
        Ok(self.nums(el, class, name, 3, element)?.map(|v| Vector3::new(v[0], v[1], v[2])))
    }

    fn scalar(&self, el: &El, class: &Class, name: &str, element: &str) -> Result<Option<f64>> {
        Ok(self.nums(el, class, name, 1, element)?.map(|v| v[0]))
    }

    fn word<'s>(&self, el: &'s El, class: &'s Class, name: &str) -> Option<&'s str> {
        self.get(el, class, name).map(|a| a.value.as_str())
    }

    // -----------------------------------------------------------------------------------------
    // The body tree.

    fn build(&mut self, root: &El, opts: &MjcfOptions) -> Result<Model> {
        let model_name = root.attr("model").map_or("MuJoCo Model".to_string(), |a| a.value.clone());
        // Gravity.
        let empty = Class::default();
        let mut gravity = Vector3::new(0.0, 0.0, -9.81);
        for o in root.elems("option") {
            if let Some(g) = self.vec3(o, &empty, "gravity", "<option>")? {
                gravity = g;
            }
            for f in o.elems("flag") {
                if let Some(a) = f.attr("gravity") {
                    match a.value.as_str() {
                        "disable" => gravity = Vector3::zeros(),
                        "enable" => {}
                        v => {
                            return Err(model_err(
                                &f.file,
                                a.line,
                                "<flag>",
                                format!("attribute gravity=\"{v}\": expected enable or disable"),
                            ));
                        }
                    }
                }
            }
        }
        // Read the tree.
        let root_class = "main".to_string();
        for wb in root.elems("worldbody") {
            if let Some(a) = wb.attrs.first() {
                return Err(model_err(
                    &wb.file,
                    a.line,
                    "<worldbody>",
                    format!(
                        "attribute {}=\"{}\": the world body has no attributes (MuJoCo refuses \
                         it too; a childclass belongs on a <body> or <frame>)",
                        a.name, a.value
                    ),
                ));
            }
            self.tree(wb, &root_class)?;
        }
        self.mass_rules()?;

        // Free joints on top-level bodies only; the floating-base option.
        let mut b = ModelBuilder::new(&model_name);
        b.set_gravity(gravity);
        if opts.floating_base {
            let top: Vec<usize> =
                (0..self.bodies.len()).filter(|&i| self.bodies[i].parent.is_none()).collect();
            if top.len() != 1 {
                return Err(model_err(
                    &root.file,
                    root.line,
                    "<worldbody>",
                    format!(
                        "the floating-base option needs exactly one body in <worldbody>, found {}",
                        top.len()
                    ),
                ));
            }
            let body = &self.bodies[top[0]];
            if !body.joints.is_empty() {
                return Err(model_err(
                    &body.file,
                    body.line,
                    &body_elem(body),
                    "the floating-base option adds a free joint to this body, which has joints \
                     of its own",
                ));
            }
        }
        // Joint names: explicit ones are reserved before unnamed joints are named.
        let mut taken: HashSet<String> = self
            .bodies
            .iter()
            .flat_map(|b| b.joints.iter().filter_map(|j| j.name.clone()))
            .collect();
        taken.insert("universe".into());
        if opts.floating_base && taken.contains(ROOT_JOINT_NAME) {
            let j = self
                .bodies
                .iter()
                .flat_map(|b| b.joints.iter())
                .find(|j| j.name.as_deref() == Some(ROOT_JOINT_NAME))
                .expect("the name is taken by a joint");
            return Err(model_err(
                &j.file,
                j.line,
                &format!("joint \"{ROOT_JOINT_NAME}\""),
                "the joint name \"root_joint\" is reserved for the floating-base option",
            ));
        }

        // (sodyn joint, placement of the body frame in that joint's frame) per body.
        let mut at: Vec<(usize, Transform)> = Vec::with_capacity(self.bodies.len());
        // MuJoCo's qpos0 (the reference configuration of the equality constraints), per sodyn
        // joint: a free joint at its body's pose, a hinge or slide at its `ref`; ball joints at
        // the identity.
        let mut qpos0: Vec<(usize, Vec<f64>)> = Vec::new();
        let pose7 = |t: &Transform| {
            let r = UnitQuaternion::from_matrix(&t.rot);
            let c = r.coords;
            vec![t.trans.x, t.trans.y, t.trans.z, c.x, c.y, c.z, c.w]
        };
        let mut jid = 0usize;
        let mut nv = 0usize;
        for i in 0..self.bodies.len() {
            let body = &self.bodies[i];
            let belem = body_elem(body);
            let wrap = |e: Error| match e {
                Error::Build(s) => model_err(&body.file, body.line, &belem, s),
                other => other,
            };
            let (pj, pplace) = match body.parent {
                Some(p) => at[p],
                None => (0, Transform::identity()),
            };
            let place = pplace.compose(&body.pose);
            let mut cur = (pj, place);
            if opts.floating_base && body.parent.is_none() {
                let id = b
                    .add_joint(0, ROOT_JOINT_NAME, JointType::FreeFlyer, Transform::identity())
                    .map_err(wrap)?;
                nv += 6;
                qpos0.push((id, pose7(&place)));
                cur = (id, Transform::identity());
            }
            // Anchor of the previous joint in the body frame (the chain's offset).
            let mut anchor = Vector3::zeros();
            let mut seen_ball = false;
            for (k, j) in body.joints.iter().enumerate() {
                let name = match &j.name {
                    Some(n) => n.clone(),
                    None => {
                        let mut n = format!("joint{jid}");
                        while taken.contains(&n) {
                            n.push('_');
                        }
                        taken.insert(n.clone());
                        n
                    }
                };
                jid += 1;
                let jelem = format!("joint \"{name}\"");
                let jerr = |reason: String| model_err(&j.file, j.line, &jelem, reason);
                let jwrap = |e: Error| match e {
                    Error::Build(s) => model_err(&j.file, j.line, &jelem, s),
                    other => other,
                };
                let limit = |nv: usize| {
                    if nv > MAX_URDF_DOFS {
                        return Err(jerr(format!(
                            "the model has more than {MAX_URDF_DOFS} degrees of freedom (the \
                             loader's limit, MAX_URDF_DOFS): {nv} up to this joint"
                        )));
                    }
                    Ok(())
                };
                if j.kind == JKind::Free {
                    if body.parent.is_some() || body.joints.len() > 1 {
                        return Err(jerr(format!(
                            "a free joint must be the only joint of a body directly in \
                             <worldbody>; {belem} {}",
                            if body.parent.is_some() {
                                "is nested in another body"
                            } else {
                                "has other joints"
                            }
                        )));
                    }
                    nv += 6;
                    limit(nv)?;
                    let id = b
                        .add_joint(0, &name, JointType::FreeFlyer, Transform::identity())
                        .map_err(jwrap)?;
                    b.set_armature(id, &[j.armature; 6]).map_err(jwrap)?;
                    qpos0.push((id, pose7(&place)));
                    cur = (id, Transform::identity());
                    continue;
                }
                if seen_ball && matches!(j.kind, JKind::Hinge | JKind::Ball) {
                    return Err(jerr(format!(
                        "a rotation follows a ball joint in body {belem} (MuJoCo refuses it too)"
                    )));
                }
                let (kind, off, c) = match j.kind {
                    JKind::Hinge => {
                        let r = UnitQuaternion::from_axis_angle(
                            &nalgebra::Unit::new_unchecked(j.axis),
                            -j.refpos,
                        );
                        (
                            JointType::Revolute { axis: j.axis },
                            unit_transform(&r, j.pos - anchor),
                            j.pos,
                        )
                    }
                    JKind::Slide => (
                        JointType::Prismatic { axis: j.axis },
                        Transform::from_translation(-j.axis * j.refpos - anchor),
                        Vector3::zeros(),
                    ),
                    JKind::Ball => {
                        seen_ball = true;
                        (JointType::Spherical, Transform::from_translation(j.pos - anchor), j.pos)
                    }
                    JKind::Free => unreachable!("handled above"),
                };
                let placement = if k == 0 { cur.1.compose(&off) } else { off };
                let parent = cur.0;
                nv += kind.nv();
                limit(nv)?;
                let id = b.add_joint(parent, &name, kind, placement).map_err(jwrap)?;
                if let Some((lo, hi)) = j.range {
                    b.set_limits(id, &[lo], &[hi]).map_err(jwrap)?;
                }
                b.set_armature(id, &vec![j.armature; kind.nv()]).map_err(jwrap)?;
                if matches!(j.kind, JKind::Hinge | JKind::Slide) {
                    qpos0.push((id, vec![j.refpos]));
                }
                anchor = c;
                cur = (id, Transform::identity());
            }
            if body.joints.iter().any(|j| j.kind != JKind::Free) {
                cur.1 = Transform::from_translation(-anchor);
            }
            if let Some(n) = &body.name {
                b.add_frame(n, cur.0, cur.1).map_err(wrap)?;
            }
            if let Some(inertia) = &body.inertia {
                b.append_inertia(cur.0, &cur.1, inertia).map_err(wrap)?;
            }
            at.push(cur);
        }
        // Sites (after every body, so that a site named like a body is the one skipped): the
        // world's, then the bodies'.
        let mut world_sites = Vec::new();
        for wb in root.elems("worldbody") {
            self.collect(
                wb,
                Transform::identity(),
                &root_class,
                &mut Vec::new(),
                &mut world_sites,
            )?;
        }
        let world_sites = world_sites.into_iter().map(|(n, p, l, f)| (n, (0, p), l, f));
        let body_sites = self.bodies.iter().enumerate().flat_map(|(i, body)| {
            let (j, place) = at[i];
            body.sites
                .iter()
                .map(move |(n, p, l, f)| (n.clone(), (j, place.compose(p)), *l, f.clone()))
        });
        let sites: Vec<_> = world_sites.chain(body_sites).collect();
        for (name, (j, place), line, file) in sites {
            if b.add_frame(&name, j, place).is_err() {
                self.warnings.push(format!(
                    "{file}:{line}: site \"{name}\": a frame of this name exists (a body's): the \
                     site is not a frame"
                ));
            }
        }
        let mut model = b.build_unchecked();
        model.validate().map_err(|e| Error::Model {
            file: root.file.to_string(),
            line: None,
            element: format!("model \"{}\"", model.name),
            reason: e.to_string(),
        })?;
        model.tendons = self.tendons(root, &model)?;
        let mut q0 = model.neutral();
        for (j, x) in &qpos0 {
            let a = model.idx_q[*j];
            q0.as_mut_slice()[a..a + x.len()].copy_from_slice(x);
        }
        let Equalities { contacts: constraints, mimics, rows } =
            self.equality(root, &model, &q0)?;
        model.constraints = constraints;
        let mut model = if !rows.is_empty() {
            // With a tendon coupling: the joint couplings are checked as mimic constraints
            // first (their errors), then every linear constraint is eliminated in turn.
            if !mimics.is_empty() {
                let (lines, ms): (Vec<_>, Vec<_>) = mimics.into_iter().unzip();
                model.with_mimic_joints(&ms).map_err(|e| mimic_error(e, &lines))?;
            }
            let (lines, couplings): (Vec<_>, Vec<_>) = eliminate(rows)?.into_iter().unzip();
            model.with_linear_couplings(&couplings).map_err(|e| {
                // "coupling K: REASON" names the constraint that eliminated the K-th joint.
                let Error::Build(full) = &e else { return e };
                let (k, msg) = full
                    .strip_prefix("coupling ")
                    .and_then(|r| r.split_once(": "))
                    .and_then(|(n, why)| Some((n.parse::<usize>().ok()?, why.to_string())))
                    .unwrap_or((0, full.clone()));
                match lines.get(k).or(lines.first()) {
                    Some((file, line, element)) => model_err(file, *line, element, msg),
                    None => e,
                }
            })?
        } else if mimics.is_empty() {
            model
        } else {
            let (lines, mimics): (Vec<_>, Vec<_>) = mimics.into_iter().unzip();
            model.with_mimic_joints(&mimics).map_err(|e| mimic_error(e, &lines))?
        };
        model.warnings = std::mem::take(&mut self.warnings);
        Ok(model)
    }

    /// The `<equality>` constraints: the `<connect>`s and `<weld>`s as two-frame constraints
    /// (frame B the world frame for a constraint with the world), placed from MuJoCo's reference
    /// configuration `q0` (qpos0), and the linear `<joint>` couplings as mimic constraints
    /// (each with its file, line and element, for the errors of the reduction).
    #[allow(clippy::type_complexity)]
    fn equality(
        &mut self,
        root: &El,
        model: &Model,
        q0: &nalgebra::DVector<f64>,
    ) -> Result<Equalities> {
        use super::{Contact, ContactType, JointCoupling};
        let mut contacts = Vec::new();
        let mut mimics = Vec::new();
        let mut rows = Vec::new();
        let mut any_tendon = false;
        // World placements of the joints at q0 (`ᵖM_i = placement_i · X_J(q_i)`, composed
        // from the root), then of the frames.
        let mut joint_world = vec![Transform::identity(); model.njoints()];
        for i in 1..model.njoints() {
            let (a, n) = (model.idx_q[i], model.nqs[i]);
            let local =
                model.placements[i].compose(&model.joints[i].transform(&q0.as_slice()[a..a + n]));
            joint_world[i] = joint_world[model.parents[i]].compose(&local);
        }
        let world = |f: usize| -> Transform {
            let frame = &model.frames[f];
            joint_world[frame.joint].compose(&frame.placement)
        };
        for eq in root.elems("equality") {
            for c in &eq.children {
                let name = c.attr("name").map_or(String::new(), |a| format!(" \"{}\"", a.value));
                let elem = format!("<{}>{name}", c.tag);
                let class = self.class_of(c, "main", &elem)?;
                // Attributes of the element, else of its class's <equality> defaults.
                let get = |key: &str| -> Option<&Attr> {
                    c.attr(key).or_else(|| {
                        class
                            .attrs
                            .get("equality")
                            .and_then(|v| v.iter().find(|a| a.name == key))
                            .map(|a| &**a)
                    })
                };
                if let Some(a) = get("active")
                    && !parse_bool(c, a, &elem)?
                {
                    continue;
                }
                let nums = |key: &str, n: usize, default: &[f64]| -> Result<Vec<f64>> {
                    match get(key) {
                        Some(a) => parse_numbers(c, a, &elem, n, n),
                        None => Ok(default.to_vec()),
                    }
                };
                let at_attr = |key: &str| get(key).map_or(c.line, |a| a.line);
                // `polycoef` (default `0 1`) of a linear coupling: its coefficients (0 past the
                // fifth), or an error naming the first nonzero non-linear one.
                let linear_polycoef = |other: &str| -> Result<[f64; 5]> {
                    let mut p = match get("polycoef") {
                        Some(a) => parse_numbers(c, a, &elem, 1, 5)?,
                        None => vec![0.0, 1.0],
                    };
                    p.resize(5, 0.0);
                    if let Some(i) = (2..5).find(|&i| p[i] != 0.0) {
                        return Err(model_err(
                            &c.file,
                            at_attr("polycoef"),
                            &elem,
                            format!(
                                "polycoef: coefficient {i} is {}: only a linear coupling \
                                 (c0 + c1 · {other}) is supported",
                                p[i]
                            ),
                        ));
                    }
                    Ok([p[0], p[1], p[2], p[3], p[4]])
                };
                // A body named by attribute `key`: (its frame, its name) — the world's for
                // "world" (or no attribute, when `optional`).
                let body = |key: &str, optional: bool| -> Result<usize> {
                    let Some(a) = c.attr(key) else {
                        if optional {
                            return Ok(0);
                        }
                        return Err(err_at(c, &elem, format!("attribute {key} is missing")));
                    };
                    if a.value == "world" {
                        return Ok(0);
                    }
                    let named = self.bodies.iter().any(|b| b.name.as_deref() == Some(&a.value));
                    match model.frame_id(&a.value) {
                        Ok(f) if named => Ok(f),
                        _ => Err(model_err(
                            &c.file,
                            a.line,
                            &elem,
                            format!("{key}=\"{}\": unknown body", a.value),
                        )),
                    }
                };
                match c.tag.as_str() {
                    "connect" | "weld" => {
                        if let Some(a) = c.attr("site1").or_else(|| c.attr("site2")) {
                            return Err(model_err(
                                &c.file,
                                a.line,
                                &elem,
                                format!(
                                    "attribute {}: constraints between sites are not supported \
                                     (give body1, body2 and anchor)",
                                    a.name
                                ),
                            ));
                        }
                        let (f1, f2) = (body("body1", false)?, body("body2", true)?);
                        let anchor = nums("anchor", 3, &[0.0; 3])?;
                        let anchor = Vector3::new(anchor[0], anchor[1], anchor[2]);
                        let (x1, x2) = (world(f1), world(f2));
                        // Frame A (on body1) and frame B (on body2) placements.
                        let (pa, pb, kind) = if c.tag == "connect" {
                            let pb = x2.inverse().act_point(&x1.act_point(&anchor));
                            (
                                Transform::from_translation(anchor),
                                Transform::from_translation(pb),
                                ContactType::D3,
                            )
                        } else {
                            let rp = nums("relpose", 7, &[0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])?;
                            let rel = if rp[3..].iter().all(|&x| x == 0.0) {
                                x1.inverse().compose(&x2)
                            } else {
                                let Some(r) = quat_wxyz(rp[3], rp[4], rp[5], rp[6]) else {
                                    return Err(model_err(
                                        &c.file,
                                        at_attr("relpose"),
                                        &elem,
                                        "relpose: the quaternion is not finite",
                                    ));
                                };
                                unit_transform(&r, Vector3::new(rp[0], rp[1], rp[2]))
                            };
                            let pb = Transform::from_translation(anchor);
                            (rel.compose(&pb), pb, ContactType::D6)
                        };
                        // Frame A must move: a constraint whose body1 is on the world is held
                        // from body2's side.
                        let (fa, pa, fb, pb) = if model.frames()[f1].joint == 0 {
                            (f2, pb, f1, pa)
                        } else {
                            (f1, pa, f2, pb)
                        };
                        let fname = |f: usize| model.frames()[f].name.clone();
                        let cst = Contact::new(model, &fname(fa), Vector3::zeros())
                            .and_then(|x| x.with_placement(model, &pa))
                            .map(|x| Contact { kind, ..x })
                            .and_then(|x| x.with_frame2(model, &fname(fb), Some(&pb)))
                            .map_err(|e| {
                                let why = match e {
                                    Error::Argument { reason, .. } => reason,
                                    e => e.to_string(),
                                };
                                err_at(c, &elem, why)
                            })?;
                        contacts.push(cst);
                    }
                    "joint" => {
                        let joint = |key: &str| -> Result<Option<usize>> {
                            let Some(a) = c.attr(key) else { return Ok(None) };
                            model.joint_id(&a.value).map(Some).map_err(|_| {
                                model_err(
                                    &c.file,
                                    a.line,
                                    &elem,
                                    format!("{key}=\"{}\": unknown joint", a.value),
                                )
                            })
                        };
                        let Some(j1) = joint("joint1")? else {
                            return Err(err_at(c, &elem, "attribute joint1 is missing"));
                        };
                        let Some(j2) = joint("joint2")? else {
                            return Err(err_at(
                                c,
                                &elem,
                                "no joint2: a joint held at a constant value is not supported \
                                 (only the coupling joint1 = c0 + c1 · joint2)",
                            ));
                        };
                        let coef = linear_polycoef("joint2")?;
                        // MuJoCo: q1 − q1(qpos0) = c0 + c1 (q2 − q2(qpos0)).
                        let (r1, r2) = (q0[model.idx_q[j1]], q0[model.idx_q[j2]]);
                        let (c0, c1) = (coef[0], coef[1]);
                        let loc = (c.file.clone(), c.line, elem.clone());
                        let offset = c0 + r1 - c1 * r2;
                        rows.push((
                            loc.clone(),
                            LinearRow {
                                terms: vec![(j1, 1.0), (j2, -c1)],
                                rhs: offset,
                                prefer: vec![j1, j2],
                            },
                        ));
                        mimics.push((
                            loc,
                            JointCoupling { joint: j1, reference: j2, multiplier: c1, offset },
                        ));
                    }
                    "tendon" => {
                        any_tendon = true;
                        // A fixed tendon named by attribute `key`: its (joint, coef) path.
                        let tendon = |key: &str| -> Result<Option<&[(usize, f64)]>> {
                            let Some(a) = c.attr(key) else { return Ok(None) };
                            let at = |why: String| model_err(&c.file, a.line, &elem, why);
                            let t = model
                                .tendons
                                .iter()
                                .find(|t| t.name.as_deref() == Some(a.value.as_str()))
                                .ok_or_else(|| {
                                    at(format!("{key}=\"{}\": unknown tendon", a.value))
                                })?;
                            match &t.path {
                                super::TendonPath::Fixed(p) => {
                                    if let Some(&(j, _)) = p.iter().find(|&&(j, _)| {
                                        !matches!(
                                            model.joints[j],
                                            JointType::Revolute { .. }
                                                | JointType::Continuous { .. }
                                                | JointType::Prismatic { .. }
                                        )
                                    }) {
                                        return Err(at(format!(
                                            "{key}=\"{}\": joint \"{}\" of the tendon is not a \
                                             scalar (hinge or slide) joint",
                                            a.value, model.names[j]
                                        )));
                                    }
                                    Ok(Some(p.as_slice()))
                                }
                                super::TendonPath::Spatial(_) => Err(at(format!(
                                    "{key}=\"{}\" is a spatial tendon: only fixed tendons \
                                     (linear in the joint coordinates) are supported in an \
                                     equality constraint",
                                    a.value
                                ))),
                            }
                        };
                        let Some(t1) = tendon("tendon1")? else {
                            return Err(err_at(c, &elem, "attribute tendon1 is missing"));
                        };
                        let t2 = tendon("tendon2")?;
                        let coef = linear_polycoef("tendon2")?;
                        // MuJoCo: L1 − L1(qpos0) = c0 + c1 (L2 − L2(qpos0)), L = Σ coef · q;
                        // without tendon2, L1 − L1(qpos0) = c0.
                        let (c0, c1) = (coef[0], if t2.is_some() { coef[1] } else { 0.0 });
                        let length = |t: &[(usize, f64)]| -> f64 {
                            t.iter().map(|&(j, x)| x * q0[model.idx_q[j]]).sum()
                        };
                        let mut terms: Vec<(usize, f64)> = t1.to_vec();
                        let mut rhs = c0 + length(t1);
                        let mut prefer: Vec<usize> = t1.iter().rev().map(|&(j, _)| j).collect();
                        if let Some(t2) = t2 {
                            rhs -= c1 * length(t2);
                            for &(j, x) in t2 {
                                match terms.iter_mut().find(|(i, _)| *i == j) {
                                    Some(t) => t.1 -= c1 * x,
                                    None => terms.push((j, -c1 * x)),
                                }
                            }
                            prefer.extend(t2.iter().rev().map(|&(j, _)| j));
                        }
                        if !rhs.is_finite() || terms.iter().any(|t| !t.1.is_finite()) {
                            return Err(model_err(
                                &c.file,
                                at_attr("polycoef"),
                                &elem,
                                "polycoef and the tendon coefficients must be finite",
                            ));
                        }
                        rows.push((
                            (c.file.clone(), c.line, elem.clone()),
                            LinearRow { terms, rhs, prefer },
                        ));
                    }
                    other => {
                        return Err(err_at(
                            c,
                            &elem,
                            format!(
                                "<{other}> equality constraints are not supported (only \
                                 <connect>, <weld>, and linear <joint> and fixed-<tendon> \
                                 couplings)"
                            ),
                        ));
                    }
                }
            }
        }
        Ok(Equalities { contacts, mimics, rows: if any_tendon { rows } else { Vec::new() } })
    }

    /// Reads the bodies of a `<worldbody>` depth-first in document order (MuJoCo's order),
    /// with an explicit stack: a chain of [`MAX_URDF_DOFS`] nested bodies does not recurse.
    fn tree<'e>(&mut self, worldbody: &'e El, childclass: &str) -> Result<()> {
        let mut stack: Vec<Item<'e>> = Vec::new();
        push_children(&mut stack, worldbody, None, Transform::identity(), childclass)?;
        while let Some(item) = stack.pop() {
            let Item { el, parent, frame, class } = item;
            if el.tag == "body" {
                let (index, cc) = self.body(el, parent, &frame, &class)?;
                push_children(&mut stack, el, Some(index), Transform::identity(), &cc)?;
            } else {
                let cc = el.attr("childclass").map_or(class.as_str(), |a| a.value.as_str());
                if !self.classes.contains_key(cc) {
                    return Err(err_at(el, "<frame>", format!("unknown default class \"{cc}\"")));
                }
                let q = self.orientation(el, None, "<frame>")?;
                let p = self.vec3(el, &Class::default(), "pos", "<frame>")?.unwrap_or_default();
                let f = frame.compose(&unit_transform(&q, p));
                if el.elems("joint").next().is_some() || el.elems("freejoint").next().is_some() {
                    return Err(err_at(el, "<frame>", "a <frame> cannot hold joints"));
                }
                let cc = cc.to_string();
                push_children(&mut stack, el, parent, f, &cc)?;
            }
        }
        Ok(())
    }

    /// Reads a `<body>` (not its child bodies) placed at `frame` in body `parent`; returns its
    /// index and the class of its children.
    fn body(
        &mut self,
        el: &El,
        parent: Option<usize>,
        frame: &Transform,
        childclass: &str,
    ) -> Result<(usize, String)> {
        let name = el.attr("name").map(|a| a.value.clone());
        let belem = match &name {
            Some(n) => format!("body \"{n}\""),
            None => "unnamed body".to_string(),
        };
        if let Some(a) = el.attr("class") {
            return Err(model_err(
                &el.file,
                a.line,
                &belem,
                format!(
                    "attribute class=\"{}\": a <body> has no class (MuJoCo refuses it too; \
                     childclass sets the class of the elements in it)",
                    a.value
                ),
            ));
        }
        let cc = el.attr("childclass").map_or(childclass, |a| a.value.as_str()).to_string();
        if !self.classes.contains_key(&cc) {
            return Err(err_at(el, &belem, format!("unknown default class \"{cc}\"")));
        }
        let empty = Class::default();
        let q = self.orientation(el, None, &belem)?;
        let p = self.vec3(el, &empty, "pos", &belem)?.unwrap_or_default();
        let pose = frame.compose(&unit_transform(&q, p));
        if let Some(g) = self.scalar(el, &empty, "gravcomp", &belem)?
            && g != 0.0
        {
            let reason = format!(
                "gravcomp=\"{g}\" ignored (gravity compensation is not part of the rigid-body \
                 dynamics)"
            );
            self.warn(&el.file.clone(), el.line, &belem, reason);
        }

        // Joints, in document order.
        let mut joints = Vec::new();
        for j in el.children.iter().filter(|c| c.tag == "joint" || c.tag == "freejoint") {
            joints.push(self.joint(j, &cc, &belem)?);
        }
        let index = self.bodies.len();
        // Geoms and sites, with the frames that hold them.
        let mut geoms: Vec<(&El, Transform, String)> = Vec::new();
        let mut sites = Vec::new();
        self.collect(el, Transform::identity(), &cc, &mut geoms, &mut sites)?;
        let inertial: Vec<&El> = el.elems("inertial").collect();
        if inertial.len() > 1 {
            return Err(err_at(inertial[1], &belem, "several <inertial> elements"));
        }
        // Does the body move (has joints, or is welded to a moving body)?
        let moving = !joints.is_empty() || parent.is_some_and(|p| self.moving(p));
        let use_geoms = match self.comp.inertiafromgeom {
            FromGeom::True => true,
            FromGeom::False => false,
            FromGeom::Auto => inertial.is_empty(),
        };
        let inertia = if use_geoms {
            self.geom_inertia(&geoms, &belem, el, moving)?
        } else if let Some(i) = inertial.first() {
            Some(self.inertial(i, &belem)?)
        } else {
            Some(Inertia::zero())
        };
        self.bodies.push(Body {
            name,
            file: el.file.clone(),
            line: el.line,
            parent,
            pose,
            joints,
            inertia,
            sites,
        });
        Ok((index, cc))
    }

    fn moving(&self, mut b: usize) -> bool {
        loop {
            if !self.bodies[b].joints.is_empty() {
                return true;
            }
            match self.bodies[b].parent {
                Some(p) => b = p,
                None => return false,
            }
        }
    }

    /// The geoms and named sites of a body (its own and those in its `<frame>`s), with their
    /// frame's placement and class name.
    fn collect<'e>(
        &self,
        el: &'e El,
        frame: Transform,
        cc: &str,
        geoms: &mut Vec<(&'e El, Transform, String)>,
        sites: &mut Vec<Site>,
    ) -> Result<()> {
        for c in &el.children {
            match c.tag.as_str() {
                "geom" => geoms.push((c, frame, cc.to_string())),
                "site" => {
                    if let Some(n) = c.attr("name") {
                        let selem = format!("site \"{}\"", n.value);
                        let class = self.class_of(c, cc, &selem)?;
                        let (pose, _) = self.pose(c, class, &selem)?;
                        sites.push((n.value.clone(), frame.compose(&pose), c.line, c.file.clone()));
                    }
                }
                "frame" => {
                    let ncc = c.attr("childclass").map_or(cc, |a| a.value.as_str());
                    let q = self.orientation(c, None, "<frame>")?;
                    let p = self.vec3(c, &Class::default(), "pos", "<frame>")?.unwrap_or_default();
                    self.collect(c, frame.compose(&unit_transform(&q, p)), ncc, geoms, sites)?;
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn joint(&mut self, el: &El, cc: &str, belem: &str) -> Result<Jnt> {
        let name = el.attr("name").map(|a| a.value.clone());
        let jelem = match &name {
            Some(n) => format!("joint \"{n}\""),
            None => format!("unnamed joint of {belem}"),
        };
        if el.tag == "freejoint" {
            if let Some(a) = el.attr("align")
                && a.value == "true"
            {
                return Err(model_err(&el.file, a.line, &jelem, "align=\"true\" is not supported"));
            }
            return Ok(Jnt {
                name,
                kind: JKind::Free,
                pos: Vector3::zeros(),
                axis: Vector3::z(),
                refpos: 0.0,
                range: None,
                armature: 0.0,
                file: el.file.clone(),
                line: el.line,
            });
        }
        let class = self.class_of(el, cc, &jelem)?.clone();
        let kind = match self.word(el, &class, "type").unwrap_or("hinge") {
            "hinge" => JKind::Hinge,
            "slide" => JKind::Slide,
            "ball" => JKind::Ball,
            "free" => JKind::Free,
            other => {
                let line = self.get(el, &class, "type").map_or(el.line, |a| a.line);
                return Err(model_err(
                    &el.file,
                    line,
                    &jelem,
                    format!("unknown joint type \"{other}\" (expected hinge, slide, ball or free)"),
                ));
            }
        };
        let pos = self.vec3(el, &class, "pos", &jelem)?.unwrap_or_default();
        let axis_raw = self.vec3(el, &class, "axis", &jelem)?.unwrap_or_else(Vector3::z);
        let axis = if matches!(kind, JKind::Hinge | JKind::Slide) {
            let n = axis_raw.norm();
            if n < 1e-12 {
                return Err(err_at(
                    el,
                    &jelem,
                    format!("zero axis [{} {} {}]", axis_raw.x, axis_raw.y, axis_raw.z),
                ));
            }
            axis_raw / n
        } else {
            axis_raw
        };
        let is_angle = kind == JKind::Hinge;
        let conv = |x: f64| if is_angle { self.angle(x) } else { x };
        let refpos = match kind {
            JKind::Hinge | JKind::Slide => {
                conv(self.scalar(el, &class, "ref", &jelem)?.unwrap_or(0.0))
            }
            _ => 0.0,
        };
        let range = self.nums(el, &class, "range", 2, &jelem)?;
        let limited = match self.word(el, &class, "limited").unwrap_or("auto") {
            "true" => true,
            "false" => false,
            "auto" => self.comp.autolimits && range.is_some(),
            other => {
                return Err(err_at(
                    el,
                    &jelem,
                    format!("limited=\"{other}\": expected true, false or auto"),
                ));
            }
        };
        let range = match (kind, limited, range) {
            (JKind::Hinge | JKind::Slide, true, Some(r)) => {
                let (lo, hi) = (conv(r[0]), conv(r[1]));
                if lo >= hi {
                    let line = self.get(el, &class, "range").map_or(el.line, |a| a.line);
                    return Err(model_err(
                        &el.file,
                        line,
                        &jelem,
                        format!("range [{} {}] is empty", r[0], r[1]),
                    ));
                }
                Some((lo, hi))
            }
            _ => None,
        };
        let armature = self.scalar(el, &class, "armature", &jelem)?.unwrap_or(0.0);
        if !armature.is_finite() || armature < 0.0 {
            let line = self.get(el, &class, "armature").map_or(el.line, |a| a.line);
            return Err(model_err(
                &el.file,
                line,
                &jelem,
                format!("armature=\"{armature}\" is negative or not finite"),
            ));
        }
        if kind == JKind::Free && armature != 0.0 {
            let file = el.file.clone();
            self.warn(
                &file,
                el.line,
                &jelem,
                format!(
                    "armature=\"{armature}\" on a free joint acts on sodyn's (Pinocchio's) \
                     body-frame velocity [ω; v]; MuJoCo's acts on [ṗ_world; ω]: M agrees, τ \
                     differs by armature·(ω × v) in the translation rows"
                ),
            );
        }
        Ok(Jnt {
            name,
            kind,
            pos,
            axis,
            refpos,
            range,
            armature,
            file: el.file.clone(),
            line: el.line,
        })
    }

    /// The body inertia of an `<inertial>`, in the body frame.
    fn inertial(&self, el: &El, belem: &str) -> Result<Inertia> {
        let empty = Class::default();
        let Some(pos) = self.vec3(el, &empty, "pos", belem)? else {
            return Err(err_at(el, belem, "<inertial> has no pos attribute"));
        };
        if el.attr("fullinertia").is_some()
            && let Some(a) = el.attrs.iter().find(|a| ORIENT.contains(&a.name.as_str()))
        {
            return Err(model_err(
                &el.file,
                a.line,
                belem,
                format!(
                    "<inertial> has both fullinertia and {} (the orientation of a full inertia \
                     is its own; MuJoCo refuses both too)",
                    a.name
                ),
            ));
        }
        let q = self.orientation(el, None, belem)?;
        let Some(mass) = self.scalar(el, &empty, "mass", belem)? else {
            return Err(err_at(el, belem, "<inertial> has no mass attribute"));
        };
        if mass < 0.0 {
            return Err(err_at(el, belem, format!("<inertial> has a negative mass {mass}")));
        }
        let diag = self.vec3(el, &empty, "diaginertia", belem)?;
        let full = self.nums(el, &empty, "fullinertia", 6, belem)?;
        let i_local = match (diag, full) {
            (Some(_), Some(_)) => {
                return Err(err_at(el, belem, "<inertial> has both diaginertia and fullinertia"));
            }
            (None, None) => {
                return Err(err_at(
                    el,
                    belem,
                    "<inertial> has neither diaginertia nor fullinertia",
                ));
            }
            (Some(d), None) => {
                if d.iter().any(|&x| x < 0.0) {
                    return Err(err_at(
                        el,
                        belem,
                        format!(
                            "<inertial> diaginertia=\"{} {} {}\" has a negative moment",
                            d.x, d.y, d.z
                        ),
                    ));
                }
                Matrix3::from_diagonal(&d)
            }
            (None, Some(f)) => Matrix3::new(f[0], f[3], f[4], f[3], f[1], f[5], f[4], f[5], f[2]),
        };
        let r = q.to_rotation_matrix();
        let r = r.matrix();
        let i_com = r * i_local * r.transpose();
        let inertia = Inertia::from_com(mass, pos, i_com);
        if let Some(d) = inertia_defect(&inertia)
            && !(self.comp.balanceinertia
                && matches!(d, crate::spatial::InertiaDefect::TriangleInequality(_)))
        {
            return Err(err_at(
                el,
                belem,
                format!("invalid <inertial>: {d} (MuJoCo refuses it too)"),
            ));
        }
        Ok(inertia)
    }

    /// The inertia of a body from its geoms (`None`: a static body with a geom whose inertia
    /// is not computed, e.g. a mesh).
    fn geom_inertia(
        &self,
        geoms: &[(&El, Transform, String)],
        belem: &str,
        body: &El,
        moving: bool,
    ) -> Result<Option<Inertia>> {
        let mut total = Inertia::zero();
        for (g, frame, cc) in geoms {
            let gelem = match g.attr("name") {
                Some(n) => format!("geom \"{}\" of {belem}", n.value),
                None => format!("geom of {belem}"),
            };
            let class = self.class_of(g, cc, &gelem)?;
            let int = |name: &str, default: i64| -> Result<i64> {
                match self.scalar(g, class, name, &gelem)? {
                    Some(x) if x.fract() == 0.0 => Ok(x as i64),
                    Some(x) => Err(err_at(g, &gelem, format!("{name}=\"{x}\" is not an integer"))),
                    None => Ok(default),
                }
            };
            let group = int("group", 0)?;
            if group < self.comp.group_range.0 || group > self.comp.group_range.1 {
                continue;
            }
            if self.word(g, class, "shellinertia") == Some("true") {
                return Err(err_at(
                    g,
                    &gelem,
                    "shellinertia=\"true\" is not supported (give the body an <inertial>)",
                ));
            }
            // A primitive with a mesh attribute is sized from the mesh (MuJoCo's default type
            // is sphere also then).
            let has_mesh = self.get(g, class, "mesh").is_some();
            let ty = self.word(g, class, "type").unwrap_or("sphere");
            let mass = self.scalar(g, class, "mass", &gelem)?;
            let density = self.scalar(g, class, "density", &gelem)?.unwrap_or(1000.0);
            if mass.is_some_and(|m| m < 0.0) || density < 0.0 {
                return Err(err_at(g, &gelem, "negative mass or density"));
            }
            let massless = mass == Some(0.0) || (mass.is_none() && density == 0.0);
            if self.comp.discardvisual
                && self.comp.inertiafromgeom == FromGeom::True
                && !massless
                && int("contype", 1)? == 0
                && int("conaffinity", 1)? == 0
            {
                return Err(err_at(
                    g,
                    &gelem,
                    "a visual geom (contype and conaffinity 0) with mass, which \
                     discardvisual=\"true\" would discard from the inertia that \
                     inertiafromgeom=\"true\" infers from the geoms (MuJoCo refuses it too; \
                     with inertiafromgeom=\"auto\" the geom counts)",
                ));
            }
            let what = match ty {
                "sphere" | "capsule" | "ellipsoid" | "cylinder" | "box" if has_mesh => {
                    format!("{ty} geom sized from a mesh")
                }
                "sphere" | "capsule" | "ellipsoid" | "cylinder" | "box" => String::new(),
                "plane" if moving => {
                    return Err(err_at(
                        g,
                        &gelem,
                        "a plane geom is only allowed in a static body (MuJoCo's rule)",
                    ));
                }
                "plane" => continue,
                "mesh" | "hfield" | "sdf" => format!("{ty} geom"),
                other => {
                    return Err(err_at(g, &gelem, format!("unknown geom type \"{other}\"")));
                }
            };
            if !what.is_empty() {
                if massless {
                    continue;
                }
                // A static body's inertia only matters for settotalmass.
                if !moving && self.comp.settotalmass <= 0.0 {
                    return Ok(None);
                }
                return Err(err_at(
                    body,
                    belem,
                    format!(
                        "the body's inertia would come from a {what} (line {}), which sodyn \
                         cannot compute: give the body an <inertial> element",
                        g.line
                    ),
                ));
            }
            let mut size = [0.0; 3];
            if let Some(a) = g.attr("size") {
                // A partial size on the element keeps the class's (or the default's) other entries.
                if let Some(ca) =
                    class.attrs.get("geom").and_then(|v| v.iter().find(|b| b.name == "size"))
                {
                    for (k, x) in parse_numbers(g, ca, &gelem, 1, 3)?.into_iter().enumerate() {
                        size[k] = x;
                    }
                }
                for (k, x) in parse_numbers(g, a, &gelem, 1, 3)?.into_iter().enumerate() {
                    size[k] = x;
                }
            } else if let Some(a) = self.get(g, class, "size") {
                for (k, x) in parse_numbers(g, a, &gelem, 1, 3)?.into_iter().enumerate() {
                    size[k] = x;
                }
            }
            let (pose, half) = self.pose(g, class, &gelem)?;
            if let Some(h) = half {
                match ty {
                    "capsule" | "cylinder" => size[1] = h,
                    "box" | "ellipsoid" => {
                        size[1] = size[0];
                        size[2] = h;
                    }
                    _ => {
                        return Err(err_at(
                            g,
                            &gelem,
                            "fromto requires a capsule, cylinder, box or ellipsoid",
                        ));
                    }
                }
            }
            let n = match ty {
                "sphere" => 1,
                "capsule" | "cylinder" => 2,
                _ => 3,
            };
            if size[..n].iter().any(|&s| s < 0.0) {
                return Err(err_at(g, &gelem, format!("negative size {:?}", &size[..n])));
            }
            let (vol, unit) = primitive(ty, &size);
            let m = match mass {
                Some(m) => m,
                None => density * vol,
            };
            let i = if vol > 0.0 { unit * m } else { Matrix3::zeros() };
            let gi = Inertia::from_com(m, Vector3::zeros(), i);
            total += frame.compose(&pose).act_inertia(&gi);
        }
        Ok(Some(total))
    }

    /// The `<tendon>` elements, checked as MuJoCo checks them (the joints, sites and geoms
    /// they name exist; a fixed path has distinct hinge or slide joints, a spatial one at
    /// least two elements, each geom between two sites and each site next to a non-pulley).
    fn tendons(&mut self, root: &El, model: &Model) -> Result<Vec<Tendon>> {
        let mut sites = HashSet::new();
        let mut geoms = HashSet::new();
        let mut stack: Vec<&El> = root.elems("worldbody").collect();
        while let Some(el) = stack.pop() {
            for c in &el.children {
                match (c.tag.as_str(), c.attr("name")) {
                    ("site", Some(n)) => {
                        sites.insert(n.value.as_str());
                    }
                    ("geom", Some(n)) => {
                        geoms.insert(n.value.as_str());
                    }
                    ("body" | "frame", _) => stack.push(c),
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        let mut names = HashSet::new();
        let mut first: Option<&El> = None;
        let (mut nfixed, mut nspatial) = (0usize, 0usize);
        for sec in root.elems("tendon") {
            for t in &sec.children {
                let name = t.attr("name").map(|a| a.value.clone());
                let telem = match &name {
                    Some(n) => format!("tendon \"{n}\""),
                    None => format!("unnamed <{}> tendon", t.tag),
                };
                if t.tag != "fixed" && t.tag != "spatial" {
                    return Err(err_at(
                        t,
                        &format!("<{}>", t.tag),
                        format!("<{}> in <tendon> (expected <fixed> or <spatial>)", t.tag),
                    ));
                }
                if let Some(n) = &name
                    && !names.insert(n.clone())
                {
                    return Err(err_at(t, &telem, "a second tendon of this name"));
                }
                first.get_or_insert(t);
                let cname = t.attr("class").map_or("main", |a| a.value.as_str());
                let Some(class) = self.classes.get(cname) else {
                    return Err(err_at(t, &telem, format!("unknown default class \"{cname}\"")));
                };
                let armature = t.attr("armature").or_else(|| {
                    class.attrs.get("tendon")?.iter().find(|a| a.name == "armature").map(|a| &**a)
                });
                if let Some(a) = armature {
                    let x = parse_numbers(t, a, &telem, 1, 1)?[0];
                    if x < 0.0 {
                        return Err(model_err(
                            &t.file,
                            a.line,
                            &telem,
                            format!("armature=\"{x}\" is negative (MuJoCo refuses it too)"),
                        ));
                    }
                    if x > 0.0 {
                        return Err(model_err(
                            &t.file,
                            a.line,
                            &telem,
                            format!(
                                "tendon armature=\"{x}\" is not supported: MuJoCo adds \
                                 armature · JᵀJ (J the tendon's Jacobian) to the mass matrix, \
                                 which sodyn does not model (remove it, or move it to the joints)"
                            ),
                        ));
                    }
                }
                let path = if t.tag == "fixed" {
                    nfixed += 1;
                    let mut joints: Vec<(usize, f64)> = Vec::new();
                    for c in &t.children {
                        let celem = format!("<{}> of {telem}", c.tag);
                        if c.tag != "joint" {
                            return Err(err_at(c, &celem, "a fixed tendon holds only <joint>s"));
                        }
                        let (Some(j), Some(coef)) = (c.attr("joint"), c.attr("coef")) else {
                            return Err(err_at(
                                c,
                                &celem,
                                "a tendon <joint> needs the joint and coef attributes",
                            ));
                        };
                        let coef = parse_numbers(c, coef, &celem, 1, 1)?[0];
                        let id = model.joint_id(&j.value).map_err(|_| {
                            err_at(c, &celem, format!("unknown joint \"{}\"", j.value))
                        })?;
                        if !matches!(
                            model.joints()[id],
                            JointType::Revolute { .. } | JointType::Prismatic { .. }
                        ) {
                            return Err(err_at(
                                c,
                                &celem,
                                format!(
                                    "joint \"{}\" is not a hinge or slide joint (MuJoCo refuses \
                                     it too)",
                                    j.value
                                ),
                            ));
                        }
                        if joints.iter().any(|&(k, _)| k == id) {
                            return Err(err_at(
                                c,
                                &celem,
                                format!(
                                    "joint \"{}\" is repeated (MuJoCo refuses it too)",
                                    j.value
                                ),
                            ));
                        }
                        joints.push((id, coef));
                    }
                    if joints.is_empty() {
                        return Err(err_at(t, &telem, "empty path (MuJoCo refuses it too)"));
                    }
                    TendonPath::Fixed(joints)
                } else {
                    nspatial += 1;
                    let mut path = Vec::new();
                    for c in &t.children {
                        let celem = format!("<{}> of {telem}", c.tag);
                        let need = |a: &str| {
                            c.attr(a)
                                .ok_or_else(|| err_at(c, &celem, format!("missing {a} attribute")))
                        };
                        let known = |set: &HashSet<&str>, what: &str, n: &str| {
                            if set.contains(n) {
                                Ok(())
                            } else {
                                Err(err_at(c, &celem, format!("unknown {what} \"{n}\"")))
                            }
                        };
                        path.push(match c.tag.as_str() {
                            "site" => {
                                let n = &need("site")?.value;
                                known(&sites, "site", n)?;
                                SpatialWrap::Site(n.clone())
                            }
                            "geom" => {
                                let n = &need("geom")?.value;
                                known(&geoms, "geom", n)?;
                                let sidesite = c.attr("sidesite").map(|a| a.value.clone());
                                if let Some(ss) = &sidesite {
                                    known(&sites, "side site", ss)?;
                                }
                                SpatialWrap::Geom { geom: n.clone(), sidesite }
                            }
                            "pulley" => SpatialWrap::Pulley {
                                divisor: parse_numbers(c, need("divisor")?, &celem, 1, 1)?[0],
                            },
                            _ => {
                                return Err(err_at(
                                    c,
                                    &celem,
                                    "a spatial tendon holds <site>, <geom> and <pulley> elements",
                                ));
                            }
                        });
                    }
                    if path.len() < 2 {
                        return Err(err_at(
                            t,
                            &telem,
                            "a spatial path needs at least two elements (MuJoCo refuses it too)",
                        ));
                    }
                    let site = |k: Option<usize>| {
                        k.and_then(|k| path.get(k))
                            .is_some_and(|w| matches!(w, SpatialWrap::Site(_)))
                    };
                    let segment = |k: Option<usize>| {
                        k.and_then(|k| path.get(k))
                            .is_some_and(|w| !matches!(w, SpatialWrap::Pulley { .. }))
                    };
                    for (k, w) in path.iter().enumerate() {
                        let bad = match w {
                            SpatialWrap::Geom { .. } => {
                                !(site(k.checked_sub(1)) && site(Some(k + 1)))
                            }
                            SpatialWrap::Site(_) => {
                                !(segment(k.checked_sub(1)) || segment(Some(k + 1)))
                            }
                            SpatialWrap::Pulley { .. } => false,
                        };
                        if bad {
                            let what = match w {
                                SpatialWrap::Geom { .. } => "is not between two sites",
                                _ => "has no neighbour that is a site or geom",
                            };
                            let c = t.children.get(k).unwrap_or(t);
                            return Err(err_at(
                                c,
                                &telem,
                                format!(
                                    "path element {} (<{}>) {what} (MuJoCo refuses it too)",
                                    k + 1,
                                    c.tag
                                ),
                            ));
                        }
                    }
                    TendonPath::Spatial(path)
                };
                out.push(Tendon { name, path });
            }
        }
        if let Some(t) = first {
            let (file, line) = (t.file.clone(), t.line);
            self.warn(
                &file,
                line,
                "<tendon>",
                format!(
                    "{} tendons ({nfixed} fixed, {nspatial} spatial) are recorded \
                     (Model::tendons) but do not enter the dynamics: tendon limits, springs, \
                     damping, friction loss and actuation are not modelled",
                    out.len()
                ),
            );
        }
        Ok(out)
    }

    /// MuJoCo's per-body rules after the inertias are known: `boundmass`, `boundinertia`,
    /// `balanceinertia`, positive mass and moments of moving bodies, `settotalmass`.
    fn mass_rules(&mut self) -> Result<()> {
        let (bm, bi, bal) = (self.comp.boundmass, self.comp.boundinertia, self.comp.balanceinertia);
        for i in 0..self.bodies.len() {
            let body = &mut self.bodies[i];
            let Some(inertia) = &mut body.inertia else { continue };
            let mass = inertia.mass;
            let com = if mass > 0.0 { inertia.com() } else { Vector3::zeros() };
            let ic = if mass > 0.0 { inertia.inertia_about_com() } else { inertia.rot };
            let eig = SymmetricEigen::new(ic);
            let mut ev = eig.eigenvalues;
            let mut changed = false;
            if mass < bm {
                changed = true;
            }
            for x in ev.iter_mut() {
                if *x < bi {
                    *x = bi;
                    changed = true;
                }
            }
            if bal {
                let s = ev.sum();
                if (0..3).any(|k| ev[k] > s - ev[k]) {
                    ev = Vector3::repeat(s / 3.0);
                    changed = true;
                }
            }
            if changed {
                let m = mass.max(bm);
                let r = eig.eigenvectors;
                let ic = r * Matrix3::from_diagonal(&ev) * r.transpose();
                *inertia = Inertia::from_com(m, com, (ic + ic.transpose()) * 0.5);
            }
        }
        // MuJoCo's rule on a body with joints: the inertia of the body and the bodies welded
        // to it (its weld group, one sodyn joint's body) has a positive mass and positive
        // principal moments.
        let mut group: Vec<Option<(usize, Transform)>> = Vec::with_capacity(self.bodies.len());
        let mut composite: Vec<Inertia> = vec![Inertia::zero(); self.bodies.len()];
        for i in 0..self.bodies.len() {
            let body = &self.bodies[i];
            let g = if body.joints.is_empty() {
                body.parent
                    .and_then(|p| group[p])
                    .map(|(root, place): (usize, Transform)| (root, place.compose(&body.pose)))
            } else {
                Some((i, Transform::identity()))
            };
            if let (Some((root, place)), Some(inertia)) = (g, &body.inertia) {
                composite[root] += place.act_inertia(inertia);
            }
            group.push(g);
        }
        for (body, inertia) in self.bodies.iter().zip(&composite) {
            if body.joints.is_empty() {
                continue;
            }
            let ev = if inertia.mass > 0.0 {
                SymmetricEigen::new(inertia.inertia_about_com()).eigenvalues
            } else {
                Vector3::zeros()
            };
            if inertia.mass.is_nan() || inertia.mass <= 1e-15 || ev.min() < 1e-15 {
                return Err(model_err(
                    &body.file,
                    body.line,
                    &body_elem(body),
                    format!(
                        "a moving body (with the bodies welded to it) needs a positive mass and \
                         positive principal moments (MuJoCo's rule; mass {}, moments [{:e} {:e} \
                         {:e}])",
                        inertia.mass, ev[0], ev[1], ev[2]
                    ),
                ));
            }
        }
        if self.comp.settotalmass > 0.0 {
            let total: f64 = self.bodies.iter().map(|b| b.inertia.map_or(0.0, |i| i.mass)).sum();
            if total > 0.0 {
                let s = self.comp.settotalmass / total;
                for b in &mut self.bodies {
                    if let Some(i) = &mut b.inertia {
                        i.mass *= s;
                        i.h *= s;
                        i.rot *= s;
                    }
                }
            }
        }
        Ok(())
    }
}

/// A `<body>` or `<frame>` to read, with its parent body, the placement of its parent element
/// in that body, and the class it inherits.
struct Item<'e> {
    el: &'e El,
    parent: Option<usize>,
    frame: Transform,
    class: String,
}

/// Pushes the `<body>` and `<frame>` children of `el` onto `stack`, the first one on top; an
/// element that would add bodies sodyn cannot read is an error.
fn push_children<'e>(
    stack: &mut Vec<Item<'e>>,
    el: &'e El,
    parent: Option<usize>,
    frame: Transform,
    class: &str,
) -> Result<()> {
    for c in &el.children {
        if let "composite" | "flexcomp" | "replicate" | "attach" | "flex" = c.tag.as_str() {
            return Err(err_at(
                c,
                &format!("<{}>", c.tag),
                format!("<{}> is not supported (it adds bodies or degrees of freedom)", c.tag),
            ));
        }
    }
    for c in el.children.iter().rev().filter(|c| c.tag == "body" || c.tag == "frame") {
        stack.push(Item { el: c, parent, frame, class: class.to_string() });
    }
    Ok(())
}

/// The elements a `<default>` may hold (besides nested `<default>`s), as MuJoCo's schema.
const DEFAULT_ELEMENTS: [&str; 21] = [
    "mesh",
    "material",
    "texture",
    "joint",
    "geom",
    "site",
    "camera",
    "light",
    "pair",
    "equality",
    "tendon",
    "general",
    "motor",
    "position",
    "velocity",
    "intvelocity",
    "damper",
    "cylinder",
    "muscle",
    "adhesion",
    "dcmotor",
];

const ORIENT: [&str; 5] = ["quat", "axisangle", "euler", "xyaxes", "zaxis"];

fn body_elem(b: &Body) -> String {
    match &b.name {
        Some(n) => format!("body \"{n}\""),
        None => "unnamed body".to_string(),
    }
}

/// Volume and rotational inertia per unit mass (about the centre, in the geom frame) of a
/// primitive geom with MuJoCo's `size`.
fn primitive(ty: &str, s: &[f64; 3]) -> (f64, Matrix3<f64>) {
    use std::f64::consts::PI;
    let d = |a: f64, b: f64, c: f64| Matrix3::from_diagonal(&Vector3::new(a, b, c));
    match ty {
        "sphere" => {
            let r = s[0];
            (4.0 / 3.0 * PI * r * r * r, d(0.4 * r * r, 0.4 * r * r, 0.4 * r * r))
        }
        "capsule" => {
            let (r, h) = (s[0], 2.0 * s[1]);
            let vs = 4.0 / 3.0 * PI * r * r * r;
            let vc = PI * r * r * h;
            let v = vs + vc;
            if v <= 0.0 {
                return (0.0, Matrix3::zeros());
            }
            let (fs, fc) = (vs / v, vc / v);
            let t = fc * (3.0 * r * r + h * h) / 12.0
                + fs * (0.4 * r * r + h * h / 4.0 + 3.0 * h * r / 8.0);
            let a = fc * r * r / 2.0 + fs * 0.4 * r * r;
            (v, d(t, t, a))
        }
        "cylinder" => {
            let (r, h) = (s[0], 2.0 * s[1]);
            let t = (3.0 * r * r + h * h) / 12.0;
            (PI * r * r * h, d(t, t, r * r / 2.0))
        }
        "ellipsoid" => {
            let (a, b, c) = (s[0], s[1], s[2]);
            (
                4.0 / 3.0 * PI * a * b * c,
                d((b * b + c * c) / 5.0, (a * a + c * c) / 5.0, (a * a + b * b) / 5.0),
            )
        }
        _ => {
            // box, half sizes
            let (a, b, c) = (s[0], s[1], s[2]);
            (
                8.0 * a * b * c,
                d((b * b + c * c) / 3.0, (a * a + c * c) / 3.0, (a * a + b * b) / 3.0),
            )
        }
    }
}
