"""The meshcat commands that draw and animate a run: the robot, the contact layers and pairs,
the force arrows, the head-up text and the cameras."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..contact.friction import NONE, SLIPPING, STICKING
from ..tables import PHASE_NAMES as PHASE_KEYS
from .run import Kinematics, Run, display_frames, recorded_state
from .three import Clip, ObjectTree, colour, matrix_of, moves, new_uuid, node

#: Pair state colours of the paper's Fig. 9 (RGB in [0, 1]).
STATE_COLOURS = {NONE: (0.10, 0.30, 1.00), SLIPPING: (1.00, 0.12, 0.12), STICKING: (0.55, 0.85, 1.00)}
#: Drawn size of a sphere, as a fraction of its radius: the layers' grid step is one radius,
#: so idle spheres drawn smaller leave gaps; the spheres of pairs in contact are drawn over
#: them at their diameter.
IDLE_SPHERE_SIZE, PAIR_SPHERE_SIZE = 0.5, 2.0
#: Arm meshes are coarsened by vertex clustering on this grid (m): the example-robot-data
#: meshes hold 130-250 k triangles (14-21 MB of COLLADA), a few thousand keep their shape.
COARSE_MESH_CELL_M = 0.006
#: Visuals drawn see-through, by the end of their URDF visual's or link's name, with their
#: opacity: the adapter block holds the grooves and the fingers' backs hide the wedges, where
#: the spheres are.
SEE_THROUGH = {"adapter": 0.25, "finger_upper": 0.35, "finger_lower": 0.35}
#: Visuals left out, by link name: the Z1's own gripper, which the paper's end-effector replaces
#: (example-robot-data's Z1 carries it) and which would hide the fingers.
LEFT_OUT = ("gripperStator", "gripperMover")
#: Opacity of the contact faces' plates: the spheres in contact lie between two of them.
PLATE_OPACITY = 0.35
#: Longest force arrow for a typical load (95th percentile of the run's nonzero forces), m.
ARROW_LENGTH_M = 0.08
#: Light grey background (Pinocchio's "gray" preset): the blue and light blue spheres need it.
BACKGROUND = ([0.98, 0.98, 0.98], [0.8, 0.8, 0.8])
#: Perspective camera of meshcat's viewer: vertical field of view, deg.
CAMERA_FOV_DEG = 75.0
#: The whole-scene camera, chosen by eye: its direction from the scene's centre (world axes)
#: and its distance in units of the scene's radius; a fixed arm, and the free-flying robot.
SCENE_VIEWS = {"fixed": ((1.0, -1.3, 0.8), 2.2), "free": ((1.0, 0.6, 0.5), 3.0)}

ROOT = "/meshcat/spotsim"
CAMERA = "/Cameras/default/rotated/<object>"
HUD = CAMERA + "/spotsim_hud"
# the server replays its scene tree node by node; the animation must come after every object
# it animates, so it is filed under a node created last (the viewer ignores this path)
ANIMATION_NODE = "/spotsim_animation"
CLEAR = (ROOT, HUD, ANIMATION_NODE)

#: How the head-up text names each phase of the summary.
PHASE_NAMES = dict(zip(PHASE_KEYS, ("approach", "self-centring", "complete"), strict=True))



# ------------------------------------------------------------------------------ the scene


def coarse_mesh(vertices: np.ndarray, triangles: np.ndarray, cell: float):
    """Vertex clustering: the vertices in one cube of side `cell` merge at their mean and the
    triangles that collapse are dropped. vertices (n, 3), triangles (m, 3) int."""
    key = np.floor(vertices / cell).astype(np.int64)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    counts = np.bincount(inverse)
    merged = np.stack([np.bincount(inverse, vertices[:, i]) for i in range(3)], axis=1) / counts[:, None]
    tri = inverse[triangles]
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])]
    _, first = np.unique(np.sort(tri, axis=1), axis=0, return_index=True)
    return merged, tri[np.sort(first)]


def visual_model(model) -> tuple[pin.Model, pin.GeometryModel]:
    """The unreduced scene with its visual geometry: arm meshes coarsened, the adapter see-through."""
    import io

    import coal
    import yourdfpy

    full = pin.buildModelFromXML(model.urdf)
    visual = pin.buildGeomFromUrdfString(full, model.urdf, pin.GeometryType.VISUAL)
    # Pinocchio names visuals <link>_<i>; the URDF's own names say which is which
    urdf = yourdfpy.URDF.load(io.BytesIO(model.urdf.encode()), load_meshes=False, build_scene_graph=False,
                              load_collision_meshes=False)
    names = {f"{link.name}_{i}": (link.name, v.name or "") for link in urdf.robot.links
             for i, v in enumerate(link.visuals)}
    for g in [g.name for g in visual.geometryObjects if names.get(g.name, ("", ""))[0] in LEFT_OUT]:
        visual.removeGeometryObject(g)
    for g in visual.geometryObjects:
        link, name = names.get(g.name, ("", ""))
        for suffix, opacity in SEE_THROUGH.items():
            if name.endswith(suffix) or link.endswith(suffix):
                colour = g.meshColor.copy()
                colour[3] = opacity
                g.meshColor = colour
        geom = g.geometry
        if isinstance(geom, coal.BVHModelBase) and geom.num_tris:
            tris = np.array([[t[0], t[1], t[2]] for t in map(geom.tri_indices, range(geom.num_tris))])
            scale = np.asarray(g.meshScale)
            v, t = coarse_mesh(geom.vertices() * scale, tris, COARSE_MESH_CELL_M)
            bvh = coal.BVHModelOBBRSS()
            bvh.beginModel(len(t), len(v))
            bvh.addVertices(v / scale)
            bvh.addTriangles(t)
            bvh.endModel()
            g.geometry, g.meshPath = bvh, ""  # no file: the visualizer sends these triangles
    return full, visual


@dataclass
class ReplayInfo:
    frames: int
    rate_hz: float
    duration_s: float
    force_mm_per_N: float
    views: dict  # name -> {"camera": [x, y, z], "target": [x, y, z]} (three.js axes)


class _Commands:
    """A meshcat window that keeps the lowered commands instead of sending them."""

    def __init__(self):
        self.commands: list[dict] = []

    def send(self, command) -> None:
        self.commands.append(command.lower())


def build(run: Run, rate_hz: float = 100.0, spheres: bool = True, force_mm_per_N: float | None = None,
          loop: bool = True) -> tuple[list[dict], ReplayInfo]:
    """The meshcat commands that draw and animate a run, and what they show.

    rate_hz: display frames per simulated second. spheres: draw the sphere layers.
    force_mm_per_N: arrow scale (None: ARROW_LENGTH_M for a typical load, rounded to 1-2-5).
    """
    import meshcat
    from pinocchio.visualize import MeshcatVisualizer

    model = run.model
    frames = display_frames(run, rate_hz)
    keys = frames.keys
    states = [recorded_state(run, r) for r in frames.rows]

    window = _Commands()
    vis = meshcat.Visualizer(window=window)
    for path in CLEAR:
        vis[path].delete()
    full, visual = visual_model(model)
    viz = MeshcatVisualizer(full, None, visual)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName="spotsim")
    full_kin = Kinematics(run, full)
    viz.display(full_kin.q(*states[0]))
    clips = []
    vdata = visual.createData()
    placements = [[] for _ in visual.geometryObjects]
    finger_frames = {name: full.getFrameId(name, pin.BODY) for name in model.layout.fingers}
    finger_poses = {name: [] for name in finger_frames}  # each finger link's, per display frame
    for s in states:
        data = full_kin.place(*s)
        pin.updateGeometryPlacements(full, data, visual, vdata)
        for g, M in enumerate(vdata.oMg):
            placements[g].append(M.copy())
        for name, fid in finger_frames.items():
            finger_poses[name].append(pin.updateFramePlacement(full, data, fid).copy())
    for g, obj in enumerate(visual.geometryObjects):
        if moves(placements[g]):
            clip = Clip(f"{ROOT}/visuals/{obj.name}")
            clip.pose("", placements[g], keys)
            clips.append(clip)

    first = Kinematics(run, model.pin_model)
    datas = [[M.copy() for M in first.place(*s).oMi] for s in states]
    module_poses = [[oMi[m.joint] for oMi in datas] for m in model.modules]
    clips += _contact_bodies(run, frames, keys, finger_poses, module_poses, spheres, window.commands)
    scale = _force_scale(run, frames) if force_mm_per_N is None else force_mm_per_N * 1e-3
    clips += _force_arrows(run, frames, keys, states, scale, window.commands)
    clips.append(_hud(run, frames, keys, scale, spheres, window.commands))

    focus, views = _views(run, states[0], datas[0])
    vis[ROOT].set_transform(pin.SE3(np.eye(3), -focus).homogeneous)
    for path, prop, value in (("/Background", "top_color", BACKGROUND[0]),
                              ("/Background", "bottom_color", BACKGROUND[1]),
                              ("/Grid", "visible", False), ("/Axes", "visible", False),
                              (CAMERA, "position", views["scene"]["camera"])):
        vis[path].set_property(prop, value)
    window.commands.append({
        "type": "set_animation", "path": "",
        "animations": [c.lower(frames.rate_hz) for c in clips],
        "options": {"play": True, "repetitions": float("inf") if loop else 1},
    })
    return window.commands, ReplayInfo(len(frames.rows), frames.rate_hz, float(frames.t[-1]), scale * 1e3, views)


def _body_of_faces(model):
    """Group the first model's faces by the body their spheres ride: each finger link (on its
    joint, or locked on the body it is mounted on) and each module. Returns [(name, kind,
    index, master faces, slave faces)], kind "finger" (index: the link's name) or "module"."""
    link_of = {face.name: face.link for face in model.faces}
    masters, _ = model.face_names
    bodies = []
    n_master_faces = len(masters)
    for name in model.layout.fingers:
        faces = np.array([k for k, n in enumerate(masters) if link_of[n] == name], dtype=int)
        if len(faces):
            bodies.append((name, "finger", name, faces, np.zeros(0, int)))
    for k, mod in enumerate(model.modules):
        faces = np.unique(model.slave.face[model.slave.joint == mod.joint])
        bodies.append((mod.name, "module", k, np.zeros(0, int), faces + n_master_faces))
    return bodies, n_master_faces


def _in_body_frames(model) -> tuple[np.ndarray, dict]:
    """The master spheres' centres in their finger link's frame (they are given in their
    joint's, the finger's own or, locked, the body it is mounted on), and each master face's
    placement change from its joint's frame to its link's (an SE3 per face)."""
    link_of = {face.name: face.link for face in model.faces}
    masters, _ = model.face_names
    centres = model.master.centre_J.copy()
    to_link = {}
    for f, name in enumerate(masters):
        link = model.pin_model.frames[model.pin_model.getFrameId(link_of[name], pin.BODY)].placement.inverse()
        on = model.master.face == f
        centres[on] = model.master.centre_J[on] @ link.rotation.T + link.translation
        to_link[f] = link
    return centres, to_link


def _contact_bodies(run, frames, keys, finger_poses, module_poses, spheres, commands) -> list[Clip]:
    """Per finger and per module: its contact faces as thin plates, the sphere layers of its
    faces in contact range and, over them, the spheres of the pairs in contact by state. A
    finger is drawn in its link's frame (finger_poses: each link's world pose per display
    frame), a module in its joint's (module_poses)."""
    model = run.model
    snaps = run.snapshots
    bodies, _ = _body_of_faces(model)
    p = model.law
    master_B, to_link = _in_body_frames(model)
    # three.js draws a point of `size` as wide as a segment of size * tan(fov / 2) at its depth
    focal = 1 / np.tan(np.radians(CAMERA_FOV_DEG) / 2)
    face_layers = []  # per face (first-model numbering): (positions in its body frame, radius)
    for layers, centres, r in ((model.master, master_B, p.r1), (model.slave, model.slave.centre_J, p.r2)):
        for f in range(int(layers.face.max()) + 1):
            face_layers.append((centres[layers.face == f], r))
    plates = _plates(model)
    clips = []
    for name, kind, i, mfaces, sfaces in bodies:
        tree = ObjectTree()
        children = []
        plate_mat = tree.add("materials", {"type": "MeshLambertMaterial", "side": 2, "transparent": True,
                                           "opacity": PLATE_OPACITY, "depthWrite": False,
                                           "color": colour((0.3, 0.45, 0.9) if kind == "finger" else (0.5, 0.5, 0.52))})
        for f in [*mfaces, *sfaces]:
            size, M = plates[f]
            if f in to_link:
                M = to_link[f] * M
            g = tree.add("geometries", {"type": "BoxGeometry", "width": size[0], "height": size[1], "depth": size[2]})
            children.append(node("Mesh", f"plate{f}", g, plate_mat, matrix=matrix_of(M)))
        clip = Clip(f"{ROOT}/contact/{name}")
        clip.pose("", finger_poses[i] if kind == "finger" else module_poses[i], keys)
        if spheres and snaps is not None:
            snap = frames.snapshot
            for f in [*mfaces, *sfaces]:
                centres, r = face_layers[f]
                shown = np.where(snap >= 0, snaps["faces_in_range"][np.maximum(snap, 0), f], False)
                children.append(tree.points(f"f{f}", centres, None, IDLE_SPHERE_SIZE * r * focal,
                                            STATE_COLOURS[NONE], visible=bool(shown[0])))
                clip.visible(f"f{f}", shown, keys)
            if kind == "finger":
                on_body, layer = np.isin(model.master.face, mfaces), (master_B, p.r1, "master")
            else:
                on_body, layer = model.slave.joint == model.modules[i].joint, (model.slave.centre_J, p.r2, "slave")
            for child, shown in _pair_clouds(snaps, snap, layer, on_body, tree, focal):
                children.append(child)
                clip.visible(child["name"], shown, keys)
        commands.append(tree.command(f"{ROOT}/contact/{name}", node("Group", "body", children=children)))
        clips.append(clip)
    return clips


def _plates(model) -> dict:
    """Each contact face's thin box: (size (3,), placement in its body's sphere frame)."""
    objects = model.geom_model.geometryObjects
    masters = list(model.master_geoms)
    slaves = [g for g in range(len(objects)) if g not in set(masters)]
    out = {}
    for f, g in enumerate(masters + slaves):
        o = objects[g]
        out[f] = (2 * np.asarray(o.geometry.halfSide), o.placement)
    return out


def _pair_clouds(snaps, snap, layer, on_body, tree, focal):
    """The coloured spheres of one body at each display frame, one point cloud per distinct
    set (a grasp that holds shows one cloud for many frames). layer: (the role's sphere
    centres in the body's frame, their radius, "master" or "slave"); on_body: (n,) the role's
    spheres on this body. Yields (cloud, shown per frame)."""
    ends = snaps["pairs_end"]
    clouds: dict[bytes, tuple[dict, np.ndarray]] = {}
    order = []
    centres, r, idx_key = layer
    for frame, s in enumerate(snap):
        if s < 0:
            continue
        lo, hi = (ends[s - 1] if s else 0), ends[s]
        idx, st = snaps[idx_key][lo:hi], snaps["state"][lo:hi]
        mine = on_body[idx]
        if not mine.any():
            continue
        # a sphere in pairs of both states shows slipping
        idx, st = idx[mine], st[mine]
        o = np.lexsort((st, idx))
        idx, st = idx[o], st[o]
        first = np.r_[True, idx[1:] != idx[:-1]]
        idx, st = idx[first], st[first]
        key = idx.tobytes() + st.tobytes()
        if key not in clouds:
            colours = np.array([STATE_COLOURS[int(x)] for x in st])
            cloud = tree.points(f"s{len(order)}", centres[idx], colours, PAIR_SPHERE_SIZE * r * focal,
                                visible=False, render_order=1)
            clouds[key] = (cloud, np.zeros(len(snap), dtype=bool))
            order.append(key)
        clouds[key][1][frame] = True
    for key in order:
        cloud, shown = clouds[key]
        cloud["visible"] = bool(shown[0])
        yield cloud, shown


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above x."""
    k = np.floor(np.log10(x))
    for m in (5, 2, 1):
        if m * 10 ** k <= x:
            return float(m * 10 ** k)
    return float(10 ** k)


def _force_scale(run, frames) -> float:
    """Arrow length per newton, m/N: a typical load (95th percentile) draws ARROW_LENGTH_M."""
    if run.snapshots is None:
        return 1e-3
    F = np.linalg.norm(run.snapshots["force_W"], axis=2).ravel()
    F = F[F > 0]
    return _nice(ARROW_LENGTH_M / np.percentile(F, 95)) if len(F) else 1e-3


def _force_arrows(run, frames, keys, states, scale, commands) -> list[Clip]:
    """The combined contact force on each module: an arrow from its groove frame origin O_b,
    drawn over everything, `scale` m per N; hidden while the module takes no force."""
    if run.snapshots is None:
        return []
    clips = []
    F_all = run.snapshots["force_W"]
    shaft_r, head_r, head_h = 0.0012, 0.0035, 0.008
    for k, mod in enumerate(run.model.modules):
        F = np.where((frames.snapshot >= 0)[:, None], F_all[np.maximum(frames.snapshot, 0), k], 0.0)
        norm = np.linalg.norm(F, axis=1)
        L, shown = norm * scale, norm > 0
        poses = []
        for (modules_W, *_), f, n in zip(states, F, norm):
            R = pin.Quaternion.FromTwoVectors(np.array([0.0, 1.0, 0.0]), f / n).matrix() if n > 0 else np.eye(3)
            poses.append(pin.SE3(R, modules_W[k].translation))
        tree = ObjectTree()
        mat = tree.add("materials", {"type": "MeshLambertMaterial", "color": 0xE000E0, "depthTest": False,
                                     "transparent": True, "opacity": 0.9})
        shaft = tree.add("geometries", {"type": "CylinderGeometry", "radiusTop": shaft_r, "radiusBottom": shaft_r,
                                        "height": 1.0, "radialSegments": 12})
        head = tree.add("geometries", {"type": "CylinderGeometry", "radiusTop": 0.0, "radiusBottom": head_r,
                                       "height": head_h, "radialSegments": 16})
        path = f"{ROOT}/forces/{mod.name}"
        commands.append(tree.command(path, node("Group", "arrow", children=[
            node("Mesh", "shaft", shaft, mat, renderOrder=10), node("Mesh", "head", head, mat, renderOrder=10)],
            visible=bool(shown[0]))))
        clip = Clip(path)
        clip.pose("", poses, keys)
        clip.visible("arrow", shown, keys)
        Lc = np.maximum(L, 1e-6)
        clip.vector("shaft", "scale", keys, np.stack([np.ones_like(Lc), Lc, np.ones_like(Lc)], axis=1))
        clip.vector("shaft", "position", keys, np.stack([0 * Lc, Lc / 2, 0 * Lc], axis=1))
        clip.vector("head", "position", keys, np.stack([0 * Lc, Lc + head_h / 2, 0 * Lc], axis=1))
        clips.append(clip)
    return clips


# ------------------------------------------------------------------------------ head-up text

#: The head-up text: glyphs drawn by meshcat's viewer (its `_text` canvas textures, 256 px,
#: black), monospace; one plane per character, HUD_GLYPH_M wide at HUD_DISTANCE_M in front of
#: the camera, so that it keeps its place on screen as the camera moves.
HUD_FONT_PX, HUD_GLYPH_M, HUD_DISTANCE_M = 160, 0.09, 1.0
HUD_ADVANCE_M = 0.6 * HUD_FONT_PX / 256 * HUD_GLYPH_M  # monospace advance ~0.6 em
HUD_LINE_M = 0.06


class _Text:
    def __init__(self, tree: ObjectTree):
        self.tree = tree
        self.plane = tree.add("geometries", {"type": "PlaneGeometry", "width": HUD_GLYPH_M, "height": HUD_GLYPH_M})

    def glyph(self, ch: str, x: float, y: float, name: str = "") -> dict:
        tex = self.tree.add("textures", {"type": "_text", "text": ch, "font_size": HUD_FONT_PX,
                                         "font_face": "monospace"}, key=ch)
        mat = self.tree.add("materials", {"type": "MeshBasicMaterial", "map": tex, "transparent": True,
                                          "depthTest": False, "depthWrite": False}, key=ch)
        return node("Mesh", name or f"g{new_uuid()[:8]}", self.plane, mat,
                    matrix=matrix_of(pin.SE3(np.eye(3), np.array([x, y, 0.0]))), renderOrder=1001, frustumCulled=False)

    def line(self, text: str, x0: float, y: float, name: str, visible=True) -> dict:
        """Glyph i of `text` centred at x0 + (i + 1/2) advances."""
        chars = [self.glyph(c, x0 + (i + 0.5) * HUD_ADVANCE_M, y) for i, c in enumerate(text) if c != " "]
        return node("Group", name, children=chars, visible=visible)

    def box(self, rgb, x: float, y: float, w: float, h: float, opacity=1.0, order=1001) -> dict:
        g = self.tree.add("geometries", {"type": "PlaneGeometry", "width": w, "height": h}, key=("box", w, h))
        m = self.tree.add("materials", {"type": "MeshBasicMaterial", "color": colour(rgb), "transparent": True,
                                        "opacity": opacity, "depthTest": False, "depthWrite": False},
                          key=("box", tuple(rgb), opacity))
        return node("Mesh", f"b{new_uuid()[:8]}", g, m, matrix=matrix_of(pin.SE3(np.eye(3), np.array([x, y, 0.0]))),
                    renderOrder=order, frustumCulled=False)


def phase_labels(summary: dict) -> list[tuple[float, str]]:
    """(start time, label) of each grasp phase, in order."""
    phases = summary["phases"]
    grasps = summary["grasps"]
    if isinstance(phases, dict):
        phases = [phases]
    out = []
    for g, (times, grasp) in enumerate(zip(phases, grasps, strict=True)):
        who = f"{grasp['end_effector']} on {grasp['module']}"
        if len(grasps) > 1:
            who = f"grasp {g + 1}/{len(grasps)} {who}"
        for phase in PHASE_KEYS:
            if times.get(phase) is not None:
                out.append((float(times[phase]), f"{who}: {PHASE_NAMES[phase]}"))
    return sorted(out, key=lambda x: x[0])


def time_digits(t: np.ndarray, n_int: int) -> np.ndarray:
    """(n, n_int + 2) the digits of each time (s) to 0.01 s, -1 for a leading blank."""
    cs = np.round(np.asarray(t) * 100).astype(np.int64)
    digits = np.stack([(cs // 10 ** p) % 10 for p in range(n_int + 1, -1, -1)], axis=1)
    for col in range(n_int - 1):  # leading zeros of the integer part are blank
        blank = (cs < 10 ** (n_int + 1 - col))
        digits[blank, col] = -1
    return digits


def _hud(run, frames, keys, scale, spheres, commands) -> Clip:
    """Time and phase at the top, the run and the legend at the bottom, fixed on screen."""
    tree = ObjectTree()
    text = _Text(tree)
    half_h = HUD_DISTANCE_M * np.tan(np.radians(CAMERA_FOV_DEG) / 2)
    top, bottom = half_h - 0.13, -half_h + 0.05  # below meshcat's "Open Controls" bar
    clip = Clip(HUD)
    labels = phase_labels(run.summary)
    n_int = max(1, len(str(int(frames.t[-1]))))
    # top line: "t = 12.34 s   <phase label>", the time's digits per slot (column)
    time_cols = [4 + s + (s >= n_int) for s in range(n_int + 2)]  # after "t = ", "." skipped
    label_col = 4 + n_int + 3 + 5
    n_cols = label_col + max((len(l) for _, l in labels), default=0)
    x0 = -n_cols * HUD_ADVANCE_M / 2
    col = lambda c: x0 + (c + 0.5) * HUD_ADVANCE_M  # noqa: E731
    children = [text.box((1, 1, 1), 0, top + 0.015, n_cols * HUD_ADVANCE_M + 0.04, HUD_LINE_M, 0.7, 1000),
                text.line("t =", x0, top, "tlabel"),
                text.glyph(".", col(4 + n_int), top), text.glyph("s", col(4 + n_int + 4), top)]
    digits = time_digits(frames.t, n_int)
    for slot, c in enumerate(time_cols):
        for d in range(10):  # ten planes per slot, one shown
            shown = digits[:, slot] == d
            if shown.any():
                name = f"d{slot}_{d}"
                g = text.glyph(str(d), col(c), top, name)
                g["visible"] = bool(shown[0])
                children.append(g)
                clip.visible(name, shown, keys)
    starts = np.array([t for t, _ in labels])
    current = np.searchsorted(starts, frames.t + 1e-9, side="right") - 1
    for k, (_, label) in enumerate(labels):
        shown = current == k
        if shown.any():
            children.append(text.line(label, col(label_col) - HUD_ADVANCE_M / 2, top, f"p{k}",
                                      visible=bool(shown[0])))
            clip.visible(f"p{k}", shown, keys)
    # bottom lines: the run, and the legend with a swatch in the gap before each entry
    s = run.summary
    status = f"{s['scenario']}: {s['status']} at {s['sim_time_s']:.3f} s"
    legend = f"   force {scale * 1e3:g} mm/N" + ("     spheres:   none   slipping   sticking" if spheres else "")
    swatches = [("force", (0.88, 0.0, 0.88), 0.045, 0.01)]
    if spheres:
        swatches += [(w, STATE_COLOURS[st], 0.025, 0.025) for w, st in
                     (("none", NONE), ("slipping", SLIPPING), ("sticking", STICKING))]
    for y, line in ((bottom + HUD_LINE_M, status), (bottom, legend)):
        w = len(line) * HUD_ADVANCE_M
        children.append(text.box((1, 1, 1), 0, y + 0.015, w + 0.04, HUD_LINE_M, 0.7, 1000))
        children.append(text.line(line, -w / 2, y, f"l{len(children)}"))
    w = len(legend) * HUD_ADVANCE_M
    for word, rgb, bw, bh in swatches:
        x = -w / 2 + (legend.index(word) - 1) * HUD_ADVANCE_M
        children.append(text.box(rgb, x, bottom + 0.012, bw, bh))
    commands.append(tree.command(HUD, node("Group", "hud", children=children,
                                           matrix=matrix_of(pin.SE3(np.eye(3), np.array([0, 0, -HUD_DISTANCE_M]))))))
    return clip


# ------------------------------------------------------------------------------ camera


def _three(p_W: np.ndarray) -> list[float]:
    """Meshcat's world (z up) in the axes of three.js (y up), where its camera lives."""
    return [float(p_W[0]), float(p_W[2]), float(-p_W[1])]


def _views(run, state0, oMi0) -> tuple[np.ndarray, dict]:
    """The point the scene is centred on (world), and camera views about it: `scene` (all of
    it) and one close view per end-effector's grasp, in three.js axes of the centred scene."""
    model = run.model
    grasps = [oMi0[e.joint] * e.placement for e in model.end_effectors]
    modules_W = state0[0]
    points = np.array([g.translation for g in grasps] + [M.translation for M in modules_W])
    focus = points.mean(axis=0)
    radius = max(0.15, float(np.linalg.norm(points - focus, axis=1).max()) + 0.15)
    direction, distance = SCENE_VIEWS["free" if model.robot_joint else "fixed"]
    direction = np.array(direction) / np.linalg.norm(direction)
    views = {"scene": {"camera": _three(direction * radius * distance), "target": [0.0, 0.0, 0.0]}}
    for e, (ee, g) in enumerate(zip(model.end_effectors, grasps)):
        # from the side (y_a), a little above: along both grooves' V between the bodies
        d = g.rotation @ np.array([0.0, 1.0, 0.3])
        d /= np.linalg.norm(d)
        target = g.translation - focus
        views[ee.name] = {"camera": _three(target + 0.08 * d), "target": _three(target)}
    return focus, views
