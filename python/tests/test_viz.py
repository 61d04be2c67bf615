"""sodyn.viz: geometry read from URDF/MJCF files, poses from frame_placement, the HTML
document's scene, and renders of that document in headless Chromium (network disabled)
whose screenshots must show the robot and a moving animation.

The browser tests need ``chromium`` (Debian) on the PATH (or ``$SODYN_CHROMIUM``) and skip
without it; everything else needs only the ``viz`` extra (meshcat)."""

import base64
import json
import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import sodyn

meshcat = pytest.importorskip("meshcat")
import umsgpack  # noqa: E402 - a meshcat dependency

from sodyn import viz  # noqa: E402
from sodyn.viz import _html  # noqa: E402

from conftest import HAVE_SHARED, MODELS_DIR  # noqa: E402

DATA = Path(__file__).resolve().parent / "data" / "viz"
CUBE_STL = DATA / "meshes" / "cube.stl"

ARM_URDF = """<?xml version="1.0"?>
<robot name="arm">
  <material name="blue"><color rgba="0 0 1 1"/></material>
  <link name="base">
    <visual><origin xyz="0 0 0.05"/><geometry><box size="0.4 0.3 0.1"/></geometry>
      <material name="blue"/></visual>
  </link>
  <link name="upper">
    <visual><origin xyz="0 0 0.2" rpy="0 0 0"/>
      <geometry><cylinder radius="0.05" length="0.4"/></geometry></visual>
    <visual><origin xyz="0 0 0.4"/><geometry><sphere radius="0.07"/></geometry></visual>
  </link>
  <link name="lower">
    <visual><origin xyz="0 0 0.15" rpy="0.1 0.2 0.3"/>
      <geometry><mesh filename="package://vizpkg/meshes/cube.stl" scale="0.1 0.1 0.3"/></geometry>
      <material name="red"><color rgba="1 0 0 1"/></material></visual>
  </link>
  <link name="hand">
    <visual><geometry><mesh filename="meshes/cube.stl" scale="0.08 0.08 0.08"/></geometry></visual>
  </link>
  <link name="tip"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="lower"/><origin xyz="0 0 0.4"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="wrist" type="revolute">
    <parent link="lower"/><child link="hand"/><origin xyz="0 0 0.3"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="tip_joint" type="fixed">
    <parent link="hand"/><child link="tip"/><origin xyz="0 0 0.1"/>
  </joint>
</robot>
"""


@pytest.fixture()
def arm(tmp_path):
    """The arm URDF in a directory holding ``meshes/cube.stl`` (the relative mesh path) and
    a package directory ``pkgs/vizpkg/meshes/cube.stl`` (the package:// one)."""
    (tmp_path / "meshes").mkdir()
    shutil.copy(CUBE_STL, tmp_path / "meshes" / "cube.stl")
    pkg = tmp_path / "pkgs" / "vizpkg" / "meshes"
    pkg.mkdir(parents=True)
    shutil.copy(CUBE_STL, pkg / "cube.stl")
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_URDF)
    return path, tmp_path / "pkgs"


def decode_commands(html):
    """The meshcat commands embedded in a saved document (msgpack, base64)."""
    m = re.search(r"var commands = (\[.*?\]);", html, re.S)
    assert m, "no command list in the document"
    return [umsgpack.unpackb(base64.b64decode(s)) for s in json.loads(m.group(1))]


def transforms(cmds):
    out = {}
    for c in cmds:
        if c["type"] == "set_transform":
            out[c["path"]] = np.array(c["matrix"], dtype=float).reshape(4, 4).T
    return out


def rpy(r, p, y):
    return viz._geometry.rpy_matrix(r, p, y)


# ------------------------------------------------------------------------------------------
# Geometry
# ------------------------------------------------------------------------------------------

