"""Type stubs of the compiled extension ``sodyn._sodyn`` (re-exported by ``sodyn``)."""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

ArrayLike = npt.ArrayLike
Vector = npt.NDArray[np.float64]
Matrix = npt.NDArray[np.float64]
Tensor = npt.NDArray[np.float64]

class SodynError(ValueError):
    """Every error of the sodyn core (model loading, invalid states, singular systems)."""

class Joint:
    """One row of the joint table (joints 1..njoints-1, the world excluded)."""

    name: str
    type: str
    parent: str
    idx_q: int
    nq: int
    idx_v: int
    nv: int
    mimic: Optional[str]
    """In a model loaded with ``mimic=True``, the reference joint of a mimic joint (whose
    ``nq``, ``nv`` are 0 and ``idx_q``, ``idx_v`` those of the reference, as Pinocchio's
    ``JointModelMimic``); ``None`` otherwise."""
    multiplier: float
    """``m`` of a mimic joint, ``q = m * q_ref + c`` (1 otherwise)."""
    offset: float
    """``c`` of a mimic joint (0 otherwise)."""

class Model:
    """Immutable kinematic tree (Pinocchio's ``Model``); gravity may be set."""

    @staticmethod
    def from_urdf(path: Union[str, os.PathLike[str]], floating_base: bool = False,
                  strict_inertia: bool = False, mimic: bool = False) -> "Model":
        """Loads a URDF file. ``floating_base=True`` adds a free-flyer root joint
        ``root_joint``. A link inertia that is not physical but harmless (a positive
        semi-definite one that violates the triangle inequality, or one welded to a fixed base)
        loads with a message in ``warnings``; ``strict_inertia=True`` refuses it instead.
        ``mimic=True`` reads each ``<mimic joint multiplier offset>`` as the constraint
        ``q = multiplier * q_ref + offset``: the mimic joints have no degree of freedom, and
        ``nq``, ``nv``, every state and every output are in the reduced coordinates (a
        ``<mimic>`` whose reference is unknown, a mimic joint, or not a one-DoF joint of the
        same kind is a ``SodynError``). Such a model supports ``rnea``, ``crba``, ``aba``,
        ``nonlinear_effects``, ``id_derivatives``, ``fd_derivatives``, ``id_so_derivatives``,
        ``fd_so_derivatives``, ``id_so_contracted``, ``fd_so_contracted``, ``idfoza``,
        ``idsoza``, ``constrained_id_derivatives``, ``kkt_derivatives``,
        ``impact_derivatives``, ``kkt_so_contracted``, ``impact_so_contracted``,
        ``frame_placement``, ``frame_jacobian``, ``frame_velocity``, ``frame_acceleration``,
        ``frame_velocity_derivatives``, ``frame_acceleration_derivatives``,
        ``frame_jacobian_derivative``, ``frame_placement_hessian`` (any frame of the
        full tree; Jacobians and derivatives ``(6, nv)`` in the reduced coordinates, the full
        tree's times ``G``), ``center_of_mass``, ``center_of_mass_motion``,
        ``center_of_mass_jacobian``, ``center_of_mass_velocity_derivatives``,
        ``centroidal_dynamics_derivatives`` and the methods
        ``integrate``, ``difference``, ``d_integrate``, ``d_difference``; every other function
        raises ``SodynError`` naming itself. See docs/python.md."""
    @staticmethod
    def from_urdf_string(xml: str, floating_base: bool = False,
                         strict_inertia: bool = False, mimic: bool = False) -> "Model":
        """Loads a URDF document given as a string (options as ``from_urdf``)."""
    @staticmethod
    def from_mjcf(path: Union[str, os.PathLike[str]], floating_base: bool = False) -> "Model":
        """Loads an MJCF (MuJoCo XML) file: ``<worldbody>`` bodies with hinge, slide, ball and
        free joints (several per body), ``<default>`` classes, ``<include>``, ``<compiler>``
        (``angle``, ``eulerseq``, ``autolimits``, ``inertiafromgeom``, mass bounds),
        ``<inertial>`` and inertias from primitive geoms (a mesh geom needs an ``<inertial>``).
        Joints and coordinates are MuJoCo's, in its order, except that quaternions are
        ``[x, y, z, w]`` and a free joint's velocity is ``[ω_body, v_body]`` (MuJoCo:
        ``[v_world, ω_body]``); see docs/conventions.md. The joints' ``armature`` (with its
        defaults) is the model's ``armature``. ``floating_base=True`` adds a free-flyer
        ``root_joint`` in front of the ``<worldbody>``'s only body."""
    @staticmethod
    def from_mjcf_string(xml: str, base_dir: Optional[Union[str, os.PathLike[str]]] = None,
                         floating_base: bool = False) -> "Model":
        """Loads an MJCF document given as a string; ``<include>`` paths are relative to
        ``base_dir`` (default: the current directory)."""
    @staticmethod
    def from_pinocchio(pin_model: Any) -> "Model":
        """Reads a ``pinocchio.Model`` (duck-typed; Pinocchio 2 to 4; reduced models of
        ``pinocchio.buildReducedModel`` too): joints, placements, inertias, armature, position
        limits (Pinocchio's ``±max double`` as ``±inf``), gravity, name and every frame.
        Joint ``i`` and frame ``k`` are Pinocchio's joint ``i`` and frame ``k`` (a frame name
        already taken by an earlier frame becomes ``"{name}#{k}"``). Supported joints:
        FreeFlyer, RX/RY/RZ, RevoluteUnaligned, RUBX/RUBY/RUBZ and RevoluteUnboundedUnaligned
        (continuous: one coordinate, the angle), PX/PY/PZ, PrismaticUnaligned, Spherical,
        Planar (``q = [x, y, θ]``); any other type raises ``SodynError`` naming the joint and
        the type. ``sodyn.pinocchio_layout`` maps states, velocities and Jacobians (the free
        flyer's ``v`` is ``[ω; v]`` here, ``[v; ω]`` in Pinocchio)."""
    @staticmethod
    def builtin(name: str) -> "Model": ...
    @staticmethod
    def builtin_names() -> list[str]: ...
    @property
    def name(self) -> str: ...
    @property
    def nq(self) -> int: ...
    @property
    def nv(self) -> int: ...
    @property
    def njoints(self) -> int: ...
    @property
    def has_mimic(self) -> bool:
        """Whether the model was loaded with ``mimic=True``."""
    @property
    def full_model(self) -> Optional["Model"]:
        """For a model loaded with ``mimic=True``: the full tree, every joint independent (as
        ``mimic=False`` loads it); ``None`` otherwise."""
    @property
    def mimic_map(self) -> Optional[Matrix]:
        """For a model loaded with ``mimic=True``: ``G``, ``(full nv, nv)``, with
        ``v_full = G v``, ``tau = G.T @ tau_full``, ``M = G.T @ M_full @ G``; ``None``
        otherwise."""
    def expand_configuration(self, q: ArrayLike) -> Vector:
        """The full tree's configuration of a reduced one (``mimic=True`` models only)."""
    @property
    def constraints(self) -> list["Contact"]:
        """The model's own constraints: MJCF ``<equality>`` ``<connect>`` (3-D) and ``<weld>``
        (6-D) as two-frame constraints (``frame2`` ``"universe"`` for the world), the loops of
        ``builtin:fourbar`` and ``builtin:delta``; empty for other models. The contact
        functions take them when called with ``contacts=None``."""
    @property
    def tendons(self) -> list[dict[str, Any]]:
        """The MJCF ``<tendon>``s in document order (data only: they do not enter the
        dynamics), one dict each: ``name`` (``None`` if unnamed), ``type`` (``"fixed"`` or
        ``"spatial"``) and ``path``: ``(joint name, coef)`` pairs for a fixed tendon;
        ``("site", name)``, ``("geom", name, sidesite or None)`` and ``("pulley", divisor)``
        for a spatial one. Empty for other models."""
    @property
    def warnings(self) -> list[str]:
        """What the URDF or MJCF loader accepted with a reservation, one ``"FILE:LINE: ELEMENT:
        REASON"`` string each: a non-physical but harmless link inertia, a ``<mimic>`` naming an
        unknown joint, an ignored MJCF ``gravcomp``, the armature of an MJCF
        free joint (see docs/conventions.md). Empty for built-in models; nothing is printed."""
    @property
    def armature(self) -> Vector:
        """Armature (rotor inertia) of each velocity coordinate, shape ``(nv,)``, a fresh array
        (zeros unless set by ``with_armature`` or an MJCF ``armature``). Every algorithm uses
        the mass matrix ``M(q) + diag(armature)`` and inverse dynamics
        ``τ = M(q) q̈ + b(q, q̇) + diag(armature) q̈`` (Pinocchio's ``model.armature``, MuJoCo's
        ``dof_armature``)."""
    def with_armature(self, a: ArrayLike) -> "Model":
        """A copy of the model with the armature ``a`` (shape ``(nv,)``, finite, non-negative;
        otherwise ``ValueError`` or ``SodynError`` naming the joint). A ``Data`` made for this
        model serves the copy too. With ``mimic=True``, ``armature`` and ``a`` are per DoF of
        the full tree (``full_model.nv``), mimic joints included."""
    @property
    def gravity(self) -> Vector:
        """Spatial gravity ``[0, 0, 0, gx, gy, gz]`` (angular first), a fresh array."""
    @gravity.setter
    def gravity(self, g: ArrayLike) -> None:
        """Sets gravity from a linear ``(3,)`` or a spatial ``(6,)`` vector with zero angular part."""
    @property
    def joints(self) -> list[Joint]: ...
    @property
    def frames(self) -> list[str]: ...
    @property
    def lower_limits(self) -> Vector: ...
    @property
    def upper_limits(self) -> Vector: ...
    def frame_id(self, name: str) -> int: ...
    def joint_id(self, name: str) -> int: ...
    def neutral(self) -> Vector: ...
    def random_configuration(self, seed: Optional[int] = None) -> Vector: ...
    def integrate(self, q: ArrayLike, dq: ArrayLike) -> Vector: ...
    def difference(self, q0: ArrayLike, q1: ArrayLike) -> Vector: ...
    def d_integrate(self, q: ArrayLike, dq: ArrayLike, arg: int) -> Matrix:
        """``d(q ⊕ dq)/dq`` (``arg=0``) or ``d(q ⊕ dq)/d dq`` (``arg=1``), ``(nv, nv)``:
        Pinocchio's ``dIntegrate`` with ``ARG0`` / ``ARG1``. With ``mimic=True``, in the reduced
        coordinates (block diagonal by independent joint)."""
    def d_difference(self, q0: ArrayLike, q1: ArrayLike, arg: int) -> Matrix:
        """``d(q1 ⊖ q0)/dq0`` (``arg=0``) or ``d(q1 ⊖ q0)/dq1`` (``arg=1``), ``(nv, nv)``:
        Pinocchio's ``dDifference`` with ``ARG0`` / ``ARG1``. With ``mimic=True``, in the
        reduced coordinates (block diagonal by independent joint)."""
    def create_data(self) -> "Data": ...
    def __copy__(self) -> "Model": ...
    def __deepcopy__(self, memo: object) -> "Model": ...

