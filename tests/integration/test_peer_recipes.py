"""The identification recipes of fight 1's wresdyn leg (``benchmarks/peers/recipe_search.py``): each is a valid
:class:`~wresdyn.identify.sysid_config.SysIdConfig`, ``default`` is its defaults (the leg without ``--recipe`` is
unchanged), and the leg's outputs are named after the recipe. No fit runs here (each takes minutes)."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path

import pytest

from wresdyn.identify.sysid_config import SysIdConfig

PEERS = Path(__file__).resolve().parents[2] / "benchmarks" / "peers"


@pytest.fixture(scope="module")
def recipes():
    sys.path.insert(0, str(PEERS))
    spec = importlib.util.spec_from_file_location("peers_recipe_search", PEERS / "recipe_search.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_recipe_is_a_config_and_default_is_the_defaults(recipes):
    assert recipes.recipe_config("default") == SysIdConfig()
    fields = {f.name for f in dataclasses.fields(SysIdConfig)}
    for name, over in recipes.RECIPES.items():
        assert set(over) <= fields, name
        cfg = recipes.recipe_config(name, "cpu")
        assert all(getattr(cfg, k) == v for k, v in over.items()), name
    with pytest.raises(SystemExit):
        recipes.recipe_config("no such recipe")


def test_the_leg_names_its_outputs_after_the_recipe():
    """Without ``--tag``: ``wresdyn_cpu`` / ``wresdyn_cuda`` for the defaults (as before recipes existed),
    ``wresdyn_RECIPE`` else; ``--tag`` wins."""
    if not hasattr(pytest.importorskip("mujoco.sysid"), "optimize"):  # humanoid.py imports the peer's adapter
        pytest.skip("mujoco[sysid] extra not installed (pip install -e '.[bench]')")
    spec = importlib.util.spec_from_file_location("peers_humanoid_recipes", PEERS / "humanoid.py")
    fight = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fight)
    assert fight.leg_tag(None, "default", "cpu") == "cpu"
    assert fight.leg_tag(None, "default", "cuda:0") == "cuda"
    assert fight.leg_tag(None, "refine", "cpu") == "refine"
    assert fight.leg_tag("cpu_peer_host", "refine", "cpu") == "cpu_peer_host"
    for name in ("default", "refine"):  # the parser takes a recipe and defaults to the defaults
        parsed = fight.build_parser().parse_args(["wresdyn", "d.npz", "--out", "o", "--recipe", name])
        assert parsed.recipe == name
    assert fight.build_parser().parse_args(["wresdyn", "d.npz", "--out", "o"]).recipe == "default"
