"""three.js scene JSON as meshcat takes it: objects, materials, geometries, animation clips."""

from __future__ import annotations

import uuid

import numpy as np
import pinocchio as pin

# ------------------------------------------------------------------------------ three.js JSON


def new_uuid() -> str:
    return str(uuid.uuid4())


def _array(a: np.ndarray, dtype=np.float32) -> dict:
    """A typed array as meshcat packs one: msgpack ext types the viewer decodes."""
    import umsgpack

    codes = {np.dtype(np.float32): (0x17, "Float32Array"), np.dtype(np.uint8): (0x12, "Uint8Array")}
    a = np.ascontiguousarray(a, dtype=dtype)
    code, name = codes[a.dtype]
    return {"itemSize": a.shape[1] if a.ndim == 2 else 1, "type": name,
            "array": umsgpack.Ext(code, a.tobytes()), "normalized": a.dtype == np.uint8}


def _ext_f32(a) -> object:
    import umsgpack

    return umsgpack.Ext(0x17, np.ascontiguousarray(a, dtype=np.float32).tobytes())


def matrix_of(M: pin.SE3 | None = None, scale=None) -> list[float]:
    """Column-major 4x4 (three.js `matrix`)."""
    T = np.eye(4) if M is None else M.homogeneous.copy()
    if scale is not None:
        T[:3, :3] = T[:3, :3] @ np.diag(scale)
    return [float(x) for x in T.T.ravel()]


def colour(rgb) -> int:
    r, g, b = (int(round(255 * c)) for c in rgb)
    return (r << 16) + (g << 8) + b


class ObjectTree:
    """One three.js object tree in the JSON of meshcat's set_object, geometries, materials and
    textures shared by key."""

    def __init__(self):
        self.lists = {"geometries": [], "materials": [], "textures": []}
        self.keys: dict = {}

    def add(self, kind: str, data: dict, key=None) -> str:
        if key is not None and (kind, key) in self.keys:
            return self.keys[kind, key]
        data = {"uuid": new_uuid(), **data}
        self.lists[kind].append(data)
        if key is not None:
            self.keys[kind, key] = data["uuid"]
        return data["uuid"]

    def points(self, name: str, positions: np.ndarray, colours: np.ndarray | None, size: float,
               rgb=(1, 1, 1), visible=True, render_order=0) -> dict:
        """A point cloud, `positions` (n, 3) m; per-point `colours` (n, 3) or one `rgb`."""
        attrs = {"position": _array(positions)}
        if colours is not None:  # bytes, read as [0, 1] (normalized)
            attrs["color"] = _array(np.round(np.asarray(colours) * 255), np.uint8)
        g = self.add("geometries", {"type": "BufferGeometry", "data": {"attributes": attrs}})
        m = self.add("materials", {"type": "PointsMaterial", "size": size, "sizeAttenuation": True,
                                   "vertexColors": colours is not None, "color": colour(rgb)},
                     key=("points", size, colours is not None, tuple(rgb)))
        return node("Points", name, g, m, visible=visible, renderOrder=render_order, frustumCulled=False)

    def command(self, path: str, root: dict) -> dict:
        obj = {"metadata": {"version": 4.5, "type": "Object"}, **self.lists, "images": [], "object": root}
        return {"type": "set_object", "path": path, "object": obj}


def node(kind: str, name: str, geometry: str | None = None, material: str | None = None,
         matrix=None, children=(), **extra) -> dict:
    n = {"uuid": new_uuid(), "type": kind, "name": name, "matrix": matrix or matrix_of()}
    if geometry is not None:
        n["geometry"], n["material"] = geometry, material
    if children:
        n["children"] = list(children)
    n.update(extra)
    return n


class Clip:
    """One node's animation clip; keys are in frames of the display rate, values float32."""

    def __init__(self, path: str):
        self.path, self.tracks = path, []

    def pose(self, target: str, poses: list[pin.SE3], times: np.ndarray) -> None:
        xyzq = np.array([pin.SE3ToXYZQUAT(M) for M in poses])
        self.vector(target, "position", times, xyzq[:, :3])
        self.tracks.append({"name": f"{target}.quaternion", "type": "quaternion", "times": _ext_f32(times),
                            "values": _ext_f32(_continuous(xyzq[:, 3:]).ravel())})

    def vector(self, target: str, prop: str, times, values) -> None:
        self.tracks.append({"name": f"{target}.{prop}", "type": "vector3", "times": _ext_f32(times),
                            "values": _ext_f32(np.asarray(values).ravel())})

    def visible(self, target: str, shown: np.ndarray, times: np.ndarray) -> None:
        """`shown` (n_frames,) bool: keys only where it changes (discrete track)."""
        keep = np.flatnonzero(np.r_[True, shown[1:] != shown[:-1]])
        self.tracks.append({"name": f"{target}.visible", "type": "boolean",
                            "times": _ext_f32(times[keep]), "values": [bool(v) for v in shown[keep]]})

    def lower(self, fps: float) -> dict:
        return {"path": self.path, "clip": {"fps": fps, "name": "default", "uuid": new_uuid(), "tracks": self.tracks}}


def _continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions (n, 4) with signs flipped so that consecutive ones are on the same side."""
    q = q.copy()
    for i in range(1, len(q)):
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    return q


def moves(poses: list[pin.SE3]) -> bool:
    return any(not M.isApprox(poses[0], 1e-9) for M in poses[1:])
