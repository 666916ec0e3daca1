"""Position-controlled copies of the CPU envs: the same task, a position servo on each joint.

A real UR5e takes joint position targets (URScript ``servoj``, or a ROS 2 position controller)
where the training envs take velocity targets. These envs keep everything of the contract
(spaces, observation, reward, success, termination, sampling: all from :class:`BaseRobotEnv`)
and change only the actuation. The action is still the contract's velocity action; the env's
velocity hook passes the joint velocity targets through the sim-to-real chain,
:class:`VelocityToPositionAdapter` then :class:`SafetyLimiter`, and the limiter's command becomes
the position servos' target. A policy runs on these envs unchanged, and what the robot would
have been sent is logged per episode (:attr:`episodes`).

The servo is a position loop around the env's own velocity servo, as in an industrial joint
drive (position loop, velocity loop, current loop)::

    torque = clip(kv * (K * (q_target - q) - qdot), +-effort)

``kv`` is the velocity actuator's gain of the converted model (the smallest apparent joint
inertia over the joint ranges divided by ``sim_dt``, see
:class:`mjx_arm.urdf.convert.ConvertConfig`), ``effort`` the URDF torque cap and ``K`` the
position-loop gain (1/s) of :class:`ServoConfig`. So ``kp = K * kv`` and the damping is the
velocity loop's own ``kv``. Gravity compensation, joint damping and armature are the velocity
model's. In MuJoCo the loop is a ``position`` actuator (``kp``, ``kv``), made by editing the
compiled task model's actuators in place (the model's ids and sensors are those of the velocity
env); in PyBullet it is applied as torques at every substep, like the velocity servo there.

How the commands reach the servo (:class:`ServoConfig`). By default they are streamed at the
servo rate with velocity feed-forward, as a drive's trajectory interface does: within a control
period the reference runs on the line from the previous command to the current one, and the
velocity target is ``v_cmd + K * (q_ref - q)`` with ``v_cmd`` the limiter's command velocity
(in MuJoCo: the position actuator's control ``q_ref + v_cmd / K``). The feed-forward does the
moving, so ``K`` (10 /s) only pulls drift back onto the command path and the arm stays as
compliant to contact as the velocity servo the policy was trained on. With ``feedforward``
off, each command is held for the whole control period and the loop is ``K * (q_cmd - q)``
alone: to move at ``v`` the command must lead the arm by ``v / K`` and a period of motion, and a
joint blocked by the table or the cube pushes that much harder (Lift lost up to half its
episodes that way in C MuJoCo: benchmarks/results/sim2real/).

Stability: around one joint of inertia ``I`` the loop is ``I s^2 + kv s + kv K``. With
``b = kv / I`` (the velocity loop's bandwidth: 240 /s at the smallest inertia, about 100 /s for
the shoulder lift at the home pose) the damping ratio is ``0.5 * sqrt(b / K)``: above 1 for
every joint at ``K = 10`` (0.79 at the shoulder lift for ``K = 40``), so no joint rings.