def test_urdf_visuals_and_mesh_paths(arm):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every mesh is found: no warning
        v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False)
    shapes = v.geometry.shapes
    assert [s.kind for s in shapes["base"]] == ["box"]
    assert shapes["base"][0].size == (0.4, 0.3, 0.1)
    assert shapes["base"][0].rgba == (0.0, 0.0, 1.0, 1.0)
    assert [s.kind for s in shapes["upper"]] == ["cylinder", "sphere"]
    assert shapes["upper"][0].size == (0.05, 0.4)
    low = shapes["lower"][0]
    assert low.kind == "mesh" and Path(low.mesh_file) == pkgs / "vizpkg" / "meshes" / "cube.stl"
    assert low.scale == (0.1, 0.1, 0.3) and low.rgba == (1.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(low.origin[:3, :3], rpy(0.1, 0.2, 0.3), atol=1e-15)
    np.testing.assert_allclose(low.origin[:3, 3], [0, 0, 0.15])
    assert Path(shapes["hand"][0].mesh_file) == path.parent / "meshes" / "cube.stl"
    # tip has no visual: a joint marker, and no bone (it has no child joint)
    assert "tip" in v.geometry.joint_markers and "tip" not in shapes
    assert not [b for b in v.geometry.bones if b[0] == "tip"]


def test_rpy_is_urdf_convention():
    # R = Rz(y) Ry(p) Rx(r): the x axis of rpy (0, 0, pi/2) is the world y axis
    np.testing.assert_allclose(rpy(0, 0, np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rpy(np.pi / 2, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    r, p, y = 0.3, -0.7, 1.1
    c, s = np.cos, np.sin
    Rx = np.array([[1, 0, 0], [0, c(r), -s(r)], [0, s(r), c(r)]])
    Ry = np.array([[c(p), 0, s(p)], [0, 1, 0], [-s(p), 0, c(p)]])
    Rz = np.array([[c(y), -s(y), 0], [s(y), c(y), 0], [0, 0, 1]])
    np.testing.assert_allclose(rpy(r, p, y), Rz @ Ry @ Rx, atol=1e-15)


def test_missing_mesh_warns_and_falls_back(arm):
    path, _ = arm
    model = sodyn.Model.from_urdf(str(path))
    # without the package directory, lower's package:// mesh is missing
    with pytest.warns(viz.VizWarning, match=r"arm\.urdf:\d+: link 'lower'.*'package://vizpkg/"
                      r"meshes/cube\.stl' not found") as rec:
        v = viz.Visualizer(model, path, viewer=False)
    assert len(rec) == 1
    assert "lower" not in v.geometry.shapes
    assert "lower" in v.geometry.joint_markers
    # a bone from lower's origin to the wrist joint origin (0, 0, 0.3) in lower's frame
    bones = [(a, b) for f, a, b in v.geometry.bones if f == "lower"]
    assert len(bones) == 1
    np.testing.assert_allclose(bones[0][0], 0)
    np.testing.assert_allclose(bones[0][1], [0, 0, 0.3])


def test_malformed_urdf_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text('<robot name="x">\n<link name="a">\n<visual><geometry>'
                   '<box size="1 2"/></geometry></visual>\n</link>\n</robot>\n')
    model = sodyn.Model.from_urdf_string('<robot name="x"><link name="a"/></robot>')
    with pytest.raises(ValueError, match=r"bad\.urdf:3: link 'a' visual 0 <box> size: '1 2' is "
                       r"not 3 finite number"):
        viz.Visualizer(model, bad, viewer=False)
    broken = tmp_path / "broken.urdf"
    broken.write_text('<robot name="x">\n<link name="a">\n</robot>\n')
    with pytest.raises(ValueError, match=r"broken\.urdf: line 3: malformed XML"):
        viz.Visualizer(model, broken, viewer=False)
    with pytest.raises(ValueError, match="is not a file"):
        viz.Visualizer(model, tmp_path / "nope.urdf", viewer=False)


def test_bad_arguments_raise_value_errors(arm):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False)
    with pytest.raises(ValueError, match=r"q: length 2, expected nq = 3"):
        v.display([0.0, 0.0])
    with pytest.raises(ValueError, match="not finite"):
        v.display([0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match=r"xs\[1\]: length 4"):
        v.play([np.zeros(3), np.zeros(4)], 0.1)
    with pytest.raises(ValueError, match="dt: expected a positive"):
        v.play([np.zeros(3)], 0.0)
    with pytest.raises(ValueError, match="'nowhere' is not a frame"):
        v.show_frames(["nowhere"])
    with pytest.raises(ValueError, match="'nowhere' is not a frame"):
        v.display(np.zeros(3), forces={"nowhere": [0, 0, 1]})
    with pytest.raises(ValueError, match=r"expected 3 \(force\) or 6"):
        v.display(np.zeros(3), forces={"hand": [0, 1]})
    with pytest.raises(ValueError, match="dt: required"):
        v.html(trajectory=[np.zeros(3)] * 2)
    with pytest.raises(TypeError, match="sodyn.Model"):
        viz.Visualizer("arm.urdf", viewer=False)


# ------------------------------------------------------------------------------------------
# Poses in the document: each link node is placed by frame_placement, each visual by its
# URDF origin (and scale) in that link's frame.
# ------------------------------------------------------------------------------------------

def test_document_places_links_by_frame_placement(arm):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False)
    q = np.array([0.4, -0.9, 1.3])
    v.display(q)
    cmds = decode_commands(v.html())
    tf = transforms(cmds)
    data = sodyn.Data(model)
    for link in ("upper", "lower", "hand", "tip"):
        expected = sodyn.frame_placement(model, data, q, link)
        np.testing.assert_allclose(tf[f"/meshcat/sodyn/links/{link}"], expected, atol=1e-12)
    # lower's mesh: the URDF origin times the scale, in lower's frame
    m = tf["/meshcat/sodyn/links/lower/v0"]
    np.testing.assert_allclose(m[:3, :3], rpy(0.1, 0.2, 0.3) @ np.diag([0.1, 0.1, 0.3]),
                               atol=1e-12)
    # the world pose of the cylinder's axis (three.js cylinders run along y): upper's z axis
    w = tf["/meshcat/sodyn/links/upper"] @ tf["/meshcat/sodyn/links/upper/v0"]
    oMu = sodyn.frame_placement(model, data, q, "upper")
    np.testing.assert_allclose(w[:3, 1], oMu[:3, 2], atol=1e-12)
    np.testing.assert_allclose(w[:3, 3], oMu[:3, 3] + 0.2 * oMu[:3, 2], atol=1e-12)
    objects = {c["path"]: c["object"] for c in cmds if c["type"] == "set_object"}
    stl = objects["/meshcat/sodyn/links/lower/v0"]["geometries"][0]
    assert stl["format"] == "stl"
    assert bytes(stl["data"].data) == CUBE_STL.read_bytes()


def test_states_trajectory_animation_and_forces(arm):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False, force_scale=0.01)
    T = 5
    qs = np.array([[0.2 * k, -0.1 * k, 0.3 * k] for k in range(T)])
    xs = np.hstack([qs, np.ones((T, model.nv))])  # states x = [q; v]
    forces = [{"hand": [0.0, 0.0, 10.0 * (k + 1)]} for k in range(T)]
    v.play(xs, 0.05, forces=forces)
    np.testing.assert_array_equal(v.q, qs[-1])
    cmds = decode_commands(v.html())
    anim = [c for c in cmds if c["type"] == "set_animation"]
    assert len(anim) == 1
    clips = {a["path"]: a["clip"] for a in anim[0]["animations"]}
    assert all(abs(c["fps"] - 20.0) < 1e-12 for c in clips.values())
    data = sodyn.Data(model)
    hand = clips["/meshcat/sodyn/links/hand"]
    pos = next(t for t in hand["tracks"] if t["name"] == ".position")
    assert [k["time"] for k in pos["keys"]] == list(range(T))
    for k in range(T):
        expected = sodyn.frame_placement(model, data, qs[k], "hand")[:3, 3]
        np.testing.assert_allclose(pos["keys"][k]["value"], expected, atol=1e-12)
    # the force arrow's shaft: 0.01 m/N, from the hand origin, along +z
    shaft = clips["/meshcat/sodyn/forces/hand/shaft"]
    scale = next(t for t in shaft["tracks"] if t["name"] == ".scale")
    spos = next(t for t in shaft["tracks"] if t["name"] == ".position")
    for k in range(T):
        length = 0.01 * 10.0 * (k + 1)
        np.testing.assert_allclose(scale["keys"][k]["value"], [1, length, 1], atol=1e-12)
        origin = sodyn.frame_placement(model, data, qs[k], "hand")[:3, 3]
        np.testing.assert_allclose(spos["keys"][k]["value"], origin + [0, 0, 0.5 * length],
                                   atol=1e-12)


def test_contact_force_in_local_axes(arm):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False, force_scale=0.1)
    q = np.array([0.5, 0.3, -0.2])
    contact = sodyn.Contact("hand", point=[0.0, 0.0, 0.04], reference="local")
    v.display(q, forces={contact: [0.0, 0.0, 2.0]})
    tf = transforms(decode_commands(v.html()))
    shaft = tf["/meshcat/sodyn/forces/hand@0,0,0.04/shaft"]
    oMf = sodyn.frame_placement(model, sodyn.Data(model), q, "hand")
    point = oMf[:3, :3] @ [0, 0, 0.04] + oMf[:3, 3]
    direction = oMf[:3, 2]  # local z in world axes
    np.testing.assert_allclose(shaft[:3, 1] / 0.2, direction, atol=1e-12)  # y axis, scaled
    np.testing.assert_allclose(shaft[:3, 3], point + 0.1 * direction, atol=1e-12)


def test_builtin_model_without_file():
    model = sodyn.Model.builtin("humanoid")
    v = viz.Visualizer(model, viewer=False)
    skeleton = dict(v._skeleton())
    # every frame but the universe is drawn; the floating pelvis is not tied to the origin
    assert set(skeleton) == set(model.frames[1:])
    assert skeleton["pelvis"] is None
    assert skeleton["left_forearm"] == "left_upper_arm"
    q = model.random_configuration(seed=3)
    v.display(q)
    tf = transforms(decode_commands(v.html()))
    data = sodyn.Data(model)
    a = sodyn.frame_placement(model, data, q, "left_upper_arm")[:3, 3]
    b = sodyn.frame_placement(model, data, q, "left_forearm")[:3, 3]
    bone = tf["/meshcat/sodyn/bones/left_forearm"]
    np.testing.assert_allclose(bone[:3, 3], 0.5 * (a + b), atol=1e-12)
    np.testing.assert_allclose(bone[:3, 1], b - a, atol=1e-12)  # unit cylinder scaled


def test_document_is_self_contained(arm, tmp_path):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False)
    out = v.save_html(tmp_path / "arm.html", trajectory=[np.zeros(3), np.ones(3)], dt=0.5)
    text = out.read_text()
    assert _html.viewer_js()[:2000] in text  # meshcat's viewer, inlined
    assert not re.search(r"<script[^>]+src=|<link[^>]+href=|<img[^>]+src=", text)
    assert "fetch(" not in text.split("var viewer = new MeshCat.Viewer")[1]


