"""Build the virtual sphere layers of a finger flank and a groove flank and print their size.

    python examples/sphere_layers.py

Reads the contact faces from the compiled scene URDF (yourdfpy), generates each face's
layer (paper Eq. 1-5: grid of step r, spheres tangent to the face) and prints, per face,
the sphere count, the grid step measured between neighbours, and the height of the centres
above the face, which must equal the radius.
"""

import numpy as np

from spotsim.assemble.assets import URDF_DIR, compile_xacro
from spotsim.assemble.faces import contact_faces, face_basis, sphere_layer
from spotsim.assemble.scene import geometry_args
from spotsim.scenario import Contact, Geometry


def describe(face, radius: float) -> None:
    layer = sphere_layer(face.vertices_L, radius)
    n, t1, t2 = face_basis(face.vertices_L)
    height = (layer.centres - face.vertices_L[0]) @ n
    along = np.diff(np.unique(((layer.centres - face.vertices_L[0]) @ t1).round(12)))
    across = np.diff(np.unique(((layer.centres - face.vertices_L[0]) @ t2).round(12)))
    corners = face.vertices_L
    size = np.linalg.norm(corners[1] - corners[0]), np.linalg.norm(corners[3] - corners[0])
    print(f"{face.name:30s} {size[0] * 1e3:5.1f} x {size[1] * 1e3:5.2f} mm: {len(layer.centres):5d} spheres "
          f"of r = {radius * 1e3:.1f} mm, spacing {along.mean() * 1e3:.3f} / {across.mean() * 1e3:.3f} mm, "
          f"centres {height.min() * 1e3:.3f}-{height.max() * 1e3:.3f} mm above the face")


def main() -> None:
    contact = Contact()
    urdf = compile_xacro(URDF_DIR / "single_arm_scene.urdf.xacro", geometry_args(Geometry()))
    faces = {f.name: f for f in contact_faces(urdf)}
    describe(faces["ee_finger_upper_flank_pos"], contact.sphere_radius_finger_mm * 1e-3)
    describe(faces["tm_groove_upper_flank_pos"], contact.sphere_radius_groove_mm * 1e-3)


if __name__ == "__main__":
    main()
