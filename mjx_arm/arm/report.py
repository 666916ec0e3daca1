"""What ``mjx-arm arm`` prints and draws: an arm's facts, its setup per task, whether it can do
each task, and a picture of its home pose over the task area."""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path

import numpy as np

from mjx_arm.arm.info import ArmInfo, arm_info, tool_down_solver
from mjx_arm.arm.setup import ArmSetup, arm_setup
from mjx_arm.arm.verdict import gripper_problem, task_verdict
from mjx_arm.inputs import write_atomic
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.repair import UrdfRepairs
from mjx_arm.urdf.scene_shapes import table_top_extent


def describe(arm: ArmInfo) -> str:
    """Human-readable lines of an arm's facts (no task: fast)."""
    ft = arm.ft_joint or f"the last arm joint (tool link {arm.ft_link!r})"
    derived = "" if arm.config.ee_offset else " (derived: where the tool meets a pressed surface)"
    if arm.tool_axis is not None and not arm.config.ee_offset:
        derived = " (derived: the tool's deepest point, off its axis: it meets a surface first)"
    gain = "" if arm.config.kv_factor else " (derived: presses like the shipped arm)"
    lines = [
        f"urdf        {arm.urdf}",
        f"ee_link     {arm.ee_link}; ee point {_vector(arm.ee_offset)} m in its frame{derived}",
    ]
    grip = arm.grip_offset
    if grip is not None and not np.allclose(grip, arm.ee_offset, atol=1e-9):
        lines.append(f"            Lift's ee point {_vector(grip)} m: where the gripper holds")
    lines += [
        f"joints      {arm.n_joints}: observation {16 + arm.n_joints}, action {arm.n_joints}",
    ]
    for name, lo, hi, v, turn in zip(
        arm.joint_names, arm.lower, arm.upper, arm.v_max, arm.full_turn, strict=True
    ):
        kind = "  full turn" if turn else ""
        lines.append(f"  {name:<24} range [{lo:+.3f}, {hi:+.3f}]  v_max {v:g}{kind}")
    gripper = (
        "none"
        if arm.gripper is None
        else (
            f"{arm.gripper.joint} drives {len(arm.gripper.pad_links)} fingers, opens "
            f"{arm.gripper.opening * 100:.1f} cm"
        )
    )
    if arm.gripper is not None and arm.gripper.kind == "linkage":
        gripper = _linkage_lines(arm.gripper)
    elif arm.gripper is not None and arm.gripper.kind == "jaw":
        gripper = _jaw_lines(arm.gripper)
    lines += [
        f"F/T         {ft}; tool {arm.tool.mass:.3f} kg",
        f"gripper     {gripper}",
        f"servo gain  kv_factor {arm.kv_factor:.3f}{gain}",
        f"reach scale {arm.reach_scale:.3f} (the shipped arm's reach is 1)",
        f"collision   {arm.config.collision}{_mesh_ee_note(arm)}",
    ]
    repairs = UrdfRepairs.of(arm.config)
    if repairs.any:
        lines.append(f"repairs     {repairs.describe()} (in MuJoCo and PyBullet alike)")
    return "\n".join(lines)


# mm: a derived ee point this far from the meshes' is named (a fitted primitive moves it)
EE_NOTE_MM = 1.0


def _mesh_ee_note(arm: ArmInfo) -> str:
    """Where fitted primitives derive another ee point than the arm's own meshes: by how much,
    and the ``ee_offset`` that trains on the meshes' point ("" otherwise). An engine that keeps
    the meshes (PyBullet) presses with the meshes' tool, so a policy trained on the
    primitives' point misses there (the xArm7's capsules: 9 mm)."""
    if arm.config.collision == "mesh" or arm.config.ee_offset:
        return ""
    mesh = arm_info(arm.config.replace(collision="mesh")).ee_offset
    gap = 1000 * float(np.linalg.norm(np.asarray(arm.ee_offset) - mesh))
    if gap < EE_NOTE_MM:
        return ""
    point = ", ".join(f"{v:g}" for v in mesh)
    return (
        f"; its ee point is {gap:.1f} mm from the meshes' {_vector(mesh)}, which engines that "
        f"keep the meshes (PyBullet) press with: set ee_offset = [{point}] in the arm file"
    )