class Data:
    """Preallocated workspace for one model; not shared between threads."""

    def __init__(self, model: Model) -> None: ...

class Contact:
    """A contact (Pinocchio's ``RigidConstraintModel``): a contact frame fixed on a frame (a
    URDF link), given by ``point`` (a 3-D contact's point, frame coordinates) or ``placement``
    (a ``(4, 4)`` homogeneous matrix in the frame's coordinates; default the frame itself, not
    both). ``type`` is ``"3d"`` (a point, 3 rows, ``CONTACT_3D``) or ``"6d"`` (the whole frame,
    6 rows ``[angular; linear]``, ``CONTACT_6D`` whose rows are ``[linear; angular]``);
    ``reference`` is ``"local_world_aligned"`` (world axes at the contact point) or ``"local"``
    (the contact frame's axes); other strings raise ``ValueError`` listing the allowed values.
    A 3-D contact holds the classical acceleration of its point, a 6-D contact the spatial
    acceleration of its frame; forces ``lambda_`` are applied to the robot in each contact's
    axes (docs/conventions.md, "Contacts"). Baumgarte gains ``kp``, ``kd`` >= 0 (default 0;
    Pinocchio's ``corrector``): the KKT dynamics then hold ``a_c + kd v_c + kp e_c = 0`` with
    the reference placement fixed where the contact frame is at the ``q`` of the call
    (``e_c``: the position error for 3-D, ``log6`` of the placement error for 6-D), or, with
    ``xref``, fixed in the world (Crocoddyl's ``ContactModel3D/6D`` ``xref``): a 3-D contact
    takes a point ``(3,)`` (``e_c = p − xref``, in ``local`` rows ``Rᵀ(p − xref)``), a 6-D
    contact a ``(4, 4)`` placement (``e_c = log6(xref⁻¹ M)``, ``local_world_aligned`` rows
    rotated by ``diag(R, R)``); a wrong shape, a non-finite entry or a rotation block that is
    not a rotation is a ``ValueError`` naming ``xref``. ``kkt_derivatives`` differentiates
    that term exactly; the second order (``order=2``, ``kkt_so_contracted``), mimic models and
    two-frame constraints refuse a world reference with ``kp > 0``. Impacts ignore the gains. A body held by a 6-D contact that carries another contact is a redundant
    set: an error naming the contacts.

    With ``frame2`` (a frame name) the constraint is a two-frame (closed-loop) one: frame A
    (``point``/``placement`` in ``frame``) is held on frame B, given by ``point2`` (3-D) or
    ``placement2`` (a ``(4, 4)`` matrix) in ``frame2``'s coordinates (docs/conventions.md);
    both frames on one body is a ``ValueError``. ``Model.constraints`` lists a model's own."""

    def __init__(self, frame: str, point: Optional[ArrayLike] = None, kp: float = 0.0,
                 kd: float = 0.0, type: str = "3d", reference: str = "local_world_aligned",
                 placement: Optional[ArrayLike] = None, frame2: Optional[str] = None,
                 point2: Optional[ArrayLike] = None,
                 placement2: Optional[ArrayLike] = None,
                 xref: Optional[ArrayLike] = None) -> None: ...
    @property
    def frame2(self) -> Optional[str]:
        """Frame B of a two-frame constraint, ``None`` for a contact with the world."""
    @property
    def point2(self) -> Vector:
        """Origin of frame B's contact frame in ``frame2``'s coordinates ``(3,)``."""
    @property
    def placement2(self) -> Matrix:
        """Frame B's contact frame in ``frame2``'s coordinates, ``(4, 4)`` homogeneous matrix."""
    @property
    def frame(self) -> str: ...
    @property
    def point(self) -> Vector:
        """Origin of the contact frame in the frame's coordinates ``(3,)``."""
    @property
    def placement(self) -> Matrix:
        """The contact frame in the frame's coordinates, ``(4, 4)`` homogeneous matrix."""
    @property
    def type(self) -> str:
        """``"3d"`` or ``"6d"``."""
    @property
    def reference(self) -> str:
        """``"local_world_aligned"`` or ``"local"``."""
    @property
    def kp(self) -> float: ...
    @property
    def kd(self) -> float: ...
    @property
    def xref(self) -> Optional[Union[Vector, Matrix]]:
        """The world reference of ``kp``: ``None``, a 3-D contact's point ``(3,)`` or a 6-D
        contact's placement ``(4, 4)``."""