# ------------------------------------------------------------------------------------------
# MJCF geometry (MuJoCo compiles the file); sodyn's body frames are MuJoCo's body frames.
# ------------------------------------------------------------------------------------------

MJCF = """<mujoco model="twolink">
  <asset><mesh name="cube" file="{stl}" scale="0.1 0.1 0.1"/></asset>
  <default><geom rgba="0.2 0.6 0.3 1"/><default class="red"><geom rgba="1 0 0 1"/></default></default>
  <worldbody>
    <body name="link1" pos="0 0 0.5" euler="0 30 0">
      <joint name="j1" type="hinge" axis="0 1 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04"/>
      <body name="link2" pos="0.4 0 0">
        <joint name="j2" type="hinge" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
        <geom class="red" type="box" pos="0.15 0 0" size="0.15 0.03 0.02"/>
        <geom type="mesh" mesh="cube" pos="0.3 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_mjcf_geometry_matches_mujoco(tmp_path):
    mujoco = pytest.importorskip("mujoco")
    path = tmp_path / "twolink.xml"
    path.write_text(MJCF.format(stl=CUBE_STL))
    model = sodyn.Model.from_mjcf(str(path))
    v = viz.Visualizer(model, path, viewer=False)
    shapes = v.geometry.shapes
    assert [s.kind for s in shapes["link1"]] == ["capsule"]
    assert [s.kind for s in shapes["link2"]] == ["box", "trimesh"]
    assert shapes["link2"][0].rgba == (1.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(shapes["link1"][0].size, [0.04, 0.4], atol=1e-12)
    # world pose of every geom: sodyn's frame placement times the geom's pose in its body
    # equals MuJoCo's geom_xpos / geom_xmat at the same joint angles
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    q = np.array([0.7, -0.4])
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    data = sodyn.Data(model)
    k = 0
    for body in ("link1", "link2"):
        oMb = sodyn.frame_placement(model, data, q, body)
        for s in shapes[body]:
            world = oMb @ s.origin
            np.testing.assert_allclose(world[:3, 3], d.geom_xpos[k], atol=1e-9)
            np.testing.assert_allclose(world[:3, :3], d.geom_xmat[k].reshape(3, 3), atol=1e-9)
            k += 1


def test_obj_mesh_and_mjcf_missing_mesh(tmp_path):
    obj = tmp_path / "tri.obj"
    obj.write_text("v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\nf 1 2 3\n")
    urdf = tmp_path / "one.urdf"
    urdf.write_text('<robot name="one"><link name="a"><visual><geometry>'
                    '<mesh filename="tri.obj"/></geometry></visual></link></robot>')
    model = sodyn.Model.from_urdf(str(urdf))
    v = viz.Visualizer(model, urdf, viewer=False)
    objects = {c["path"]: c["object"] for c in decode_commands(v.html())
               if c["type"] == "set_object"}
    geom = objects["/meshcat/sodyn/links/a/v0"]["geometries"][0]
    assert geom["format"] == "obj" and geom["data"] == obj.read_text()
    pytest.importorskip("mujoco")
    xml = tmp_path / "nomesh.xml"
    xml.write_text('<mujoco><asset><mesh name="m" file="absent.stl"/></asset><worldbody>'
                   '<body name="b"><joint type="hinge"/><inertial pos="0 0 0" mass="1" '
                   'diaginertia="1 1 1"/><geom type="mesh" mesh="m"/></body>'
                   '</worldbody></mujoco>')
    model = sodyn.Model.from_mjcf(str(xml))
    with pytest.warns(viz.VizWarning, match=r"nomesh\.xml: MuJoCo cannot compile.*absent\.stl"):
        v = viz.Visualizer(model, xml, viewer=False)
    assert not v.geometry.shapes
    tf = transforms(decode_commands(v.html()))
    assert "/meshcat/sodyn/joints/b" in tf  # the fallback drawing


# ------------------------------------------------------------------------------------------
# The command line
# ------------------------------------------------------------------------------------------

def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "sodyn.viz", *args], capture_output=True,
                          text=True, timeout=120)


def test_cli(tmp_path):
    out = tmp_path / "quad.html"
    model = sodyn.Model.builtin("quadruped")
    traj = np.array([model.random_configuration(seed=s) for s in range(4)])
    np.save(tmp_path / "traj.npy", traj)
    r = run_cli("builtin:quadruped", "--trajectory", str(tmp_path / "traj.npy"), "--dt", "0.1",
                "--html", str(out))
    assert r.returncode == 0, r.stderr
    assert "4 frame(s)" in r.stdout
    assert any(c["type"] == "set_animation" for c in decode_commands(out.read_text()))
    r = run_cli(str(tmp_path / "missing.urdf"), "--html", str(out))
    assert r.returncode == 2 and "missing.urdf: no such file" in r.stderr
    np.save(tmp_path / "bad.npy", traj[:, :3])
    r = run_cli("builtin:quadruped", "--trajectory", str(tmp_path / "bad.npy"), "--html", str(out))
    assert r.returncode == 2 and "length 3, expected nq" in r.stderr
    assert "Traceback" not in r.stderr


# ------------------------------------------------------------------------------------------
# Headless Chromium, network disabled
# ------------------------------------------------------------------------------------------

def chromium():
    env = os.environ.get("SODYN_CHROMIUM")
    if env:
        return env
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


CHROMIUM = chromium()
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed")
SIZE = (640, 480)


def _isolated():
    """``unshare -n`` (a network namespace without any interface) when it works here."""
    if shutil.which("unshare") is None:
        return []
    try:
        ok = subprocess.run(["unshare", "-n", "true"], capture_output=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return []
    return ["unshare", "-n"] if ok.returncode == 0 else []


def render(html_path, png_path, fragment="", size=SIZE, budget_ms=5000):
    """A screenshot of the document (software WebGL, no network: no interface when
    ``unshare -n`` works, and in any case an unreachable proxy and no host resolution)."""
    from PIL import Image  # a meshcat dependency

    cmd = _isolated() + [
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu-sandbox",
        "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars",
        "--proxy-server=http://127.0.0.1:9", "--proxy-bypass-list=<-loopback>",
        "--host-resolver-rules=MAP * ~NOTFOUND", "--disable-extensions",
        f"--user-data-dir={png_path.parent / ('chrome-' + png_path.stem)}",
        f"--window-size={size[0]},{size[1]}", f"--virtual-time-budget={budget_ms}",
        f"--screenshot={png_path}", Path(html_path).resolve().as_uri() + fragment,
    ]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert png_path.is_file(), f"no screenshot: {r.returncode}\n{r.stderr[-2000:]}"
    return np.asarray(Image.open(png_path).convert("RGB"), dtype=int)


def background_of(html_text, tmp_path, name):
    """The same view with nothing drawn (same camera), rendered."""
    cfg = json.loads(re.search(r"var cfg = (\{.*?\});", html_text).group(1))
    empty = tmp_path / f"{name}-empty.html"
    empty.write_text(_html.document([], cfg["center"], cfg["radius"], 0.0))
    return render(empty, tmp_path / f"{name}-empty.png")


def robot_box(img, bg):
    """Bounding box (as fractions of the image) of the pixels that differ from the empty
    view, and their count; the top bar of meshcat's controls is left out."""
    diff = np.abs(img - bg).sum(axis=2) > 60
    diff[:24, :] = False
    ys, xs = np.nonzero(diff)
    if len(xs) == 0:
        return None, 0
    h, w = diff.shape
    return ((xs.max() - xs.min() + 1) / w, (ys.max() - ys.min() + 1) / h), int(diff.sum())


