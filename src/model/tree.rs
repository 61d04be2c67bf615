//! The kinematic tree: Model (immutable description) and its builder.

use super::joint::{JointType, unit_axis};
use crate::error::{Error, Result};
use crate::rng::Rng;
use crate::spatial::{Inertia, Motion, Transform};
use nalgebra::{DVector, Vector3};

/// A named frame rigidly attached to a joint's body: every URDF link is one (also the links
/// merged into their parent body by fixed joints).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Name (the URDF link name).
    pub name: String,
    /// Index of the joint whose body carries the frame (0 = the fixed world).
    pub joint: usize,
    /// Pose of the frame in that joint's (child) frame.
    pub placement: Transform,
}

/// Immutable description of a kinematic tree, numbered like Pinocchio: joint 0 is the fixed
/// world ("universe", no degrees of freedom), joints `1..njoints` have `parents[i] < i`.
///
/// Body `i` is the body moved by joint `i`; its inertia and frame are the joint's child frame.
#[derive(Clone, Debug)]
pub struct Model {
    /// Model name.
    pub name: String,
    /// Joint names (index 0: `"universe"`).
    pub names: Vec<String>,
    /// Joint types (index 0 unused: a dummy fixed entry).
    pub joints: Vec<JointType>,
    /// Parent joint `λ(i)` (index 0 unused).
    pub parents: Vec<usize>,
    /// Pose of joint `i`'s frame (at q = neutral) in its parent joint's child frame.
    pub placements: Vec<Transform>,
    /// Body inertias in their joint's child frame (fixed bodies merged in).
    pub inertias: Vec<Inertia>,
    /// First configuration coordinate of each joint.
    pub idx_q: Vec<usize>,
    /// Configuration dimension of each joint.
    pub nqs: Vec<usize>,
    /// First velocity coordinate of each joint.
    pub idx_v: Vec<usize>,
    /// Velocity dimension of each joint.
    pub nvs: Vec<usize>,
    /// Total configuration dimension.
    pub nq: usize,
    /// Total velocity dimension.
    pub nv: usize,
    /// Joint owning each velocity coordinate.
    pub dof_joint: Vec<usize>,
    /// Previous degree of freedom on the path to the root, `λ(k)` of the LTLᵀ factorisation.
    pub dof_parent: Vec<Option<usize>>,
    /// Strict ancestor DoFs of each DoF `k`, nearest first:
    /// `dof_ancestors[dof_ancestors_start[k]..dof_ancestors_start[k + 1]]`.
    pub dof_ancestors: Vec<usize>,
    /// Offsets into [`Model::dof_ancestors`] (length `nv + 1`).
    pub dof_ancestors_start: Vec<usize>,
    /// Motion-subspace column of each degree of freedom, in its joint's child frame.
    pub subspace: Vec<Motion>,
    /// Gravity as a spatial acceleration in the world frame (default `[0 0 0 0 0 −9.81]`).
    pub gravity: Motion,
    /// Lower configuration limits (−∞ where absent).
    pub lower: DVector<f64>,
    /// Upper configuration limits (+∞ where absent).
    pub upper: DVector<f64>,
    /// For joints loaded from a URDF `<mimic>`: the name of the mimicked joint (loaded as an
    /// independent joint).
    pub mimic: Vec<Option<String>>,
    /// Frames (URDF links), first one the world.
    pub frames: Vec<Frame>,
    /// Per joint, its indices and kind packed for the kinematics kernels (see [`JointKin`]);
    /// computed by [`ModelBuilder::build`].
    pub(crate) kin: Vec<JointKin>,
    /// Configuration index of each joint with a revolute axis `±eₖ` ([`JointKin::axis`]
    /// `< 3`), in joint order: their angles are evaluated four at a time.
    pub(crate) rev_q: Vec<usize>,
    /// `Some(a)` if `rev_q` is `a, a + 1, …` (the angles are contiguous in `q`).
    pub(crate) rev_q_start: Option<usize>,
}

/// One joint's entries of [`Model`] used on every call of the kinematics kernels, in one
/// place, with its revolute axis classified once (`joint::unit_axis`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct JointKin {
    /// `parents[i]`.
    pub(crate) parent: usize,
    /// `idx_q[i]`.
    pub(crate) idx_q: usize,
    /// `nqs[i]`.
    pub(crate) nq: usize,
    /// `idx_v[i]`.
    pub(crate) idx_v: usize,
    /// `nvs[i]`.
    pub(crate) nv: usize,
    /// `k` for a revolute or continuous joint about `±eₖ` exactly, otherwise 3.
    pub(crate) axis: usize,
    /// The sign of that axis (`±1`; 1 for other joints).
    pub(crate) sign: f64,
}