def rnea(model: Model, data: Data, q: ArrayLike, v: ArrayLike, a: ArrayLike,
         fext: Optional[ArrayLike] = None) -> Vector: ...
def crba(model: Model, data: Data, q: ArrayLike) -> Matrix: ...
def aba(model: Model, data: Data, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
        fext: Optional[ArrayLike] = None) -> Vector: ...
def nonlinear_effects(model: Model, data: Data, q: ArrayLike, v: ArrayLike) -> Vector: ...
def id_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike, a: ArrayLike,
                   fext: Optional[ArrayLike] = None) -> Tuple[Matrix, Matrix]: ...
def fd_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                   fext: Optional[ArrayLike] = None) -> Tuple[Matrix, Matrix, Matrix]: ...
def id_so_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike, a: ArrayLike,
                      out: Optional[Tuple[Tensor, Tensor, Tensor, Tensor]] = None
                      ) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Second-order inverse-dynamics derivatives ``(d2tau_dq2, d2tau_dv2, d2tau_dqdv, dM_dq)``;
    with ``out`` they are written into those arrays (see ``fd_so_derivatives``)."""
def fd_so_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                      out: Optional[Tuple[Tensor, Tensor, Tensor, Tensor]] = None
                      ) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Second-order forward-dynamics derivatives ``(d2qdd_dq2, d2qdd_dv2, d2qdd_dqdv,
    d2qdd_dtaudq)``; with ``out`` (four Fortran-order ``(nv, nv, nv)`` float64 arrays, e.g. a
    previous result) they are written there and ``out`` is returned."""
