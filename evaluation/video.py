"""Videos of deployments: one MP4 per trained (agent, task) cell, with the task and belief overlaid.

    MUJOCO_GL=egl python -m hyperstate.evaluation.video OUT [--cells AGENT__TASK__sSEED ...] [--tasks N]
                                                 [--width 320 --height 240]

renders, for each cell of a finished `evaluation/run.py` results folder OUT (default: the first seed
of every (agent, task)), deterministic deployments on the first N held-out tasks (default 1; a finite
prior's support is covered in turn, so `--tasks 2` shows cheetah-dir's backward and forward task), one
after the other in OUT/videos/<cell>.mp4 at the task's real-time frame rate. The task draws its
decorations into the scene (e.g. the zone's borders, the goal); a caption shows the task, step, return
so far and the exact belief where the task has one. Needs an off-screen OpenGL backend: MUJOCO_GL=egl
(libegl1) or osmesa (Debian's libosmesa6); `evaluation/run.py --video` runs this module with
MUJOCO_GL=egl.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import mujoco
import numpy as np
from PIL import Image, ImageDraw

from hyperstate import suite
from hyperstate.evaluation import grid as grid_layout
from hyperstate.evaluation import protocol
from hyperstate.evaluation.deploy import EVAL_SEED, evaluation_tasks
from hyperstate.evaluation.imports import import_modules

GEOM_TYPES = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
}


def _add_markers(markers):
    def callback(physics, scene: mujoco.MjvScene) -> None:
        for m in markers:
            if scene.ngeom >= scene.maxgeom:
                return
            scene.ngeom += 1  # first: the bindings expose only the scene's first `ngeom` geoms
            mujoco.mjv_initGeom(
                scene.geoms[scene.ngeom - 1],
                GEOM_TYPES[m.type],
                np.asarray(m.size, np.float64),
                np.asarray(m.pos, np.float64),
                np.eye(3).ravel(),
                np.asarray(m.rgba, np.float32),
            )

    return callback


def _caption(frame: np.ndarray, lines: list[str]) -> np.ndarray:
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    height = 12 * len(lines) + 6
    draw.rectangle((0, 0, image.width, height), fill=(0, 0, 0))
    for i, line in enumerate(lines):
        draw.text((4, 3 + 12 * i), line, fill=(255, 255, 255))
    return np.asarray(image)


def render_deployment(
    agent,
    task: str,
    path: str | os.PathLike,
    *,
    task_parameters: np.ndarray | None = None,
    episodes_per_task: int | None = None,
    width: int = 320,
    height: int = 240,
) -> dict:
    """Deploys `agent` on `task` (deterministic actions, each deployment from the prior belief) once per
    row of `task_parameters` (one task's parameters, or (N, P) for N tasks one after the other; default:
    the first held-out task) and writes the frames to the MP4 `path`; returns
    {"return": mean over the deployments, "returns": [...], "frames": ..., "fps": ...}."""
    import imageio_ffmpeg

    kwargs = {} if episodes_per_task is None else {"episodes_per_task": episodes_per_task}
    env = suite.load(task, seed=EVAL_SEED, privileged=True, **kwargs)
    if task_parameters is None:
        task_parameters = evaluation_tasks(task, 1)[:1]
    task_parameters = np.asarray(task_parameters, dtype=np.float64)
    if task_parameters.ndim < 2:
        task_parameters = task_parameters.reshape(1, -1)
    fps = 1.0 / env.control_timestep()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = imageio_ffmpeg.write_frames(
        str(path), (width, height), fps=fps, macro_block_size=1, output_params=["-loglevel", "error"]
    )
    writer.send(None)
    returns, frames = [], 0
    try:
        for parameters in task_parameters:
            env.task.force_task(parameters)
            total, n = _render_one(agent, task, env, writer, width, height)
            returns.append(total)
            frames += n
    finally:
        writer.close()
    return {"return": float(np.mean(returns)), "returns": returns, "frames": frames, "fps": fps}


def _render_one(agent, task: str, env, writer, width: int, height: int) -> tuple[float, int]:
    """One deployment from reset into `writer`; returns (return, frames written)."""
    step = env.reset()
    state, total, t, frames = None, 0.0, 0, 0
    axis = suite.position_axis(task)  # where the task declares one, the caption says where the agent is

    def frame(reward_so_far: float) -> np.ndarray:
        pixels = env.physics.render(
            height, width, camera_id=env.task.video_camera, scene_callback=_add_markers(env.task.markers(env.physics))
        )
        lines = [f"{agent.name} on {task}", env.task.caption()]
        status = (
            f"episode {env.task.inner_episode + 1}/{env.task.episodes_per_task}  step {t}  return {reward_so_far:.1f}"
        )
        if axis is not None and axis.key in step.observation:
            status += "  " + axis.describe(float(np.asarray(step.observation[axis.key]).ravel()[0]))
        lines.append(status)
        if env.task.belief is not None:
            lines.append("exact belief " + " ".join(f"{p:.2f}" for p in env.task.belief))
        return _caption(pixels, lines)

    writer.send(np.ascontiguousarray(frame(0.0)))
    frames += 1
    while not step.last():
        obs = {k: np.asarray(v)[None] for k, v in step.observation.items()}
        reward = None if state is None else np.array([step.reward])
        action, state = agent.act(obs, state, deterministic=True, reward=reward)
        step = env.step(action[0])
        total += step.reward
        t += 1
        writer.send(np.ascontiguousarray(frame(total)))
        frames += 1
    return total, frames


def default_cells(grid: dict) -> list[str]:
    """The cells filmed when none are named: the first seed of every (agent, task) of a grid.json."""
    return [grid_layout.cell_id(a, t, grid["seeds"][0]) for t in grid["tasks"] for a in grid["agents"]]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("out", type=Path, help="a results folder of evaluation/run.py")
    parser.add_argument("--cells", nargs="+", help="cell folder names (default: the first seed of each agent and task)")
    parser.add_argument(
        "--import",
        dest="imports",
        nargs="+",
        default=[],
        metavar="MODULE",
        help="modules or .py files registering the tasks (as for evaluation/run.py)",
    )
    parser.add_argument(
        "--tasks", type=int, default=1, metavar="N", help="deployments per video, on the first N held-out tasks"
    )
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    args = parser.parse_args(argv)
    grid_file = args.out / grid_layout.GRID
    if not grid_file.exists():
        print(
            f"evaluation/video.py: error: {args.out} holds no evaluation/run.py results (no grid.json)", file=sys.stderr
        )
        return 2
    if args.tasks < 1:
        print(f"evaluation/video.py: error: --tasks must be >= 1, got {args.tasks}", file=sys.stderr)
        return 2
    grid = json.loads(grid_file.read_text())
    import_modules(args.imports)
    cells = args.cells or default_cells(grid)
    for cell in cells:
        saved = grid_layout.cell_dir(args.out, cell) / grid_layout.AGENT
        if not saved.exists():
            print(f"evaluation/video.py: no trained agent for {cell} (skipped)", file=sys.stderr)
            continue
        name, task, _ = grid_layout.parse_cell_id(cell)
        agent = protocol.load_agent(name, saved)
        path = args.out / "videos" / f"{cell}.mp4"
        info = render_deployment(
            agent,
            task,
            path,
            task_parameters=evaluation_tasks(task, args.tasks)[: args.tasks],
            episodes_per_task=grid.get("episodes_per_task"),
            width=args.width,
            height=args.height,
        )
        returns = ", ".join(f"{r:.1f}" for r in info["returns"])
        print(f"{path}: {info['frames']} frames at {info['fps']:.0f} fps, returns {returns}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
