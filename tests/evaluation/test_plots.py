"""The learning curves' reader: a run without tensorboard events (a gradient fit) reads none without importing
tensorboard's reader; a run with events reads their scalars."""

import subprocess
import sys

import numpy as np

from wresdyn.evaluation.plots import learning_curves


def test_a_run_without_events_has_no_curves_and_leaves_tensorboard_unimported(tmp_path):
    code = ("import sys; from wresdyn.evaluation.plots import learning_curves; "
            f"assert learning_curves({str(tmp_path)!r}) == {{}}; "
            "print(any(m.startswith('tensorboard') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_run_with_events_reads_their_scalars(tmp_path):
    from torch.utils.tensorboard import SummaryWriter

    with SummaryWriter(str(tmp_path)) as w:
        for step, value in ((1, 0.5), (2, 0.25)):
            w.add_scalar("Error/mean_abs_dq", value, step)
    curves = learning_curves(tmp_path)
    steps, values = curves["Error/mean_abs_dq"]
    assert steps.tolist() == [1, 2] and np.allclose(values, [0.5, 0.25])
