"""`spotsim replay`: what the recorder keeps, the animation it builds, a real headless browser
showing it, and a live Meshcat server receiving it."""

import base64
import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from conftest import CASE_I, ROOT

import spotsim
from spotsim.cli import main
from spotsim.contact.friction import SLIPPING, STICKING
from spotsim.replay.scene import ARROW_LENGTH_M

DUAL = ROOT / "config" / "dual_arm_sequential.yaml"
#: Case I touches at 0.43 s, has sticking pairs from 0.51 s and completes at 0.96 s: 0.9 s
#: holds the approach and self-centring with pairs in both states.
SINGLE_S = 0.9
#: The dual-arm run welds TM-1 at 2.32 s and EE-2 touches TM-2 at 2.89 s: 3.2 s holds both.
DUAL_S = 3.2
RATE_HZ = 100.0
#: The animation stores float32: key times and positions agree to its round-off.
F32 = 1e-6
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"


# ------------------------------------------------------------------------------ helpers


def run_to(config, duration, out):
    code = main(["run", str(config), "--out", str(out), "--quiet", "--no-figures",
                 "--set", f"simulation.duration_s={duration}"])
    assert code in (0, 3)
    return out


def decode_blobs(blobs):
    import umsgpack

    return [umsgpack.unpackb(base64.b64decode(b)) for b in blobs]


def html_commands(text):
    m = re.search(r'<script type="application/json" id="spotsim-commands">(.*?)</script>', text, re.S)
    return decode_blobs(json.loads(m.group(1)))


def f32(x):
    return np.frombuffer(x.data, dtype=np.float32) if hasattr(x, "data") else np.asarray(x, dtype=float)


def objects(cmds):
    return {c["path"]: c["object"] for c in cmds if c["type"] == "set_object"}


def animation(cmds):
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    return anim


def tracks(anim, path):
    """{track name: (times in frames, values)} of the clip animating `path`."""
    (clip,) = [a["clip"] for a in anim["animations"] if a["path"] == path]
    return {t["name"]: (f32(t["times"]), t["values"] if t["type"] == "boolean" else f32(t["values"]))
            for t in clip["tracks"]}


def at(track, key, size=1):
    """A track's value at key time `key` (frames): discrete, the last key at or before it."""
    times, values = track
    i = np.searchsorted(times, key + 1e-6, side="right") - 1
    return values[i] if size == 1 else np.asarray(values[i * size:(i + 1) * size])


def children(obj):
    return {c["name"]: c for c in obj["object"].get("children", [])}


def geometry(obj, child, attribute):
    (g,) = [g for g in obj["geometries"] if g["uuid"] == child["geometry"]]
    a = g["data"]["attributes"][attribute]
    dtype = {"Float32Array": np.float32, "Uint8Array": np.uint8}[a["type"]]
    return np.frombuffer(a["array"].data, dtype=dtype).reshape(-1, a["itemSize"])


# ------------------------------------------------------------------------------ fixtures


def replayed(d, config, seconds):
    """A run of `config` for `seconds` in d/run, its replay page and the commands it embeds."""
    run_to(config, seconds, d / "run")
    page = d / "replay.html"
    assert main(["replay", str(d / "run"), "--html", str(page)]) == 0
    return d / "run", page, html_commands(page.read_text())


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    """A short Case I run, its replay page and the commands the page embeds."""
    return replayed(tmp_path_factory.mktemp("single"), CASE_I, SINGLE_S)


@pytest.fixture(scope="module")
def dual(tmp_path_factory):
    """A dual-arm run through the weld into the second grasp, its page and its commands."""
    return replayed(tmp_path_factory.mktemp("dual"), DUAL, DUAL_S)


