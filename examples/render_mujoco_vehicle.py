"""Render the MuJoCo vehicle that agvdyn generates (docs/mujoco_vehicle.png), offscreen.

Run: ``MUJOCO_GL=egl .venv/bin/python examples/render_mujoco_vehicle.py [OUT.png]`` (needs an EGL or
OSMesa driver; no window). The prototype with the Table 2 parameters, steered (left 0.35 rad, right
0.22 rad), seen from the front left; the chassis box is drawn translucent so the steering units
(passive hinges at +-l/2, +-b/2) and the wheels (caster offset a outboard) show.
"""
from __future__ import annotations

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mujoco  # noqa: E402

from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE  # noqa: E402
from agvdyn.simulation.mujoco_plant import MujocoVehicle, initial_state  # noqa: E402


def render(out: str = "docs/mujoco_vehicle.png") -> None:
    vehicle = MujocoVehicle.generate(PROTOTYPE, PAPER_PARAMETERS)
    spec = mujoco.MjSpec.from_string(vehicle.xml)
    spec.worldbody.add_light(pos=[0.0, -1.0, 3.0], dir=[0.0, 0.3, -1.0], diffuse=[0.8, 0.8, 0.8])
    spec.worldbody.add_light(pos=[2.0, 2.0, 2.0], dir=[-1.0, -1.0, -1.0], diffuse=[0.4, 0.4, 0.4])
    for geom in spec.geoms:
        if geom.name == "floor":
            geom.rgba = [0.85, 0.85, 0.82, 1.0]
        elif geom.name == "chassis_box":
            geom.rgba = [0.2, 0.45, 0.8, 0.35]
        elif geom.name.startswith(("contact_", "wheel")):
            geom.rgba = [0.15, 0.15, 0.15, 1.0] if geom.rgba[3] > 0 else geom.rgba
    spec.visual.global_.offwidth, spec.visual.global_.offheight = 720, 480
    model = spec.compile()
    data = mujoco.MjData(model)
    initial_state(model, data, [0.35, 0.22])  # steered: left 0.35 rad, right 0.22 rad
    camera = mujoco.MjvCamera()
    camera.lookat[:] = [0.0, 0.0, 0.1]
    camera.distance, camera.azimuth, camera.elevation = 2.6, 215.0, -28.0
    renderer = mujoco.Renderer(model, 480, 720)
    renderer.update_scene(data, camera)
    image = renderer.render()
    fig, ax = plt.subplots(figsize=(7.2, 4.8), dpi=100)
    ax.imshow(image)
    ax.set_axis_off()
    ax.set_title("agvdyn's MuJoCo vehicle: prototype, Table 2 parameters, steering 0.35 / 0.22 rad", fontsize=10)
    fig.tight_layout()
    fig.savefig(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    render(*sys.argv[1:2])
