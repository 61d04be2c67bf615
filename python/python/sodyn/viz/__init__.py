"""sodyn.viz: a 3-D viewer of sodyn models, states and trajectories (meshcat).

``Visualizer(model, urdf_or_mjcf_path=None, package_dirs=())`` draws the robot from the
geometry of its URDF (``<visual>``: box, cylinder, sphere, STL/DAE/OBJ meshes) or MJCF
(``<geom>``, compiled by MuJoCo) file, placed by :func:`sodyn.frame_placement`. Links without
geometry, and models without a file, are drawn as spheres at the joint origins and capsules
between them. ``display(q)`` and ``play(qs or xs, dt)`` update a live meshcat viewer (in a
browser tab; started on first use), ``save_html(path, trajectory, dt)`` writes one
self-contained HTML file (meshcat's three.js viewer inlined, no network) that plays the
motion. ``python -m sodyn.viz MODEL --html out.html`` is the command line. See docs/viz.md.

Needs the ``viz`` extra: ``pip install "./python[viz]"`` (meshcat); MJCF geometry also needs
``mujoco``.
"""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

import sodyn

from ._geometry import (
    BONE_COLOR,
    FORCE_COLOR,
    JOINT_COLOR,
    RobotGeometry,
    Shape,
    VizWarning,
    homogeneous,
    mjcf_geometry,
    segment_transform,
    urdf_geometry,
)

__all__ = ["Visualizer", "VizWarning", "load_model"]

try:  # meshcat is the optional ``viz`` extra
    with warnings.catch_warnings():  # meshcat's server module imports a deprecated pyzmq module
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat  # noqa: F401
    import meshcat.geometry as _mg
    from meshcat.animation import Animation as _Animation
    from meshcat.commands import SetAnimation, SetObject, SetTransform
    from meshcat.path import Path as _MPath

    _IMPORT_ERROR: Optional[ImportError] = None
except ImportError as _e:  # pragma: no cover - exercised only without the extra
    _IMPORT_ERROR = _e

_ROOT = ("meshcat", "sodyn")
_RX90 = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # y -> z
_TINY = 1e-6


def _require_meshcat() -> None:
    if _IMPORT_ERROR is not None:
        raise ImportError(
            "sodyn.viz needs meshcat: pip install \"./python[viz]\" (or pip install meshcat)"
        ) from _IMPORT_ERROR


def _clean(name: str) -> str:
    """A meshcat path element (``/`` separates elements)."""
    return name.replace("/", "_") or "_"


def _color(rgba: Sequence[float]) -> Tuple[int, float]:
    r, g, b, a = (min(max(float(c), 0.0), 1.0) for c in rgba)
    return (int(r * 255) << 16) | (int(g * 255) << 8) | int(b * 255), a


def _material(rgba: Sequence[float]):
    color, alpha = _color(rgba)
    return _mg.MeshLambertMaterial(color=color, opacity=alpha)


def _scale_matrix(s: Sequence[float]) -> np.ndarray:
    return np.diag([float(s[0]), float(s[1]), float(s[2]), 1.0])


def load_model(spec: str, floating_base: bool = False) -> Tuple["sodyn.Model", Optional[str]]:
    """The model of a command-line ``MODEL``: a URDF path, an MJCF path ending in ``.xml``,
    or ``builtin:NAME``; returns ``(model, geometry file or None)``."""
    if spec.startswith("builtin:"):
        name = spec[len("builtin:"):]
        if floating_base:
            raise ValueError(f"{spec}: --floating-base applies to URDF and MJCF files only")
        return sodyn.Model.builtin(name), None
    if not Path(spec).is_file():
        raise ValueError(f"{spec}: no such file (MODEL is a URDF path, an MJCF .xml path or "
                         "builtin:NAME)")
    if spec.lower().endswith(".xml"):
        return sodyn.Model.from_mjcf(spec, floating_base=floating_base), spec
    return sodyn.Model.from_urdf(spec, floating_base=floating_base), spec


