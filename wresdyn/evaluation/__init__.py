"""Stage 5, evaluation: open-loop replay of held-out and out-of-distribution recordings, metrics, reports,
and the same replays in the browser (:mod:`wresdyn.evaluation.viewer`)."""
