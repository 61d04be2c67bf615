//! Built-in robot models, written in code (no URDF needed): a serial chain, an n-link planar
//! pendulum, random kinematic trees, a quadruped, a humanoid, a four-bar linkage and a
//! delta-type parallel robot (closed kinematic chains, their loops in [`Model::constraints`]).
//!
//! | name (for [`by_name`])          | builder                          | floating | nq   | nv   |
//! |---------------------------------|----------------------------------|----------|------|------|
//! | `humanoid`                      | [`humanoid`]`()`                 | yes      | 39   | 38   |
//! | `quadruped`                     | [`quadruped`]`()`                | yes      | 19   | 18   |
//! | `chain<N>`, `serial_chain<N>`   | [`serial_chain`]`(N)`            | no       | N    | N    |
//! | `pendulum<N>`                   | [`pendulum`]`(N)`                | no       | N    | N    |
//! | `random_tree<N>[_ff][_s<SEED>]` | [`random_tree`]`(N, SEED, _ff?)` | if `_ff` | var. | var. |
//! | `fourbar`                       | [`fourbar`]`()`                  | no       | 6    | 5    |
//! | `delta`                         | [`delta`]`()`                    | no¹      | 22   | 18   |
//!
//! ¹ The base is fixed; the delta's moving platform is on a free-flyer joint, held by the
//! model's three loops.
//!
//! Every body of every built-in model carries mass and a physically valid rotational inertia
//! (principal moments satisfying the triangle inequality; all positive except for the point
//! masses of [`pendulum`]), so the joint-space mass matrix is positive definite at every
//! configuration. All models are deterministic: the same
//! arguments always give the same model.

use super::joint::{JointType, quat_to_rot};
use super::tree::{Model, ModelBuilder};
use crate::rng::Rng;
use crate::spatial::{Inertia, Transform};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::{FRAC_PI_2, PI};

/// Largest `N` accepted by [`by_name`] for the parameterised families (`chain<N>`,
/// `pendulum<N>`, `random_tree<N>`).
pub const MAX_NAMED_JOINTS: usize = 10_000;

// ---------------------------------------------------------------------------------------------
// Small helpers.
// ---------------------------------------------------------------------------------------------

/// Wraps [`ModelBuilder`]: the built-in models are valid by construction, so a builder error is
/// a bug in this module and panics with its message.
struct Builder(ModelBuilder);

impl Builder {
    fn new(name: &str) -> Self {
        Self(ModelBuilder::new(name))
    }
    fn body(
        &mut self,
        parent: usize,
        joint: &str,
        kind: JointType,
        placement: Transform,
        body: &str,
        inertia: Inertia,
    ) -> usize {
        self.0
            .add_body(parent, joint, kind, placement, body, inertia)
            .unwrap_or_else(|e| panic!("built-in model: joint {joint}: {e}"))
    }
    /// A revolute joint with limits `[lo, hi]`.
    #[allow(clippy::too_many_arguments)]
    fn revolute(
        &mut self,
        parent: usize,
        joint: &str,
        axis: Vector3<f64>,
        placement: Transform,
        body: &str,
        inertia: Inertia,
        lo: f64,
        hi: f64,
    ) -> usize {
        let id = self.body(parent, joint, JointType::Revolute { axis }, placement, body, inertia);
        self.limits(id, lo, hi);
        id
    }
    fn limits(&mut self, joint: usize, lo: f64, hi: f64) {
        self.0
            .set_limits(joint, &[lo], &[hi])
            .unwrap_or_else(|e| panic!("built-in model: limits of joint {joint}: {e}"));
    }
    /// A rigidly attached body (emulated fixed joint): its inertia, given in a frame at
    /// `placement` in joint `joint`'s body frame, is merged into that body, and a frame named
    /// `name` is added at `placement`.
    fn fixed(&mut self, joint: usize, name: &str, placement: Transform, inertia: Inertia) {
        self.0
            .append_inertia(joint, &placement, &inertia)
            .unwrap_or_else(|e| panic!("built-in model: fixed body {name}: {e}"));
        self.frame(name, joint, placement);
    }
    fn frame(&mut self, name: &str, joint: usize, placement: Transform) {
        self.0
            .add_frame(name, joint, placement)
            .unwrap_or_else(|e| panic!("built-in model: frame {name}: {e}"));
    }
    fn build(self) -> Model {
        self.0.build().unwrap_or_else(|e| panic!("built-in model: {e}"))
    }
}

