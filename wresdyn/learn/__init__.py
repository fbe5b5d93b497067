"""What every learner shares: run folders and checkpoints (:mod:`.runs`), the window-fit loop of the gradient
learners (:mod:`.window_fit`, its learning-rate schedules in :mod:`.schedule`), the residual models (networks in
:mod:`.residual`, the parametric baseline in :mod:`.parametric`), model selection on the validation split
(:mod:`.selection`) and the file format every learned network is saved in (:mod:`.network_file`). The learners
themselves sit above it: :mod:`wresdyn.identify`, :mod:`wresdyn.fit`, :mod:`wresdyn.ppo`."""
