#!/usr/bin/env python3
"""Loosely paired clips of two different arms, rendered with MuJoCo: an alignment
validation set that is not milv-sim.

Each pair shares one end-effector path over a cluttered, textured table (a smooth curve
through random waypoints, at varying heights). A grey-and-orange industrial arm (domain
`robot`) and a sleeved human-like arm with a hand (domain `human`, mounted on the other
side of the table) each follow it with inverse kinematics, at their own speed: every clip
has its own random monotone time warp of the path and its own length (50-80 frames), and
each arm is filmed by its own camera (its own azimuth, elevation and distance). Nothing
of milv-sim's scene holds: no flat uniformly coloured table quad, arms that do not enter
from an image border, perspective views from anywhere around the table.

Writes into OUT:
  <family>_<domain>_paired_<i>.mp4 + .json   128x128 H.264 at 10 fps; milv-sidecar/1 with
                                             the end-effector position as state (x, y, z),
                                             its per-frame change as action
  manifest.jsonl                             for `milv-ingest DS --manifest`
  warps.jsonl                                ground truth for `milv-align --truth`: per pair,
                                             for each human frame the robot frame at the
                                             same point of the path
  summary.json                               the proportional warp's frame error per pair

Render headless: MUJOCO_GL=egl (default here) or osmesa, with Debian's Mesa
(libegl1, libgl1-mesa-dri / libosmesa6; tools/setup.sh installs them).

  python tools/mujoco/paired_arms.py OUT --pairs 10 --seed 100
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import av  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

FAMILY = "mjreach"
TABLE_TOP = 0.75
SIZE = 128
FPS = 10

# --- the scene ----------------------------------------------------------------------

ROBOT_ARM = """
<body name="base" pos="{bx} {by} {top}">
  <geom type="cylinder" size=".075 .03" pos="0 0 .03" rgba=".25 .25 .28 1"/>
  <body name="l1" pos="0 0 .06">
    <joint name="j1" axis="0 0 1" range="-3.1 3.1"/>
    <geom type="cylinder" size=".05 .06" pos="0 0 .06" rgba="{accent} 1"/>
    <body name="l2" pos="0 0 .12">
      <joint name="j2" axis="0 1 0" range="-2.2 2.2"/>
      <geom type="box" size=".035 .035 .17" pos="0 0 .17" rgba=".78 .78 .8 1"/>
      <geom type="cylinder" size=".045 .045" zaxis="0 1 0" rgba="{accent} 1"/>
      <body name="l3" pos="0 0 .34">
        <joint name="j3" axis="0 1 0" range="-2.6 2.6"/>
        <geom type="cylinder" size=".04 .04" zaxis="0 1 0" rgba="{accent} 1"/>
        <geom type="box" size=".028 .028 .14" pos="0 0 .14" rgba=".78 .78 .8 1"/>
        <body name="l4" pos="0 0 .28">
          <joint name="j4" axis="0 1 0" range="-2.2 2.2"/>
          <geom type="cylinder" size=".03 .03" zaxis="0 1 0" rgba=".25 .25 .28 1"/>
          <geom type="box" size=".05 .015 .012" pos="0 0 .05" rgba=".25 .25 .28 1"/>
          <geom type="box" size=".008 .012 .04" pos=".035 0 .1" rgba=".15 .15 .15 1"/>
          <geom type="box" size=".008 .012 .04" pos="-.035 0 .1" rgba=".15 .15 .15 1"/>
          <site name="ee" pos="0 0 .13" size=".005"/>
        </body>
      </body>
    </body>
  </body>
