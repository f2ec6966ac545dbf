"""Offscreen rendering of the arm environments with MuJoCo's renderer (CPU MuJoCo, no MJX).

    from envs import render
    env = envs.make("ur5e-reach-avoid")
    state = env.reset(jax.random.PRNGKey(0))
    image = render.render_state(env, state)                         # (H, W, 3) uint8
    frames = render.rollout_frames(env, evaluation.rollout(...))     # eval.py --video
    render.write_video("out.mp4", frames, fps=25)

The env's MJX state supplies joint positions, target and obstacles; a CPU `MjModel` copy of the
robot (obstacle radius and target size set from the env config, a sphere per extra obstacle and a
backdrop added) and a CPU
`MjData` turn them into images: `mj_forward` puts the bodies, `mujoco.Renderer` draws them.

Headless OpenGL: MuJoCo picks its GL backend from MUJOCO_GL when `mujoco` is first imported (GLFW,
which needs a display, if unset). Without a display and without MUJOCO_GL, `ensure_headless_gl`
switches the renderer to OSMesa if libOSMesa is installed, else to EGL (`envs` imports mujoco
first, so this usually means handing the renderer a headless context class). On Debian/Ubuntu CPU
machines: `apt-get install -y libosmesa6` (or `libegl1 libegl-mesa0 libgl1-mesa-dri` for EGL);
GPU machines use the driver's EGL. Videos need the `viz` extra (imageio, imageio-ffmpeg).
"""

from __future__ import annotations

import ctypes.util
import os
import sys

import numpy as np

TARGET_MARKER_RADIUS = 0.04
"""Radius the target is drawn with (m): the 1-2 cm targets are hard to see (the paper's figure
enlarges them to 5 cm "for clarity"); the collision logic never reads it."""


def _headless_backend() -> str:
    if ctypes.util.find_library("OSMesa"):
        return "osmesa"
    return "egl"


def ensure_headless_gl() -> str:
    """Makes `mujoco.Renderer` work without a display; returns the backend in use."""
    chosen = os.environ.get("MUJOCO_GL", "").lower()
    if chosen:
        return chosen
    if sys.platform != "linux" or os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "glfw"
    backend = _headless_backend()
    if "mujoco" not in sys.modules:
        os.environ["MUJOCO_GL"] = backend  # read by mujoco at import
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
        return backend
    # mujoco was imported already (with GLFW): hand the renderer a headless context class instead.
    from mujoco.rendering.classic import gl_context

    if getattr(gl_context, "_MUJOCO_GL", "") in ("", "glfw", "enable", "enabled", "on", "true", "1"):
        if backend == "osmesa":
            from mujoco.osmesa import GLContext
        else:
            from mujoco.egl import GLContext
        gl_context.GLContext = GLContext
        os.environ["MUJOCO_GL"] = backend
    return backend


ensure_headless_gl()

import mujoco  # noqa: E402