def _linkage_lines(gripper) -> str:
    """What ``--check`` says of a linkage gripper: driven joint, followers, pads and sizes."""
    followers = ", ".join(f"{f.joint} x{f.multiplier:+g}" for f in gripper.followers)
    return (
        f"linkage: {gripper.joint} driven ({gripper.open_q:g} open to {gripper.closed_q:g} "
        f"closed), pads {' and '.join(gripper.pad_links[:2])}: stroke "
        f"{gripper.opening * 100:.1f} cm, pad width {gripper.pad_width * 100:.1f} cm, closes at "
        f"{gripper.pad_speed * 100:.0f} cm/s\n            followers ({len(gripper.followers)}, "
        f"<mimic>): {followers}"
    )


def _jaw_lines(gripper) -> str:
    """What ``--check`` says of a one-jaw gripper: the driven jaw, the fixed jaw, sizes."""
    moving, hand = gripper.pad_links[:2]
    fitted = " (pads fitted to the meshes)" if gripper.fitted.boxes else ""
    return (
        f"jaw: {gripper.joint} turns {moving} ({gripper.open_q:g} open to "
        f"{gripper.closed_q:g} closed) against the fixed jaw of {hand}{fitted}: opens "
        f"{gripper.opening * 100:.1f} cm, fixed jaw {gripper.pad_width * 100:.1f} cm wide"
    )


def check_lines(arm: ArmInfo, tasks: list[TaskConfig]) -> str:
    """Per task: whether the arm can do it and why not, with the derived setup."""
    lines = ["tasks"]
    for task in tasks:
        ok, why = task_verdict(arm, task)
        lines.append(f"  {task.task:<6} {'yes' if ok else 'no '}  {why}")
        if task.spec.gripper and gripper_problem(arm):
            continue
        setup = arm_setup(arm, task)
        lines.append(
            f"         home {_vector(setup.home_qpos)} ({setup.home_source}), "
            f"manipulability {setup.manipulability:.3f}"
        )
        lines.append(
            f"         {setup.reached} of {setup.targets} grid targets reached, slowest move "
            f"{setup.travel_time:.1f} s, episode {setup.episode_steps} steps"
        )
        lines += [f"         note: {note}" for note in setup.notes]
    return "\n".join(lines)


def arm_file_text(arm: ArmInfo, touch: ArmSetup | None = None) -> str:
    """The resolved arm as TOML: every default written out. A derived home (one per task) is
    written as a comment with Touch's, to fix it for every task by removing the ``#``."""
    values = {
        "urdf": str(arm.urdf),
        "ee_link": arm.ee_link,
        "joints": list(arm.joint_names),
        "ft_joint": arm.ft_joint,
        "collision": arm.config.collision,
        "kv_factor": round(float(arm.kv_factor), 6),
        "ee_offset": [round(float(v), 6) for v in arm.ee_offset],
    }
    # one ee_offset serves every task: an arm with a grip point of its own leaves it derived
    two_points = arm.grip_offset is not None and not arm.config.ee_offset
    two_points = two_points and not np.allclose(arm.grip_offset, arm.ee_offset, atol=1e-9)
    point = values.pop("ee_offset") if two_points else None
    repairs = UrdfRepairs.of(arm.config)  # written where set: the arm needs them to load
    values |= {key: value for key, value in dataclasses.asdict(repairs).items() if value}
    body = [f"{key} = {json.dumps(value)}" for key, value in values.items()]
    if point is not None:
        grip = [round(float(v), 6) for v in arm.grip_offset]
        body.append(
            f"# ee_offset = {json.dumps(point)}  # derived for Reach and Touch, {json.dumps(grip)} "
            "for Lift; set, one point serves every task"
        )
    if arm.config.home_qpos:
        body.append(f"home_qpos = {json.dumps([round(float(q), 6) for q in arm.home_qpos])}")
    elif touch is not None:
        home = [round(float(q), 6) for q in touch.home_qpos]
        body.append(f"# home_qpos = {json.dumps(home)}  # Touch's derived home")
    text = "\n".join(body)
    return f"# An arm file (mjx-arm train --arm THIS_FILE); every field as resolved.\n{text}\n"


