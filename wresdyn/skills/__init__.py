"""Using the corrected simulator: skills trained in it and deployed zero-shot on the real robot, on the stand
or on the floor (two task configurations of one pipeline, :class:`~.skill_config.SkillTaskConfig`).

- :mod:`.families`: the motion families of each task, one registry, and the keyframes each family draws;
- :mod:`.motions`: reference motions from those keyframes (sole IK and arm joints), placed on the floor for the floor
  task;
- :mod:`.plants`: what a skill acts on: the simulators (nominal, calibrated, delta action; :class:`~.plants.SimPlant`
  on :class:`wresdyn.sim.Simulator`) and the "real" robot (:class:`~.plants.RealPlant`, MuJoCo C);
- :mod:`.skill_config`: the configs of the task (its stand and floor variants) and of its PPO, torch-free (the
  command line reads them);
- :mod:`.reference`: the motions as the environment plays them (tensors at the policy rate), the base's IMU;
- :mod:`.env`: the tracking environment (rsl-rl ``VecEnv``) on any plant, either task;
- :mod:`.skill_ppo`: PPO and fine-tuning of a skill (rsl-rl), checkpoints and resume;
- :mod:`.evaluate`: deployment and its metrics (MPJPE, foot error or g-MPJPE, success, smoothness, the gap closed);
- :mod:`.feasibility`: what a floor motion asks of the robot (zero-moment point, joint torques), the screening of
  every floor motion drawn;
- :mod:`.ledger`: the held-out ledger, every configuration scored on held-out motions;
- :mod:`.report`: the report of a zero-shot benchmark, with its USD animation (:mod:`wresdyn.evaluation.animation`).
  The benchmark itself, which trains every policy, is :mod:`wresdyn.experiments.skills`.
"""