impl Model {
    /// Number of joints including the world joint 0.
    pub fn njoints(&self) -> usize {
        self.joints.len()
    }
    /// Index of the joint named `name`.
    pub fn joint_id(&self, name: &str) -> Result<usize> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| Error::Unknown { kind: "joint".into(), name: name.into() })
    }
    /// Index of the frame named `name`.
    pub fn frame_id(&self, name: &str) -> Result<usize> {
        self.frames
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| Error::Unknown { kind: "frame".into(), name: name.into() })
    }
    /// Strict ancestor DoFs of DoF `k`, nearest first.
    #[inline]
    pub fn ancestors_of_dof(&self, k: usize) -> &[usize] {
        &self.dof_ancestors[self.dof_ancestors_start[k]..self.dof_ancestors_start[k + 1]]
    }
    /// True if joint `j` is `i` or one of its ancestors (`j ⪯ i`).
    pub fn is_ancestor(&self, j: usize, i: usize) -> bool {
        let mut k = i;
        while k > j {
            k = self.parents[k];
        }
        k == j
    }
    /// The neutral configuration.
    pub fn neutral(&self) -> DVector<f64> {
        let mut q = DVector::zeros(self.nq);
        for i in 1..self.njoints() {
            let (a, n) = (self.idx_q[i], self.nqs[i]);
            self.joints[i].neutral(&mut q.as_mut_slice()[a..a + n]);
        }
        q
    }
    /// A random valid configuration (see [`JointType::random`]).
    pub fn random_configuration(&self, rng: &mut Rng) -> DVector<f64> {
        let mut q = DVector::zeros(self.nq);
        for i in 1..self.njoints() {
            let (a, n) = (self.idx_q[i], self.nqs[i]);
            self.joints[i].random(
                rng,
                &self.lower.as_slice()[a..a + n],
                &self.upper.as_slice()[a..a + n],
                &mut q.as_mut_slice()[a..a + n],
            );
        }
        q
    }
    /// `q ⊕ δ` (right, body-frame perturbation per joint).
    pub fn integrate(&self, q: &DVector<f64>, delta: &DVector<f64>) -> Result<DVector<f64>> {
        self.check_q(q)?;
        self.check_v("delta", delta)?;
        let mut out = q.clone();
        for i in 1..self.njoints() {
            let (a, n, b, m) = (self.idx_q[i], self.nqs[i], self.idx_v[i], self.nvs[i]);
            self.joints[i].integrate(
                &q.as_slice()[a..a + n],
                &delta.as_slice()[b..b + m],
                &mut out.as_mut_slice()[a..a + n],
            );
        }
        Ok(out)
    }
    /// Checks a configuration: length `nq`, finite, unit quaternions.
    #[inline(always)]
    pub fn check_q(&self, q: &DVector<f64>) -> Result<()> {
        // Fast path (inline): every coordinate finite and every quaternion of unit norm (each
        // quaternion joint, spherical or free-flyer, has nq = nv + 1 and every other joint
        // nq = nv, so there is none when nq = nv). Anything else goes through the per-joint
        // checks, which name the joint and the problem.
        let qs = q.as_slice();
        if qs.len() == self.nq && all_finite(qs) && (self.nq == self.nv || self.quats_valid(qs)) {
            return Ok(());
        }
        self.check_q_slow(q)
    }
    /// True if every quaternion of `qs` (length `nq`) has unit norm within
    /// [`super::joint::QUAT_NORM_TOL`] (out of line: only models with quaternions).
    #[inline(never)]
    fn quats_valid(&self, qs: &[f64]) -> bool {
        // The scan stops after the nq − nv quaternions (the root free-flyer, for most robots).
        let mut quats = self.nq.saturating_sub(self.nv);
        let mut ok = true;
        let mut i = 1;
        while quats > 0 && i < self.njoints() {
            let a = self.idx_q[i];
            let quat = match self.joints[i] {
                JointType::Spherical => &qs[a..a + 4],
                JointType::FreeFlyer => &qs[a + 3..a + 7],
                _ => {
                    i += 1;
                    continue;
                }
            };
            quats -= 1;
            i += 1;
            let n = quat.iter().map(|x| x * x).sum::<f64>().sqrt();
            ok &= (n - 1.0).abs() <= super::joint::QUAT_NORM_TOL;
        }
        ok
    }
    /// [`Self::check_q`] with the error reporting (out of line).
    #[cold]
    #[inline(never)]
    fn check_q_slow(&self, q: &DVector<f64>) -> Result<()> {
        if q.len() != self.nq {
            return Err(Error::Dimension { what: "q".into(), expected: self.nq, got: q.len() });
        }
        for i in 1..self.njoints() {
            let (a, n) = (self.idx_q[i], self.nqs[i]);
            self.joints[i].check_configuration(&q.as_slice()[a..a + n]).map_err(|reason| {
                Error::InvalidConfiguration {
                    joint: self.names[i].clone(),
                    reason: format!("{reason} (q indices {a}..{})", a + n),
                }
            })?;
        }
        Ok(())
    }
    /// Checks a velocity-sized vector: length `nv`, finite.
    pub fn check_v(&self, what: &str, x: &DVector<f64>) -> Result<()> {
        check_vec(what, x, self.nv)
    }
}