@pytest.fixture(scope="module")
def meshcat_server():
    """A Meshcat server on localhost, stopped after the module."""
    proc = subprocess.Popen([sys.executable, "-u", "-m", "meshcat.servers.zmqserver"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        zmq_url = proc.stdout.readline().strip().removeprefix("zmq_url=")
        assert zmq_url.startswith("tcp://127.0.0.1:"), zmq_url
        yield zmq_url
    finally:
        proc.kill()
        proc.wait()


def server_commands(zmq_url):
    """The scene the server would send a browser connecting now (its static page's commands)."""
    from spotsim import replay

    server = replay.Server(zmq_url)
    try:
        page = server.scene_html()
    finally:
        server.close()
    return decode_blobs(re.findall(r"octet-binary;base64,([A-Za-z0-9+/=]+)", page))


# ------------------------------------------------------------------------------ the recorder


def test_welded_model_spheres_map_to_the_same_first_model_spheres():
    """After a weld, each remaining sphere keeps its place: mapped by face name to the first
    model, it has the same centre in its body's frame (a finger's link, whether on its joint or
    locked; a module's joint), and a module's the same joint."""
    from spotsim.assemble.model import build_model
    from spotsim.replay.scene import _in_body_frames
    from spotsim.sim.recorder import SphereIds

    s = spotsim.load_scenario(DUAL)
    first = build_model(s)
    welded = build_model(s, welded={0: ((0.0, 0.001, 0.0), (0.0, 0.0, 0.0))})
    ids = SphereIds(welded, first)
    assert len(welded.master.centre_J) < len(first.master.centre_J)
    # EE-2's fingers: locked on the robot in the first model, on their joints after the weld
    centres, f_centres = _in_body_frames(welded)[0], _in_body_frames(first)[0]
    np.testing.assert_allclose(f_centres[ids.master], centres, rtol=0, atol=1e-15)
    assert np.array_equal(first.slave.centre_J[ids.slave], welded.slave.centre_J)
    assert np.array_equal(first.slave.normal_J[ids.slave], welded.slave.normal_J)
    names = [first.pin_model.names[int(j)] for j in first.slave.joint[ids.slave]]
    assert names == [welded.pin_model.names[int(j)] for j in welded.slave.joint]


def test_recorder_keeps_contact_snapshots_at_the_replay_rate(single):
    """replay.npz holds one snapshot per 10 ms; its pairs are those the timeseries counts."""
    run_dir, _, _ = single
    snaps = np.load(run_dir / "replay.npz")
    ts = np.load(run_dir / "timeseries.npz")
    assert float(snaps["rate_hz"]) == RATE_HZ
    assert np.array_equal(snaps["row"], np.arange(0, len(ts["t"]), 10))
    counts = np.diff(np.r_[0, snaps["pairs_end"]])
    state = snaps["state"]
    ends = snaps["pairs_end"]
    for s, row in enumerate(snaps["row"]):
        st = state[(ends[s - 1] if s else 0):ends[s]]
        assert (st == SLIPPING).sum() == ts["pairs_slipping"][row]
        assert (st == STICKING).sum() == ts["pairs_sticking"][row]
    assert counts.sum() > 0 and snaps["faces_in_range"][counts > 0].any(axis=1).all()


# ------------------------------------------------------------------------------ the static page


def test_html_page_is_self_contained_and_covers_the_run(single, capsys):
    """The page loads nothing from a network and its animation holds one frame per 10 ms over
    the run, from 0 to the run's last sample."""
    run_dir, page, cmds = single
    text = page.read_text()
    assert not re.search(r"""<(script|link|img)[^>]+(src|href)=["']?(https?:)?//""", text)
    assert "http://" not in text.split("<script>", 1)[0]
    anim = animation(cmds)
    keys = np.unique(np.concatenate([f32(t["times"]) for a in anim["animations"] for t in a["clip"]["tracks"]]))
    fps = {a["clip"]["fps"] for a in anim["animations"]}
    assert fps == {RATE_HZ}
    summary = json.loads((run_dir / "summary.json").read_text())
    assert len(keys) == round(SINGLE_S * RATE_HZ) + 1
    assert keys[0] == 0 and abs(keys[-1] / RATE_HZ - summary["sim_time_s"]) < F32
    # visual tracks run over every frame
    module = tracks(anim, "/meshcat/spotsim/visuals/tm_module_1")
    assert len(module[".position"][0]) == len(keys)
    assert cmds[-1]["type"] == "set_animation"  # after every object it binds to


def check_sphere_colours(run_dir, cmds, frame_t):
    """At the display frame nearest frame_t, the coloured spheres on every finger and module are
    exactly the spheres of the recorded pairs (first-model centres, in the finger link's or the
    module joint's frame), coloured by state, and the layers shown are those of the faces
    recorded in contact range."""
    from spotsim import replay
    from spotsim.replay.scene import _body_of_faces, _in_body_frames

    run = replay.load_run(run_dir)
    snaps = run.snapshots
    frame = int(round(frame_t * RATE_HZ))
    s = int(np.searchsorted(snaps["row"], frame * 10, side="right") - 1)
    lo, hi = (snaps["pairs_end"][s - 1] if s else 0), snaps["pairs_end"][s]
    anim, objs = animation(cmds), objects(cmds)
    model = run.model
    n_mf = len(snaps["master_faces"])
    seen = 0
    master_B, _ = _in_body_frames(model)
    bodies = [(name, model.master, master_B, snaps["master"][lo:hi], np.isin(model.master.face, faces))
              for name, kind, _, faces, _ in _body_of_faces(model)[0] if kind == "finger"]
    bodies += [(m.name, model.slave, model.slave.centre_J, snaps["slave"][lo:hi], model.slave.joint == m.joint)
               for m in model.modules]
    for name, layers, centres_B, idx, on_body in bodies:
        path = f"/meshcat/spotsim/contact/{name}"
        tr, kids = tracks(anim, path), children(objs[path])
        shown = {n[:-len(".visible")] for n, t in tr.items() if n.endswith(".visible") and at(t, frame)}
        # the layers of the faces in contact range
        faces = {int(n[1:]) for n in shown if n.startswith("f")}
        expected_faces = {f for f in np.flatnonzero(snaps["faces_in_range"][s])
                          if np.any(on_body[layers.face == (f if f < n_mf else f - n_mf)])
                          and (f < n_mf) == (layers is model.master)}
        assert faces == expected_faces, name
        # the pairs' spheres, by state
        clouds = [n for n in shown if n.startswith("s")]
        mine = on_body[idx]
        st = snaps["state"][lo:hi][mine]
        expected = {}
        for i, x in zip(idx[mine], st):
            expected[int(i)] = min(expected.get(int(i), 99), int(x))  # slipping shows over sticking
        if not expected:
            assert not clouds, name
            continue
        (cloud,) = clouds
        pos = geometry(objs[path], kids[cloud], "position")
        col = geometry(objs[path], kids[cloud], "color") / 255.0
        centres = centres_B[sorted(expected)].astype(np.float32)  # as drawn: both sorted alike
        order = np.lexsort(pos.T[::-1])
        assert np.allclose(pos[order], centres[np.lexsort(centres.T[::-1])], atol=F32)
        by_pos = {tuple(np.round(p, 6)): c for p, c in zip(pos, col)}
        for i, x in expected.items():
            c = by_pos[tuple(np.round(centres_B[i].astype(np.float32), 6))]
            assert np.allclose(c, replay.STATE_COLOURS[x], atol=1 / 255), (name, i, x)
        seen += len(expected)
    return seen


def test_sphere_colours_match_the_recorded_pair_states(single):
    """At the frame with most pairs in contact, the coloured spheres are the recorded ones."""
    run_dir, _, cmds = single
    ts = np.load(run_dir / "timeseries.npz")
    pairs = (ts["pairs_slipping"] + ts["pairs_sticking"])[::10]
    t = float(np.argmax(pairs)) / RATE_HZ
    assert check_sphere_colours(run_dir, cmds, t) > 0
    assert check_sphere_colours(run_dir, cmds, 0.2) == 0  # approach: nothing coloured


def test_replay_spans_the_weld_and_maps_the_second_grasp_spheres(dual):
    """Across the weld, TM-1 follows its recorded pose and its faces leave contact range; in
    the second grasp the coloured spheres of EE-2 and TM-2 are the recorded ones."""
    run_dir, _, cmds = dual
    ts = np.load(run_dir / "timeseries.npz")
    summary = json.loads((run_dir / "summary.json").read_text())
    (weld,) = summary["welds_s"]
    anim = animation(cmds)
    tm1 = tracks(anim, "/meshcat/spotsim/contact/TM-1")
    keys, pos = tm1[".position"]
    rows = np.round(keys * 10).astype(int)
    assert np.allclose(pos.reshape(-1, 3), ts["TM-1_pos_m"][rows], atol=F32)
    after = keys / RATE_HZ > weld + 0.01
    shown = [n for n, t in tm1.items() if n.endswith(".visible") and n.startswith("f")]
    assert shown and not any(at(tm1[n], k) for n in shown for k in keys[after])
    pairs = (ts["pairs_slipping"] + ts["pairs_sticking"])[::10]
    late = np.arange(len(pairs)) / RATE_HZ > weld + 0.01
    assert pairs[late].max() > 0
    t = float(np.flatnonzero(late)[np.argmax(pairs[late])]) / RATE_HZ
    assert check_sphere_colours(run_dir, cmds, t) > 0


#: The relative round-off of an arrow's length per newton times a load (two float products).
SCALE_ROUND_OFF = 1e-12


def test_force_arrow_shows_the_recorded_combined_force(single):
    """The module's arrow is shown only under load, along the recorded force, scaled per newton."""
    run_dir, _, cmds = single
    snaps = np.load(run_dir / "replay.npz")
    tr = tracks(animation(cmds), "/meshcat/spotsim/forces/TM")
    scale = None
    for s, row in enumerate(snaps["row"]):
        F = snaps["force_W"][s, 0]
        key = row / 10
        assert bool(at(tr["arrow.visible"], key)) == bool(np.linalg.norm(F) > 0)
        if np.linalg.norm(F) > 1.0:
            length = at(tr["shaft.scale"], key, 3)[1]
            scale = scale or length / np.linalg.norm(F)
            assert abs(length - scale * np.linalg.norm(F)) < 1e-6 + 1e-5 * length
            q = at(tr[".quaternion"], key, 4)
            y = pin.Quaternion(*map(float, (q[3], q[0], q[1], q[2]))).matrix()[:, 1]
            assert np.allclose(y, F / np.linalg.norm(F), atol=1e-5)
    loads = np.linalg.norm(snaps["force_W"], axis=2).ravel()
    typical = np.percentile(loads[loads > 0], 95)
    # rounded down to 1, 2 or 5 times a power of ten: at most 2.5 times shorter (5 -> 2), never
    # longer but for the product's round-off (SCALE_ROUND_OFF)
    assert ARROW_LENGTH_M / 2.5 < scale * typical <= ARROW_LENGTH_M * (1 + SCALE_ROUND_OFF)


def test_head_up_line_shows_the_time_and_the_phase(single):
    """At each frame one digit plane per slot is shown, spelling the time, and the phase label
    shown is the recorded phase."""
    run_dir, _, cmds = single
    anim, objs = animation(cmds), objects(cmds)
    hud_path = "/Cameras/default/rotated/<object>/spotsim_hud"
    tr = tracks(anim, hud_path)
    ts = np.load(run_dir / "timeseries.npz")
    onset = json.loads((run_dir / "summary.json").read_text())["phases"]["self_centring"]
    labels = {n: c for n, c in children(objs[hud_path]).items() if n.startswith("p")}
    texts = {}
    for n, c in labels.items():  # each glyph's texture holds its character
        mats = {m["uuid"]: m for m in objs[hud_path]["materials"]}
        texs = {t["uuid"]: t["text"] for t in objs[hud_path]["textures"]}
        texts[n] = "".join(texs[mats[g["material"]]["map"]] for g in c["children"])
    for key in (0, 20, 43, 50, 60):
        digits = sorted((int(n[1]), n[3]) for n, t in tr.items() if n.startswith("d") and at(t, key))
        t = ts["t"][key * 10]
        assert "".join(d for _, d in digits) == f"{t:.2f}".replace(".", ""), key
        (label,) = [texts[n[:-len(".visible")]] for n, tk in tr.items() if n.startswith("p") and at(tk, key)]
        assert label.endswith("centring" if t >= onset else "approach"), (key, label)


# ------------------------------------------------------------------------------ a real browser


def screenshot(page, query, out):
    """Chromium, headless with software WebGL (SwiftShader), renders the page at 800x600."""
    if not shutil.which(CHROMIUM):
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run installs it)")
    profile = out.parent / f"profile-{out.stem}"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--use-angle=swiftshader", "--enable-unsafe-swiftshader", f"--user-data-dir={profile}",
           f"--screenshot={out}", "--window-size=800,600", "--virtual-time-budget=5000",
           f"{page.as_uri()}?{query}"]
    subprocess.run(cmd, capture_output=True, timeout=120)
    from PIL import Image

    return np.asarray(Image.open(out).convert("RGB")).astype(int)


