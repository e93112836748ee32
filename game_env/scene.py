"""MuJoCo scene of a course, built with ``mujoco.MjSpec`` and cached per (map_id, seed, racers)."""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from game_env.constants import (
    FEET,
    FRICTION,
    RACER_FORCE,
    RACER_HALF,
    RACER_KV,
    RACER_MASS,
    RACER_RADIUS,
    TIMESTEP,
)
from game_env.course import Course
from game_env.generator import generate_course

MAX_RACERS = 16
RACER_COLORS = [
    (0.95, 0.35, 0.55, 1), (0.3, 0.6, 1.0, 1), (1.0, 0.8, 0.2, 1), (0.4, 0.9, 0.4, 1),
    (0.7, 0.4, 1.0, 1), (1.0, 0.55, 0.2, 1), (0.2, 0.9, 0.9, 1), (0.9, 0.9, 0.9, 1),
]
KIND_RGBA = {
    "platform": (0.55, 0.75, 0.95, 1), "start": (0.6, 0.9, 0.6, 1), "finish": (0.95, 0.85, 0.4, 1),
    "ramp": (0.7, 0.6, 0.95, 1), "conveyor": (0.35, 0.35, 0.4, 1), "hammer": (0.95, 0.7, 0.7, 1),
    "balloons": (0.95, 0.8, 0.95, 1), "trampoline": (0.6, 0.95, 0.85, 1),
}


def _quat_y(angle: float) -> list[float]:
    return [math.cos(angle / 2), 0.0, math.sin(angle / 2), 0.0]


def _quat_z(angle: float) -> list[float]:
    return [math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)]


