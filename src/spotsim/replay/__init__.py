"""`spotsim replay`: a run in Meshcat, live in the browser or as one self-contained HTML file.

The scene is built from the run's own scenario.yaml, unwelded: Pinocchio's MeshcatVisualizer
loads its visual geometry (the arm meshes coarsened, see COARSE_MESH_CELL_M), and each display
frame places every body from the recorded poses (timeseries.npz): the modules, the free-flying
base, the finger openings. A welded module is placed from its own recorded pose, so one model
serves the whole run. From replay.npz come the paper's Fig. 9 on screen: the sphere layers of
the faces in contact range (blue), the spheres of the pairs in contact coloured by state
(slipping red, sticking light blue), and the combined contact force on each module as an
arrow. A head-up line shows the simulated time and the grasp phase.

Everything is one meshcat animation (play, pause, time slider, speed, loop) whose time is the
simulated time. The commands are built once, then either sent to a Meshcat server or written
into meshcat's static page with the animation embedded.
"""

from .page import Server, commands_of_html, packed, static_html, write_html
from .run import Run, display_frames, load_run
from .scene import (
           CAMERA_FOV_DEG,
           STATE_COLOURS,
           ReplayInfo,
           build,
           coarse_mesh,
           phase_labels,
           time_digits,
)

__all__ = ["CAMERA_FOV_DEG", "STATE_COLOURS", "ReplayInfo", "Run", "Server", "build", "coarse_mesh", "commands_of_html",
           "display_frames", "load_run", "packed", "phase_labels", "static_html", "time_digits", "write_html"]