fn v3(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn at(x: f64, y: f64, z: f64) -> Transform {
    Transform::from_translation(v3(x, y, z))
}

/// Rotational inertia (about its centre) of a solid box with side lengths `d`, axis-aligned.
fn box_rot(mass: f64, d: [f64; 3]) -> Matrix3<f64> {
    let [x, y, z] = d.map(|s| s * s);
    Matrix3::from_diagonal(&v3(y + z, x + z, x + y)) * (mass / 12.0)
}

/// Rotational inertia (about its centre) of a solid cylinder of radius `r`, length `l` along z.
fn cylinder_z_rot(mass: f64, r: f64, l: f64) -> Matrix3<f64> {
    let t = mass * (3.0 * r * r + l * l) / 12.0;
    Matrix3::from_diagonal(&v3(t, t, 0.5 * mass * r * r))
}

/// Rotational inertia of a solid sphere of radius `r`.
fn sphere_rot(mass: f64, r: f64) -> Matrix3<f64> {
    Matrix3::identity() * (0.4 * mass * r * r)
}

/// A solid box body: mass, centre of mass and side lengths.
fn box_body(mass: f64, com: Vector3<f64>, d: [f64; 3]) -> Inertia {
    Inertia::from_com(mass, com, box_rot(mass, d))
}

/// A solid cylinder link along z (radius `r`, length `l`) with its centre of mass at `com`.
fn rod_body(mass: f64, com: Vector3<f64>, r: f64, l: f64) -> Inertia {
    Inertia::from_com(mass, com, cylinder_z_rot(mass, r, l))
}

/// Normalised vector.
fn unit(x: f64, y: f64, z: f64) -> Vector3<f64> {
    v3(x, y, z).normalize()
}

// ---------------------------------------------------------------------------------------------
// Serial chain and pendulum.
// ---------------------------------------------------------------------------------------------

/// A fixed-base serial chain of `n` revolute joints (nq = nv = `n`), for tests and benchmarks.
///
/// Joint `k` (1-based) is named `joint_k` and moves body/frame `link_k`; a frame `ee` sits at
/// the tip of the last link. The joint axes cycle through z, y, x and two oblique unit axes,
/// so consecutive axes are never parallel. Each joint frame is placed with a non-trivial
/// rotation and offset (about 0.25 m along the link), and each link has mass 1–1.75 kg, an
/// off-axis centre of mass and a full (rotated box) 3×3 rotational inertia. Joints have no
/// limits. `serial_chain(0)` is the empty (world-only) model.
pub fn serial_chain(n: usize) -> Model {
    let axes =
        [Vector3::z(), Vector3::y(), Vector3::x(), unit(1.0, 1.0, 0.0), unit(0.0, -1.0, 2.0)];
    let link = |k: usize| {
        let kf = k as f64;
        let mass = 1.0 + 0.25 * (k % 4) as f64;
        let com = v3(0.02 + 0.01 * (k % 3) as f64, -0.015, 0.12);
        let r = Transform::from_rpy_xyz([0.2, 0.1 + 0.05 * kf, 0.3 * kf], [0.0; 3]).rot;
        let rot = r * box_rot(mass, [0.06, 0.08, 0.25]) * r.transpose();
        Inertia::from_com(mass, com, rot)
    };
    let mut b = Builder::new(&format!("serial_chain{n}"));
    let mut parent = 0;
    for k in 0..n {
        let kf = k as f64;
        let sign = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
        let placement = if k == 0 {
            Transform::from_rpy_xyz([0.0, 0.0, 0.1], [0.0, 0.0, 0.1])
        } else {
            Transform::from_rpy_xyz(
                [0.3 * ((k % 3) as f64 - 1.0), 0.15 * sign, 0.1 * (kf % 5.0)],
                [0.05, 0.02 * sign, 0.25],
            )
        };
        let kind = JointType::Revolute { axis: axes[k % axes.len()] };
        parent = b.body(
            parent,
            &format!("joint_{}", k + 1),
            kind,
            placement,
            &format!("link_{}", k + 1),
            link(k),
        );
    }
    b.frame("ee", parent, at(0.05, 0.0, 0.25));
    b.build()
}

/// A fixed-base planar `n`-link pendulum swinging about y (nq = nv = `n`), a small sanity model
/// with known closed-form dynamics.
///
/// Joint `k` (1-based, `joint_k`, revolute about y, no limits) sits at the tip of link `k − 1`
/// (the first at the world origin); link `k` (frame `link_k`) hangs 1 m along −z and carries a
/// 1 kg point mass at its tip (zero rotational inertia about the mass). A frame `tip` is at the
/// last mass. Gravity is the default −9.81 m/s² along z, so q = 0 hangs straight down.
pub fn pendulum(n: usize) -> Model {
    let mut b = Builder::new(&format!("pendulum{n}"));
    let mut parent = 0;
    for k in 0..n {
        let placement = if k == 0 { Transform::identity() } else { at(0.0, 0.0, -1.0) };
        parent = b.body(
            parent,
            &format!("joint_{}", k + 1),
            JointType::Revolute { axis: Vector3::y() },
            placement,
            &format!("link_{}", k + 1),
            Inertia::from_com(1.0, v3(0.0, 0.0, -1.0), Matrix3::zeros()),
        );
    }
    b.frame("tip", parent, at(0.0, 0.0, -1.0));
    b.build()
}

/// A four-bar linkage in the x–z plane, its loop closed by a 3-D connect (nq = 6, nv = 5).
///
/// The tree: `crank` (revolute `crank_joint` about y at the world origin, 0.2 m long, hanging
/// along −z at q = 0), `coupler` (ball joint `coupler_joint` at the crank tip, frame
/// `crank_tip`) and `rocker` (revolute `rocker_joint` about y at the ground pivot (0.3, 0, 0),
/// 0.25 m long, 0.3 rad from −z towards +x at q = 0). The loop: frame `coupler_tip` on the
/// coupler and frame `rocker_tip` on the rocker coincide at the neutral configuration (q = 0,
/// the ball joint's quaternion the identity); [`fourbar_loop`] is that constraint. The
/// coupler's ball joint (instead of a third hinge) keeps the connect's three rows independent:
/// with three parallel hinges, the out-of-plane row of a 3-D connect is identically zero. The
/// mechanism has two DoF: the crank angle and the coupler's spin about the line through its
/// two ends. Every link is a solid box with its own mass and inertia.
pub fn fourbar() -> Model {
    let (l1, l3, pivot, tilt) = (0.2, 0.25, 0.3, 0.3f64);
    let b_pt = v3(0.0, 0.0, -l1);
    let c_pt = v3(pivot + l3 * tilt.sin(), 0.0, -l3 * tilt.cos());
    let coupler = c_pt - b_pt;
    let mut b = Builder::new("fourbar");
    let hinge = JointType::Revolute { axis: Vector3::y() };
    let crank = b.body(
        0,
        "crank_joint",
        hinge,
        Transform::identity(),
        "crank",
        box_body(0.5, b_pt * 0.5, [0.02, 0.03, l1]),
    );
    let coupler_id = b.body(
        crank,
        "coupler_joint",
        JointType::Spherical,
        Transform::from_translation(b_pt),
        "coupler",
        box_body(0.8, coupler * 0.5 + v3(0.0, 0.01, 0.0), [coupler.norm(), 0.03, 0.02]),
    );
    let rocker = b.body(
        0,
        "rocker_joint",
        hinge,
        at(pivot, 0.0, 0.0),
        "rocker",
        box_body(0.6, (c_pt - v3(pivot, 0.0, 0.0)) * 0.5, [0.02, 0.04, l3]),
    );
    b.frame("crank_tip", crank, Transform::from_translation(b_pt));
    b.frame("coupler_tip", coupler_id, Transform::from_translation(coupler));
    b.frame("rocker_tip", rocker, Transform::from_translation(c_pt - v3(pivot, 0.0, 0.0)));
    let m = b.build();
    let c = fourbar_loop(&m).unwrap_or_else(|e| panic!("built-in model: fourbar loop: {e}"));
    m.with_constraints(&[c]).unwrap_or_else(|e| panic!("built-in model: fourbar loop: {e}"))
}

/// The loop constraint of [`fourbar`] (also its [`Model::constraints`]): a 3-D connect of frame
/// `coupler_tip` to frame `rocker_tip` (`local_world_aligned`).
///
/// # Errors
/// [`crate::error::Error::Unknown`] if `model` lacks those frames (not a four-bar).
pub fn fourbar_loop(model: &Model) -> crate::error::Result<super::Contact> {
    super::Contact::new(model, "coupler_tip", Vector3::zeros())?.with_frame2(
        model,
        "rocker_tip",
        None,
    )
}

/// Radius of the delta's base circle (the shoulder hinges), its platform circle (the wrists),
/// the upper-arm length and the platform's depth below the base at the neutral configuration.
const DELTA: (f64, f64, f64, f64) = (0.2, 0.05, 0.2, 0.4);

/// A delta-type parallel robot: three arms 120° apart close three loops on a moving platform
/// (nq = 22, nv = 18; three 3-D connects, [`delta_loops`], which are also the model's
/// [`Model::constraints`]).
///
/// Arm `k` (`k` = 1, 2, 3, at the angle `φ = 2π(k − 1)/3` about z, radial direction
/// `e = (cos φ, sin φ, 0)`): `shoulder_k` (revolute, the actuated joint, about the tangent
/// `(−sin φ, cos φ, 0)` at `0.2 e` on the base, limits ±1.2 rad) moves `upper_arm_k` (0.2 m
/// along `e`, horizontal at q = 0); `elbow_k` (a ball joint at the upper arm's tip, frame
/// `elbow_k`) moves `forearm_k`, which reaches from the elbow to the platform (0.35 m inwards,
/// 0.4 m down: 0.532 m), its far end the frame `forearm_tip_k`. The platform (`platform_joint`,
/// a free flyer placed 0.4 m below the base's origin, body `platform`) carries the frames
/// `platform_k` at `0.05 e`. Loop `k` joins `forearm_tip_k` to `platform_k`; at the neutral
/// configuration (every joint at zero, quaternions the identity) all three are closed.
///
/// The forearms are single rods with spherical ends (a 3-RSS mechanism) instead of the
/// parallelograms of a real delta, so the platform's orientation is not held constant: with the
/// shoulders locked, the platform keeps three DoF, and each forearm's spin about its own axis is
/// a further (unactuated, inertial) DoF. The nine loop rows are independent away from the
/// mechanism's singular poses (18 − 9 = 9 DoF). Every link is a solid box (the forearms flat
/// bars 8 cm wide, standing for the parallelograms' width) or a disc (the platform).
pub fn delta() -> Model {
    let (rb, rp, l1, h) = DELTA;
    let mut b = Builder::new("delta");
    let platform = b.body(
        0,
        "platform_joint",
        JointType::FreeFlyer,
        at(0.0, 0.0, -h),
        "platform",
        Inertia::from_com(0.3, v3(0.0, 0.0, -0.005), cylinder_z_rot(0.3, rp + 0.01, 0.01)),
    );
    for k in 0..3 {
        let phi = 2.0 * PI * k as f64 / 3.0;
        let (c, s) = (phi.cos(), phi.sin());
        let e = v3(c, s, 0.0);
        // Link frames: x along e, y along the shoulder axis, z up.
        let rot = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        let n = |part: &str| format!("{part}_{}", k + 1);
        let upper = b.revolute(
            0,
            &n("shoulder"),
            Vector3::y(),
            Transform::new(rot, e * rb),
            &n("upper_arm"),
            box_body(0.4, v3(0.5 * l1, 0.0, 0.0), [l1, 0.03, 0.02]),
            -1.2,
            1.2,
        );
        // The forearm in the link frame: from the elbow to the platform point.
        let reach = v3(rp - rb - l1, 0.0, -h);
        let len = reach.norm();
        let dir = reach / len;
        // A flat bar along `dir`, 8 cm wide along the shoulder axis (the width of a delta's
        // parallelogram), 1 cm thick: a box in a frame turned from z onto `dir` (the turn is
        // about the y axis, so the width stays along y).
        let turn = z_onto(&dir);
        let bar = turn * box_rot(0.2, [0.01, 0.08, len]) * turn.transpose();
        let forearm = b.body(
            upper,
            &n("elbow"),
            JointType::Spherical,
            at(l1, 0.0, 0.0),
            &n("forearm"),
            Inertia::from_com(0.2, reach * 0.5, bar),
        );
        b.frame(&n("forearm_tip"), forearm, Transform::from_translation(reach));
        b.frame(&n("platform"), platform, Transform::from_translation(e * rp));
    }
    let m = b.build();
    let loops = delta_loops(&m).unwrap_or_else(|e| panic!("built-in model: delta loops: {e}"));
    m.with_constraints(&loops).unwrap_or_else(|e| panic!("built-in model: delta loops: {e}"))
}

/// A rotation taking z onto the unit vector `d`.
fn z_onto(d: &Vector3<f64>) -> Matrix3<f64> {
    let z = Vector3::z();
    let axis = z.cross(d);
    let (s, c) = (axis.norm(), z.dot(d));
    if s < 1e-12 {
        return if c > 0.0 {
            Matrix3::identity()
        } else {
            Matrix3::from_diagonal(&v3(1.0, -1.0, -1.0))
        };
    }
    let r = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), s.atan2(c));
    *r.matrix()
}

