"""Stage 4, the learners: grey-box identification of the simulator's own physics (:mod:`.sysid`), residual models (networks, the parametric baseline), Table I rewards, the PPO replay
environment and trainer (rsl-rl), and the gradient fit through the differentiable simulation."""
