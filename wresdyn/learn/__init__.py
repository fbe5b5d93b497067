"""Stage 4, the learners: grey-box identification of the simulator's own physics (:mod:`.sysid`), residual models (networks, the parametric baseline), Table I rewards, the PPO replay
environment and trainer (rsl-rl), the gradient fit through the differentiable simulation, and the file format every
learned network is saved in (:mod:`.network_file`)."""
