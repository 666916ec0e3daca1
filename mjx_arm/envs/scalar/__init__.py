"""The CPU envs' step on Python floats: the task's rules, one env at a time, without numpy's
cost per call.

A CPU env scores one step at a time on a handful of floats, where numpy's cost per call (a few
microseconds) would be most of the step. The rules stay in :mod:`mjx_arm.task`, written once
against an array namespace; this package serves them to one env:

* :mod:`~mjx_arm.envs.scalar.xp`: :data:`~mjx_arm.envs.scalar.xp.SCALAR_XP`, numpy's names
  with a plain Python path for scalars and short lists;
* :mod:`~mjx_arm.envs.scalar.state`: the flat state, distance and force of a reading in floats;
* :mod:`~mjx_arm.envs.scalar.step`: what one step's scoring takes and gives
  (:class:`~mjx_arm.envs.scalar.step.StepInput`, :class:`~mjx_arm.envs.scalar.step.StepOutcome`)
  and the rules run through ``SCALAR_XP``;
* :mod:`~mjx_arm.envs.scalar.codegen`: the same rules traced once into one straight-line
  function per task and arm, with the ``SCALAR_XP`` path where they do not trace.

Every value is the one the rules give through numpy (the tests say how closely).
"""