def assert_robot_drawn(img, bg, what):
    box, n = robot_box(img, bg)
    assert box is not None, f"{what}: nothing drawn"
    assert n > 2000, f"{what}: only {n} pixels differ from the empty view"
    assert 0.1 < box[1] <= 1.0 and 0.05 < box[0] <= 1.0, f"{what}: bounding box {box}"


def assert_whole_robot_in_view(img, bg, what, margin=3):
    """No pixel of the robot on the image's border (left, right, bottom, and the top below
    meshcat's 24-pixel control bar): the camera framing shows all of it."""
    diff = np.abs(img - bg).sum(axis=2) > 60
    diff[:24, :] = False
    ys, xs = np.nonzero(diff)
    h, w = diff.shape
    assert xs.min() >= margin and xs.max() < w - margin, f"{what}: cut at the side ({xs.min()}, {xs.max()})"
    assert ys.min() >= 24 + margin and ys.max() < h - margin, \
        f"{what}: cut at the top or bottom ({ys.min()}, {ys.max()})"


@needs_chromium
@pytest.mark.skipif(not HAVE_SHARED, reason="../shared/models is absent")
def test_browser_talos_fallback_drawing_and_animation(tmp_path):
    urdf = MODELS_DIR / "talos_full_v2.urdf"
    model = sodyn.Model.from_urdf(str(urdf), floating_base=True)
    with pytest.warns(viz.VizWarning, match="not found"):  # the shared files have no meshes
        v = viz.Visualizer(model, urdf, viewer=False)
    q0 = model.neutral()
    q0[2] = 1.0  # standing above the floor
    q1 = q0.copy()
    shoulder = next(j for j in model.joints if j.name == "arm_left_2_joint")
    q1[shoulder.idx_q] = 1.4  # the left arm raised sideways
    knee = next(j for j in model.joints if j.name == "leg_right_4_joint")
    q1[knee.idx_q] = 1.5
    traj = [q0 + (q1 - q0) * t for t in np.linspace(0, 1, 11)]
    html = v.save_html(tmp_path / "talos.html", trajectory=traj, dt=0.1)
    text = html.read_text()
    bg = background_of(text, tmp_path, "talos")
    first = render(html, tmp_path / "talos-t0.png", "#t=0")
    last = render(html, tmp_path / "talos-t1.png", "#t=1")
    assert_robot_drawn(first, bg, "talos t=0")
    assert_robot_drawn(last, bg, "talos t=1")
    assert_whole_robot_in_view(first, bg, "talos t=0")
    assert_whole_robot_in_view(last, bg, "talos t=1")
    moved = (np.abs(first - last).sum(axis=2) > 60).sum()
    assert moved > 500, f"the two animation frames differ in {moved} pixels only"
    # "#t=1" pauses the animation there: a render 1.25 s (of page time) later is the same
    # picture (a playing, looping animation would be elsewhere in its 1 s cycle)
    later = render(html, tmp_path / "talos-t1-later.png", "#t=1", budget_ms=6250)
    changed = (np.abs(later - last).sum(axis=2) > 60).sum()
    assert changed < 50, f"the paused frame changed in {changed} pixels"


