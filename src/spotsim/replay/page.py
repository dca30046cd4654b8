"""Delivering the commands: one self-contained HTML page, or a Meshcat server."""

from __future__ import annotations

import base64
import json
from pathlib import Path

from ..errors import SpotsimError
from .scene import ANIMATION_NODE, ReplayInfo

#: How long `replay --zmq-url` waits for a Meshcat server to answer, s.
ZMQ_TIMEOUT_S = 5.0

# ------------------------------------------------------------------------------ delivery


def packed(commands: list[dict]) -> list[bytes]:
    import umsgpack

    return [umsgpack.packb(c) for c in commands]


PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title></head>
<body>
<div id="meshcat-pane"></div>
<script>{main_js}</script>
<script type="application/json" id="spotsim-commands">{commands}</script>
<script type="application/json" id="spotsim-views">{views}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{
  // the commands in order, decoded at once: the animation binds to objects already made
  const blobs = JSON.parse(document.getElementById("spotsim-commands").textContent);
  for (const b of blobs) {{
    viewer.handle_command_bytearray(Uint8Array.from(atob(b), (c) => c.charCodeAt(0)));
  }}
  // ?t=<simulated s> shows that instant, paused; ?view=scene|<end-effector>; ?speed=<x>
  const q = new URLSearchParams(window.location.search || window.location.hash.slice(1));
  const views = JSON.parse(document.getElementById("spotsim-views").textContent);
  const view = views[q.get("view") || "scene"];
  if (view) {{
    viewer.camera.position.set(...view.camera);
    viewer.controls.target.set(...view.target);
    viewer.controls.update();
  }}
  const a = viewer.animator;
  if (q.has("speed")) a.mixer.timeScale = parseFloat(q.get("speed"));
  if (q.has("t")) {{
    a.pause();
    const t = parseFloat(q.get("t"));
    a.seek(t * (1 + 1e-6) + 1e-6);  // past float32 key times equal to t
    a.display_progress(t);
  }}
  viewer.set_dirty();
}})();
</script>
<style>body {{margin: 0;}} #meshcat-pane {{width: 100vw; height: 100vh; overflow: hidden;}}</style>
</body>
</html>
"""


def static_html(commands: list[dict], info: ReplayInfo, title: str) -> str:
    """Meshcat's static page: its viewer inline and the commands embedded (no server, no
    network); URL parameters t, view and speed pick the instant, the camera and the speed."""
    import html

    import meshcat

    main_js = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text()
    blobs = [base64.b64encode(b).decode("ascii") for b in packed(commands)]
    return PAGE.format(title=html.escape(title), main_js=main_js, commands=json.dumps(blobs),
                       views=json.dumps(info.views))


def write_html(path: Path, text: str) -> None:
    """Write the page atomically: an interrupted write leaves no half page."""
    from ..files import atomic_write

    atomic_write(Path(path), text)


def commands_of_html(text: str) -> list[dict]:
    """The meshcat commands a page written by `static_html` embeds, decoded."""
    import re

    import umsgpack

    m = re.search(r'<script type="application/json" id="spotsim-commands">(.*?)</script>', text, re.S)
    if m is None:
        raise SpotsimError("not a page written by spotsim replay --html")
    return [umsgpack.unpackb(base64.b64decode(b)) for b in json.loads(m.group(1))]


class Server:
    """A Meshcat server over ZeroMQ: the one at `zmq_url`, or a new local one (ours to stop)."""

    def __init__(self, zmq_url: str | None = None):
        import zmq

        self.proc = None
        if zmq_url is None:
            from meshcat.servers.zmqserver import start_zmq_server_as_subprocess

            try:
                self.proc, zmq_url, _ = start_zmq_server_as_subprocess()
            except Exception as e:  # meshcat raises RuntimeError, or whatever its server did
                raise SpotsimError(f"cannot start a Meshcat server: {e}") from e
        self.zmq_url = zmq_url
        self.context = zmq.Context.instance()
        self.socket = self._connect()
        self.web_url = self._request([b"url"]).decode()

    def _connect(self):
        import zmq

        s = self.context.socket(zmq.REQ)
        s.setsockopt(zmq.LINGER, 0)
        s.setsockopt(zmq.RCVTIMEO, int(ZMQ_TIMEOUT_S * 1000))
        s.setsockopt(zmq.SNDTIMEO, int(ZMQ_TIMEOUT_S * 1000))
        try:
            s.connect(self.zmq_url)
        except zmq.ZMQError as e:
            s.close()
            raise SpotsimError(f"--zmq-url {self.zmq_url}: {e}") from e
        return s

    def _request(self, frames: list[bytes]) -> bytes:
        import zmq

        try:
            self.socket.send_multipart(frames)
            return self.socket.recv()
        except zmq.ZMQError as e:
            self.close()
            raise SpotsimError(f"no Meshcat server answers at {self.zmq_url} (waited {ZMQ_TIMEOUT_S:g} s); "
                               f"start one with `meshcat-server`") from e

    def send(self, commands: list[dict]) -> None:
        for cmd, data in zip(commands, packed(commands), strict=True):
            route = ANIMATION_NODE if cmd["type"] == "set_animation" else cmd["path"]
            reply = self._request([cmd["type"].encode(), route.encode(), data])
            if reply != b"ok":
                raise SpotsimError(f"the Meshcat server at {self.zmq_url} refused {cmd['type']}: {reply!r}")

    def scene_html(self) -> str:
        """The server's scene as its static page (meshcat's `get_scene`)."""
        return self._request([b"get_scene"]).decode()

    def close(self) -> None:
        self.socket.close()
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None