def id_so_contracted(model: Model, data: Data, q: ArrayLike, v: ArrayLike, a: ArrayLike,
                     w: ArrayLike) -> Tuple[Matrix, Matrix, Matrix, Matrix]:
    """Hessians of ``w @ tau(q, v, a)``: ``(C_qq, C_vv, C_qv, C_Mq)``, ``C[j, k] = sum_i w[i] T[i, j, k]``."""
def fd_so_contracted(model: Model, data: Data, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                     w: ArrayLike) -> Tuple[Matrix, Matrix, Matrix, Matrix]:
    """Hessians of ``w @ qdd(q, v, tau)``: ``(C_qq, C_vv, C_qv, C_tauq)``."""
def idfoza(model: Model, data: Data, q: ArrayLike, x: ArrayLike) -> Matrix:
    """IDFOZA: ``d(M(q) x)/dq``, ``(nv, nv)`` (with ``mimic=True``: ``M = G^T M_full G`` of the
    reduced coordinates)."""
def idsoza(model: Model, data: Data, q: ArrayLike, x: ArrayLike) -> Tensor:
    """IDSOZA: ``d2(M(q) x)/dq2``, ``(nv, nv, nv)``, ``T[i, j, k] = d/dq_k d(M x)_i/dq_j``
    (with ``mimic=True``: in the reduced coordinates)."""
