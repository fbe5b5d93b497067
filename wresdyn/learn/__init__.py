"""What every learner shares: run folders and checkpoints (:mod:`.runs`, the resume check's comparison in
:mod:`.config_diff`), the window-fit loop of the gradient learners (:mod:`.window_fit`, the settings both share in
:mod:`.window_fit_config`, its learning-rate schedules in :mod:`.schedule`), the residual models (networks in
:mod:`.residual`, the parametric baseline in :mod:`.parametric`), model selection on the validation split
(:mod:`.selection`), the file format every learned network is saved in (:mod:`.network_file`) and a run's exported
residual read back without any learner (:mod:`.run_residual`). The learners themselves sit above it:
:mod:`wresdyn.identify`, :mod:`wresdyn.fit`, :mod:`wresdyn.ppo`."""
