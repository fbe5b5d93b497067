"""The CUDA-graph update (:class:`wresdyn.ppo.graph_update.GraphPPO`) against the packed update it replays.

A CUDA graph cannot be captured on the CPU, so the CPU tests run the step the graph captures eagerly
(``static_update(capture=False)``: the same kept input buffers, the learning rate on the device, the gather inside
the step, the pinned normaliser std) and require it to equal :class:`~wresdyn.ppo.packed_update.PackedPPO` bit for
bit over two consecutive updates, in one process and in two over gloo; what the capture itself adds (the side-stream
warm-up, the replay, capturable Adam's rounding, NCCL inside the graph) is checked only where CUDA is present
(against :data:`~wresdyn.ppo.graph_update.CUDA_RTOL`)."""

import copy
import json
import os
import sys
from pathlib import Path

import pytest
import torch

from test_packed_update import KLS, _rollout, _state  # noqa: E402  (the same directory)
from wresdyn.config_fields import set_fields
from wresdyn.errors import WresdynError
from wresdyn.ppo.graph_update import CUDA_RTOL, GraphPPO
from wresdyn.ppo.packed_update import PackedPPO
from wresdyn.ppo.ppo_config import RESUME_MAY_CHANGE, PPOConfig
from wresdyn.ppo.trainer import runner_cfg

ROOT = Path(__file__).resolve().parents[2]
TESTS = Path(__file__).resolve().parents[1]
if str(TESTS) not in sys.path:  # run as torchrun's script: conftest's helpers
    sys.path.insert(0, str(TESTS))
from conftest import tiny_ppo_config as tiny, torchrun_two  # noqa: E402

UPDATES = 2
"""Consecutive updates compared: the second reads the normalisers' std pinned after the first and reuses the kept
buffers."""


def _updates(alg, storage, cls, run) -> tuple[list[torch.Tensor], float, list[dict]]:
    """``UPDATES`` updates of ``alg`` run as ``cls`` by ``run(alg)``, each on a copy of the same rollout and with its
    own seed of the mini-batch permutation (a captured graph may advance CUDA's generator other than the eager steps
    do, by the action samples the forward pass draws and discards): the state after them, the learning rate, the
    losses of each."""
    alg.__class__ = cls
    losses = []
    for k in range(UPDATES):
        alg.storage = copy.deepcopy(storage)
        torch.manual_seed(1 + k)
        losses.append(run(alg))
    return _state(alg), alg.learning_rate, losses


def compare(alg, run_graph=lambda alg: alg.static_update(capture=False)) -> dict:
    """The packed update and the graph update's step from the same state, rollout and mini-batch order: whether the
    weights, optimiser state and learning rate are equal, the largest difference relative to each tensor's size, the
    losses of both, whether the update moved the weights."""
    start = copy.deepcopy((alg.actor.state_dict(), alg.critic.state_dict(), alg.optimizer.state_dict(),
                           alg.learning_rate))
    before = [p.detach().clone() for p in (*alg.actor.parameters(), *alg.critic.parameters())]
    storage = copy.deepcopy(alg.storage)
    ref, ref_lr, ref_losses = _updates(alg, storage, PackedPPO, lambda a: a.update())
    moved = max(float((p.detach() - b).abs().max())
                for p, b in zip((*alg.actor.parameters(), *alg.critic.parameters()), before))
    alg.actor.load_state_dict(start[0])
    alg.critic.load_state_dict(start[1])
    alg.optimizer.load_state_dict(start[2])
    alg.learning_rate = start[3]
    got, lr, losses = _updates(alg, storage, GraphPPO, run_graph)
    alg.__class__ = PackedPPO
    rel = max(float((g.cpu().double() - r.cpu().double()).abs().max() / (r.cpu().double().abs().max() + 1e-7))
              for r, g in zip(ref, got) if r.is_floating_point() and r.numel())
    equal = len(ref) == len(got) and all(torch.equal(r.cpu(), g.cpu()) for r, g in zip(ref, got))
    return {"moved": moved, "equal": equal, "rel": rel, "lr": [ref_lr, lr, start[3]], "losses": [ref_losses, losses]}