def constrained_id_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike,
                               a: ArrayLike, contacts: Optional[Sequence[Contact]], lambda_: ArrayLike,
                               order: int = 1) -> dict[str, Vector]:
    """``tau = M a + b - J_c^T lambda_`` and its derivatives, ``lambda_`` with 3 or 6 rows per
    contact (held fixed in each contact's axes); ``sodyn.constrained_id_derivatives`` wraps the
    dict in a ``ConstrainedIdResult``."""
def kkt_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                    contacts: Optional[Sequence[Contact]] = None, order: int = 1,
                    damping: float = 0.0) -> dict[str, Vector]:
    """The KKT contact dynamics and its derivatives (``sodyn.kkt_derivatives``), ``damping``
    added to the Delassus matrix's diagonal."""
def impact_derivatives(model: Model, data: Data, q: ArrayLike, v_minus: ArrayLike,
                       contacts: Optional[Sequence[Contact]] = None, restitution: float = 0.0,
                       order: int = 1, damping: float = 0.0) -> dict[str, Vector]:
    """The impact dynamics and its derivatives (``sodyn.impact_derivatives``), ``damping``
    added to the Delassus matrix's diagonal."""

def kkt_so_contracted(model: Model, data: Data, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                      contacts: Optional[Sequence[Contact]], w_qdd: ArrayLike, w_lambda: ArrayLike,
                      damping: float = 0.0) -> Tuple[Matrix, Matrix, Matrix, Matrix]:
    """Hessians of ``w_qdd @ qdd + w_lambda @ lambda`` of the KKT dynamics:
    ``(C_qq, C_vv, C_qv, C_tauq)``; ``w_lambda`` has 3 or 6 rows per contact."""
def impact_so_contracted(model: Model, data: Data, q: ArrayLike, v_minus: ArrayLike,
                         contacts: Optional[Sequence[Contact]], w_vplus: ArrayLike,
                         w_impulse: ArrayLike,
                         restitution: float = 0.0,
                         damping: float = 0.0) -> Tuple[Matrix, Matrix]:
    """Hessians of ``w_vplus @ vplus + w_impulse @ impulse`` of the impact dynamics:
    ``(C_qq, C_qvminus)``; ``w_impulse`` has 3 or 6 rows per contact."""
def frame_placement(model: Model, data: Data, q: ArrayLike, frame: Union[str, int]) -> Matrix:
    """World placement of a frame (a URDF link, merged ones included) as a (4, 4) homogeneous
    matrix (Pinocchio's ``data.oMf``)."""
def frame_jacobian(model: Model, data: Data, q: ArrayLike, frame: Union[str, int],
                   reference: str = "local") -> Matrix:
    """``(6, nv)`` Jacobian of a frame, rows ``[w; v]``; ``reference`` is ``"local"``,
    ``"world"`` or ``"local_world_aligned"`` (Pinocchio's ``getFrameJacobian``, rows ``[v; w]``
    there). With ``mimic=True``, ``J_full G`` in the reduced coordinates."""