def projected(view, p, size=(800, 600)):
    """Pixel (column, row) of point p (three.js axes) for a camera at view['camera'] looking at
    view['target'], y up, with meshcat's 75 deg vertical field of view."""
    from spotsim.replay import CAMERA_FOV_DEG

    c, t = np.array(view["camera"]), np.array(view["target"])
    back = (c - t) / np.linalg.norm(c - t)
    right = np.cross([0.0, 1.0, 0.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    d = np.asarray(p) - c
    x, y, z = d @ right, d @ up, -(d @ back)
    f = 1 / np.tan(np.radians(CAMERA_FOV_DEG) / 2)
    w, h = size
    return int(round((1 + f * x / z * h / w) * w / 2)), int(round((1 - f * y / z) * h / 2))


GOLD = lambda a: (a[..., 0] > 150) & (a[..., 0] - a[..., 2] > 80) & (a[..., 1] > 90)  # noqa: E731
RED = lambda a: (a[..., 0] > 150) & (a[..., 0] - a[..., 1] > 80) & (a[..., 0] - a[..., 2] > 80)  # noqa: E731
#: Light blue (140, 217, 255), also as seen through a plate or a finger (G - R >= 50), but not
#: the see-through blue fingers (G - R ~ 30) nor the idle blue spheres (R < 90).
LIGHT_BLUE = lambda a: (a[..., 2] - a[..., 0] > 60) & (a[..., 1] - a[..., 0] > 45) & (a[..., 0] > 90)  # noqa: E731
#: Rows of an 800x600 screenshot between the head-up lines at the top and the bottom.
SCENE_ROWS = slice(70, 530)


def visual_pixel(page, cmds, view, name, key):
    """Where the view's camera sees the centre of visual `name` at key time `key` (frames)."""
    views = json.loads(re.search(r'id="spotsim-views">(.*?)</script>', page.read_text(), re.S).group(1))
    body = tracks(animation(cmds), f"/meshcat/spotsim/visuals/{name}")
    shift = np.array([c["matrix"][12:15] for c in cmds if c["type"] == "set_transform"
                      and c["path"] == "/meshcat/spotsim"][0])
    p = at(body[".position"], key, 3) + shift
    return projected(views[view], [p[0], p[2], -p[1]])


def contact_view_shows(page, run_dir, ee, tmp_path, grasp=0):
    """Screenshots of an end-effector's close view: none before contact, and one at the frame
    of its grasp with most pairs of each state, which must show that state's colour."""
    ts = np.load(run_dir / "timeseries.npz")
    mine = ts["grasp"][::10] == grasp  # the pairs of other grasps are other end-effectors'
    before = screenshot(page, f"t=0.2&view={ee}", tmp_path / f"{ee}-before.png")[SCENE_ROWS]
    assert RED(before).sum() == 0 and LIGHT_BLUE(before).sum() == 0
    for state, key, colour in ((SLIPPING, "pairs_slipping", RED), (STICKING, "pairs_sticking", LIGHT_BLUE)):
        counts = np.where(mine, ts[key][::10], 0)
        assert counts.max() > 0, key
        t = float(np.argmax(counts)) / RATE_HZ
        img = screenshot(page, f"t={t}&view={ee}", tmp_path / f"{ee}-{state}.png")[SCENE_ROWS]
        assert colour(img).sum() >= 3, (state, t)


def test_static_page_renders_the_scene_in_headless_chromium(single, tmp_path):
    """In a real browser the page draws the module where the camera sees it, and the contact
    view shows red and light blue spheres exactly when the run recorded such pairs."""
    run_dir, page, cmds = single
    img = screenshot(page, "t=0.5&view=scene", tmp_path / "scene.png")
    assert img.shape == (600, 800, 3) and img.std() > 10
    col, row = visual_pixel(page, cmds, "scene", "tm_module_1", 50)
    assert GOLD(img[row - 6:row + 7, col - 6:col + 7]).mean() > 0.8, (col, row)
    assert GOLD(img).mean() < 0.5
    contact_view_shows(page, run_dir, "EE", tmp_path)


def test_dual_arm_page_renders_both_modules_and_the_first_grasp(dual, tmp_path):
    """The dual-arm page draws both modules where the camera sees them in the second grasp, and
    EE-1's contact view shows the first grasp's pair states."""
    run_dir, page, cmds = dual
    img = screenshot(page, "t=3.0&view=scene", tmp_path / "scene.png")
    for module in ("tm1_module_1", "tm2_module_1"):
        col, row = visual_pixel(page, cmds, "scene", module, 300)
        assert GOLD(img[row - 4:row + 5, col - 4:col + 5]).mean() > 0.8, (module, col, row)
    contact_view_shows(page, run_dir, "EE-1", tmp_path)


# ------------------------------------------------------------------------------ a live server


def test_replay_sets_the_scene_on_a_meshcat_server(single, meshcat_server, capsys):
    """Against a local server, replay sets every visual, each finger's and module's contact
    body, the force arrow and the head-up line, then the animation, last."""
    run_dir, _, _ = single
    assert main(["replay", str(run_dir), "--zmq-url", meshcat_server]) == 0
    assert "replaying" in capsys.readouterr().out
    cmds = server_commands(meshcat_server)
    paths = set(objects(cmds))
    for name in ("visuals/tm_module_0", "visuals/tm_module_1", "visuals/ee_finger_upper_0", "visuals/link06_0",
                 "contact/ee_finger_upper", "contact/ee_finger_lower", "contact/TM", "forces/TM"):
        assert f"/meshcat/spotsim/{name}" in paths, name
    assert "/Cameras/default/rotated/<object>/spotsim_hud" in paths
    assert cmds[-1]["type"] == "set_animation"
    animated = {a["path"] for a in cmds[-1]["animations"]}
    assert animated <= paths


def test_run_with_replay_sends_the_new_run_to_the_server(meshcat_server, tmp_path):
    """`spotsim run --replay` replays the run it just made: the server's animation spans it."""
    code = main(["run", str(CASE_I), "--out", str(tmp_path / "r"), "--quiet", "--no-figures",
                 "--set", "simulation.duration_s=0.25", "--replay", "--zmq-url", meshcat_server])
    assert code == 3  # 0.25 s: incomplete, as a run without --replay
    anim = animation(server_commands(meshcat_server))
    end = max(f32(t["times"]).max() for a in anim["animations"] for t in a["clip"]["tracks"])
    assert abs(end / RATE_HZ - 0.25) < F32


# ------------------------------------------------------------------------------ bad input


def test_a_bad_results_directory_is_a_clear_error(tmp_path, capsys):
    """A directory without results gives one clear line and exit 2."""
    assert main(["replay", str(tmp_path), "--html", str(tmp_path / "x.html")]) == 2
    assert "not a spotsim results directory" in capsys.readouterr().err
    assert not (tmp_path / "x.html").exists()


def test_missing_meshcat_is_a_clear_error(single, monkeypatch, capsys):
    """Without meshcat, replay and run --replay exit 2 with an install hint, before any run."""
    run_dir, _, _ = single
    monkeypatch.setitem(sys.modules, "meshcat", None)
    assert main(["replay", str(run_dir), "--html", str(run_dir / "x.html")]) == 2
    assert "pip install meshcat" in capsys.readouterr().err
    assert main(["run", str(CASE_I), "--out", str(run_dir / "never"), "--replay"]) == 2
    assert "pip install meshcat" in capsys.readouterr().err and not (run_dir / "never").exists()


def test_no_server_at_the_url_and_a_bad_rate_are_clear_errors(single, monkeypatch, capsys):
    """An unanswered --zmq-url and a display rate above the recorded one exit 2."""
    import spotsim.replay.page as page

    run_dir, _, _ = single
    monkeypatch.setattr(page, "ZMQ_TIMEOUT_S", 0.3)
    assert main(["replay", str(run_dir), "--zmq-url", "tcp://127.0.0.1:5"]) == 2
    assert "no Meshcat server answers at tcp://127.0.0.1:5" in capsys.readouterr().err
    assert main(["replay", str(run_dir), "--rate", "500", "--html", str(run_dir / "x.html")]) == 2
    assert "--rate 500: must be in (0, 100] Hz" in capsys.readouterr().err


def test_coarse_mesh_keeps_the_shape_within_one_cell():
    """Vertex clustering of a finely meshed sphere keeps far fewer triangles, every vertex
    within one cell of the original surface."""
    from spotsim.replay import coarse_mesh

    u, v = np.meshgrid(np.linspace(0, np.pi, 60), np.linspace(0, 2 * np.pi, 120), indexing="ij")
    pts = 0.05 * np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], axis=-1).reshape(-1, 3)
    idx = np.arange(60 * 120).reshape(60, 120)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    cell = 0.006
    V, T = coarse_mesh(pts, tris, cell)
    assert 50 < len(T) < len(tris) / 4
    assert np.all(np.abs(np.linalg.norm(V, axis=1) - 0.05) < cell)
