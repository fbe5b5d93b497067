"""A residual learned by PPO (rsl-rl): the replay environment (:mod:`.replay_env`, its settings in
:mod:`.replay_env_config`), the Table I rewards (:mod:`.rewards`), the run configuration (:mod:`.ppo_config`), the
rsl-rl runner glue the skills share (:mod:`.runner`), the one-sync update (:mod:`.update`), the packed update
(:mod:`.packed_update`) and its CUDA-graph form (:mod:`.graph_update`), and the trainer (:mod:`.trainer`)."""
