"""Evaluation: open-loop replay of held-out and out-of-distribution recordings, metrics, reports,
rollouts side by side as a USD animation (:mod:`wresdyn.evaluation.animation`) and in the browser
(:mod:`wresdyn.evaluation.viewer`)."""