/// True if every entry of `qs` is finite.
#[inline(always)]
fn all_finite(qs: &[f64]) -> bool {
    // x · 0 is ±0 for finite x and NaN otherwise: the sums (four lanes) are 0 iff every
    // coordinate is finite.
    let mut acc = [0.0f64; 4];
    let chunks = qs.chunks_exact(4);
    for (a, &x) in acc.iter_mut().zip(chunks.remainder()) {
        *a += x * 0.0;
    }
    for c in chunks {
        for (a, &x) in acc.iter_mut().zip(c) {
            *a += x * 0.0;
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) == 0.0
}

/// Checks length and finiteness of an input vector.
pub fn check_vec(what: &str, x: &DVector<f64>, n: usize) -> Result<()> {
    if x.len() != n {
        return Err(Error::Dimension { what: what.into(), expected: n, got: x.len() });
    }
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::NotFinite { what: what.into(), index });
    }
    Ok(())
}

/// Builds a [`Model`] joint by joint. Joints must be added after their parent, which makes the
/// numbering a topological (for the URDF loader: depth-first) order.
#[derive(Clone, Debug)]
pub struct ModelBuilder {
    m: Model,
}

impl ModelBuilder {
    /// An empty tree with only the world (joint 0, frame `"universe"`).
    pub fn new(name: &str) -> Self {
        let m = Model {
            name: name.into(),
            names: vec!["universe".into()],
            joints: vec![JointType::Revolute { axis: Vector3::z() }],
            parents: vec![0],
            placements: vec![Transform::identity()],
            inertias: vec![Inertia::zero()],
            idx_q: vec![0],
            nqs: vec![0],
            idx_v: vec![0],
            nvs: vec![0],
            nq: 0,
            nv: 0,
            dof_joint: vec![],
            dof_parent: vec![],
            dof_ancestors: vec![],
            dof_ancestors_start: vec![0],
            subspace: vec![],
            gravity: Motion::new(Vector3::zeros(), Vector3::new(0.0, 0.0, -9.81)),
            lower: DVector::zeros(0),
            upper: DVector::zeros(0),
            mimic: vec![None],
            frames: vec![Frame {
                name: "universe".into(),
                joint: 0,
                placement: Transform::identity(),
            }],
            kin: vec![],
            rev_q: vec![],
            rev_q_start: None,
        };
        Self { m }
    }

    /// Number of joints so far (including the world).
    pub fn njoints(&self) -> usize {
        self.m.joints.len()
    }

    /// Adds a joint of type `kind` whose frame sits at `placement` in body `parent`'s frame.
    /// Returns the new joint index. Its body starts massless; see [`Self::append_inertia`].
    pub fn add_joint(
        &mut self,
        parent: usize,
        name: &str,
        kind: JointType,
        placement: Transform,
    ) -> Result<usize> {
        let m = &mut self.m;
        if parent >= m.joints.len() {
            return Err(Error::Build(format!(
                "joint \"{name}\": parent index {parent} does not exist"
            )));
        }
        if m.names.iter().any(|n| n == name) {
            return Err(Error::Build(format!("joint \"{name}\" is defined twice")));
        }
        if let JointType::Revolute { axis }
        | JointType::Continuous { axis }
        | JointType::Prismatic { axis } = kind
            && (!axis.iter().all(|x| x.is_finite()) || (axis.norm() - 1.0).abs() > 1e-9)
        {
            return Err(Error::Build(format!(
                "joint \"{name}\": axis [{}, {}, {}] is not a unit vector",
                axis.x, axis.y, axis.z
            )));
        }
        let id = m.joints.len();
        let (nq, nv) = (kind.nq(), kind.nv());
        // Last dof on the path to the root.
        let mut anc = parent;
        while anc > 0 && m.nvs[anc] == 0 {
            anc = m.parents[anc];
        }
        let mut prev = if anc > 0 { Some(m.idx_v[anc] + m.nvs[anc] - 1) } else { None };
        for c in 0..nv {
            m.dof_joint.push(id);
            m.dof_parent.push(prev);
            prev = Some(m.nv + c);
            m.subspace.push(kind.subspace_column(c));
        }
        m.names.push(name.into());
        m.joints.push(kind);
        m.parents.push(parent);
        m.placements.push(placement);
        m.inertias.push(Inertia::zero());
        m.idx_q.push(m.nq);
        m.nqs.push(nq);
        m.idx_v.push(m.nv);
        m.nvs.push(nv);
        m.mimic.push(None);
        m.nq += nq;
        m.nv += nv;
        let (mut lo, mut hi) = (m.lower.as_slice().to_vec(), m.upper.as_slice().to_vec());
        lo.extend(std::iter::repeat_n(f64::NEG_INFINITY, nq));
        hi.extend(std::iter::repeat_n(f64::INFINITY, nq));
        m.lower = DVector::from_vec(lo);
        m.upper = DVector::from_vec(hi);
        Ok(id)
    }