def draw_check(arm: ArmInfo, tasks: list[TaskConfig], path: Path) -> None:
    """A PNG of the home pose of the first task the arm can do over the table and the task
    areas, from above and from the side: the arm's links, the grid targets (reached: dots,
    not: crosses) and the tool axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, side) = plt.subplots(1, 2, figsize=(11, 4.8))
    (x0, y0), (x1, y1) = table_top_extent()
    top.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, color="#c8b49a", alpha=0.5))
    side.plot([x0, x1], [0, 0], color="#8a6d4b", linewidth=4)
    shown = [t for t in tasks if not (t.spec.gripper and gripper_problem(arm))]
    for task, colour in zip(
        shown, ("tab:blue", "tab:red", "tab:green", "tab:purple"), strict=False
    ):
        _draw_targets(top, side, arm, task, colour)
    if shown:
        _draw_arm(top, side, arm, arm_setup(arm, shown[-1]))
    for ax, (label, axes) in zip(
        (top, side), (("from above", "xy"), ("from the side", "xz")), strict=True
    ):
        ax.set_title(f"{arm.urdf.name}: home over the task area, {label}")
        ax.set_xlabel(f"{axes[0]} (m)")
        ax.set_ylabel(f"{axes[1]} (m)")
        ax.set_aspect("equal")
        ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    image = io.BytesIO()
    fig.savefig(image, format="png", dpi=110)
    plt.close(fig)
    write_atomic(image.getvalue(), Path(path))  # its folder is made where missing


def _draw_targets(top, side, arm: ArmInfo, task: TaskConfig, colour: str) -> None:
    from mjx_arm.arm.setup import grid_targets

    setup = arm_setup(arm, task)
    points = grid_targets(task.replace(workspace_scale=setup.workspace_scale))
    solver = tool_down_solver(arm)
    home = np.asarray(setup.home_qpos)
    poses = solver.reach_from(home, points, tool_down=task.uses_contact)
    ok = np.array([p is not None for p in poses])
    for ax, j in ((top, 1), (side, 2)):
        ax.scatter(points[ok, 0], points[ok, j], s=14, color=colour, label=f"{task.task} targets")
        if (~ok).any():
            ax.scatter(points[~ok, 0], points[~ok, j], s=30, marker="x", color="black")


def _draw_arm(top, side, arm: ArmInfo, setup: ArmSetup) -> None:
    """The chain's body origins from the base to the ee point, and the tool axis."""
    solver = tool_down_solver(arm)
    model, data = solver.ik.model, solver.ik.data
    ee, axis = solver.ik.pose(np.asarray(setup.home_qpos))
    body = int(model.site_bodyid[solver.ik.site_id])
    chain = []
    while body > 0:
        chain.append(data.xpos[body].copy())
        body = int(model.body_parentid[body])
    points = np.array([*reversed(chain), ee])
    tip = ee + 0.1 * axis
    for ax, j in ((top, 1), (side, 2)):
        ax.plot(points[:, 0], points[:, j], "-o", color="dimgray", markersize=3, label="arm")
        ax.plot([ee[0], tip[0]], [ee[j], tip[j]], color="orange", label="tool axis")


def _vector(values) -> str:
    return "(" + ", ".join(f"{float(v):+.3f}" for v in values) + ")"