def solved_trot():
    """Crocoddyl's ANYmal trot built with sodyn.ocp (``gait_problems.py``) and solved by
    sodyn's FDDP: ``(model, problem, solver)``."""
    from sodyn import ocp

    import gait_problems

    model, problem, xs, us = gait_problems.anymal_trot(MODELS_DIR / "anymal.urdf")
    solver = ocp.SolverFDDP(problem)
    assert solver.solve(xs, us, 100), solver.termination
    return model, problem, solver


@needs_chromium
@pytest.mark.skipif(not HAVE_SHARED, reason="../shared/models is absent")
def test_browser_solved_anymal_trot(tmp_path):
    model, problem, solver = solved_trot()
    urdf = MODELS_DIR / "anymal.urdf"
    with pytest.warns(viz.VizWarning, match="not found"):  # the shared files have no meshes
        v = viz.Visualizer(model, urdf, viewer=False)
    solver.display(v)  # Crocoddyl's habit: viz.play(solver.xs, dt) with the knots' dt
    html = v.save_html(tmp_path / "trot.html")
    text = html.read_text()
    # the document animates the solver's states: the base at each knot where
    # frame_placement puts it, one knot every 10 ms (the problem's dt)
    anim = next(c for c in decode_commands(text) if c["type"] == "set_animation")
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    base = clips["/meshcat/sodyn/links/base"]
    assert abs(base["fps"] - 100.0) < 1e-9
    pos = next(t for t in base["tracks"] if t["name"] == ".position")
    xs = solver.xs
    assert len(pos["keys"]) == len(xs) == problem.T + 1
    data = sodyn.Data(model)
    for k in (0, 20, len(xs) - 1):
        expected = sodyn.frame_placement(model, data, xs[k][: model.nq], "base")[:3, 3]
        np.testing.assert_allclose(pos["keys"][k]["value"], expected, atol=1e-12)
    # renders: the robot drawn and whole at the start and at the top of the first swing (RF
    # and LH lifted), and the two frames differ
    bg = background_of(text, tmp_path, "trot")
    first = render(html, tmp_path / "trot-t0.png", "#t=0")
    swing = render(html, tmp_path / "trot-swing.png", "#t=0.145")
    for img, what in ((first, "trot t=0"), (swing, "trot t=0.145")):
        assert_robot_drawn(img, bg, what)
        assert_whole_robot_in_view(img, bg, what)
    moved = (np.abs(first - swing).sum(axis=2) > 60).sum()
    assert moved > 300, f"the two animation frames differ in {moved} pixels only"