    /// Adds the inertia of a body rigidly attached to joint `joint`'s body, given in a frame at
    /// `placement` in that body's frame (lumping, as fixed joints are merged).
    pub fn append_inertia(
        &mut self,
        joint: usize,
        placement: &Transform,
        inertia: &Inertia,
    ) -> Result<()> {
        if joint >= self.m.joints.len() {
            return Err(Error::Build(format!(
                "append_inertia: joint index {joint} does not exist"
            )));
        }
        self.m.inertias[joint] += placement.act_inertia(inertia);
        Ok(())
    }

    /// Adds a named frame on joint `joint`'s body. Returns its index.
    pub fn add_frame(&mut self, name: &str, joint: usize, placement: Transform) -> Result<usize> {
        if joint >= self.m.joints.len() {
            return Err(Error::Build(format!(
                "frame \"{name}\": joint index {joint} does not exist"
            )));
        }
        if self.m.frames.iter().any(|f| f.name == name) {
            return Err(Error::Build(format!("frame \"{name}\" is defined twice")));
        }
        self.m.frames.push(Frame { name: name.into(), joint, placement });
        Ok(self.m.frames.len() - 1)
    }

    /// Convenience: joint + a frame `body_name` at the joint frame + the body's inertia
    /// (expressed in the joint's child frame). Returns the joint index.
    pub fn add_body(
        &mut self,
        parent: usize,
        joint_name: &str,
        kind: JointType,
        placement: Transform,
        body_name: &str,
        inertia: Inertia,
    ) -> Result<usize> {
        let id = self.add_joint(parent, joint_name, kind, placement)?;
        self.add_frame(body_name, id, Transform::identity())?;
        self.m.inertias[id] = inertia;
        Ok(id)
    }

    /// Sets the configuration limits of a 1-coordinate joint (or of each coordinate).
    pub fn set_limits(&mut self, joint: usize, lower: &[f64], upper: &[f64]) -> Result<()> {
        if joint == 0
            || joint >= self.m.joints.len()
            || lower.len() != self.m.nqs[joint]
            || upper.len() != lower.len()
        {
            return Err(Error::Build(format!("set_limits: bad joint {joint} or limit length")));
        }
        let a = self.m.idx_q[joint];
        for c in 0..lower.len() {
            self.m.lower[a + c] = lower[c];
            self.m.upper[a + c] = upper[c];
        }
        Ok(())
    }

    /// Marks joint `joint` as a URDF mimic of `of` (kept as an independent joint).
    pub fn set_mimic(&mut self, joint: usize, of: &str) {
        if joint < self.m.mimic.len() {
            self.m.mimic[joint] = Some(of.into());
        }
    }

    /// Sets gravity (a linear acceleration in the world frame).
    pub fn set_gravity(&mut self, g: Vector3<f64>) {
        self.m.gravity = Motion::new(Vector3::zeros(), g);
    }

    /// Finishes the model.
    pub fn build(mut self) -> Model {
        let m = &mut self.m;
        m.dof_ancestors.clear();
        m.dof_ancestors_start = vec![0];
        for k in 0..m.nv {
            let mut d = m.dof_parent[k];
            while let Some(a) = d {
                m.dof_ancestors.push(a);
                d = m.dof_parent[a];
            }
            m.dof_ancestors_start.push(m.dof_ancestors.len());
        }
        m.kin = (0..m.joints.len())
            .map(|i| {
                let rev = match m.joints[i] {
                    JointType::Revolute { axis } | JointType::Continuous { axis } if i > 0 => {
                        unit_axis(&axis)
                    }
                    _ => None,
                };
                let (axis, sign) = rev.unwrap_or((3, 1.0));
                JointKin {
                    parent: m.parents[i],
                    idx_q: m.idx_q[i],
                    nq: m.nqs[i],
                    idx_v: m.idx_v[i],
                    nv: m.nvs[i],
                    axis,
                    sign,
                }
            })
            .collect();
        m.rev_q = m.kin.iter().filter(|k| k.axis < 3).map(|k| k.idx_q).collect();
        m.rev_q_start = match m.rev_q.first() {
            Some(&a) if m.rev_q.iter().enumerate().all(|(r, &b)| b == a + r) => Some(a),
            _ => None,
        };
        self.m
    }
}