def spawn_offsets(num_racers: int) -> np.ndarray:
    """(N, 2) x/y offsets of racers around a spawn point: rows of four, 1.4 m apart."""
    i = np.arange(num_racers)
    return np.stack([-(i // 4) * 1.4, ((i % 4) - 1.5) * 1.4], axis=1)


def build_spec(course: Course, num_racers: int) -> mujoco.MjSpec:
    """Build the MjSpec of ``course`` with ``num_racers`` racers on the start pad."""
    if not 1 <= num_racers <= MAX_RACERS:
        raise ValueError(f"num_racers={num_racers!r} is out of range; allowed: 1..{MAX_RACERS}")
    spec = mujoco.MjSpec()
    spec.modelname = f"race_map{course.map_id}_seed{course.seed}"
    opt = spec.option
    opt.timestep = TIMESTEP
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    spec.visual.quality.shadowsize = 0
    spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    spec.visual.rgba.haze = [0.6, 0.8, 1.0, 1]
    sky = spec.add_texture()
    sky.name, sky.type, sky.builtin = "sky", mujoco.mjtTexture.mjTEXTURE_SKYBOX, mujoco.mjtBuiltin.mjBUILTIN_GRADIENT
    sky.rgb1, sky.rgb2, sky.width, sky.height = [0.55, 0.8, 1.0], [0.95, 0.97, 1.0], 64, 64
    wb = spec.worldbody
    light = wb.add_light()
    light.pos = [course.length / 2, 0, 40]
    light.dir = [0.3, 0.2, -1]
    light.castshadow = False

    def static(name, size, pos, rgba, quat=None, geom_type=mujoco.mjtGeom.mjGEOM_BOX, collide=True):
        g = wb.add_geom()
        g.name, g.type, g.size, g.pos, g.rgba = name, geom_type, size, pos, rgba
        if quat is not None:
            g.quat = quat
        if collide:
            g.friction = [FRICTION, 0.005, 0.0001]
            g.contype, g.conaffinity = 1, 1
        else:
            g.contype, g.conaffinity = 0, 0
            g.group = 1
        return g

    for k, b in enumerate(course.boxes):
        g = static(f"floor{k}", [b.hx, b.hy, b.hz], [b.cx, b.cy, b.cz], KIND_RGBA.get(b.kind, (0.6, 0.6, 0.6, 1)),
                   _quat_y(b.pitch) if b.pitch else None)
        if b.kind == "conveyor":
            g.surfacevel = [b.belt[0], b.belt[1], 0, 0, 0, 0]
        depth = (b.cz - b.hz) - (course.floor_min - 3.0)
        if b.kind != "ramp" and depth > 0.1:  # a visual pillar shows how high the platform is
            static(f"pillar{k}", [0.85 * b.hx, 0.85 * b.hy, depth / 2], [b.cx, b.cy, b.cz - b.hz - depth / 2],
                   (0.75, 0.78, 0.85, 1), collide=False)
    for k, t in enumerate(course.trampolines):
        static(f"tramp{k}", [t.hx, t.hy, 0.03], [t.cx, t.cy, t.top - 0.02], (0.1, 0.85, 0.5, 1),
               _quat_y(t.tilt), collide=False)
    for k, z in enumerate(course.archives):
        static(f"archive{k}", [z.hx, z.hy, 0.02], [z.cx, z.cy, z.z], (0.2, 0.5, 1.0, 0.9), collide=False)
    for k, z in enumerate(course.goals):
        static(f"goal{k}", [z.hx, z.hy, 0.02], [z.cx, z.cy, z.z], (1.0, 0.6, 0.1, 0.9), collide=False)
    d = course.destination
    static("destination", [d.hx, d.hy, 0.03], [d.cx, d.cy, d.z], (1.0, 0.9, 0.0, 1), _quat_z(d.yaw), collide=False)
    static("flag", [0.08, 2.0, 0], [d.cx, d.cy, d.z + 2.0], (1, 0.2, 0.2, 1), None,
           mujoco.mjtGeom.mjGEOM_CYLINDER, collide=False)
    for k, (px, py, pz) in enumerate(course.props):
        static(f"prop{k}", [0.25, 0, 0], [px, py, pz], (0.9, 0.2, 0.9, 1), None,
               mujoco.mjtGeom.mjGEOM_SPHERE, collide=False)
    for k, t in enumerate(course.tiles):
        body = wb.add_body()
        body.name, body.mocap, body.pos = f"tile{k}", True, [t.cx, t.cy, t.top - 0.25]
        g = body.add_geom()
        g.name, g.type, g.size = f"tile{k}", mujoco.mjtGeom.mjGEOM_BOX, [t.hx, t.hy, 0.25]
        g.rgba = (1.0, 0.45, 0.3, 1) if t.collapses else (0.8, 0.8, 0.7, 1)
        g.friction = [FRICTION, 0.005, 0.0001]
    for k, h in enumerate(course.hammers):
        body = wb.add_body()
        body.name, body.mocap, body.pos = f"hammer{k}", True, [h.px, h.py, h.floor]
        body.quat = _quat_z(h.phase)
        post = body.add_geom()
        post.type, post.size, post.pos = mujoco.mjtGeom.mjGEOM_CYLINDER, [0.3, 0.5, 0], [0, 0, 0.5]
        bar = body.add_geom()
        half = h.arm / 2 if h.arms == 1 else h.arm
        bar.type, bar.size = mujoco.mjtGeom.mjGEOM_BOX, [half, 0.15, (h.bar_top - 0.2) / 2]
        bar.pos = [h.arm / 2 if h.arms == 1 else 0.0, 0, (h.bar_top + 0.2) / 2]
        for g in (post, bar):
            g.contype, g.conaffinity, g.rgba = 0, 0, (0.85, 0.15, 0.15, 1)
    for k, bal in enumerate(course.balloons):
        body = wb.add_body()
        body.name, body.pos, body.gravcomp = f"balloon{k}", [bal.x, bal.y, bal.z], 1.0
        for axis, jn, ref in (([1, 0, 0], "x", bal.x), ([0, 1, 0], "y", bal.y)):
            j = body.add_joint()
            j.name, j.type, j.axis = f"balloon{k}_{jn}", mujoco.mjtJoint.mjJNT_SLIDE, axis
            j.ref, j.springref = ref, ref  # qpos is the world coordinate
            j.stiffness, j.damping = [bal.stiffness, 0, 0], [2.0, 0, 0]
        g = body.add_geom()
        g.name, g.type, g.size, g.mass = f"balloon{k}", mujoco.mjtGeom.mjGEOM_SPHERE, [bal.radius, 0, 0], 0.2
        g.contype, g.conaffinity = 2, 0
        g.rgba = (1.0, 0.3, 0.6, 0.85) if bal.burst else (0.3, 0.7, 1.0, 0.85)
    offsets = spawn_offsets(num_racers)
    sx, sy, sz = course.start
    for i in range(num_racers):
        body = wb.add_body()
        body.name = f"racer{i}"
        pos = [sx + offsets[i, 0], sy + offsets[i, 1], sz + FEET]
        body.pos = pos
        for axis, jn, ref in zip(([1, 0, 0], [0, 1, 0], [0, 0, 1]), "xyz", pos, strict=True):
            j = body.add_joint()
            j.name, j.type, j.axis = f"racer{i}_{jn}", mujoco.mjtJoint.mjJNT_SLIDE, axis
            j.ref = ref  # qpos is the world coordinate
        g = body.add_geom()
        g.name, g.type = f"racer{i}", mujoco.mjtGeom.mjGEOM_CAPSULE
        g.size, g.mass = [RACER_RADIUS, RACER_HALF, 0], RACER_MASS
        g.contype, g.conaffinity, g.condim = 3, 3, 1  # frictionless: actuators do the walking
        g.priority = 1  # its condim wins over the floor's (MuJoCo uses the max otherwise)
        g.rgba = RACER_COLORS[i % len(RACER_COLORS)]
        eye = body.add_geom()
        eye.type, eye.size, eye.pos = mujoco.mjtGeom.mjGEOM_SPHERE, [0.12, 0, 0], [0, 0, RACER_HALF]
        eye.contype, eye.conaffinity, eye.mass, eye.rgba = 0, 0, 0.0, (1, 1, 1, 1)
        for jn in ("x", "y"):
            a = spec.add_actuator()
            a.name, a.target = f"racer{i}_v{jn}", f"racer{i}_{jn}"
            a.trntype = mujoco.mjtTrn.mjTRN_JOINT
            a.set_to_velocity(kv=RACER_KV)
            a.forcelimited, a.forcerange = True, [-RACER_FORCE, RACER_FORCE]
            a.ctrllimited, a.ctrlrange = True, [-20.0, 20.0]
            a.group = i
    return spec


@dataclass
class SceneIndex:
    """Ids and addresses the simulator needs, resolved once per compiled model."""

    racer_qpos: np.ndarray  # (N, 3) qpos addresses of x, y, z
    racer_qvel: np.ndarray  # (N, 3)
    racer_geom: np.ndarray  # (N,)
    racer_ctrl: np.ndarray  # (N, 2)
    balloon_geom: np.ndarray
    balloon_qpos: np.ndarray  # (B, 2)
    tile_mocap: np.ndarray
    tile_geom: np.ndarray
    hammer_mocap: np.ndarray
    geom_belt: np.ndarray  # (ngeom, 2) surface velocity of every geom


def scene_index(model: mujoco.MjModel, course: Course, num_racers: int) -> SceneIndex:
    """Resolve names to ids in ``model``."""

    def jnt(name: str) -> int:
        return model.jnt_qposadr[model.joint(name).id]

    def dof(name: str) -> int:
        return model.jnt_dofadr[model.joint(name).id]

    def gid(name: str) -> int:
        return model.geom(name).id

    def mocap(name: str) -> int:
        return model.body_mocapid[model.body(name).id]

    axes = ("x", "y", "z")
    belt = np.zeros((model.ngeom, 2))
    belt[:] = model.geom_surfacevel[:, :2]
    return SceneIndex(
        racer_qpos=np.array([[jnt(f"racer{i}_{a}") for a in axes] for i in range(num_racers)]),
        racer_qvel=np.array([[dof(f"racer{i}_{a}") for a in axes] for i in range(num_racers)]),
        racer_geom=np.array([gid(f"racer{i}") for i in range(num_racers)]),
        racer_ctrl=np.array([[model.actuator(f"racer{i}_v{a}").id for a in axes[:2]] for i in range(num_racers)]),
        balloon_geom=np.array([gid(f"balloon{k}") for k in range(len(course.balloons))], dtype=np.int64),
        balloon_qpos=np.array([[jnt(f"balloon{k}_{a}") for a in axes[:2]] for k in range(len(course.balloons))],
                              dtype=np.int64).reshape(-1, 2),
        tile_mocap=np.array([mocap(f"tile{k}") for k in range(len(course.tiles))], dtype=np.int64),
        tile_geom=np.array([gid(f"tile{k}") for k in range(len(course.tiles))], dtype=np.int64),
        hammer_mocap=np.array([mocap(f"hammer{k}") for k in range(len(course.hammers))], dtype=np.int64),
        geom_belt=belt,
    )


@functools.lru_cache(maxsize=64)
def _compiled(map_id: int, seed: int, num_racers: int) -> tuple[Course, mujoco.MjModel]:
    course = generate_course(map_id, seed)
    return course, build_spec(course, num_racers).compile()


def load_scene(map_id: int, seed: int, num_racers: int) -> tuple[Course, mujoco.MjModel, SceneIndex]:
    """Course, a private copy of its compiled model (safe to edit) and its index."""
    course, model = _compiled(map_id, seed, num_racers)
    model = copy.deepcopy(model)
    return course, model, scene_index(model, course, num_racers)


def course_xml(map_id: int, seed: int, num_racers: int = 1) -> str:
    """The MJCF text of a course (byte-identical for the same arguments)."""
    return build_spec(generate_course(map_id, seed), num_racers).to_xml()
