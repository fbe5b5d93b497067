"""Stage 5, evaluation: open-loop replay of held-out and out-of-distribution recordings, metrics, reports,
and the learner ablation."""