@pytest.mark.parametrize("desired_kl", KLS)
def test_graph_step_equals_the_packed_update_on_the_cpu(robot, data, tmp_path, desired_kl):
    r = compare(_rollout(robot, data.split("train"), data.rate_hz, tmp_path, desired_kl))
    assert r["moved"] > 1e-4 and r["equal"]
    ref_lr, lr, lr0 = r["lr"]
    assert lr == ref_lr and lr != lr0
    assert r["losses"][1] == r["losses"][0]


def test_graph_update_on_the_cpu_is_the_packed_update(robot, data, tmp_path):
    """On the CPU ``update`` is the packed update itself: the same numbers, nothing kept for a graph."""
    alg = _rollout(robot, data.split("train"), data.rate_hz, tmp_path, 0.03)
    r = compare(alg, run_graph=lambda a: a.update())
    assert r["equal"] and r["losses"][1] == r["losses"][0]
    assert getattr(alg, "_static", None) is None and getattr(alg, "_graph", None) is None


def test_kept_tensors_and_the_recapture_check(robot, data, tmp_path):
    """The normalisers' std stays one tensor across updates (the graph reads it); a checkpoint loaded into the
    optimiser replaces Adam's state, which the inputs' addresses notice (a graph is then captured again)."""
    alg = _rollout(robot, data.split("train"), data.rate_hz, tmp_path, 0.03)
    storage = copy.deepcopy(alg.storage)
    alg.__class__ = GraphPPO
    alg.static_update(capture=False)
    std = alg.actor.obs_normalizer._std
    inputs = alg._inputs()
    alg.storage = copy.deepcopy(storage)
    alg.static_update(capture=False)
    assert alg.actor.obs_normalizer._std is std and alg._inputs() != inputs  # another storage, the same std
    inputs = alg._inputs()
    alg.optimizer.load_state_dict(copy.deepcopy(alg.optimizer.state_dict()))
    assert alg._inputs() != inputs


class _Recorded:
    """A stand-in for a captured graph on the CPU: its replay runs the step, after checking that no tensor the step
    reads was replaced since the capture (a real graph would read the old addresses)."""

    def __init__(self, alg, step) -> None:
        self.alg, self.step, self.inputs = alg, step, alg._inputs()

    def replay(self) -> None:
        assert self.alg._inputs() == self.inputs
        self.step()


@pytest.fixture
def recorded_capture(monkeypatch) -> list:
    """The CUDA path's warm-up and capture replaced by eager stand-ins (:class:`_Recorded`); the captures made."""
    captures = []
    monkeypatch.setattr(GraphPPO, "_on_side_stream", lambda self, step: step())
    monkeypatch.setattr(GraphPPO, "_capture", lambda self, step: captures.append(_Recorded(self, step)) or captures[-1])
    return captures


@pytest.mark.parametrize("desired_kl", KLS[:2])
def test_capture_path_order_equals_the_packed_update(robot, data, tmp_path, recorded_capture, desired_kl):
    """The CUDA path's control flow (``WARMUP`` eager mini-batches, one capture, the captured mini-batch and every
    later one replayed) with the capture recorded instead: the packed update bit for bit. ``compare`` gives each update
    a copied rollout, new tensors, so the second update captures again."""
    r = compare(_rollout(robot, data.split("train"), data.rate_hz, tmp_path, desired_kl),
                run_graph=lambda a: a.static_update(capture=True))
    assert r["moved"] > 1e-4 and r["equal"] and r["losses"][1] == r["losses"][0]
    assert len(recorded_capture) == UPDATES


def test_one_capture_while_the_inputs_stay(robot, data, tmp_path, recorded_capture):
    """A rollout refilled in place (as rsl-rl's runner does) keeps the graph; a checkpoint's optimiser state loaded
    replaces Adam's tensors, and the next update captures again instead of replaying on the old ones."""
    alg = _rollout(robot, data.split("train"), data.rate_hz, tmp_path, 0.03)
    saved = copy.deepcopy(alg.storage)
    alg.__class__ = GraphPPO

    def refill():
        st = alg.storage
        with torch.inference_mode():  # where the runner writes its rollout
            st.observations.copy_(saved.observations)
            for name in ("actions", "values", "returns", "actions_log_prob", "rewards", "dones"):
                getattr(st, name).copy_(getattr(saved, name))
            for mine, theirs in zip(st.distribution_params, saved.distribution_params):
                mine.copy_(theirs)
        st.advantages, st.step = saved.advantages.clone(), saved.step  # rsl-rl makes the advantages anew

    for _ in range(2):
        refill()
        alg.static_update(capture=True)
    assert len(recorded_capture) == 1
    alg.optimizer.load_state_dict(copy.deepcopy(alg.optimizer.state_dict()))
    refill()
    alg.static_update(capture=True)
    assert len(recorded_capture) == 2