class _Node:
    """A moving scene node: its meshcat path and how its pose follows the configuration."""

    __slots__ = ("path", "kind", "frame", "extra")

    def __init__(self, path: Tuple[str, ...], kind: str, frame: Any = None, extra: Any = None):
        self.path, self.kind, self.frame, self.extra = path, kind, frame, extra


class Visualizer:
    """A meshcat view of a sodyn model.

    Parameters
    ----------
    model:
        A :class:`sodyn.Model`. Its frames (URDF link names, MJCF body names) place the
        geometry; ``display`` and ``play`` take its configurations.
    urdf_or_mjcf_path:
        The URDF or MJCF (``.xml``) file of the model, read for its visual geometry. ``None``:
        spheres at the joint origins and capsules between them (the drawing of a link without
        visuals too).
    package_dirs:
        Directories searched for ``package://PKG/...`` and relative mesh paths (then
        ``$ROS_PACKAGE_PATH``, then the URDF's directory and its parents).
    viewer:
        ``None`` (default): a live meshcat viewer (a local server on 127.0.0.1, opened in a
        browser tab at its printed URL) is started by the first ``display``, ``play`` or
        ``open``. A ``meshcat.Visualizer``: draw into that one. ``False``: no live viewer;
        ``display`` and ``play`` only set the state that ``save_html`` writes.
    force_scale:
        Arrow length per newton of the contact forces (metres per newton).
    frame_scale:
        Axis length of the frames drawn by ``show_frames`` (metres).

    Missing or unreadable mesh files raise a :class:`VizWarning` naming the file; that link
    is drawn as a sphere and capsules.
    """

    def __init__(self, model: "sodyn.Model", urdf_or_mjcf_path: Optional[Union[str, os.PathLike]] = None,
                 package_dirs: Sequence[Union[str, os.PathLike]] = (), *, viewer: Any = None,
                 force_scale: float = 1e-3, frame_scale: float = 0.1) -> None:
        _require_meshcat()
        if not isinstance(model, sodyn.Model):
            raise TypeError(f"model: expected a sodyn.Model, got {type(model).__name__}")
        if isinstance(package_dirs, (str, os.PathLike)):
            package_dirs = [package_dirs]
        self.model = model
        self.data = sodyn.Data(model)
        self.force_scale = float(force_scale)
        self.frame_scale = float(frame_scale)
        self.package_dirs = [str(d) for d in package_dirs]
        self._frame_names = set(model.frames)
        self.geometry = self._load_geometry(urdf_or_mjcf_path)
        self._q = np.asarray(model.neutral(), dtype=float)
        self._shown_frames: List[str] = []
        self._forces: Dict[Any, np.ndarray] = {}
        self._trajectory: Optional[List[np.ndarray]] = None
        self._trajectory_forces: Optional[List[Mapping[Any, Any]]] = None
        self._dt: Optional[float] = None
        self._viewer: Any = None if viewer is None else (viewer if viewer is not False else False)
        self._live_ready = False
        if self._viewer not in (None, False):
            self._send_scene()

    # --------------------------------------------------------------------------------------
    # Geometry
    # --------------------------------------------------------------------------------------

    def _load_geometry(self, path: Optional[Union[str, os.PathLike]]) -> RobotGeometry:
        if path is None:
            return RobotGeometry()
        p = Path(path)
        if not p.is_file():
            raise ValueError(f"urdf_or_mjcf_path: {str(p)!r} is not a file")
        if p.suffix.lower() == ".xml":
            try:
                geo = mjcf_geometry(p)
            except ImportError:
                warnings.warn(f"{p}: MJCF geometry needs the mujoco package (pip install "
                              "mujoco); the model is drawn as spheres and capsules",
                              VizWarning, stacklevel=3)
                return RobotGeometry()
            except ValueError as e:
                warnings.warn(f"{e}; the model is drawn as spheres and capsules", VizWarning,
                              stacklevel=3)
                return RobotGeometry()
        else:
            text = p.read_text(encoding="utf-8", errors="replace")
            geo = urdf_geometry(text, str(p), p.parent, self.package_dirs)
        unknown = [f for f in geo.shapes if f not in self._frame_names and f != "world"]
        for f in unknown:
            warnings.warn(f"{p}: link {f!r} is not a frame of the model; its visuals are not "
                          "drawn", VizWarning, stacklevel=3)
            del geo.shapes[f]
        geo.bones = [b for b in geo.bones if b[0] in self._frame_names]
        geo.joint_markers = [f for f in geo.joint_markers if f in self._frame_names]
        return geo

    def _shape_objects(self, shape: Shape) -> List[Tuple[Any, np.ndarray]]:
        """meshcat objects of a shape with their transforms in the frame."""
        mat = _material(shape.rgba)
        o = shape.origin
        k, s = shape.kind, shape.size
        if k == "box":
            return [(_mg.Mesh(_mg.Box(list(s)), mat), o)]
        if k == "sphere":
            return [(_mg.Mesh(_mg.Sphere(s[0]), mat), o)]
        if k == "ellipsoid":
            return [(_mg.Mesh(_mg.Sphere(1.0), mat), o @ _scale_matrix(s))]
        if k == "cylinder":
            return [(_mg.Mesh(_mg.Cylinder(s[1], s[0]), mat), o @ _RX90)]
        if k == "capsule":
            r, length = s
            out = [(_mg.Mesh(_mg.Cylinder(length, r), mat), o @ _RX90)]
            for z in (-0.5 * length, 0.5 * length):
                out.append((_mg.Mesh(_mg.Sphere(r), mat), o @ homogeneous(np.eye(3), (0, 0, z))))
            return out
        if k == "trimesh":
            return [(_mg.Mesh(_mg.TriangularMeshGeometry(shape.vertices, shape.faces), mat), o)]
        if k == "mesh":
            assert shape.mesh_file is not None
            suffix = Path(shape.mesh_file).suffix.lower()
            try:
                if suffix == ".stl":
                    geom = _mg.StlMeshGeometry.from_file(shape.mesh_file)
                elif suffix == ".obj":
                    geom = _mg.ObjMeshGeometry.from_file(shape.mesh_file)
                else:
                    geom = _mg.DaeMeshGeometry.from_file(shape.mesh_file)
            except (OSError, UnicodeDecodeError) as e:
                warnings.warn(f"mesh file {shape.mesh_file!r} cannot be read ({e}); drawn as a "
                              "sphere", VizWarning, stacklevel=4)
                return [(_mg.Mesh(_mg.Sphere(0.02), _material(JOINT_COLOR)), o)]
            return [(_mg.Mesh(geom, mat), o @ _scale_matrix(shape.scale))]
        raise AssertionError(k)

    def _skeleton(self) -> List[Tuple[str, Optional[str]]]:
        """``(frame, parent frame)`` for every frame but the first (the universe): the parent
        frame is the first frame carried by the parent joint of the frame's joint (the frame
        itself for the world-fixed frames: ``universe``). A frame's joint is the deepest
        joint whose velocity columns of its Jacobian are non-zero (at a random
        configuration: the columns of a frame's supporting joints never vanish)."""
        model = self.model
        joints = list(model.joints)
        index = {j.name: i for i, j in enumerate(joints)}
        depth: Dict[str, int] = {}

        def joint_depth(name: str) -> int:
            if name not in index:
                return 0
            if name not in depth:
                depth[name] = 1 + joint_depth(joints[index[name]].parent)
            return depth[name]

        dof_joint = [None] * model.nv
        for j in joints:
            for c in range(j.nv):
                dof_joint[j.idx_v + c] = j.name  # type: ignore[call-overload]
        q = np.asarray(model.random_configuration(seed=7), dtype=float)
        frames = list(model.frames)
        carrier: Dict[str, Optional[str]] = {}
        for f in frames:
            J = np.asarray(sodyn.frame_jacobian(model, self.data, q, f, "world"))
            moving = [dof_joint[c] for c in range(model.nv) if np.abs(J[:, c]).max() > 1e-12]
            carrier[f] = max(moving, key=joint_depth) if moving else None
        first: Dict[Optional[str], str] = {}
        for f in frames:
            first.setdefault(carrier[f], f)
        out = []
        for f in frames[1:]:
            j = carrier[f]
            parent_joint = joints[index[j]].parent if j is not None else None
            while parent_joint is not None and parent_joint not in first:
                parent_joint = (joints[index[parent_joint]].parent
                                if parent_joint in index else None)
            parent = first.get(parent_joint, frames[0]) if j is not None else frames[0]
            if first.get(j) != f and j is not None:
                parent = first[j]  # a second frame of the same body: from the body's first
            elif j is not None and parent == frames[0] and \
                    joints[index[j]].type in ("free_flyer", "planar"):
                parent = None  # a floating base is not tied to the world origin
            out.append((f, parent))
        return out

    def _bone_radius(self) -> float:
        return 0.015

    def _scene(self) -> Tuple[List[Any], List[_Node]]:
        """The commands that build the scene (objects and their constant transforms) and the
        moving nodes."""
        cmds: List[Any] = []
        nodes: List[_Node] = []
        geo = self.geometry
        r = self._bone_radius()
        frames = sorted(set(geo.shapes) | set(geo.joint_markers) | {b[0] for b in geo.bones},
                        key=lambda f: f)
        for frame in frames:
            base = _ROOT + ("links", _clean(frame))
            if frame in self._frame_names:  # MJCF world-body geoms ("world") are static
                nodes.append(_Node(base, "frame", frame))
            i = 0
            for shape in geo.shapes.get(frame, []):
                for obj, tf in self._shape_objects(shape):
                    path = _MPath(base + (f"v{i}",))
                    cmds += [SetObject(obj, path=path), SetTransform(tf, path)]
                    i += 1
            if frame in geo.joint_markers:
                path = _MPath(base + ("joint",))
                cmds.append(SetObject(_mg.Mesh(_mg.Sphere(1.6 * r), _material(JOINT_COLOR)),
                                      path=path))
            for k, (bf, a, b) in enumerate(b for b in geo.bones if b[0] == frame):
                tf, length = segment_transform(a, b)
                path = _MPath(base + (f"bone{k}",))
                cmds += [SetObject(_mg.Mesh(_mg.Cylinder(length, r), _material(BONE_COLOR)),
                                   path=path), SetTransform(tf @ _RX90, path)]
        if geo.source is None:
            # No file: a sphere at every frame origin and a unit capsule, scaled at each
            # configuration, from the frame of the parent body to it.
            for frame, parent in self._skeleton():
                jp = _ROOT + ("joints", _clean(frame))
                cmds.append(SetObject(_mg.Mesh(_mg.Sphere(1.6 * r), _material(JOINT_COLOR)),
                                      path=_MPath(jp)))
                nodes.append(_Node(jp, "frame", frame))
                if parent is None:
                    continue
                bp = _ROOT + ("bones", _clean(frame))
                cmds.append(SetObject(_mg.Mesh(_mg.Cylinder(1.0, r), _material(BONE_COLOR)),
                                      path=_MPath(bp)))
                nodes.append(_Node(bp, "segment", (parent, frame)))
        # Shown frames: three axes as thin cylinders (red x, green y, blue z).
        for name in self._shown_frames:
            fp = _ROOT + ("frames", _clean(name))
            nodes.append(_Node(fp, "frame", name))
            L = self.frame_scale
            for axis, rgba, rot in (("x", (0.9, 0.1, 0.1, 1), np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1.0]])),
                                    ("y", (0.1, 0.8, 0.1, 1), np.eye(3)),
                                    ("z", (0.1, 0.2, 0.9, 1), _RX90[:3, :3])):
                # the cylinder runs along y; rot takes y to the axis, shifted by half its length
                tf = homogeneous(rot, rot @ np.array([0, 0.5 * L, 0]))
                path = _MPath(fp + (axis,))
                cmds += [SetObject(_mg.Mesh(_mg.Cylinder(L, L / 25), _material(rgba)), path=path),
                         SetTransform(tf, path)]
        # Force arrows: a unit shaft scaled to the force and a cone at its tip.
        for key in self._force_keys():
            ap = _ROOT + ("forces", _clean(self._force_name(key)))
            hr = self.frame_scale * 0.25
            cmds += [SetObject(_mg.Mesh(_mg.Cylinder(1.0, hr * 0.4), _material(FORCE_COLOR)),
                               path=_MPath(ap + ("shaft",))),
                     SetObject(_mg.Mesh(_mg.Cylinder(2 * hr, radiusTop=0.0, radiusBottom=hr),
                                        _material(FORCE_COLOR)), path=_MPath(ap + ("head",)))]
            nodes.append(_Node(ap + ("shaft",), "shaft", key))
            nodes.append(_Node(ap + ("head",), "head", key))
        return cmds, nodes

    def _force_keys(self) -> List[Any]:
        keys: List[Any] = []
        sources: List[Mapping[Any, Any]] = [self._forces]
        if self._trajectory_forces:
            sources += list(self._trajectory_forces)
        for d in sources:
            for k in d:
                if not any(self._same_key(k, e) for e in keys):
                    keys.append(k)
        return keys

    @staticmethod
    def _same_key(a: Any, b: Any) -> bool:
        return a is b or (not isinstance(a, sodyn.Contact) and not isinstance(b, sodyn.Contact)
                          and a == b)

    @staticmethod
    def _force_name(key: Any) -> str:
        if isinstance(key, sodyn.Contact):
            p = key.point
            return f"{key.frame}@{p[0]:.3g},{p[1]:.3g},{p[2]:.3g}"
        return str(key)

    # --------------------------------------------------------------------------------------
    # Poses
    # --------------------------------------------------------------------------------------

    def _configuration(self, q: Any, what: str = "q") -> np.ndarray:
        q = np.asarray(q, dtype=float).reshape(-1)
        nq, nv = self.model.nq, self.model.nv
        if q.size == nq + nv and q.size != nq:
            q = q[:nq]  # a state x = [q; v]
        if q.size != nq:
            raise ValueError(f"{what}: length {q.size}, expected nq = {nq} (a configuration) or "
                             f"nq + nv = {nq + nv} (a state x = [q; v])")
        if not np.all(np.isfinite(q)):
            raise ValueError(f"{what}: not finite")
        return q

    def _placements(self, q: np.ndarray, names: Iterable[str]) -> Dict[str, np.ndarray]:
        out = {}
        for n in names:
            if n not in out:
                out[n] = np.asarray(sodyn.frame_placement(self.model, self.data, q, n), dtype=float)
        return out

    def _force_vector(self, key: Any, f: Any, oMf: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(application point, force) in world coordinates."""
        f = np.asarray(f, dtype=float).reshape(-1)
        if f.size == 6:
            f = f[3:]  # [torque; force]: the linear part
        if f.size != 3 or not np.all(np.isfinite(f)):
            raise ValueError(f"forces[{self._force_name(key)!r}]: expected 3 (force) or 6 "
                             f"([torque; force]) finite numbers, got {f.size}")
        if isinstance(key, sodyn.Contact):
            placement = np.asarray(key.placement, dtype=float)
            oMc = oMf @ placement
            point = oMc[:3, 3]
            if key.reference == "local":
                f = oMc[:3, :3] @ f
            return point, f
        return oMf[:3, 3].copy(), f

    def _force_frame(self, key: Any) -> str:
        frame = key.frame if isinstance(key, sodyn.Contact) else key
        if isinstance(frame, (int, np.integer)):
            frames = self.model.frames
            if not 0 <= int(frame) < len(frames):
                raise ValueError(f"forces: frame index {frame} out of range 0..{len(frames) - 1}")
            return frames[int(frame)]
        if frame not in self._frame_names:
            raise ValueError(f"forces: {frame!r} is not a frame of the model")
        return str(frame)

    def _poses(self, q: np.ndarray, forces: Mapping[Any, Any]
               ) -> Dict[Tuple[str, ...], Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(position, rotation, scale) of every moving node at ``q``."""
        names = [n.frame for n in self._nodes if n.kind == "frame"]
        names += [f for n in self._nodes if n.kind == "segment" for f in n.frame]
        force_frames = {id(k): self._force_frame(k) for k in forces}
        oM = self._placements(q, list(names) + list(force_frames.values()))
        out = {}
        for n in self._nodes:
            if n.kind == "frame":
                m = oM[n.frame]
                out[n.path] = (m[:3, 3], m[:3, :3], np.ones(3))
            elif n.kind == "segment":
                a, b = oM[n.frame[0]][:3, 3], oM[n.frame[1]][:3, 3]
                tf, length = segment_transform(a, b)
                tf = tf @ _RX90
                out[n.path] = (tf[:3, 3], tf[:3, :3], np.array([1.0, max(length, _TINY), 1.0]))
            else:  # a force arrow: shaft or head
                f = None
                for k, v in forces.items():
                    if self._same_key(k, n.frame):
                        f = self._force_vector(k, v, oM[force_frames[id(k)]])
                        break
                hr = self.frame_scale * 0.25
                if f is None or np.linalg.norm(f[1]) * self.force_scale < 1e-9:
                    out[n.path] = (np.zeros(3), np.eye(3), np.full(3, _TINY))
                    continue
                point, force = f
                length = float(np.linalg.norm(force)) * self.force_scale
                tf, _ = segment_transform(point, point + force / np.linalg.norm(force) * length)
                tf = tf @ _RX90
                d = tf[:3, 1]
                if n.kind == "shaft":
                    out[n.path] = (point + 0.5 * length * d, tf[:3, :3], np.array([1, length, 1.0]))
                else:
                    out[n.path] = (point + (length + hr) * d, tf[:3, :3], np.ones(3))
        return out

    @staticmethod
    def _matrix(pose: Tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        p, R, s = pose
        return homogeneous(R @ np.diag(s), p)

    # --------------------------------------------------------------------------------------
    # Live viewer
    # --------------------------------------------------------------------------------------

    def open(self) -> str:
        """Starts (or connects to) the live meshcat viewer and returns its URL."""
        self._ensure_live()
        return self._viewer.url()

    @property
    def viewer(self) -> Any:
        """The live ``meshcat.Visualizer`` (``None`` before the first ``display``/``play``/
        ``open``; ``False`` for a visualizer created with ``viewer=False``)."""
        return self._viewer

    def _ensure_live(self) -> bool:
        if self._viewer is False:
            return False
        if self._viewer is None:
            self._viewer = meshcat.Visualizer()
            self._live_ready = False
        if not self._live_ready:
            self._send_scene()
        return True

    def _send(self, cmds: Iterable[Any]) -> None:
        window = self._viewer.window
        for c in cmds:
            window.send(c)

    def _send_scene(self) -> None:
        self._viewer["sodyn"].delete()
        cmds, self._nodes = self._scene()
        self._send(cmds)
        self._live_ready = True
        self._send_poses()

    def _send_poses(self) -> None:
        poses = self._poses(self._q, self._forces)
        self._send(SetTransform(self._matrix(p), _MPath(path)) for path, p in poses.items())

    @property
    def _nodes(self) -> List[_Node]:
        nodes = getattr(self, "_node_list", None)
        if nodes is None:
            _, nodes = self._scene()
            self._node_list = nodes
        return nodes

    @_nodes.setter
    def _nodes(self, nodes: List[_Node]) -> None:
        self._node_list = nodes

    def _scene_changed(self) -> None:
        self._node_list = None
        self._live_ready = False

    # --------------------------------------------------------------------------------------
    # Public API
    # --------------------------------------------------------------------------------------

    @property
    def q(self) -> np.ndarray:
        """The configuration last displayed (the neutral one at first); a copy."""
        return self._q.copy()

    def display(self, q: Any, forces: Optional[Mapping[Any, Any]] = None) -> None:
        """Shows the configuration ``q`` (length ``nq``; a state ``[q; v]`` of length
        ``nq + nv`` is accepted too).

        ``forces`` maps a frame (name or index) or a :class:`sodyn.Contact` to a force drawn
        as an arrow of ``force_scale`` metres per newton: 3 numbers (a force in world axes,
        at the frame origin or the contact point; a contact with ``reference="local"`` takes
        them in its own axes, as ``kkt_derivatives`` returns ``lambda_``) or 6 (``[torque;
        force]``, the force is drawn). Arrows of a previous call are hidden when their key is
        absent. ``forces=None`` keeps the previous forces."""
        q = self._configuration(q)
        if forces is not None:
            forces = dict(forces)
            for k, v in forces.items():
                self._force_vector(k, v, np.eye(4))  # validate before changing the state
                self._force_frame(k)
            new_keys = [k for k in forces if not any(self._same_key(k, e) for e in self._force_keys())]
            self._forces = forces
            if new_keys:
                self._scene_changed()
        self._q = q
        if self._ensure_live():
            if not self._live_ready:
                self._send_scene()
            else:
                self._send_poses()

    def show_frames(self, names: Iterable[Union[str, int]]) -> None:
        """Draws the axes of these frames (red x, green y, blue z, ``frame_scale`` long) from
        now on (in the live view and in ``save_html``); an empty list hides them."""
        if isinstance(names, (str, int)):
            names = [names]
        out = []
        frames = self.model.frames
        for n in names:
            if isinstance(n, (int, np.integer)):
                if not 0 <= int(n) < len(frames):
                    raise ValueError(f"show_frames: frame index {n} out of range 0..{len(frames) - 1}")
                n = frames[int(n)]
            if n not in self._frame_names:
                raise ValueError(f"show_frames: {n!r} is not a frame of the model")
            if n not in out:
                out.append(n)
        self._shown_frames = out
        self._scene_changed()
        if self._viewer not in (None, False):
            self._send_scene()

    def _trajectory_qs(self, xs: Any, what: str) -> List[np.ndarray]:
        if isinstance(xs, np.ndarray) and xs.ndim == 1:
            raise ValueError(f"{what}: expected a sequence of configurations or states "
                             f"(shape (T, nq) or (T, nq + nv)), got shape {xs.shape}")
        qs = [self._configuration(x, f"{what}[{k}]") for k, x in enumerate(xs)]
        if not qs:
            raise ValueError(f"{what}: empty trajectory")
        return qs

    @staticmethod
    def _check_dt(dt: Any) -> float:
        dt = float(dt)
        if not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt: expected a positive time step, got {dt}")
        return dt

    def _check_forces_list(self, forces: Any, n: int) -> Optional[List[Mapping[Any, Any]]]:
        if forces is None:
            return None
        forces = list(forces)
        if len(forces) != n:
            raise ValueError(f"forces: {len(forces)} entries for a trajectory of {n} frames")
        for d in forces:
            for k, v in dict(d).items():
                self._force_frame(k)
                self._force_vector(k, v, np.eye(4))
        return [dict(d) for d in forces]

    def play(self, xs: Any, dt: float, forces: Optional[Sequence[Mapping[Any, Any]]] = None,
             realtime: bool = True) -> None:
        """Plays a trajectory: ``xs`` is a sequence (or a ``(T, n)`` array) of configurations
        (``n = nq``) or states ``x = [q; v]`` (``n = nq + nv``, as an optimal-control solver's
        ``xs``), one every ``dt`` seconds. ``forces`` (optional): one ``display``-style force
        mapping per frame. In the live viewer each frame is shown in turn, ``dt`` apart when
        ``realtime``; the trajectory is kept for ``save_html``, which writes it when called
        without ``trajectory``. Ends on the last frame."""
        qs = self._trajectory_qs(xs, "xs")
        dt = self._check_dt(dt)
        fl = self._check_forces_list(forces, len(qs))
        self._trajectory, self._dt, self._trajectory_forces = qs, dt, fl
        self._scene_changed()
        if not self._ensure_live():
            self._q = qs[-1]
            if fl is not None:
                self._forces = dict(fl[-1])
            return
        t0 = time.perf_counter()
        for k, q in enumerate(qs):
            self._q = q
            if fl is not None:
                self._forces = dict(fl[k])
            if not self._live_ready:
                self._send_scene()
            else:
                self._send_poses()
            if realtime:
                wait = t0 + (k + 1) * dt - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)

    # --------------------------------------------------------------------------------------
    # Static HTML
    # --------------------------------------------------------------------------------------

    def html(self, trajectory: Any = None, dt: Optional[float] = None,
             forces: Optional[Sequence[Mapping[Any, Any]]] = None, loop: bool = True) -> str:
        """The document ``save_html`` writes (a string)."""
        if trajectory is None and self._trajectory is not None:
            qs, fl = self._trajectory, self._trajectory_forces
            dt = self._dt if dt is None else dt
            if forces is not None:
                fl = self._check_forces_list(forces, len(qs))
        elif trajectory is None:
            qs, fl = [self._q], [self._forces] if forces is None else self._check_forces_list(forces, 1)
            dt = 1.0 if dt is None else dt
        else:
            qs = self._trajectory_qs(trajectory, "trajectory")
            if dt is None:
                raise ValueError("dt: required with a trajectory")
            fl = self._check_forces_list(forces, len(qs))
        dt = self._check_dt(dt)
        saved = (self._trajectory, self._trajectory_forces, self._forces)
        try:
            self._trajectory_forces = fl
            self._node_list = None
            cmds, nodes = self._scene()
            self._node_list = nodes
            poses = [self._poses(q, fl[k] if fl else {}) for k, q in enumerate(qs)]
        finally:
            self._trajectory, self._trajectory_forces, self._forces = saved
            self._node_list = None
        cmds += [SetTransform(self._matrix(p), _MPath(path)) for path, p in poses[0].items()]
        if len(qs) > 1:
            anim = _Animation(default_framerate=1.0 / dt)
            for k, pose in enumerate(poses):
                frame = anim.at_frame(_AnimRoot(), k)
                for path, (p, R, s) in pose.items():
                    node = frame[_path_str(path)]
                    w, x, y, z = _quaternion_wxyz(R)
                    node.set_property("position", "vector3", [float(c) for c in p])
                    node.set_property("quaternion", "quaternion", [x, y, z, w])
                    node.set_property("scale", "vector3", [float(c) for c in s])
            cmds.append(SetAnimation(anim, play=True, repetitions=float("inf") if loop else 1))
        # Camera: look at the middle of everything drawn, over the whole motion.
        points = np.array([p[0] for pose in poses for path, p in pose.items()
                           if path[2] in ("links", "joints")] or [np.zeros(3)])
        lo, hi = points.min(axis=0), points.max(axis=0)
        center = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.3)
        from ._html import document

        return document(cmds, center, radius, duration=dt * (len(qs) - 1),
                        title=f"sodyn: {self.model.name}")

    def save_html(self, path: Union[str, os.PathLike], trajectory: Any = None,
                  dt: Optional[float] = None,
                  forces: Optional[Sequence[Mapping[Any, Any]]] = None, loop: bool = True) -> Path:
        """Writes a self-contained HTML file (meshcat's viewer and the scene inlined; it opens
        from disk without network) showing ``trajectory`` (configurations or states, one every
        ``dt`` seconds, played in a loop unless ``loop=False``; meshcat's "Animations" panel
        pauses and scrubs it, and a URL ending in ``#t=SECONDS`` opens it paused at that
        time). Without ``trajectory``: the last ``play``ed trajectory, else the configuration
        last displayed. ``forces``: one ``display``-style mapping per frame. Returns the
        path."""
        text = self.html(trajectory, dt, forces, loop)
        p = Path(path)
        p.write_text(text, encoding="utf-8")
        return p


class _AnimRoot:
    """The ``visualizer`` argument of meshcat's ``Animation.at_frame``: only ``path``."""

    path = _MPath(()) if _IMPORT_ERROR is None else None


def _path_str(path: Tuple[str, ...]) -> str:
    return "/" + "/".join(path)


def _quaternion_wxyz(R: np.ndarray) -> Tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (meshcat's transformations)."""
    from meshcat.transformations import quaternion_from_matrix

    m = np.eye(4)
    m[:3, :3] = R
    w, x, y, z = (float(c) for c in quaternion_from_matrix(m))
    return w, x, y, z