def frame_velocity(model: Model, data: Data, q: ArrayLike, v: ArrayLike, frame: Union[str, int],
                   reference: str = "local") -> Vector:
    """Spatial velocity ``[w; v]`` of a frame in ``reference`` (``getFrameVelocity``)."""
def frame_acceleration(model: Model, data: Data, q: ArrayLike, v: ArrayLike, a: ArrayLike,
                       frame: Union[str, int], reference: str = "local",
                       classical: bool = False) -> Vector:
    """Spatial acceleration ``[dw; dv]`` of a frame in ``reference`` without gravity
    (``getFrameAcceleration``); with ``classical=True`` the linear part is the classical
    acceleration (``getFrameClassicalAcceleration``)."""
def frame_velocity_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike,
                               frame: Union[str, int], reference: str = "local"
                               ) -> Tuple[Matrix, Matrix]:
    """``(dv_dq, dv_dv)``, each ``(6, nv)``: derivatives of ``frame_velocity``
    (``getFrameVelocityDerivatives``)."""
def frame_acceleration_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike,
                                   a: ArrayLike, frame: Union[str, int],
                                   reference: str = "local") -> Tuple[Matrix, Matrix, Matrix]:
    """``(da_dq, da_dv, da_da)``, each ``(6, nv)``: derivatives of ``frame_acceleration``
    (``getFrameAccelerationDerivatives``)."""
def center_of_mass(model: Model, data: Data, q: ArrayLike) -> Vector:
    """Centre of mass ``(3,)``, world frame (``centerOfMass``)."""
def center_of_mass_motion(model: Model, data: Data, q: ArrayLike, v: ArrayLike,
                          a: Optional[ArrayLike] = None) -> Tuple[Vector, Vector, Vector]:
    """``(com, vcom, acom)``, world frame; ``acom`` without gravity, zeros without ``a``."""
def center_of_mass_jacobian(model: Model, data: Data, q: ArrayLike) -> Matrix:
    """``(3, nv)`` centre-of-mass Jacobian (``jacobianCenterOfMass``)."""
def center_of_mass_velocity_derivatives(model: Model, data: Data, q: ArrayLike,
                                        v: ArrayLike) -> Matrix:
    """``d vcom / dq``, ``(3, nv)`` (``getCenterOfMassVelocityDerivatives``)."""
def centroidal_dynamics_derivatives(model: Model, data: Data, q: ArrayLike, v: ArrayLike,
                                    a: ArrayLike) -> dict[str, Union[Vector, Matrix]]:
    """Centroidal momentum about the centre of mass (world axes, rows ``[angular; linear]``):
    ``h``, ``hdot`` (no gravity), ``Ag`` (``h = Ag v``, ``dhdot/da``), ``dh_dq``, ``dhdot_dq``,
    ``dhdot_dv`` (``computeCentroidalDynamicsDerivatives``, rows ``[linear; angular]`` there).
    With ``mimic=True``, the matrices are ``(6, nv)`` in the reduced coordinates (the full
    tree's times ``G``)."""
def frame_jacobian_derivative(model: Model, data: Data, q: ArrayLike, frame: Union[str, int],
                              reference: str = "local") -> Tensor:
    """``(6, nv, nv)``: ``T[r, c, k] = dJ[r, c]/dq_k`` of ``frame_jacobian`` (the kinematic
    Hessian; Pinocchio's ``getJointKinematicHessian`` for joint frames)."""
def frame_placement_hessian(model: Model, data: Data, q: ArrayLike,
                            frame: Union[str, int]) -> Tensor:
    """``(6, nv, nv)`` Hessian of ``y = [log3(R(q)^T R(q')); p(q')]`` at ``q' = q``:
    ``T[r, j, k] = d/dq_k (dy_r/dq_j)`` (no Pinocchio counterpart)."""
def exp6(xi: ArrayLike) -> Matrix:
    """SE(3) exponential of ``xi = [w; v]`` as a (4, 4) homogeneous matrix (Pinocchio's ``exp6``
    takes ``[v; w]``)."""
