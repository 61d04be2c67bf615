"""Visual geometry of a robot description, read from its URDF or MJCF file.

Every shape is attached to a *model frame* (a URDF link name, an MJCF body name) and placed
by a constant ``(4, 4)`` transform in that frame's coordinates; the viewer moves the frames
with :func:`sodyn.frame_placement`. Nothing here depends on meshcat.
"""

from __future__ import annotations

import os
import warnings
import xml.etree.ElementTree as ET
from xml.parsers import expat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

# Colours (RGBA) of the drawings that do not come from the file.
LINK_COLOR = (0.75, 0.75, 0.78, 1.0)
BONE_COLOR = (0.95, 0.6, 0.15, 1.0)
JOINT_COLOR = (0.2, 0.45, 0.85, 1.0)
FORCE_COLOR = (0.9, 0.1, 0.1, 1.0)


class VizWarning(UserWarning):
    """A part of the robot description the viewer cannot draw as written (a missing or
    unreadable mesh file, an unsupported geometry); the message names the file and element,
    and the part is drawn with the fallback drawing instead."""


@dataclass
class Shape:
    """One drawable shape in the coordinates of its frame.

    ``kind`` and ``size``: ``"box"`` (full edge lengths x, y, z), ``"sphere"`` (radius,),
    ``"cylinder"`` and ``"capsule"`` (radius, length along the local z axis),
    ``"ellipsoid"`` (three radii), ``"mesh"`` (a file, ``mesh_file``, scaled by ``scale``),
    ``"trimesh"`` (``vertices`` ``(n, 3)`` and triangle ``faces`` ``(m, 3)``)."""

    kind: str
    size: Tuple[float, ...] = ()
    origin: np.ndarray = field(default_factory=lambda: np.eye(4))
    rgba: Tuple[float, float, float, float] = LINK_COLOR
    mesh_file: Optional[str] = None
    scale: Tuple[float, float, float] = (1.0, 1.0, 1.0)
    vertices: Optional[np.ndarray] = None
    faces: Optional[np.ndarray] = None


