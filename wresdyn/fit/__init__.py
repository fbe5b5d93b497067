"""A residual learned by gradient descent through the differentiable simulation (:mod:`.gradfit`, its settings in
:mod:`.gradfit_config`), alone or on top of physics identified first (:mod:`.hybrid`, which runs
:mod:`wresdyn.identify`)."""
