"""Experiments: the drivers that train and compare several things, above the learners, the evaluation and
the skills (and below the command line, which only parses flags and calls them).

- :mod:`.ablation`: PPO vs gradient vs parametric × network × residual kind × seeds, evaluated identically
  (``wresdyn ablate``);
- :mod:`.zero_shot`: what the two skill benchmarks share: the four policies and the plant each trains on, the
  corrections fitted on the stand, the results file;
- :mod:`.stand_skills`: the zero-shot skill benchmark on the stand (``wresdyn deploy``);
- :mod:`.floor_skills`: the same on the floor (``wresdyn deploy --floor``);
- :mod:`.demo_pipeline`: the whole story at a small size, record → fit → calibrated robot → skills (``wresdyn demo``).
"""