def render_model(env, target_marker: float | None = TARGET_MARKER_RADIUS, workspace_alpha: float = 0.0):
    """A CPU MjModel of `env`'s robot for drawing: obstacle radius from the config, target marker
    radius `target_marker` (None: the real target radius), a grey backdrop and floor grid. With
    `workspace_alpha` > 0 the full workspace (ball of the robot's reach) is drawn translucent."""
    robot, cfg = env.robot, env.config
    spec = mujoco.MjSpec.from_file(str(_xml_path(robot)))
    if getattr(robot, "gravity_compensation", False):
        for body in spec.bodies:
            if not body.mocap:
                body.gravcomp = 1.0
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.6, 0.6, 0.6]
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.93, 0.94, 0.96], rgb2=[0.62, 0.66, 0.72], width=256, height=256)
    tex = spec.add_texture(name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                           rgb1=[0.82, 0.84, 0.86], rgb2=[0.74, 0.76, 0.78], width=256, height=256)
    mat = spec.add_material(name="grid", texrepeat=[8, 8])
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
    # Visual only (group 0, no contact): a floor under the reachable space, below the base plane.
    floor_z = float(robot.workspace_center[2]) - robot.reach - 0.02
    spec.worldbody.add_geom(name="viz_floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.05], pos=[0, 0, floor_z],
                            material="grid", contype=0, conaffinity=0, group=0)
    if workspace_alpha > 0:
        ws = spec.add_material(name="viz_workspace", emission=0.3, specular=0.0)
        spec.worldbody.add_geom(name="viz_workspace", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[robot.reach, 0, 0],
                                pos=list(np.asarray(robot.workspace_center, float)), material=ws.name,
                                rgba=[0.5, 0.52, 0.55, workspace_alpha], contype=0, conaffinity=0, group=0)
    # Visual copies of the obstacle for num_obstacles > 1 (`Scene.draw` places and sizes them).
    obstacle = spec.geom("obstacle")
    for j in range(1, getattr(cfg, "num_obstacles", 1)):
        body = spec.worldbody.add_body(name=f"viz_obstacle{j}", mocap=True, pos=[0.5, 0, -5])
        body.add_geom(name=f"viz_obstacle{j}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=list(obstacle.size),
                      rgba=list(obstacle.rgba), group=obstacle.group, contype=0, conaffinity=0)
    model = spec.compile()
    if hasattr(cfg, "radius_bounds"):
        for geom in obstacle_geoms(model, cfg.num_obstacles):
            model.geom_size[geom, 0] = cfg.radius_bounds[1]
            model.geom_rbound[geom] = cfg.radius_bounds[1]  # culling: the largest radius an episode draws
    marker = cfg.target_radius if target_marker is None else max(target_marker, cfg.target_radius)
    model.geom_size[model.geom("target").id, 0] = marker
    return model


def obstacle_geoms(model, num_obstacles: int) -> list[int]:
    """Geom ids of the obstacles in a `render_model`: the MJCF's and its visual copies."""
    return [model.geom("obstacle").id] + [model.geom(f"viz_obstacle{j}").id for j in range(1, num_obstacles)]


def _xml_path(robot):
    from envs.robots.base import ASSETS

    return ASSETS / robot.xml_file


class Scene:
    """A renderer for one env: `draw(qpos, target, obstacle, obstacle_radius)` -> (H, W, 3) uint8."""

    def __init__(self, env, width: int = 480, height: int = 360, workspace_alpha: float = 0.0,
                 target_marker: float | None = TARGET_MARKER_RADIUS, distance: float | None = None,
                 azimuth: float = 135.0, elevation: float = -20.0):
        env = env.unwrapped
        if not hasattr(env, "robot"):
            raise ValueError(f"rendering needs an arm environment; {type(env).__name__} has no robot model.")
        self.env = env
        self.model = render_model(env, target_marker, workspace_alpha)
        self.model.vis.global_.offwidth = max(self.model.vis.global_.offwidth, width)
        self.model.vis.global_.offheight = max(self.model.vis.global_.offheight, height)
        self.data = mujoco.MjData(self.model)
        try:
            self.renderer = mujoco.Renderer(self.model, height, width)
        except Exception as error:  # GL libraries missing: the message names the fix
            raise RuntimeError(
                f"offscreen OpenGL ({os.environ.get('MUJOCO_GL', 'glfw')}) failed: {type(error).__name__}: {error}. "
                "Headless Linux needs OSMesa (apt-get install -y libosmesa6) or EGL (apt-get install -y libegl1 "
                "libegl-mesa0 libgl1-mesa-dri); MUJOCO_GL=osmesa|egl picks one.") from error
        self.camera = mujoco.MjvCamera()
        self.camera.lookat[:] = np.asarray(env.robot.workspace_center, float)
        self.camera.distance = distance or 2.6 * env.robot.reach
        self.camera.azimuth, self.camera.elevation = azimuth, elevation
        self.option = mujoco.MjvOption()
        self.option.geomgroup[:] = [1, 1, 1, 0, 0, 0]
        self._target_mocap = env.robot.target_mocap
        self._obstacle_geoms = obstacle_geoms(self.model, getattr(env.config, "num_obstacles", 1))

    def draw(self, qpos, target=None, obstacle=None, obstacle_radius=None) -> np.ndarray:
        """`obstacle`: the obstacles' centres, flat (`info["obstacle_pos"]`); `obstacle_radius`: their
        radii where they are drawn per episode (`info["obstacle_radius"]`), else the config's."""
        d = self.data
        d.qpos[:] = np.asarray(qpos, float)
        if target is not None:
            d.mocap_pos[self._target_mocap] = np.asarray(target, float)
        if obstacle is not None:
            for geom, center in zip(self._obstacle_geoms, np.reshape(np.asarray(obstacle, float), (-1, 3))):
                d.mocap_pos[self.model.body_mocapid[self.model.geom_bodyid[geom]]] = center
        if obstacle_radius is not None:
            self.model.geom_size[self._obstacle_geoms, 0] = np.asarray(obstacle_radius, float)
        mujoco.mj_kinematics(self.model, d)
        self.renderer.update_scene(d, self.camera, self.option)
        return self.renderer.render().copy()

    def close(self) -> None:
        self.renderer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def render_state(env, state, index: int | None = None, **scene_options) -> np.ndarray:
    """An image of an env `State` (unbatched, or batched with `index`)."""
    pick = (lambda x: np.asarray(x)) if index is None else (lambda x: np.asarray(x)[index])
    qpos = pick(state.pipeline_state.qpos)
    target = pick(state.info["target_pos"])
    obstacle = pick(state.info["obstacle_pos"]) if "obstacle_pos" in state.info else None
    radius = pick(state.info["obstacle_radius"]) if "obstacle_radius" in state.info else None
    with Scene(env, **scene_options) as scene:
        return scene.draw(qpos, target, obstacle, radius)