</body>
"""

# A person's arm reaching over the table from a shoulder above its far edge: a sleeve, a
# bare forearm, a hand with fingers; a torso and head behind it.
HUMAN_ARM = """
<body name="torso" pos="{bx} {by} {sz}">
  <geom type="box" size=".16 .09 .25" pos="{tx} 0 -.22" rgba="{shirt} 1"/>
  <geom type="sphere" size=".09" pos="{tx} 0 .13" rgba="{skin} 1"/>
  <body name="shoulder" pos="0 0 0">
    <joint name="s1" axis="0 0 1" range="-3.1 3.1"/>
    <joint name="s2" axis="0 1 0" range="-3.1 3.1"/>
    <joint name="s3" axis="1 0 0" range="-1.5 1.5"/>
    <geom type="capsule" fromto="0 0 0 0 0 -.32" size=".045" rgba="{shirt} 1"/>
    <body name="forearm" pos="0 0 -.32">
      <joint name="e1" axis="0 1 0" range="-2.6 0.1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -.28" size=".033" rgba="{skin} 1"/>
      <body name="hand" pos="0 0 -.28">
        <joint name="w1" axis="0 1 0" range="-1.2 1.2"/>
        <geom type="ellipsoid" size=".045 .02 .05" pos="0 0 -.05" rgba="{skin} 1"/>
        <geom type="capsule" fromto="-.03 0 -.09 -.03 0 -.14" size=".009" rgba="{skin} 1"/>
        <geom type="capsule" fromto="-.01 0 -.095 -.01 0 -.15" size=".009" rgba="{skin} 1"/>
        <geom type="capsule" fromto=".01 0 -.095 .01 0 -.148" size=".009" rgba="{skin} 1"/>
        <geom type="capsule" fromto=".03 0 -.09 .03 0 -.13" size=".009" rgba="{skin} 1"/>
        <geom type="capsule" fromto=".045 0 -.03 .06 0 -.08" size=".01" rgba="{skin} 1"/>
        <site name="ee" pos="0 0 -.13" size=".005"/>
      </body>
    </body>
  </body>
</body>
"""

SCENE = """
<mujoco>
  <compiler angle="radian"/>
  <visual><global offwidth="{size}" offheight="{size}"/><quality shadowsize="1024"/></visual>
  <asset>
    <texture name="floor" type="2d" builtin="checker" width="256" height="256"
             rgb1="{floor1}" rgb2="{floor2}"/>
    <material name="floor" texture="floor" texrepeat="6 6"/>
    <texture name="wood" type="2d" builtin="flat" mark="random" random="0.25" width="256"
             height="256" rgb1="{wood}" markrgb="{wood_dark}"/>
    <material name="wood" texture="wood" texrepeat="3 3"/>
    <texture name="cloth" type="2d" builtin="checker" width="64" height="64"
             rgb1="{cloth1}" rgb2="{cloth2}"/>
    <material name="cloth" texture="cloth" texrepeat="4 4"/>
  </asset>
  <worldbody>
    <light pos="{lx} {ly} 2.6" dir="{ldx} {ldy} -1" diffuse=".75 .75 .75" castshadow="true"/>
    <light pos="0 0 3" dir="0 0 -1" diffuse=".35 .35 .35" castshadow="false"/>
    <geom type="plane" size="3 3 .1" material="floor"/>
    <geom type="box" size=".5 .4 .02" pos="0 0 {top_c}" material="wood"/>
    <geom type="box" size=".18 .12 .002" pos="{mx} {my} {top_m}" material="cloth"/>
    {legs}
    {clutter}
    <body name="target" pos="0 0 {top}"/>
    <camera name="view" mode="targetbody" target="target" pos="{cx} {cy} {cz}" fovy="{fovy}"/>
    {arm}
  </worldbody>
