"""Everything about an arm, in one place.

- :mod:`~mjx_arm.arm.config`: the arm as a config (a URDF or an arm file), saved with runs.
- :mod:`~mjx_arm.arm.info`: what every engine needs to know about it (:class:`ArmInfo`: joints,
  limits, tool frames, reach, servo gain, gripper), read once from its config and URDF.
- :mod:`~mjx_arm.arm.ik`, :mod:`~mjx_arm.arm.setup`: what a task derives from it (home pose by
  tool-down inverse kinematics, task area, episode length) and whether it can do the task.
- :mod:`~mjx_arm.arm.model_io`: the task's MuJoCo model of the arm and its sensor read-out.
- :mod:`~mjx_arm.arm.resolve`: a task and an arm resolved once into an :class:`ArmTask`, before
  any engine is built; engines, the trainer, evaluation and benchmarks take that object.
- :mod:`~mjx_arm.arm.report`, :mod:`~mjx_arm.arm.cli`: the report and ``mjx-arm arm``.

The package sits between the engines (:mod:`mjx_arm.envs`) and the task contract
(:mod:`mjx_arm.task`): it imports the task layer and the URDF pipeline, never an engine.
"""