def rollout_frames(env, records: dict, width: int = 480, height: int = 360, hold: int = 10, **scene_options) -> np.ndarray:
    """Frames (T, H, W, 3) of `agents.evaluation.rollout` records: each env's first episode as one
    tile of a grid; an env whose episode ended early keeps its last pose, tinted red after a
    collision; every episode is held `hold` frames at the end."""
    qpos, target = records["qpos"], records["target_pos"]
    obstacle, radius = records.get("obstacle_pos"), records.get("obstacle_radius")
    lengths = records["length"]
    metrics = records.get("metrics", {})
    collided = np.zeros(len(lengths), bool)
    for key in ("episode/self_collision", "episode/obstacle_collision"):
        if key in metrics:
            collided |= np.asarray(metrics[key]) > 0
    steps = int(lengths.max()) + 1 + hold
    n = qpos.shape[1]
    cols = int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / cols))
    frames = np.zeros((steps, rows * height, cols * width, 3), np.uint8)
    with Scene(env, width, height, **scene_options) as scene:
        for i in range(n):
            r, c = divmod(i, cols)
            for t in range(steps):
                k = min(t, int(lengths[i]))  # records[0]: reset state; records[k]: after step k
                image = scene.draw(qpos[k, i], target[0, i], None if obstacle is None else obstacle[k, i],  # moving
                                   None if radius is None else radius[0, i])
                if collided[i] and t >= lengths[i]:
                    image = (0.6 * image + 0.4 * np.array([255, 0, 0])).astype(np.uint8)
                frames[t, r * height:(r + 1) * height, c * width:(c + 1) * width] = image
    return frames


def write_video(path: str, frames: np.ndarray, fps: int = 25) -> None:
    """Writes frames (T, H, W, 3) uint8 to .mp4 (imageio-ffmpeg) or .gif (imageio + Pillow)."""
    try:
        import imageio.v2 as imageio
    except ImportError:
        raise ValueError("writing videos needs imageio: pip install -e '.[viz]'") from None
    if path.lower().endswith(".gif"):
        imageio.mimsave(path, list(frames), duration=1000.0 / fps, loop=0)
    else:
        try:
            imageio.mimsave(path, list(frames), fps=fps, macro_block_size=8)
        except Exception as error:  # imageio raises a plain RuntimeError / ImportError without the ffmpeg plugin
            raise ValueError(f"writing {path!r} failed ({type(error).__name__}: {error}); mp4 needs imageio-ffmpeg "
                             "(pip install -e '.[viz]'), or write a .gif.") from None