/// The three loop constraints of [`delta`] (also its [`Model::constraints`]): 3-D connects
/// (`local_world_aligned`) of frame `forearm_tip_k` to frame `platform_k`, `k` = 1, 2, 3.
///
/// # Errors
/// [`crate::error::Error::Unknown`] if `model` lacks those frames (not a delta).
pub fn delta_loops(model: &Model) -> crate::error::Result<Vec<super::Contact>> {
    (1..=3)
        .map(|k| {
            super::Contact::new(model, &format!("forearm_tip_{k}"), Vector3::zeros())?.with_frame2(
                model,
                &format!("platform_{k}"),
                None,
            )
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Random trees.
// ---------------------------------------------------------------------------------------------

fn random_unit(rng: &mut Rng) -> Vector3<f64> {
    loop {
        let v = v3(rng.normal(), rng.normal(), rng.normal());
        let n = v.norm();
        if n > 1e-3 {
            return v / n;
        }
    }
}

fn random_rotation(rng: &mut Rng) -> Matrix3<f64> {
    loop {
        let q = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n > 1e-3 {
            return quat_to_rot(q[0] / n, q[1] / n, q[2] / n, q[3] / n);
        }
    }
}

fn random_placement(rng: &mut Rng) -> Transform {
    let rot = random_rotation(rng);
    let t = v3(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), rng.range(-0.5, 0.5));
    Transform::new(rot, t)
}

/// Random physical inertia: mass in [0.2, 5] kg, centre of mass in [−0.2, 0.2]³ m, rotational
/// inertia `R diag(a, b, c) Rᵀ` (random rotation `R`) of a solid box with random sides in
/// [0.05, 0.5] m, so the principal moments are positive and satisfy the triangle inequality.
fn random_inertia(rng: &mut Rng) -> Inertia {
    let mass = rng.range(0.2, 5.0);
    let com = v3(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), rng.range(-0.2, 0.2));
    let d = [rng.range(0.05, 0.5), rng.range(0.05, 0.5), rng.range(0.05, 0.5)];
    let r = random_rotation(rng);
    let rot = r * box_rot(mass, d) * r.transpose();
    // Exact symmetry (the product above is symmetric up to rounding).
    let rot = (rot + rot.transpose()) * 0.5;
    Inertia::from_com(mass, com, rot)
}

/// The five joint kinds a random tree mixes (fixed bodies are drawn separately).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Revolute,
    Continuous,
    Prismatic,
    Spherical,
    Planar,
}