</mujoco>
"""


def rgb(c) -> str:
    return " ".join(f"{v:.3f}" for v in c)


def scene_xml(arm: str, rng: np.random.Generator, camera: tuple[float, float, float], fovy: float) -> str:
    legs = "".join(
        f'<geom type="box" size=".03 .03 {TABLE_TOP / 2 - 0.01:.3f}" pos="{sx * 0.45} {sy * 0.35} '
        f'{TABLE_TOP / 2 - 0.01:.3f}" rgba=".3 .22 .15 1"/>'
        for sx in (-1, 1)
        for sy in (-1, 1)
    )
    clutter = []
    for k in range(rng.integers(2, 5)):
        # Objects at the table's corners, out of the way of the path.
        x = rng.choice([-1, 1]) * rng.uniform(0.3, 0.44)
        y = rng.choice([-1, 1]) * rng.uniform(0.25, 0.35)
        h = rng.uniform(0.02, 0.06)
        shape = ["box", "cylinder", "sphere"][k % 3]
        size = {"box": f"{rng.uniform(.02, .05):.3f} {rng.uniform(.02, .05):.3f} {h:.3f}",
                "cylinder": f"{rng.uniform(.02, .04):.3f} {h:.3f}",
                "sphere": f"{h:.3f}"}[shape]
        clutter.append(
            f'<geom type="{shape}" size="{size}" pos="{x:.3f} {y:.3f} {TABLE_TOP + h:.3f}" '
            f'rgba="{rgb(rng.uniform(0.1, 0.95, 3))} 1"/>'
        )
    wood = rng.uniform([0.45, 0.3, 0.15], [0.75, 0.55, 0.35])
    la = rng.uniform(0, 2 * math.pi)
    return SCENE.format(
        size=SIZE,
        floor1=rgb(rng.uniform(0.2, 0.5, 3)),
        floor2=rgb(rng.uniform(0.5, 0.8, 3)),
        wood=rgb(wood),
        wood_dark=rgb(wood * 0.6),
        cloth1=rgb(rng.uniform(0.1, 0.9, 3)),
        cloth2=rgb(rng.uniform(0.1, 0.9, 3)),
        lx=f"{1.5 * math.cos(la):.3f}",
        ly=f"{1.5 * math.sin(la):.3f}",
        ldx=f"{-math.cos(la):.3f}",
        ldy=f"{-math.sin(la):.3f}",
        top=TABLE_TOP,
        top_c=TABLE_TOP - 0.02,
        top_m=TABLE_TOP + 0.001,
        mx=f"{rng.uniform(-0.2, 0.2):.3f}",
        my=f"{rng.uniform(-0.15, 0.15):.3f}",
        legs=legs,
        clutter="\n".join(clutter),
        cx=f"{camera[0]:.3f}",
        cy=f"{camera[1]:.3f}",
        cz=f"{camera[2]:.3f}",
        fovy=f"{fovy:.1f}",
        arm=arm,
    )


def camera_at(rng: np.random.Generator, azimuth_deg: float) -> tuple[tuple[float, float, float], float]:
    """A camera around the table, looking at its centre: the azimuth given, elevation
    25-60°, distance 1.3-1.7 m, field of view 40-55°."""
    az = math.radians(azimuth_deg)
    el = math.radians(rng.uniform(25, 60))
    dist = rng.uniform(1.3, 1.7)
    pos = (dist * math.cos(el) * math.cos(az), dist * math.cos(el) * math.sin(az),
           TABLE_TOP + dist * math.sin(el))
    return pos, rng.uniform(40, 55)


# --- the motion ---------------------------------------------------------------------


def catmull_rom(points: np.ndarray, samples: int) -> np.ndarray:
    """A smooth curve through the points, resampled to equal arc length."""
    p = np.vstack([points[0], points, points[-1]])
    dense = []
    for i in range(1, len(p) - 2):
        for u in np.linspace(0, 1, 50, endpoint=False):
            p0, p1, p2, p3 = p[i - 1], p[i], p[i + 1], p[i + 2]
            dense.append(0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u**2
                                + (-p0 + 3 * p1 - 3 * p2 + p3) * u**3))
    dense.append(p[-2])
    dense = np.array(dense)
    arc = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    s = np.linspace(0, arc[-1], samples)
    return np.stack([np.interp(s, arc, dense[:, k]) for k in range(3)], axis=1)


def shared_path(rng: np.random.Generator) -> np.ndarray:
    """One end-effector path (1000 points at equal arc length, metres, world frame): from
    above the table's middle, through 3-4 waypoints, some at the table (a touch or a push)."""
    n = rng.integers(3, 5)
    pts = [np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), TABLE_TOP + 0.25])]
    for _ in range(n):
        pts.append(np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.15, 0.15),
                             TABLE_TOP + rng.choice([0.03, rng.uniform(0.05, 0.25)])]))
    return catmull_rom(np.array(pts), 1000)


def time_warp(rng: np.random.Generator, n: int) -> np.ndarray:
    """Path parameter (0 → 1) of each of n frames: a random monotone warp. The speed is a
    smooth random positive function with up to two slow-downs, so the clip lingers where
    the other does not (never a full stop: frames of a stop would all be equally right)."""
    t = np.linspace(0, 1, n)
    log_speed = np.zeros(n)
    for _ in range(3):
        f, ph, a = rng.uniform(0.5, 2.0), rng.uniform(0, 2 * math.pi), rng.uniform(0.1, 0.35)
        log_speed += a * np.sin(2 * math.pi * f * t + ph)
    speed = np.exp(log_speed)
    for _ in range(rng.integers(0, 3)):
        c, w = rng.uniform(0.15, 0.85), rng.uniform(0.04, 0.1)
        speed *= 1 - 0.8 * np.exp(-0.5 * ((t - c) / w) ** 2)
    s = np.concatenate([[0], np.cumsum(0.5 * (speed[1:] + speed[:-1]))])
    return s / s[-1]


