"""Checks that a loaded policy's metadata agrees with itself and with the env it is run in.

The standalone runtime (:mod:`mjx_arm.policy.numpy_policy`) checks each metadata field's type;
it cannot know the registered tasks or an env's observation keys. These checks can, and run
before an episode starts, so that a policy file whose metadata names a task that does not exist,
records a control step other than its training task's, or reads observation keys the env does
not give is a :class:`~mjx_arm.policy.PolicyFileError` (exit 2), not a traceback in its first
step or a run of a task it never learned.
"""

from __future__ import annotations

import math
from typing import Any

from mjx_arm.task.config import TaskConfig


def check_recorded_task(policy: Any, trained: TaskConfig | None) -> None:
    """The policy's metadata ``task`` is a registered task and, with the training task config
    ``trained`` (None: the file records none), its name; ``ctrl_dt`` is that task's.

    Raises:
        PolicyFileError: an unknown task, or metadata that disagrees with the training config.
    """
    from mjx_arm.policy import PolicyFileError
    from mjx_arm.task.registry import task_names

    metadata = getattr(policy, "metadata", {})
    name = metadata.get("task")
    if name is not None and name not in task_names():
        raise PolicyFileError(
            f"the policy's metadata names task {str(name)[:60]!r}, not a registered task "
            f"({', '.join(task_names())}): a damaged policy file; export it again"
        )
    if trained is None:
        return
    if name is not None and name != trained.task:
        raise PolicyFileError(
            f"the policy's metadata names task {name!r}, its training config {trained.task!r}: "
            "a damaged policy file; export it again (mjx-arm export RUN_DIR -o POLICY)"
        )
    ctrl_dt = metadata.get("ctrl_dt")
    if ctrl_dt is not None and not math.isclose(ctrl_dt, trained.ctrl_dt, rel_tol=1e-9):
        raise PolicyFileError(
            f"the policy's metadata records ctrl_dt {ctrl_dt!r} s, its training task "
            f"{trained.ctrl_dt!r} s: a damaged policy file; export it again"
        )


def check_obs_layout(policy: Any, layout: tuple[tuple[str, int], ...], where: str) -> None:
    """The observation keys and sizes the policy reads are those of ``layout`` (the env's
    :func:`~mjx_arm.task.observation.obs_layout`; the order may differ: the policy assembles
    its state in its own order).

    Raises:
        PolicyFileError: a key the env does not give, or of another size, named.
    """
    from mjx_arm.policy import PolicyFileError

    have = [(str(k), int(n)) for k, n in getattr(policy, "obs_layout", layout)]
    given = dict(layout)
    wrong = [(k, n) for k, n in have if given.get(k) != n]
    if wrong or len(have) != len(given):
        shown = ", ".join(f"{k[:40]!r} ({n})" for k, n in wrong[:3]) or "fewer keys"
        raise PolicyFileError(
            f"the policy reads observation keys the env does not give: {shown}; {where} gives "
            f"{', '.join(k for k, _ in layout)}: pass the task (--task) and arm (--arm) it "
            "was trained on"
        )