const ALL_KINDS: [Kind; 5] =
    [Kind::Revolute, Kind::Continuous, Kind::Prismatic, Kind::Spherical, Kind::Planar];

fn random_kind(rng: &mut Rng) -> Kind {
    let u = rng.uniform();
    match u {
        u if u < 0.35 => Kind::Revolute,
        u if u < 0.50 => Kind::Continuous,
        u if u < 0.70 => Kind::Prismatic,
        u if u < 0.85 => Kind::Spherical,
        _ => Kind::Planar,
    }
}

/// One step of the random construction: a moving joint or a fixed (merged) body.
#[derive(Clone, Copy, Debug)]
enum Event {
    Joint(Kind),
    Fixed,
}

/// A random kinematic tree with `n_joints` moving joints (plus a free-flyer root when
/// `floating_base`), deterministic in `seed`.
///
/// * **Topology**: each new joint's parent is uniform among the bodies existing so far (with a
///   fixed base this includes the world, so the model may be a forest of several subtrees; with
///   a floating base every joint descends from the root), so the tree branches.
/// * **Joint types**: revolute (random unit axis; half of them with random limits), continuous
///   (random axis), prismatic (random axis; half with random limits), spherical and planar,
///   drawn with probabilities 0.35 / 0.15 / 0.20 / 0.15 / 0.15. When `n_joints ≥ 5` each of the
///   five kinds occurs at least once.
/// * **Fixed bodies**: `⌈n_joints / 5⌉` extra bodies rigidly attached (emulated fixed joints)
///   to random moving bodies: their inertia is merged into the parent with
///   [`ModelBuilder::append_inertia`] and a frame `fixed_k` marks them.
/// * **Geometry and inertia**: random joint placements (uniform rotation, translation in
///   [−0.5, 0.5]³ m); every body (and fixed body) has mass in [0.2, 5] kg, centre of mass in
///   [−0.2, 0.2]³ m and a randomly rotated solid-box rotational inertia, so all inertias are
///   physical and the mass matrix is positive definite.
/// * **Names**: the root is `root_joint` with body `base`; joint `i` (its model index) is
///   `joint_i` with body frame `body_i`.
///
/// The DoF count is only roughly controlled: `nv` ranges over `[n_joints, 3 n_joints]`
/// (spherical and planar joints have 3 DoF), about `1.6 n_joints` on average, plus 6 with a
/// floating base; `nq` additionally counts one more coordinate per spherical joint and the
/// free-flyer quaternion.
pub fn random_tree(n_joints: usize, seed: u64, floating_base: bool) -> Model {
    let mut rng = Rng::new(seed);
    let suffix = if floating_base { "_ff" } else { "" };
    let mut b = Builder::new(&format!("random_tree{n_joints}{suffix}_s{seed}"));

    // Event sequence: every kind once (if room), the rest random, plus fixed bodies; shuffled.
    let mut events: Vec<Event> = (0..n_joints)
        .map(|k| {
            Event::Joint(if k < ALL_KINDS.len() { ALL_KINDS[k] } else { random_kind(&mut rng) })
        })
        .collect();
    events.extend(std::iter::repeat_n(Event::Fixed, n_joints.div_ceil(5)));
    for i in (1..events.len()).rev() {
        let j = rng.below(i + 1);
        events.swap(i, j);
    }

    let mut n_moving = 0; // Moving bodies so far (joint indices 1..=n_moving).
    if floating_base {
        let inertia = random_inertia(&mut rng);
        b.body(0, "root_joint", JointType::FreeFlyer, Transform::identity(), "base", inertia);
        n_moving = 1;
    }
    let mut pending_fixed = 0; // Fixed bodies drawn before any moving body existed.
    let mut n_fixed = 0;
    let mut add_fixed = |b: &mut Builder, rng: &mut Rng, n_moving: usize| {
        let parent = 1 + rng.below(n_moving);
        let placement = random_placement(rng);
        let inertia = random_inertia(rng);
        n_fixed += 1;
        b.fixed(parent, &format!("fixed_{n_fixed}"), placement, inertia);
    };
    for event in events {
        match event {
            Event::Fixed if n_moving == 0 => pending_fixed += 1,
            Event::Fixed => add_fixed(&mut b, &mut rng, n_moving),
            Event::Joint(kind) => {
                let parent =
                    if floating_base { 1 + rng.below(n_moving) } else { rng.below(n_moving + 1) };
                let placement = random_placement(&mut rng);
                let jt = match kind {
                    Kind::Revolute => JointType::Revolute { axis: random_unit(&mut rng) },
                    Kind::Continuous => JointType::Continuous { axis: random_unit(&mut rng) },
                    Kind::Prismatic => JointType::Prismatic { axis: random_unit(&mut rng) },
                    Kind::Spherical => JointType::Spherical,
                    Kind::Planar => JointType::Planar,
                };
                let inertia = random_inertia(&mut rng);
                let id = b.0.njoints();
                b.body(
                    parent,
                    &format!("joint_{id}"),
                    jt,
                    placement,
                    &format!("body_{id}"),
                    inertia,
                );
                n_moving += 1;
                let limited = rng.uniform() < 0.5;
                match kind {
                    Kind::Revolute if limited => {
                        let (lo, hi) = (-rng.range(0.3, PI), rng.range(0.3, PI));
                        b.limits(id, lo, hi);
                    }
                    Kind::Prismatic if limited => {
                        let (lo, hi) = (-rng.range(0.1, 1.0), rng.range(0.1, 1.0));
                        b.limits(id, lo, hi);
                    }
                    _ => {}
                }
                while pending_fixed > 0 {
                    pending_fixed -= 1;
                    add_fixed(&mut b, &mut rng, n_moving);
                }
            }
        }
    }
    b.build()
}