@dataclass
class RobotGeometry:
    """What the viewer draws: shapes per frame, and the segments between joint origins of
    the frames that have no shape (``bones``: ``(frame, start, end)`` in that frame's
    coordinates)."""

    shapes: Dict[str, List[Shape]] = field(default_factory=dict)
    bones: List[Tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    joint_markers: List[str] = field(default_factory=list)
    source: Optional[str] = None


# ------------------------------------------------------------------------------------------
# Small helpers
# ------------------------------------------------------------------------------------------

def rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF ``rpy``: ``R = Rz(y) Ry(p) Rx(r)``."""
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def quat_wxyz_matrix(q: Sequence[float]) -> np.ndarray:
    w, x, y, z = (float(c) for c in q)
    n = np.sqrt(w * w + x * x + y * y + z * z)
    if n == 0.0:
        return np.eye(3)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def homogeneous(rotation: np.ndarray, translation: Sequence[float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = np.asarray(translation, dtype=float)
    return m


def segment_transform(start: np.ndarray, end: np.ndarray) -> Tuple[np.ndarray, float]:
    """A transform whose z axis runs from ``start`` to ``end`` (origin at the midpoint),
    and the segment's length."""
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    d = end - start
    length = float(np.linalg.norm(d))
    z = d / length if length > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return homogeneous(np.column_stack([x, y, z]), 0.5 * (start + end)), length


class _LineParser:
    """ElementTree parse that remembers each element's line (for error messages)."""

    def __init__(self, text: str, source: str):
        self.lines: Dict[int, int] = {}
        self.source = source
        builder = ET.TreeBuilder()
        parser = expat.ParserCreate()
        lines = self.lines

        def start(tag, attrs):
            el = builder.start(tag, attrs)
            lines[id(el)] = parser.CurrentLineNumber

        parser.StartElementHandler = start
        parser.EndElementHandler = builder.end
        parser.CharacterDataHandler = builder.data
        try:
            parser.Parse(text, True)
            self.root = builder.close()
        except expat.ExpatError as e:
            raise ValueError(f"{source}: line {e.lineno}: malformed XML: "
                             f"{expat.ErrorString(e.code)}") from None
        except AssertionError:
            raise ValueError(f"{source}: malformed XML (no root element)") from None

    def where(self, el: ET.Element) -> str:
        line = self.lines.get(id(el))
        return f"{self.source}:{line}" if line else self.source


def _floats(text: Optional[str], n: int, what: str, default: Optional[Sequence[float]] = None):
    if text is None:
        if default is None:
            raise ValueError(f"{what}: missing")
        return tuple(float(x) for x in default)
    parts = text.split()
    try:
        values = tuple(float(x) for x in parts)
    except ValueError:
        raise ValueError(f"{what}: {text!r} is not {n} number(s)") from None
    if len(values) != n or not all(np.isfinite(values)):
        raise ValueError(f"{what}: {text!r} is not {n} finite number(s)")
    return values


# ------------------------------------------------------------------------------------------
# Mesh paths
# ------------------------------------------------------------------------------------------

def resolve_mesh_path(filename: str, base_dir: Optional[Path], package_dirs: Sequence[str]
                      ) -> Tuple[Optional[Path], List[Path]]:
    """Where a URDF mesh ``filename`` is: ``package://PKG/REST`` is looked up as
    ``DIR/PKG/REST`` (and ``DIR/REST`` when ``DIR`` is named ``PKG``) for each ``DIR`` of
    ``package_dirs``, then of ``$ROS_PACKAGE_PATH``, then the URDF's directory and its
    parents; ``file://ABS`` is an absolute path; any other path is relative to the URDF's
    directory, then to each of ``package_dirs``. Returns the first existing file (or
    ``None``) and every candidate tried."""
    dirs = [Path(d) for d in package_dirs]
    dirs += [Path(d) for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    tried: List[Path] = []
    if filename.startswith("package://"):
        rest = filename[len("package://"):].lstrip("/")
        pkg, _, sub = rest.partition("/")
        search = list(dirs)
        if base_dir is not None:
            search += [base_dir, *base_dir.parents]
        for d in search:
            tried.append(d / pkg / sub)
            if d.name == pkg:
                tried.append(d / sub)
    elif filename.startswith("file://"):
        tried.append(Path(filename[len("file://"):]))
    else:
        p = Path(filename)
        if p.is_absolute():
            tried.append(p)
        else:
            if base_dir is not None:
                tried.append(base_dir / p)
            tried += [d / p for d in dirs]
    for t in tried:
        if t.is_file():
            return t, tried
    return None, tried


MESH_FORMATS = (".stl", ".dae", ".obj")


# ------------------------------------------------------------------------------------------
# URDF
# ------------------------------------------------------------------------------------------

def urdf_geometry(text: str, source: str, base_dir: Optional[Path],
                  package_dirs: Sequence[str]) -> RobotGeometry:
    """Shapes of the ``<visual>`` elements of a URDF document (box, cylinder, sphere,
    capsule, mesh STL/DAE/OBJ), and bones for links without a drawable visual: from the link
    origin to each child joint's origin (a leaf link gets a joint marker only).

    A mesh file that cannot be found or has an unsupported format raises a
    :class:`VizWarning` naming the file and the link, and that link gets the fallback
    drawing. Malformed XML or numbers raise ``ValueError`` naming the file and line."""
    doc = _LineParser(text, source)
    root = doc.root
    if root.tag != "robot":
        raise ValueError(f"{doc.where(root)}: the root element is <{root.tag}>, not <robot>")

    named_colors: Dict[str, Tuple[float, ...]] = {}
    for mat in root.findall("material"):
        color = mat.find("color")
        if mat.get("name") and color is not None:
            named_colors[mat.get("name", "")] = _floats(
                color.get("rgba"), 4, f"{doc.where(color)}: material {mat.get('name')!r} rgba")

    geo = RobotGeometry(source=source)
    drawn: Dict[str, bool] = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise ValueError(f"{doc.where(link)}: <link> without a name")
        shapes: List[Shape] = []
        complete = True
        for k, vis in enumerate(link.findall("visual")):
            what = f"{doc.where(vis)}: link {name!r} visual {k}"
            origin = np.eye(4)
            o = vis.find("origin")
            if o is not None:
                xyz = _floats(o.get("xyz"), 3, f"{what}: origin xyz", (0, 0, 0))
                rpy = _floats(o.get("rpy"), 3, f"{what}: origin rpy", (0, 0, 0))
                origin = homogeneous(rpy_matrix(*rpy), xyz)
            rgba = LINK_COLOR
            m = vis.find("material")
            if m is not None:
                c = m.find("color")
                if c is not None:
                    rgba = _floats(c.get("rgba"), 4, f"{what}: material rgba")  # type: ignore
                elif m.get("name") in named_colors:
                    rgba = named_colors[m.get("name", "")]  # type: ignore
            g = vis.find("geometry")
            if g is None or len(g) == 0:
                warnings.warn(f"{what}: no <geometry>; drawn as a sphere and capsules", VizWarning, stacklevel=3)
                complete = False
                continue
            shape_el = g[0]
            kind = shape_el.tag
            gwhat = f"{doc.where(shape_el)}: link {name!r} visual {k} <{kind}>"
            if kind == "box":
                size = _floats(shape_el.get("size"), 3, f"{gwhat} size")
                shapes.append(Shape("box", size, origin, rgba))  # type: ignore[arg-type]
            elif kind == "sphere":
                r = _floats(shape_el.get("radius"), 1, f"{gwhat} radius")
                shapes.append(Shape("sphere", r, origin, rgba))  # type: ignore[arg-type]
            elif kind in ("cylinder", "capsule"):
                r = _floats(shape_el.get("radius"), 1, f"{gwhat} radius")[0]
                length = _floats(shape_el.get("length"), 1, f"{gwhat} length")[0]
                shapes.append(Shape(kind, (r, length), origin, rgba))  # type: ignore[arg-type]
            elif kind == "mesh":
                filename = shape_el.get("filename")
                if not filename:
                    raise ValueError(f"{gwhat}: no filename")
                scale = _floats(shape_el.get("scale"), 3, f"{gwhat} scale", (1, 1, 1))
                path, tried = resolve_mesh_path(filename, base_dir, package_dirs)
                if path is None:
                    shown = ", ".join(str(t) for t in tried[:4]) + (" ..." if len(tried) > 4 else "")
                    warnings.warn(f"{gwhat}: mesh file {filename!r} not found (tried {shown}); "
                                  f"link {name!r} is drawn as a sphere and capsules", VizWarning,
                                  stacklevel=3)
                    complete = False
                    continue
                if path.suffix.lower() not in MESH_FORMATS:
                    warnings.warn(f"{gwhat}: mesh file {str(path)!r} has the unsupported format "
                                  f"{path.suffix!r} (STL, DAE, OBJ are drawn); link {name!r} is "
                                  "drawn as a sphere and capsules", VizWarning, stacklevel=3)
                    complete = False
                    continue
                shapes.append(Shape("mesh", (), origin, rgba, mesh_file=str(path),
                                    scale=scale))  # type: ignore[arg-type]
            else:
                warnings.warn(f"{gwhat}: unsupported geometry; link {name!r} is drawn as a "
                              "sphere and capsules", VizWarning, stacklevel=3)
                complete = False
        if shapes:
            geo.shapes[name] = shapes
        drawn[name] = bool(shapes) and complete

    # Bones for the links that are not (completely) drawn.
    children: Dict[str, List[np.ndarray]] = {}
    for joint in root.findall("joint"):
        jname = joint.get("name", "?")
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise ValueError(f"{doc.where(joint)}: joint {jname!r} without <parent> or <child>")
        xyz = (0.0, 0.0, 0.0)
        o = joint.find("origin")
        if o is not None:
            xyz = _floats(o.get("xyz"), 3, f"{doc.where(o)}: joint {jname!r} origin xyz",
                          (0, 0, 0))
        children.setdefault(parent.get("link", ""), []).append(np.array(xyz))
    for name, ok in drawn.items():
        if ok:
            continue
        geo.joint_markers.append(name)
        for end in children.get(name, []):
            if np.linalg.norm(end) > 1e-6:
                geo.bones.append((name, np.zeros(3), end))
    return geo


# ------------------------------------------------------------------------------------------
# MJCF (through MuJoCo's own compiler: defaults, classes, includes, compiler options, meshes)
# ------------------------------------------------------------------------------------------

def mjcf_geometry(path: Path) -> RobotGeometry:
    """Shapes of the ``<geom>`` elements of an MJCF file, as MuJoCo compiles them (the
    ``mujoco`` package: defaults, classes, ``<include>``, ``fromto``, orientations, mesh
    assets, which MuJoCo re-centres, with the geom pose compensating). Geoms of groups 0-2
    (MuJoCo's visible groups) with a non-zero alpha are drawn; planes and height fields are
    not (the viewer has its own floor grid). Geoms of the world body are static.

    Raises ``ImportError`` without ``mujoco`` and ``ValueError`` (MuJoCo's message, which
    names the file, e.g. a missing mesh) if MuJoCo cannot compile the file."""
    import mujoco  # optional: pip install mujoco

    try:
        m = mujoco.MjModel.from_xml_path(str(path))
    except Exception as e:  # noqa: BLE001 - mujoco raises ValueError with its message
        raise ValueError(f"{path}: MuJoCo cannot compile the file: {e}") from None
    gt = mujoco.mjtGeom
    geo = RobotGeometry(source=str(path))
    drawn_bodies = set()
    for g in range(m.ngeom):
        if m.geom_group[g] > 2:
            continue
        rgba = tuple(float(c) for c in m.geom_rgba[g])
        if m.geom_matid[g] >= 0:
            rgba = tuple(float(c) for c in m.mat_rgba[m.geom_matid[g]])
        if rgba[3] == 0.0:
            continue
        body = int(m.geom_bodyid[g])
        frame = "world" if body == 0 else m.body(body).name
        origin = homogeneous(quat_wxyz_matrix(m.geom_quat[g]), m.geom_pos[g])
        s = [float(x) for x in m.geom_size[g]]
        t = int(m.geom_type[g])
        if t == gt.mjGEOM_SPHERE:
            shape = Shape("sphere", (s[0],), origin, rgba)  # type: ignore[arg-type]
        elif t == gt.mjGEOM_BOX:
            shape = Shape("box", (2 * s[0], 2 * s[1], 2 * s[2]), origin, rgba)  # type: ignore
        elif t == gt.mjGEOM_CYLINDER:
            shape = Shape("cylinder", (s[0], 2 * s[1]), origin, rgba)  # type: ignore
        elif t == gt.mjGEOM_CAPSULE:
            shape = Shape("capsule", (s[0], 2 * s[1]), origin, rgba)  # type: ignore
        elif t == gt.mjGEOM_ELLIPSOID:
            shape = Shape("ellipsoid", (s[0], s[1], s[2]), origin, rgba)  # type: ignore
        elif t == gt.mjGEOM_MESH:
            mid = int(m.geom_dataid[g])
            va, vn = int(m.mesh_vertadr[mid]), int(m.mesh_vertnum[mid])
            fa, fn = int(m.mesh_faceadr[mid]), int(m.mesh_facenum[mid])
            shape = Shape("trimesh", (), origin, rgba,  # type: ignore[arg-type]
                          vertices=np.array(m.mesh_vert[va:va + vn], dtype=np.float32),
                          faces=np.array(m.mesh_face[fa:fa + fn], dtype=np.uint32))
        else:
            continue  # plane, height field, signed distance field
        geo.shapes.setdefault(frame, []).append(shape)
        drawn_bodies.add(body)
    # Bodies without a drawn geom: bones from the body origin to each child body's origin.
    for b in range(1, m.nbody):
        if b in drawn_bodies:
            continue
        name = m.body(b).name
        geo.joint_markers.append(name)
        for c in range(1, m.nbody):
            if int(m.body_parentid[c]) == b and np.linalg.norm(m.body_pos[c]) > 1e-6:
                geo.bones.append((name, np.zeros(3), np.array(m.body_pos[c], dtype=float)))
    return geo