def truth_map(s_human: np.ndarray, s_robot: np.ndarray) -> list[int]:
    """For each human frame, the robot frame at the same point of the path (the robot's
    warp inverted by linear interpolation, then rounded)."""
    frames = np.arange(len(s_robot), dtype=float)
    return [math.floor(float(np.interp(s, s_robot, frames)) + 0.5) for s in s_human]


# --- inverse kinematics and rendering ----------------------------------------------


class Arm:
    def __init__(self, xml: str, rest: list[float]):
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, "ee")
        self.rest = np.array(rest)
        self.data.qpos[:] = self.rest
        mujoco.mj_forward(self.model, self.data)
        self.lo = self.model.jnt_range[:, 0]
        self.hi = self.model.jnt_range[:, 1]

    def reach(self, target: np.ndarray, iters: int = 60) -> float:
        """Damped least squares from the current pose, pulled weakly towards the rest pose;
        returns the remaining distance (m)."""
        m, d = self.model, self.data
        jac = np.zeros((3, m.nv))
        for _ in range(iters):
            mujoco.mj_forward(m, d)
            err = target - d.site_xpos[self.site]
            if np.linalg.norm(err) < 1e-4:
                break
            mujoco.mj_jacSite(m, d, jac, None, self.site)
            lam = 1e-3
            dq = jac.T @ np.linalg.solve(jac @ jac.T + lam * np.eye(3), err)
            null = np.eye(m.nv) - np.linalg.pinv(jac) @ jac
            dq += 0.05 * null @ (self.rest - d.qpos)
            d.qpos[:] = np.clip(d.qpos + dq, self.lo, self.hi)
        mujoco.mj_forward(m, d)
        return float(np.linalg.norm(target - d.site_xpos[self.site]))


def render_clip(arm: Arm, targets: np.ndarray) -> tuple[list[np.ndarray], np.ndarray, float]:
    frames, ee, worst = [], [], 0.0
    with mujoco.Renderer(arm.model, SIZE, SIZE) as r:
        # Settle on the first target so the clip does not start with a jump.
        arm.reach(targets[0], iters=300)
        for p in targets:
            worst = max(worst, arm.reach(p))
            r.update_scene(arm.data, camera="view")
            frames.append(r.render().copy())
            ee.append(arm.data.site_xpos[arm.site].copy())
    return frames, np.array(ee), worst


def write_clip(out: Path, name: str, frames, ee: np.ndarray, episode: dict) -> None:
    with av.open(str(out / f"{name}.mp4"), "w") as c:
        s = c.add_stream("libx264", rate=FPS)
        s.width, s.height, s.pix_fmt = SIZE, SIZE, "yuv420p"
        s.options = {"crf": "18", "preset": "medium"}
        for f in frames:
            c.mux(s.encode(av.VideoFrame.from_ndarray(f, format="rgb24")))
        c.mux(s.encode())
    actions = np.vstack([np.diff(ee, axis=0), np.zeros((1, 3))])
    sidecar = {
        "format": "milv-sidecar/1",
        "episode": episode,
        "state_names": ["ee_x", "ee_y", "ee_z"],
        "states": np.round(ee, 5).tolist(),
        "action_names": ["d_ee_x", "d_ee_y", "d_ee_z"],
        "actions": np.round(actions, 5).tolist(),
    }
    (out / f"{name}.json").write_text(json.dumps(sidecar) + "\n")