// ---------------------------------------------------------------------------------------------
// Quadruped.
// ---------------------------------------------------------------------------------------------

/// A floating-base quadruped the size of a small legged robot (nq = 19, nv = 18, ≈ 17.4 kg).
///
/// * Root: free flyer `root_joint` moving the trunk (frame `trunk`), a 0.4 × 0.2 × 0.1 m,
///   10 kg box (x forward, y left, z up).
/// * Legs `LF`, `RF`, `LH`, `RH` (left/right, front/hind), hips at (±0.2, ±0.1, 0) m, each
///   with three limited revolute joints: `<leg>_HAA` (hip abduction/adduction, about x),
///   `<leg>_HFE` (hip flexion/extension, about y, 0.06 m outboard of the HAA) and `<leg>_KFE`
///   (knee, about y). Bodies: `<leg>_hip` (0.5 kg), `<leg>_thigh` (1 kg, 0.2 m along −z),
///   `<leg>_shank` (0.3 kg, 0.2 m along −z).
/// * Feet: fixed 0.05 kg spheres at the shank tips, with frames `LF_FOOT`, `RF_FOOT`,
///   `LH_FOOT`, `RH_FOOT`.
///
/// At the neutral configuration the legs point straight down and the feet are 0.4 m below the
/// hip axes. The velocity vector is `[trunk ω, trunk v, LF, RF, LH, RH]` (HAA, HFE, KFE each).
pub fn quadruped() -> Model {
    let mut b = Builder::new("quadruped");
    let trunk = b.body(
        0,
        "root_joint",
        JointType::FreeFlyer,
        Transform::identity(),
        "trunk",
        box_body(10.0, v3(0.0, 0.0, 0.0), [0.4, 0.2, 0.1]),
    );
    for (leg, fx, sy) in
        [("LF", 1.0, 1.0), ("RF", 1.0, -1.0), ("LH", -1.0, 1.0), ("RH", -1.0, -1.0)]
    {
        let hip = b.revolute(
            trunk,
            &format!("{leg}_HAA"),
            Vector3::x(),
            at(0.2 * fx, 0.1 * sy, 0.0),
            &format!("{leg}_hip"),
            rod_body(0.5, v3(0.0, 0.03 * sy, 0.0), 0.03, 0.06),
            -0.8,
            0.8,
        );
        let thigh = b.revolute(
            hip,
            &format!("{leg}_HFE"),
            Vector3::y(),
            at(0.0, 0.06 * sy, 0.0),
            &format!("{leg}_thigh"),
            rod_body(1.0, v3(0.0, 0.0, -0.1), 0.025, 0.2),
            -FRAC_PI_2,
            FRAC_PI_2,
        );
        let (klo, khi) = if fx > 0.0 { (-2.7, 0.0) } else { (0.0, 2.7) };
        let shank = b.revolute(
            thigh,
            &format!("{leg}_KFE"),
            Vector3::y(),
            at(0.0, 0.0, -0.2),
            &format!("{leg}_shank"),
            rod_body(0.3, v3(0.0, 0.0, -0.1), 0.015, 0.2),
            klo,
            khi,
        );
        let foot = Inertia::from_com(0.05, Vector3::zeros(), sphere_rot(0.05, 0.02));
        b.fixed(shank, &format!("{leg}_FOOT"), at(0.0, 0.0, -0.2), foot);
    }
    b.build()
}