def test_a_graph_update_run_on_the_cpu_is_the_packed_run(robot, data, tmp_path):
    """``wresdyn train`` on the CPU with the graph update (the default, or ``--ppo.graph-update True``) trains as with
    it off (the packed update runs), checkpoints as rsl-rl does, and the switch may change on resume."""
    from wresdyn.ppo.trainer import train

    cfg = tiny(iterations=2)
    assert cfg.ppo.graph_update is None
    train(data, robot, cfg, tmp_path / "default")
    train(data, robot, set_fields(cfg, {"ppo.graph_update": True}), tmp_path / "graph")
    train(data, robot, set_fields(cfg, {"ppo.graph_update": False}), tmp_path / "packed")
    ref = torch.load(tmp_path / "packed" / "model_1.pt", weights_only=True)
    for name in ("default", "graph"):
        got = torch.load(tmp_path / name / "model_1.pt", weights_only=True)
        for key in ("actor_state_dict", "critic_state_dict"):
            assert all(torch.equal(got[key][k], ref[key][k]) for k in ref[key]), (name, key)
        assert got["optimizer_state_dict"]["param_groups"] == ref["optimizer_state_dict"]["param_groups"], name
        opt, ref_opt = got["optimizer_state_dict"]["state"], ref["optimizer_state_dict"]["state"]
        assert opt.keys() == ref_opt.keys() and all(
            torch.equal(opt[k][f], ref_opt[k][f]) for k in ref_opt for f in ref_opt[k]), name
    assert all(type(g["lr"]) is float for g in ref["optimizer_state_dict"]["param_groups"])
    s = train(data, robot, set_fields(cfg, {"ppo.graph_update": False, "ppo.iterations": 3}), tmp_path / "default")
    assert s["iterations_this_session"] == 1


def test_graph_update_config():
    """The graph update is the residual's default (it runs on CUDA only); ``one_sync_update`` asked for takes its
    place, and both asked for are refused."""
    assert PPOConfig().graph_update is None and "graph_update" in RESUME_MAY_CHANGE
    for fields, name in (({}, "graph_update:GraphPPO"), ({"ppo.graph_update": True}, "graph_update:GraphPPO"),
                         ({"ppo.graph_update": False}, "packed_update:PackedPPO"),
                         ({"ppo.one_sync_update": True}, "update:OneSyncPPO"),
                         ({"ppo.one_sync_update": True, "ppo.graph_update": False}, "update:OneSyncPPO")):
        assert runner_cfg(set_fields(tiny(), fields))["algorithm"]["class_name"] == "wresdyn.ppo." + name, fields
    with pytest.raises(WresdynError, match="choose one"):
        PPOConfig(graph_update=True, one_sync_update=True)


def _torchrun_two(tmp_path, device: str) -> None:
    """This file's worker on two processes (gloo on the CPU, NCCL on two GPUs), its results in ``tmp_path``."""
    torchrun_two(__file__, str(tmp_path), device)


def test_graph_step_equals_the_packed_update_on_two_processes(tmp_path):
    """Two ranks over gloo, each its own rollout: the step the graph captures, with the KL packed into the gradients'
    all-reduce and the rate adapted on the device of every rank, against the packed update."""
    _torchrun_two(tmp_path, "cpu")
    for rank in (0, 1):
        for kl in KLS:
            r = json.loads((tmp_path / f"rank{rank}_kl{kl}.json").read_text())
            assert r["moved"] > 1e-4 and r["equal"], (rank, kl, r)
            ref_lr, lr, lr0 = r["lr"]
            assert lr == ref_lr and lr != lr0, (rank, kl, r)
            assert r["losses"][1] == r["losses"][0], (rank, kl, r)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="a CUDA graph is captured on CUDA only")