@needs_chromium
def test_browser_stl_mesh(arm, tmp_path):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs], viewer=False)
    v.display([0.3, 0.5, 0.0])
    html = v.save_html(tmp_path / "arm.html")
    text = html.read_text()
    img = render(html, tmp_path / "arm.png")
    assert_robot_drawn(img, background_of(text, tmp_path, "arm"), "arm")
    # the red STL mesh on link 'lower' is drawn: strongly red pixels
    red = (img[..., 0] > 120) & (img[..., 1] < 60) & (img[..., 2] < 60)
    assert red.sum() > 200, f"{red.sum()} red pixels"


def example_robot_data_share():
    import site
    import sysconfig

    for d in [sysconfig.get_paths()["purelib"], *site.getsitepackages()]:
        share = Path(d) / "cmeel.prefix" / "share"
        if (share / "example-robot-data" / "robots" / "panda_description").is_dir():
            return share
    return None


@needs_chromium
@pytest.mark.skipif(example_robot_data_share() is None,
                    reason="example-robot-data (with its meshes) is not installed")
def test_browser_panda_with_meshes(tmp_path):
    share = example_robot_data_share()
    urdf = share / "example-robot-data" / "robots" / "panda_description" / "urdf" / "panda.urdf"
    model = sodyn.Model.from_urdf(str(urdf))
    with warnings.catch_warnings():
        warnings.simplefilter("error", viz.VizWarning)  # every mesh is found
        v = viz.Visualizer(model, urdf, package_dirs=[share], viewer=False)
    assert all(s.kind == "mesh" for shapes in v.geometry.shapes.values() for s in shapes)
    v.display([0, -0.5, 0, -2.0, 0, 1.5, 0.8, 0.02, 0.02])
    html = v.save_html(tmp_path / "panda.html")
    img = render(html, tmp_path / "panda.png")
    bg = background_of(html.read_text(), tmp_path, "panda")
    assert_robot_drawn(img, bg, "panda")
    assert_whole_robot_in_view(img, bg, "panda")


