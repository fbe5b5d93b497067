"""Experiments: the drivers that train and compare several things, above the learners, the evaluation and
the skills (and below the command line, which only parses flags and calls them).

- :mod:`.ablation`: PPO vs gradient vs parametric × network × residual kind × seeds, evaluated identically
  (``wresdyn ablate``);
- :mod:`.skills`: the zero-shot skill benchmark, on the stand (``wresdyn deploy``) or on the floor (``wresdyn deploy
  --floor``), the task config's variant;
- :mod:`.zero_shot`: the skill benchmark's pieces: the four policies and the plant each trains on, the corrections
  fitted on the stand, the results file;
- :mod:`.nominal_policy`: the floor's CPU run: (a) taken from a policy shipped at full size, checked to fit, and the
  held-out families it deploys on, chosen on validation motions;
- :mod:`.demo_pipeline`: the whole story at a small size, record → fit → calibrated robot → skills (``wresdyn demo``).
"""