// ---------------------------------------------------------------------------------------------
// Humanoid.
// ---------------------------------------------------------------------------------------------

/// A floating-base humanoid, about 1.9 m tall and 65.9 kg (nq = 39, nv = 38); the CLI demo's
/// default model. All joints except the free-flyer root are limited revolute joints.
///
/// Frame convention: x forward, y left, z up; `left_*` parts are at +y. Degrees of freedom, in
/// velocity order:
///
/// * `root_joint` (free flyer, 6) moving the `pelvis` (8 kg);
/// * torso (2): `torso_yaw` (z), `torso_pitch` (y); bodies `torso_base` (2 kg), `torso`
///   (18 kg);
/// * head (2): `head_yaw` (z), `head_pitch` (y); bodies `neck` (0.5 kg), `head_link` (4 kg);
///   frame `head` at the centre of the head;
/// * each arm (7 + 1 gripper), `left_` then `right_`: `*_shoulder_pitch` (y),
///   `*_shoulder_roll` (x), `*_shoulder_yaw` (z), `*_elbow` (y), `*_wrist_yaw` (z),
///   `*_wrist_pitch` (y), `*_wrist_roll` (x), `*_gripper` (x, one finger); frames `left_hand`,
///   `right_hand` at the palm centre; arm mass 5.2 kg;
/// * each leg (6), `left_` then `right_`: `*_hip_yaw` (z), `*_hip_roll` (x), `*_hip_pitch` (y),
///   `*_knee` (y), `*_ankle_pitch` (y), `*_ankle_roll` (x); frames `left_sole`, `right_sole`
///   under the feet; leg mass 11.5 kg.
///
/// Total: 6 + 2 + 2 + 2 × 8 + 2 × 6 = 38 DoF. At the neutral configuration the robot stands
/// upright with the soles 1 m below the pelvis origin and the arms hanging down.
pub fn humanoid() -> Model {
    let mut b = Builder::new("humanoid");
    let pelvis = b.body(
        0,
        "root_joint",
        JointType::FreeFlyer,
        Transform::identity(),
        "pelvis",
        box_body(8.0, v3(0.0, 0.0, 0.0), [0.2, 0.3, 0.15]),
    );

    // Torso.
    let torso_base = b.revolute(
        pelvis,
        "torso_yaw",
        Vector3::z(),
        at(0.0, 0.0, 0.1),
        "torso_base",
        rod_body(2.0, v3(0.0, 0.0, 0.03), 0.08, 0.06),
        -1.0,
        1.0,
    );
    let torso = b.revolute(
        torso_base,
        "torso_pitch",
        Vector3::y(),
        at(0.0, 0.0, 0.06),
        "torso",
        box_body(18.0, v3(-0.01, 0.0, 0.22), [0.22, 0.34, 0.44]),
        -0.5,
        1.2,
    );

    // Head.
    let neck = b.revolute(
        torso,
        "head_yaw",
        Vector3::z(),
        at(0.0, 0.0, 0.46),
        "neck",
        rod_body(0.5, v3(0.0, 0.0, 0.03), 0.04, 0.06),
        -1.3,
        1.3,
    );
    let head = b.revolute(
        neck,
        "head_pitch",
        Vector3::y(),
        at(0.0, 0.0, 0.07),
        "head_link",
        Inertia::from_com(4.0, v3(0.02, 0.0, 0.11), box_rot(4.0, [0.2, 0.16, 0.22])),
        -0.6,
        0.8,
    );
    b.frame("head", head, at(0.02, 0.0, 0.11));

    // Arms.
    for (side, s) in [("left", 1.0), ("right", -1.0)] {
        let n = |j: &str| format!("{side}_{j}");
        let p = b.revolute(
            torso,
            &n("shoulder_pitch"),
            Vector3::y(),
            at(0.0, 0.2 * s, 0.38),
            &n("shoulder_pitch_link"),
            rod_body(0.6, v3(0.0, 0.03 * s, 0.0), 0.04, 0.06),
            -3.0,
            1.2,
        );
        let (rlo, rhi) = if s > 0.0 { (-0.3, 2.8) } else { (-2.8, 0.3) };
        let r = b.revolute(
            p,
            &n("shoulder_roll"),
            Vector3::x(),
            at(0.0, 0.05 * s, 0.0),
            &n("shoulder_roll_link"),
            rod_body(0.4, v3(0.0, 0.0, -0.03), 0.04, 0.06),
            rlo,
            rhi,
        );
        let upper = b.revolute(
            r,
            &n("shoulder_yaw"),
            Vector3::z(),
            at(0.0, 0.0, -0.06),
            &n("upper_arm"),
            rod_body(1.8, v3(0.0, 0.0, -0.1), 0.045, 0.22),
            -2.6,
            2.6,
        );
        let forearm = b.revolute(
            upper,
            &n("elbow"),
            Vector3::y(),
            at(0.0, 0.0, -0.22),
            &n("forearm"),
            rod_body(1.0, v3(0.0, 0.0, -0.06), 0.04, 0.12),
            -2.5,
            0.0,
        );
        let wy = b.revolute(
            forearm,
            &n("wrist_yaw"),
            Vector3::z(),
            at(0.0, 0.0, -0.12),
            &n("wrist_yaw_link"),
            rod_body(0.6, v3(0.0, 0.0, -0.06), 0.035, 0.12),
            -2.6,
            2.6,
        );
        let wp = b.revolute(
            wy,
            &n("wrist_pitch"),
            Vector3::y(),
            at(0.0, 0.0, -0.12),
            &n("wrist_pitch_link"),
            rod_body(0.2, v3(0.0, 0.0, -0.015), 0.03, 0.03),
            -1.4,
            1.4,
        );
        let hand = b.revolute(
            wp,
            &n("wrist_roll"),
            Vector3::x(),
            at(0.0, 0.0, -0.03),
            &n("hand_link"),
            box_body(0.5, v3(0.0, 0.0, -0.06), [0.04, 0.08, 0.1]),
            -1.4,
            1.4,
        );
        b.frame(&n("hand"), hand, at(0.0, 0.0, -0.08));
        let (glo, ghi) = if s > 0.0 { (0.0, 0.8) } else { (-0.8, 0.0) };
        b.revolute(
            hand,
            &n("gripper"),
            Vector3::x(),
            at(0.0, 0.03 * s, -0.1),
            &n("finger"),
            box_body(0.1, v3(0.0, 0.0, -0.03), [0.02, 0.015, 0.06]),
            glo,
            ghi,
        );
    }

    // Legs.
    for (side, s) in [("left", 1.0), ("right", -1.0)] {
        let n = |j: &str| format!("{side}_{j}");
        let yaw = b.revolute(
            pelvis,
            &n("hip_yaw"),
            Vector3::z(),
            at(0.0, 0.1 * s, -0.08),
            &n("hip_yaw_link"),
            rod_body(1.0, v3(0.0, 0.0, -0.025), 0.05, 0.05),
            -0.8,
            0.8,
        );
        let (rlo, rhi) = if s > 0.0 { (-0.4, 0.8) } else { (-0.8, 0.4) };
        let roll = b.revolute(
            yaw,
            &n("hip_roll"),
            Vector3::x(),
            at(0.0, 0.0, -0.05),
            &n("hip_roll_link"),
            box_body(1.0, v3(0.0, 0.0, 0.0), [0.08, 0.08, 0.08]),
            rlo,
            rhi,
        );
        let thigh = b.revolute(
            roll,
            &n("hip_pitch"),
            Vector3::y(),
            Transform::identity(),
            &n("thigh"),
            rod_body(5.0, v3(0.0, 0.0, -0.18), 0.06, 0.4),
            -2.2,
            0.8,
        );
        let shin = b.revolute(
            thigh,
            &n("knee"),
            Vector3::y(),
            at(0.0, 0.0, -0.4),
            &n("shin"),
            rod_body(3.0, v3(0.0, 0.0, -0.18), 0.05, 0.4),
            0.0,
            2.5,
        );
        let ankle = b.revolute(
            shin,
            &n("ankle_pitch"),
            Vector3::y(),
            at(0.0, 0.0, -0.4),
            &n("ankle_pitch_link"),
            box_body(0.3, v3(0.0, 0.0, 0.0), [0.05, 0.05, 0.05]),
            -1.0,
            0.8,
        );
        let foot = b.revolute(
            ankle,
            &n("ankle_roll"),
            Vector3::x(),
            Transform::identity(),
            &n("foot"),
            box_body(1.2, v3(0.03, 0.0, -0.045), [0.22, 0.1, 0.05]),
            -0.5,
            0.5,
        );
        b.frame(&n("sole"), foot, at(0.0, 0.0, -0.07));
    }
    b.build()
}