# ------------------------------------------------------------------------------------------
# The live viewer (meshcat's server on 127.0.0.1)
# ------------------------------------------------------------------------------------------

def test_live_viewer_receives_the_scene(arm):
    path, pkgs = arm
    model = sodyn.Model.from_urdf(str(path))
    v = viz.Visualizer(model, path, package_dirs=[pkgs])
    try:
        q = np.array([0.1, 0.2, 0.3])
        v.display(q)
        url = v.open()
        assert url.startswith("http://127.0.0.1:")
        # meshcat's server keeps the scene; its own static HTML holds our commands
        scene = v.viewer.static_html()
        blobs = re.findall(r"base64,([A-Za-z0-9+/=]+)\"", scene)
        cmds = [umsgpack.unpackb(base64.b64decode(b)) for b in blobs]
        tf = transforms(cmds)
        expected = sodyn.frame_placement(model, sodyn.Data(model), q, "hand")
        np.testing.assert_allclose(tf["/meshcat/sodyn/links/hand"], expected, atol=1e-12)
        v.play([q, 2 * q], 0.01)
        tf = transforms([umsgpack.unpackb(base64.b64decode(b)) for b in
                         re.findall(r"base64,([A-Za-z0-9+/=]+)\"", v.viewer.static_html())])
        expected = sodyn.frame_placement(model, sodyn.Data(model), 2 * q, "hand")
        np.testing.assert_allclose(tf["/meshcat/sodyn/links/hand"], expected, atol=1e-12)
    finally:
        if v.viewer:
            v.viewer.window.server_proc.kill()
            v.viewer.window.server_proc.wait()


# ------------------------------------------------------------------------------------------
# The screenshots of docs/viz.md, made with the renders above:
#   python tests/test_viz.py --docs ../docs/viz-screenshot.png --trot ../docs/viz-trot.png
# viz-screenshot.png: the panda with its meshes (when example-robot-data is installed), then
# three frames of a scripted talos_full_v2 motion drawn without meshes; viz-trot.png: five
# frames of the solved ANYmal trot (solved_trot(), as test_browser_solved_anymal_trot), drawn
# without meshes as that test draws it, with the feet frames' axes.
# ------------------------------------------------------------------------------------------

