"""Using the corrected simulator: skills trained in it and deployed zero-shot on the real robot.

- :mod:`.motions`: reference motions from keyframes (sole IK and arm joints): kick, squat, wave; march held out;
- :mod:`.plants`: what a skill acts on: the simulators (nominal, calibrated, delta action; :class:`~.plants.SimPlant`
  on :class:`wresdyn.sim.Simulator`) and the "real" robot (:class:`~.plants.RealPlant`, MuJoCo C);
- :mod:`.skill_config`: the configs of the task (stand, floor) and of its PPO, torch-free (the command line reads
  them);
- :mod:`.env`: the tracking environment (rsl-rl ``VecEnv``) on any plant;
- :mod:`.skill_ppo`: PPO and fine-tuning of a skill (rsl-rl), checkpoints and resume;
- :mod:`.evaluate`: deployment and its metrics (MPJPE, foot error, success, smoothness, the gap closed);
- :mod:`.report`, :mod:`.floor_report`: the report of a zero-shot benchmark, with its USD animation
  (:mod:`wresdyn.evaluation.animation`). The benchmarks themselves, which train every policy, are
  :mod:`wresdyn.experiments.stand_skills` and :mod:`wresdyn.experiments.floor_skills`.
"""
