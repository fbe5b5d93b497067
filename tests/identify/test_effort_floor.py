"""The identification's floor on the effort limit (``SysIdConfig.effort_floor``): the effort search's grid is raised to
it, every step is projected above it, the default keeps the coordinate's own floor, and a bad value is a one-line
error. The file's limits as a candidate of the selection (``SysIdConfig.effort_reset``): kept where validation
is better."""

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.cli import main
from wresdyn.data.mismatch import Mismatch
from wresdyn.identify.sysid import PhysicsScore, SysIdConfig, identify
from wresdyn.sim.physics import PhysicalParams, PhysicsModel

FLOOR = 0.8
"""Fraction of the file's effort limit the bounded runs keep."""
LOW = SysIdConfig(iterations=4, windows=4, horizon_curriculum=(8, 16), effort_grid=(0.05, 0.3), effort_after=0.0)
"""The effort limit in the fit from the first step, its search among limits far below the floor."""


@pytest.fixture(scope="module")
def train_only(humanoid, record):
    # no validation split: what identify returns is the last step's parameters, not a selected earlier one
    return record(humanoid, Mismatch(torque_limit_scale=0.5), {"train": 2}, seconds=0.3, amplitude=0.3)


def test_the_floor_raises_the_search_and_bounds_every_step(humanoid, train_only):
    file = np.asarray(humanoid.effort)
    free_search, bounded_search = [], []
    free, _ = identify(humanoid, train_only, LOW, log=lambda *_: None, on_search=free_search.append)
    bounded, _ = identify(humanoid, train_only, dataclasses.replace(LOW, effort_floor=FLOOR), log=lambda *_: None,
                          on_search=bounded_search.append)
    (f,), (b,) = free_search, bounded_search
    assert f.losses.shape == (2,) and b.losses.shape == (1,)  # 0.05 and 0.3 both raised to the floor: one point
    assert set(b.choice.values()) == {FLOOR}
    # four Adam steps from the search's limit (0.3 of the file's; here up to 0.41): the free fit stays below the
    # floor, the bounded one above it
    assert (free.effort / file).max() < 0.6
    assert (bounded.effort / file).min() >= FLOOR - 1e-12


def test_project_keeps_the_floor_and_the_default_keeps_its_own(humanoid):
    u = np.linspace(-0.5, 1.5, humanoid.n_dof)  # effort coordinates: fractions of the file's limits

    def projected(floor):
        model = PhysicsModel(humanoid, fit=("effort",), effort_floor=floor)
        with torch.no_grad():
            model.u_effort.copy_(torch.as_tensor(u))
        model.project()
        return model.u_effort.detach().numpy()

    assert np.array_equal(projected(None), np.maximum(u, 0.05))  # without the option: the coordinate's own floor
    assert np.array_equal(projected(FLOOR), np.maximum(u, FLOOR))
    assert np.array_equal(projected(0.0), np.maximum(u, 0.05))  # below the coordinate's own floor: that one


@pytest.fixture(scope="module")
def with_validation(humanoid, record):
    return record(humanoid, Mismatch(torque_limit_scale=0.5), {"train": 2, "validation": 1}, seconds=0.3, amplitude=0.3)


def test_effort_reset_keeps_the_files_limits_only_where_validation_is_better(humanoid, with_validation):
    data = with_validation
    score = PhysicsScore(humanoid, data.split("validation"), data.rate_hz, weights=data.fit_weights())
    file = np.asarray(humanoid.effort)
    cfg = dataclasses.replace(LOW, effort_grid=(), select_every=2)
    for frac in (0.05, 0.6):  # every candidate far below the truth (0.5 of the file's), then near it
        start = dataclasses.replace(PhysicalParams.nominal(humanoid), effort=frac * file)
        selected, _ = identify(humanoid, data, cfg, log=lambda *_: None, start=start)
        lines = []
        reset, _ = identify(humanoid, data, dataclasses.replace(cfg, effort_reset=True), log=lines.append, start=start)
        (line,) = [x for x in lines if x.startswith("effort limits at the file's")]
        before, at_file = score(selected), score(dataclasses.replace(selected, effort=file.copy()))
        assert score(reset) == pytest.approx(min(before, at_file), rel=1e-9)
        kept = at_file < before
        assert line.endswith("not kept") != kept
        assert np.array_equal(reset.effort, file if kept else selected.effort)


def test_a_bad_floor_is_refused_in_one_line(tmp_path, capsys):
    for value in ("1.5", "-0.1"):
        assert main(["identify", str(tmp_path / "none.npz"), "--effort-floor", value]) == 2
        err = capsys.readouterr().err
        assert "effort_floor" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(ValueError, match="effort_floor"):
        SysIdConfig(fit=("kp", "friction"), effort_floor=1.0)
    with pytest.raises(ValueError, match="effort_reset"):
        SysIdConfig(fit=("kp", "friction"), effort_reset=True)
