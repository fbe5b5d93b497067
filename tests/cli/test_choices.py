"""Typed string choices (wresdyn.choices): one list of allowed values per setting, checked in one line."""

import subprocess
import sys
from typing import get_args

import pytest

from wresdyn.choices import Arch, ResidualKind, SolverKind, check_choice, check_number
from wresdyn.errors import WresdynError


def test_choices_are_checked_by_value_and_listed():
    assert check_choice("gru", Arch, "residual.arch") == "gru"
    with pytest.raises(WresdynError, match=r"^residual\.kind = 'Torque' is not one of: torque, delta_action$"):
        check_choice("Torque", ResidualKind, "residual.kind")
    with pytest.raises(WresdynError, match="is not an integer"):
        check_number(True, "ppo.num_envs", integer=True, ge=1)
    assert check_number(0.5, "x", gt=0, le=1) == 0.5


def test_solver_choices_match_the_solvers():
    from wresdyn.sim.solvers import SOLVERS

    assert get_args(SolverKind) == SOLVERS


def test_help_does_not_import_torch():
    code = "import sys; from wresdyn.cli import main\ntry: main(['train', '--help'])\nexcept SystemExit: pass\n" \
           "assert 'torch' not in sys.modules and 'warp' not in sys.modules, 'heavy import'"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-500:]