@pytest.mark.parametrize("desired_kl", KLS)
def test_captured_update_is_the_packed_update_within_rounding_on_cuda(robot, data, tmp_path, desired_kl):
    """The captured update (warm-up, capture, replays; capturable Adam) against the packed update on one GPU, over
    ``UPDATES`` updates: the rate moves the same way and every weight and optimiser tensor agrees to
    :data:`CUDA_RTOL` of its size."""
    alg = _rollout(robot, data.split("train"), data.rate_hz, tmp_path, desired_kl, device="cuda:0")
    r = compare(alg, run_graph=lambda a: a.update())
    assert r["moved"] > 1e-4 and r["rel"] <= CUDA_RTOL, r["rel"]
    ref_lr, lr, lr0 = r["lr"]
    assert lr == pytest.approx(ref_lr, rel=1e-6) and lr != lr0
    for ref, got in zip(*r["losses"]):
        assert got == pytest.approx(ref, rel=1e-3, abs=1e-6)


@pytest.mark.skipif(torch.cuda.device_count() < 2, reason="two GPUs: NCCL inside a captured graph")
def test_captured_update_is_the_packed_update_within_rounding_on_two_cuda_processes(tmp_path):
    """Two ranks on two GPUs over NCCL, the all-reduce inside each rank's graph: within :data:`CUDA_RTOL` of the
    packed update on every rank, the rate moved the same way."""
    _torchrun_two(tmp_path, "cuda")
    for rank in (0, 1):
        for kl in KLS:
            r = json.loads((tmp_path / f"rank{rank}_kl{kl}.json").read_text())
            assert r["moved"] > 1e-4 and r["rel"] <= CUDA_RTOL, (rank, kl, r["rel"])
            ref_lr, lr, lr0 = r["lr"]
            assert lr == pytest.approx(ref_lr, rel=1e-6) and lr != lr0, (rank, kl, r["lr"])


def _two_process_worker(out: Path, device: str) -> None:
    """One torchrun rank of the two-process tests: the packed update against the graph's step run eagerly (``cpu``,
    gloo) or against the captured update (``cuda``: this rank's GPU, NCCL)."""
    from wresdyn.data.dataset import load_dataset
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(ROOT / "data" / "dataset.npz", robot=robot)
    rank = int(os.environ["RANK"])
    trajs = data.split("train")[:2]
    for kl in KLS:
        (out / f"run{rank}_{kl}").mkdir()
        dev = f"cuda:{os.environ['LOCAL_RANK']}" if device == "cuda" else "cpu"
        alg = _rollout(robot, trajs, data.rate_hz, out / f"run{rank}_{kl}", kl, seed=rank, device=dev)
        assert alg.is_multi_gpu and alg.gpu_world_size == 2
        r = compare(alg) if device == "cpu" else compare(alg, run_graph=lambda a: a.update())
        (out / f"rank{rank}_kl{kl}.json").write_text(json.dumps(r))
    # gloo's worker threads must be joined before the interpreter ends: a process that exits with its group alive
    # may abort ("terminate called without an active exception") after its results are written; an NCCL group whose
    # all-reduce a graph captured hangs in destroy_process_group instead (the runner's close says so), so it is left
    # to the interpreter's exit
    torch.distributed.barrier()
    if torch.distributed.get_backend() != "nccl":
        torch.distributed.destroy_process_group()


if __name__ == "__main__":
    _two_process_worker(Path(sys.argv[1]), sys.argv[2])



def test_warm_up_releases_what_an_eager_update_kept(robot, data, tmp_path, monkeypatch):
    """An eager update leaves the actor's distribution with an autograd graph, which keeps the parameters' gradient
    accumulators (each tied to the stream it was made on) alive; the graph path's warm-up starts with that graph
    released, so the accumulators are made anew (one made on CUDA's legacy stream would make the captured backward
    touch that stream)."""
    alg = _rollout(robot, data.split("train"), data.rate_hz, tmp_path, 0.03)
    saved = copy.deepcopy(alg.storage)
    alg.update()
    assert alg.actor.output_mean.requires_grad
    seen = []
    monkeypatch.setattr(GraphPPO, "_on_side_stream",
                        lambda self, step: seen.append(self.actor.output_mean.requires_grad) or step())
    monkeypatch.setattr(GraphPPO, "_capture",
                        lambda self, step: seen.append(self.actor.output_mean.requires_grad) or _Recorded(self, step))
    alg.__class__ = GraphPPO
    alg.storage = saved
    alg.static_update(capture=True)
    assert seen == [False, True, True, False]  # released before the first warm-up and before the capture