// ---------------------------------------------------------------------------------------------
// Lookup by name.
// ---------------------------------------------------------------------------------------------

/// Example names accepted by [`by_name`], for help texts.
pub fn names() -> &'static [&'static str] {
    &[
        "humanoid",
        "quadruped",
        "fourbar",
        "delta",
        "chain6",
        "serial_chain12",
        "pendulum2",
        "random_tree20",
        "random_tree20_ff",
        "random_tree20_ff_s7",
        "random_tree40_s3",
    ]
}

/// Parses a decimal count in `1..=MAX_NAMED_JOINTS` (digits only).
fn parse_count(s: &str) -> Option<usize> {
    if s.is_empty() || !s.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    s.parse::<usize>().ok().filter(|n| (1..=MAX_NAMED_JOINTS).contains(n))
}

/// A built-in model by name (exact, lower case), `None` if the name is not recognised:
///
/// * `humanoid` → [`humanoid`]`()`, `quadruped` → [`quadruped`]`()`, `fourbar` →
///   [`fourbar`]`()`, `delta` → [`delta`]`()`;
/// * `chain<N>` or `serial_chain<N>` → [`serial_chain`]`(N)`, e.g. `chain6`;
/// * `pendulum<N>` → [`pendulum`]`(N)`, e.g. `pendulum2`;
/// * `random_tree<N>[_ff][_s<SEED>]` → [`random_tree`]`(N, SEED, ff)`: `_ff` gives a floating
///   base, `_s<SEED>` a seed (default 0), suffixes in this order, e.g. `random_tree20_ff_s7`.
///
/// `N` is a decimal integer in `1..=`[`MAX_NAMED_JOINTS`]; `SEED` a decimal `u64`.
pub fn by_name(name: &str) -> Option<Model> {
    match name {
        "humanoid" => return Some(humanoid()),
        "quadruped" => return Some(quadruped()),
        "fourbar" => return Some(fourbar()),
        "delta" => return Some(delta()),
        _ => {}
    }
    if let Some(rest) = name.strip_prefix("serial_chain").or_else(|| name.strip_prefix("chain")) {
        return parse_count(rest).map(serial_chain);
    }
    if let Some(rest) = name.strip_prefix("pendulum") {
        return parse_count(rest).map(pendulum);
    }
    let rest = name.strip_prefix("random_tree")?;
    let mut parts = rest.split('_');
    let n = parse_count(parts.next()?)?;
    let mut floating = false;
    let mut seed = 0u64;
    let mut next = parts.next();
    if next == Some("ff") {
        floating = true;
        next = parts.next();
    }
    if let Some(p) = next {
        let digits = p.strip_prefix('s')?;
        if digits.is_empty() || !digits.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        seed = digits.parse().ok()?;
        next = parts.next();
    }
    if next.is_some() {
        return None;
    }
    Some(random_tree(n, seed, floating))
}