def _strip(panels, out, height):
    from PIL import Image

    width = sum(p.width for p in panels)
    strip = Image.new("RGB", (width, height))
    x = 0
    for p in panels:
        strip.paste(p.crop((0, p.height - height, p.width, p.height)), (x, 0))
        x += p.width
    strip = strip.quantize(colors=256)
    strip.save(out, optimize=True)
    print(f"wrote {out} ({Path(out).stat().st_size} bytes)")


def docs_screenshot(out):
    import tempfile

    from PIL import Image

    assert CHROMIUM is not None, "chromium is not installed"
    tmp = Path(tempfile.mkdtemp())
    panels = []
    share = example_robot_data_share()
    if share is not None:
        urdf = share / "example-robot-data" / "robots" / "panda_description" / "urdf" / "panda.urdf"
        model = sodyn.Model.from_urdf(str(urdf))
        v = viz.Visualizer(model, urdf, package_dirs=[share], viewer=False)
        v.display([0, -0.5, 0, -2.0, 0, 1.5, 0.8, 0.02, 0.02])
        html = v.save_html(tmp / "panda.html")
        render(html, tmp / "panda.png", size=(360, 360))
        panels.append(Image.open(tmp / "panda.png").convert("RGB"))
    urdf = MODELS_DIR / "talos_full_v2.urdf"
    model = sodyn.Model.from_urdf(str(urdf), floating_base=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", viz.VizWarning)
        v = viz.Visualizer(model, urdf, viewer=False)
    v.show_frames(["left_sole_link", "right_sole_link"])
    q0 = model.neutral()
    q0[2] = 1.02

    def idx(name):
        return next(j for j in model.joints if j.name == name).idx_q

    q1 = q0.copy()
    for name, value in (("arm_left_2_joint", 1.2), ("arm_right_2_joint", -1.2),
                        ("arm_left_4_joint", -1.0), ("arm_right_4_joint", -1.0),
                        ("leg_left_3_joint", -0.6), ("leg_right_3_joint", -0.6),
                        ("leg_left_4_joint", 1.2), ("leg_right_4_joint", 1.2),
                        ("leg_left_5_joint", -0.6), ("leg_right_5_joint", -0.6)):
        q1[idx(name)] = value
    q1[2] = 1.02 - 0.12
    traj = [q0 + (q1 - q0) * t for t in np.linspace(0, 1, 21)]
    html = v.save_html(tmp / "talos.html", trajectory=traj, dt=0.05)
    for k, t in enumerate((0.0, 0.5, 1.0)):
        png = tmp / f"talos{k}.png"
        render(html, png, f"#t={t}", size=(300, 360))
        panels.append(Image.open(png).convert("RGB").crop((0, 24, 300, 360)))
    _strip(panels, out, 336)


# The frames of viz-trot.png: the start, the top of each swing (RF-LH, then LF-RH), the
# middle four-foot support and the end (knots 0, 14, 30, 44, 56 at 10 ms per knot).
TROT_FRAMES = (0.0, 0.14, 0.29, 0.43, 0.56)


def docs_trot_screenshot(out):
    import tempfile

    from PIL import Image

    assert CHROMIUM is not None, "chromium is not installed"
    tmp = Path(tempfile.mkdtemp())
    model, problem, solver = solved_trot()
    print(f"trot: T = {problem.T}, {solver.iter} FDDP iterations, cost {solver.cost:.6f}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", viz.VizWarning)  # no meshes: the fallback drawing
        v = viz.Visualizer(model, MODELS_DIR / "anymal.urdf", viewer=False)
    v.show_frames(["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"])
    solver.display(v)
    html = v.save_html(tmp / "trot.html")
    panels = []
    for k, t in enumerate(TROT_FRAMES):
        png = tmp / f"trot{k}.png"
        render(html, png, f"#t={t}", size=(280, 300))
        panels.append(Image.open(png).convert("RGB").crop((0, 24, 280, 300)))
    _strip(panels, out, 276)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser()
    parser.add_argument("--docs", metavar="OUT.png", help="the model screenshot")
    parser.add_argument("--trot", metavar="OUT.png", help="the strip of the solved trot")
    args = parser.parse_args()
    if not (args.docs or args.trot):
        parser.error("give --docs and/or --trot")
    if args.docs:
        docs_screenshot(args.docs)
    if args.trot:
        docs_trot_screenshot(args.trot)