def log6(M: ArrayLike) -> Vector:
    """SE(3) logarithm ``[w; v]`` of a (4, 4) homogeneous matrix (rotation angle <= pi)."""
def jlog6(M: ArrayLike) -> Matrix:
    """``Jlog6(M)`` (6, 6) in ``[w; v]`` order: ``log6(M exp6(e)) = log6(M) + Jlog6(M) e + O(e^2)``."""
def clear_buffer_pool() -> int:
    """Frees the recycled output memory kept for reuse (at most 512 MiB; large results are
    returned over buffers that come back to this pool when the arrays are freed, so that later
    calls do not fault in fresh pages). Returns the number of bytes freed."""

# Batched entry points (wrapped by ``sodyn.batch``).
def batch_rnea(model: Model, q: ArrayLike, v: ArrayLike, a: ArrayLike,
               threads: Optional[int] = None) -> Matrix: ...
def batch_crba(model: Model, q: ArrayLike, threads: Optional[int] = None) -> Tensor: ...
def batch_aba(model: Model, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
              threads: Optional[int] = None) -> Matrix: ...
def batch_nonlinear_effects(model: Model, q: ArrayLike, v: ArrayLike,
                            threads: Optional[int] = None) -> Matrix: ...
def batch_id_derivatives(model: Model, q: ArrayLike, v: ArrayLike, a: ArrayLike,
                         threads: Optional[int] = None) -> Tuple[Tensor, Tensor]: ...
def batch_fd_derivatives(model: Model, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                         threads: Optional[int] = None) -> Tuple[Tensor, Tensor, Tensor]: ...
def batch_id_so_derivatives(model: Model, q: ArrayLike, v: ArrayLike, a: ArrayLike,
                            threads: Optional[int] = None) -> Tuple[npt.NDArray[np.float64], ...]: ...
def batch_fd_so_derivatives(model: Model, q: ArrayLike, v: ArrayLike, tau: ArrayLike,
                            threads: Optional[int] = None) -> Tuple[npt.NDArray[np.float64], ...]: ...

# --- sodyn.ocp's Rust side (python/src/ocp.rs); use the classes of sodyn.ocp. ---
class OcpError(ValueError): ...

class _Solver:
    def __init__(self, model: Model, problem_json: str, kind: str, threads: int = 1) -> None: ...
    def solve(
        self,
        init_xs: Optional[Sequence[Sequence[float]]] = None,
        init_us: Optional[Sequence[Sequence[float]]] = None,
        maxiter: int = 100,
        is_feasible: bool = False,
        init_reg: Optional[float] = None,
    ) -> bool: ...
    def set_candidate(
        self,
        xs: Optional[Sequence[Sequence[float]]] = None,
        us: Optional[Sequence[Sequence[float]]] = None,
        is_feasible: bool = False,
    ) -> None: ...
    xs: List[np.ndarray]
    us: List[np.ndarray]
    k: List[np.ndarray]
    fs: List[np.ndarray]
    cost: float
    stop: float
    iter: int
    preg: float
    steplength: float
    is_feasible: bool
    ffeas: float
    th_stop: float
    threads: int
    termination: str
    second_order: str
    hessian_stats: Dict[str, float]
    log: List[Dict[str, float]]
    horizon: int
    nus: List[int]
    def calc(self, xs: Sequence[Sequence[float]], us: Sequence[Sequence[float]]) -> float: ...
    def calc_diff(self, xs: Sequence[Sequence[float]], us: Sequence[Sequence[float]]) -> float: ...
    def node_data(self, t: int) -> Dict[str, Any]: ...
    def node_second_order(
        self, t: int, x: Sequence[float], u: Sequence[float], vx_next: Sequence[float]
    ) -> np.ndarray: ...
    def quasi_static(self, xs: Sequence[Sequence[float]]) -> List[np.ndarray]: ...
    def rollout(self, us: Sequence[Sequence[float]]) -> List[np.ndarray]: ...
    def set_x0(self, x0: Sequence[float]) -> None: ...

# XLA FFI handlers of sodyn.jax (private; python/src/jax_ffi.rs)
def _jax_ffi_targets() -> Dict[str, Any]: ...
def _jax_ffi_model(model: Model) -> int: ...
def _jax_ffi_contacts(model: Model, contacts: Sequence[Contact],
                      restitution: float = 0.0) -> int: ...