def generate(out: Path, pairs: int, seed: int, split: str) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    manifest, warps, summary = [], [], []
    for i in range(pairs):
        rng = np.random.default_rng([seed, i])
        path = shared_path(rng)
        pair_id = f"{FAMILY}-{seed}-{i:04d}"
        accent = rgb(rng.uniform([0.8, 0.3, 0.0], [1.0, 0.6, 0.2]))
        skin = rgb(rng.uniform([0.55, 0.38, 0.28], [0.95, 0.75, 0.62]))
        shirt = rgb(rng.uniform(0.05, 0.9, 3))
        # The robot stands at the near edge (y < 0), the person leans over the far edge.
        robot_xml = ROBOT_ARM.format(bx=f"{rng.uniform(-.1, .1):.3f}", by="-0.36", top=TABLE_TOP, accent=accent)
        human_xml = HUMAN_ARM.format(bx=f"{rng.uniform(-.15, .05):.3f}", by="0.4",
                                     sz=f"{TABLE_TOP + rng.uniform(.3, .38):.3f}",
                                     tx="-.17", shirt=shirt, skin=skin)
        # Cameras in front of each arm (the person faces -y), at azimuths 40° apart or more.
        az_robot = rng.uniform(-130, -50)
        az_human = rng.uniform(-170, -10)
        while abs(az_human - az_robot) < 40:
            az_human = rng.uniform(-170, -10)
        clips, cameras = {}, {}
        for domain, arm_xml, rest, azimuth in (
            ("robot", robot_xml, [1.57, 0.3, 1.2, 1.2], az_robot),
            ("human", human_xml, [-1.57, 0.6, 0.0, -1.2, 0.3], az_human),
        ):
            n = int(rng.integers(50, 81))
            s = time_warp(rng, n)
            targets = np.stack([np.interp(s, np.linspace(0, 1, len(path)), path[:, k]) for k in range(3)], 1)
            cam, fovy = camera_at(rng, azimuth)
            arm = Arm(scene_xml(arm_xml, rng, cam, fovy), rest)
            frames, ee, worst = render_clip(arm, targets)
            if worst > 0.02:
                raise SystemExit(f"pair {pair_id}: the {domain} arm misses its path by {worst:.3f} m")
            name = f"{FAMILY}_{domain}_paired_{i:04d}"
            episode = {"domain": domain, "kind": "paired", "task_id": f"{FAMILY}/{seed}-{i:04d}",
                       "task_family": FAMILY, "pair_id": pair_id, "split": split}
            write_clip(out, name, frames, ee, episode)
            manifest.append({"path": f"{name}.mp4", "sidecar": f"{name}.json"})
            clips[domain] = s
            cameras[domain] = {"pos": [round(c, 4) for c in cam], "target": [0.0, 0.0, TABLE_TOP], "fovy": round(fovy, 2)}
        truth = truth_map(clips["human"], clips["robot"])
        nh, nr = len(clips["human"]), len(clips["robot"])
        # Half away from zero, as milv-align rounds (Python's round() goes to even).
        prop = [math.floor(k * (nr - 1) / (nh - 1) + 0.5) for k in range(nh)]
        err = [abs(a - b) for a, b in zip(prop, truth)]
        warps.append({"pair_id": pair_id, "human_frames": nh, "robot_frames": nr, "human_to_robot": truth})
        summary.append({"pair_id": pair_id, "human_frames": nh, "robot_frames": nr, "cameras": cameras,
                        "proportional_mean_error": sum(err) / nh, "proportional_max_error": max(err)})
        print(f"{pair_id}: human {nh} frames, robot {nr} frames, proportional warp "
              f"mean error {sum(err) / nh:.2f}, max {max(err)}", file=sys.stderr)
    lines = lambda rows: "".join(json.dumps(r) + "\n" for r in rows)  # noqa: E731
    (out / "manifest.jsonl").write_text(lines(manifest))
    (out / "warps.jsonl").write_text(lines(warps))
    result = {
        "pairs": summary,
        "proportional_mean_error": sum(p["proportional_mean_error"] for p in summary) / max(len(summary), 1),
        "seed": seed,
        "mujoco": mujoco.__version__,
        "gl": os.environ["MUJOCO_GL"],
    }
    (out / "summary.json").write_text(json.dumps(result, indent=1) + "\n")
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--pairs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=100, help="pairs are seeded by (seed, index)")
    ap.add_argument("--split", default="train")
    a = ap.parse_args()
    r = generate(a.out, a.pairs, a.seed, a.split)
    print(json.dumps({"out": str(a.out), "pairs": len(r["pairs"]),
                      "proportional_mean_error": r["proportional_mean_error"]}))


if __name__ == "__main__":
    main()
