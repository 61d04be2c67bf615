"""The self-contained HTML document of a scene: meshcat's viewer (three.js and its loaders,
``meshcat/viewer/dist/main.min.js`` of the installed package) inlined, followed by the scene
as meshcat commands (msgpack, base64) and a small script that frames the camera and reads
``#t=SECONDS``. Nothing is fetched from the network."""

from __future__ import annotations

import base64
import html as _html
import json
import os
from typing import Any, Iterable, Sequence

import numpy as np


# The framed sphere's radius is the scene's (half the diagonal of the box of every link and
# joint origin over the motion) times this, for the drawn geometry around those origins.
FIT_MARGIN = 1.15


def viewer_js() -> str:
    """meshcat's bundled viewer script (three.js included)."""
    import meshcat

    path = os.path.join(meshcat.viewer_assets_path(), "dist", "main.min.js")
    with open(path, encoding="utf-8") as f:
        return f.read()


def _b64(cmd: Any) -> str:
    import umsgpack

    return base64.b64encode(umsgpack.packb(cmd.lower())).decode("ascii")


def document(cmds: Iterable[Any], center: Sequence[float], radius: float, duration: float,
             title: str = "sodyn") -> str:
    """The HTML text: the viewer, the commands, a camera looking at ``center`` from the
    distance at which a sphere of ``radius`` (times ``FIT_MARGIN``) fits the window's
    narrower field of view (computed in the page, from the camera's vertical field of view
    and the window's aspect ratio, so a tall or a wide window shows the whole sphere)."""
    c = np.asarray(center, dtype=float)
    # A three-quarter view from +x, +y, above. meshcat turns its z-up scene into three.js's
    # y-up world, where the orbit target and (through "/Cameras/default/rotated") the camera
    # position live: world (x, y, z) is three.js (x, z, -y).
    direction = np.array([0.8, 0.5, 0.55])
    direction = direction / np.linalg.norm(direction)
    cfg = {
        "target": [c[0], c[2], -c[1]],
        "direction": [direction[0], direction[2], -direction[1]],
        "fit": FIT_MARGIN,
        "duration": float(duration),
        "center": [float(x) for x in c],
        "radius": float(radius),
    }
    js = viewer_js().replace("</script", "<\\/script")
    payload = json.dumps([_b64(cmd) for cmd in cmds])
    return f"""<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{_html.escape(title)}</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>
{js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{
  var commands = {payload};
  var failed = [];
  for (var i = 0; i < commands.length; i++) {{
    var s = atob(commands[i]);
    var bytes = new Uint8Array(s.length);
    for (var k = 0; k < s.length; k++) bytes[k] = s.charCodeAt(k);
    try {{
      viewer.handle_command_bytearray(bytes);
    }} catch (e) {{
      // one object the viewer cannot build (a mesh its loader refuses) must not stop the
      // rest of the scene, the camera and the animation
      failed.push(String(e));
      console.error("sodyn: command " + i + " failed: " + e);
    }}
  }}
  document.body.setAttribute("data-sodyn-failed", String(failed.length));
  var cfg = {json.dumps(cfg)};
  // The distance at which the sphere fills the narrower of the two fields of view.
  var cam = viewer.camera;
  var aspect = window.innerWidth > 0 && window.innerHeight > 0
    ? window.innerWidth / window.innerHeight : 1.0;
  var vfov = cam.fov * Math.PI / 180;
  var hfov = 2 * Math.atan(Math.tan(vfov / 2) * aspect);
  var dist = cfg.fit * cfg.radius / Math.sin(Math.min(vfov, hfov) / 2);
  var d = cfg.direction, t = cfg.target;
  cam.position.set(t[0] + dist * d[0], t[1] + dist * d[1], t[2] + dist * d[2]);
  viewer.controls.target.set(cfg.target[0], cfg.target[1], cfg.target[2]);
  viewer.controls.update();
  function seekFromHash() {{
    var m = /[#&]t=([0-9.eE+-]+)/.exec(window.location.hash);
    if (m && viewer.animator.actions.length > 0) {{
      viewer.animator.pause();
      var t = Math.max(0, Math.min(cfg.duration - 1e-6, parseFloat(m[1])));
      viewer.animator.seek(t);
      viewer.animator.display_progress(t);
    }}
  }}
  seekFromHash();
  window.addEventListener("hashchange", seekFromHash);
  viewer.set_dirty();
  document.body.setAttribute("data-sodyn-ready", "1");
}})();
</script>
</body>
</html>
"""
