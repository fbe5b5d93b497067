"""The window-fit loop (:mod:`wresdyn.learn.window_fit`) on a toy learner: the schedule, scoring and selection on
validation, a run stopped with ``until`` and resumed equal to one run straight through, ``stop_below``, and loss
parts read back late (the CUDA-graph path) giving the same rows, the start rule (``beat_start_within``) and the
clocked log's set-up line."""

from dataclasses import dataclass

import numpy as np
import pytest
import torch

from wresdyn.learn.runs import RunFolder
from wresdyn.learn.window_fit import run_window_fit, schedule


@dataclass(frozen=True)
class Cfg:
    iterations: int = 20
    lr: float = 0.1
    lr_final: float = 0.01
    select_every: int = 4


class Toy:
    """Descends (w − 3)² with a noisy gradient drawn from the window sampler; validation prefers w = 2, so the
    selected iterate is the one passing closest to 2."""

    name, what, parts, checkpoint_keys, map_location = "toy", "toy fit", ("loss", "pos"), ("w",), "cpu"
    horizons = (2, 4)

    def __init__(self, rng, deferred=False):
        self.rng, self.deferred = rng, deferred
        self.module = torch.nn.Linear(1, 1, bias=False)
        with torch.no_grad():
            self.module.weight.fill_(0.0)
        self.seen = []

    def begin(self, run):
        run.best.take(self.score(), 0, self.module)

    def step(self, it, h, lr):
        self.seen.append((it, h, lr))
        w = self.module.weight
        noise = float(self.rng.normal()) * 0.01
        with torch.no_grad():
            w -= lr * (2 * (w - 3.0) + noise)
        loss = (w.detach() - 3.0) ** 2
        parts = torch.stack([loss.reshape(()), loss.reshape(()) * 0.5])
        if self.deferred:
            return {"h": h}, parts
        return {"h": h, "loss": float(parts[0]), "pos": float(parts[1])}, None

    def score(self):
        return abs(float(self.module.weight.detach()) - 2.0)

    def state(self):
        return {"w": self.module.state_dict()}

    def meta(self):
        return {}

    def restore(self, data):
        self.module.load_state_dict(data["w"])


def test_schedule_steps_the_horizons_and_decays_the_learning_rate():
    cfg = Cfg(iterations=10)
    assert [schedule(cfg, (2, 4), it)[0] for it in range(10)] == [2] * 5 + [4] * 5
    assert schedule(cfg, (2,), 0)[1] == pytest.approx(0.1)
    assert schedule(cfg, (2,), 5)[1] == pytest.approx(0.055)  # halfway down the cosine
    assert schedule(cfg, (2,), 9)[1] > 0.01


def _run(out, until=None, stop_below=None, deferred=False, cfg=Cfg()):
    rng = np.random.default_rng(0)
    toy = Toy(rng, deferred)
    run = RunFolder(out, {"iterations": cfg.iterations}, key="toy")
    curve = run_window_fit(cfg, toy, run, rng, log=lambda *_: None, until=until, stop_below=stop_below)
    return toy, run, [{k: v for k, v in r.items() if k != "wall"} for r in curve]


def test_the_loop_scores_selects_and_resumes_to_the_same_numbers(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    toy, run, curve = _run(None)
    assert [r["iteration"] for r in curve] == list(range(1, 21))
    scored = [r for r in curve if "validation" in r]
    assert [r["iteration"] for r in scored] == [4, 8, 12, 16, 20]
    best = min(scored, key=lambda r: r["validation"])
    assert run.best.iteration == best["iteration"] and toy.score() == best["validation"]  # the best one, restored
    assert not list(tmp_path.iterdir())  # a run without a folder writes nothing

    _, stopped, first = _run(tmp_path / "run", until=7)
    assert len(first) == 7 and stopped.best.iteration == 4 and (tmp_path / "run" / "checkpoint.pt").is_file()
    toy2, _, resumed = _run(tmp_path / "run")
    assert toy2.seen[0][0] == 7  # continued where it stopped
    assert resumed == curve  # the same rows as straight through, the window sampler included
    assert toy2.module.weight.item() == toy.module.weight.item()

    _, _, late = _run(None, deferred=True)
    assert late == curve  # parts read back late land in the same rows


def test_stop_below_ends_at_the_first_score_that_reaches_it():
    _, _, curve = _run(None, stop_below=0.5)
    scores = [r["validation"] for r in curve if "validation" in r]
    assert scores[-1] <= 0.5 and all(v > 0.5 for v in scores[:-1]) and "validation" in curve[-1]
    assert len(curve) < 20


def test_a_non_finite_loss_read_back_late_names_its_iteration():
    class Diverging(Toy):
        def step(self, it, h, lr):
            fields, parts = super().step(it, h, lr)
            return fields, parts * (float("nan") if it == 2 else 1.0)

    rng = np.random.default_rng(0)
    with pytest.raises(FloatingPointError, match="toy fit: non-finite loss at iteration 3"):
        run_window_fit(Cfg(), Diverging(rng, deferred=True), RunFolder(None, {}), rng, log=lambda *_: None)


def test_a_learner_names_its_own_error_for_a_non_finite_loss_read_back_late():
    """Identification's deferred step raises its own error (what to change) through ``non_finite``, with the
    iteration counted from 0 as its eager step counts it."""
    class Own(Toy):
        def step(self, it, h, lr):
            fields, parts = super().step(it, h, lr)
            return fields, parts * (float("nan") if it == 2 else 1.0)

        def non_finite(self, it):
            return ArithmeticError(f"own error at {it}")

    rng = np.random.default_rng(0)
    with pytest.raises(ArithmeticError, match="own error at 2"):
        run_window_fit(Cfg(), Own(rng, deferred=True), RunFolder(None, {}), rng, log=lambda *_: None)


@dataclass(frozen=True)
class PlateauCfg:
    iterations: None = None
    lr: float = 0.1
    lr_final: float = 0.025
    select_every: int = 2
    patience: int = 2
    min_improvement: float = 0.01
    lr_decay: float = 0.5
    max_iterations: int = 400
    max_seconds: float | None = None
    beat_start_within: int | None = None


class Target(Toy):
    """Descends towards the validation optimum itself (w = 2), so validation improves until w has arrived: a fit
    that must run until it plateaus, wherever the count would have stopped."""

    def step(self, it, h, lr):
        self.seen.append((it, h, lr))
        w = self.module.weight
        with torch.no_grad():
            w -= lr * 0.2 * (w - 2.0)
        loss = (w.detach() - 2.0) ** 2
        return {"h": h, "loss": float(loss), "pos": float(loss)}, None

    def score(self):  # a floor, as a real validation error has: the relative gains fade
        return super().score() + 0.05

    def on_stage(self, stage, it):
        self.stages = getattr(self, "stages", []) + [(stage, it)]


def _plateau(out, cfg=PlateauCfg(), until=None):
    rng = np.random.default_rng(0)
    toy, lines = Target(rng), []
    run = RunFolder(out, {"iterations": None}, key="toy")
    curve = run_window_fit(cfg, toy, run, rng, log=lines.append, until=until)
    return toy, run, curve, lines


def test_until_a_plateau_each_horizon_runs_until_validation_stops_improving_then_the_rate_falls():
    toy, run, curve, lines = _plateau(None)
    n = len(curve)
    assert 20 < n < 400  # neither a fixed count nor the ceiling
    assert any("converged" in line for line in lines), lines[-3:]
    stages = toy.stages
    assert [s for s, _ in stages] == [0, 1] and stages[0][1] == 0 and stages[1][1] > 0
    hs = [h for _, h, _ in toy.seen]
    assert hs == sorted(hs) and set(hs) == {2, 4}  # the curriculum in order, each horizon once
    lrs = [lr for _, h, lr in toy.seen if h == 4]
    assert lrs[0] == pytest.approx(0.0625)  # stage 1 of 2 starts at the cosine's rate halfway
    assert min(lrs) == pytest.approx(0.025) and lrs == sorted(lrs, reverse=True)  # plateaus lower it to lr_final
    scores = [r["validation"] for r in curve if "validation" in r]
    # when it stops, the last `patience` checks brought less than 1 % on the best before them
    assert min(scores[-2:]) > min(scores[:-2]) * 0.99
    assert run.best.value == min(scores)


def test_until_a_plateau_stops_at_the_ceiling_and_says_so():
    toy, _, curve, lines = _plateau(None, cfg=PlateauCfg(max_iterations=10))
    assert len(curve) == 10 and any("ceiling of 10 iterations" in line for line in lines)


def test_until_a_plateau_resumes_to_the_same_numbers(tmp_path):
    _, _, straight, _ = _plateau(None)
    _plateau(tmp_path / "run", until=len(straight) // 2)
    toy, _, resumed, lines = _plateau(tmp_path / "run")
    strip = lambda rows: [{k: v for k, v in r.items() if k != "wall"} for r in rows]  # noqa: E731
    assert strip(resumed) == strip(straight) and any("converged" in line for line in lines)


class Away(Target):
    """Drifts away from the validation optimum: no check ever beats the start."""

    def step(self, it, h, lr):
        self.seen.append((it, h, lr))
        w = self.module.weight
        with torch.no_grad():
            w -= lr * 0.2 * (w + 1.0)
        loss = (w.detach() + 1.0) ** 2
        return {"h": h, "loss": float(loss), "pos": float(loss)}, None


def _strip(rows):
    return [{k: v for k, v in r.items() if k != "wall"} for r in rows]


def _start_rule(learner, within, out=None, until=None):
    rng = np.random.default_rng(0)
    toy, lines = learner(rng), []
    run = RunFolder(out, {"iterations": None}, key="toy")
    curve = run_window_fit(PlateauCfg(beat_start_within=within), toy, run, rng, log=lines.append, until=until)
    return toy, run, curve, lines


def test_a_fit_that_never_beats_its_start_stops_after_beat_start_within_checks_with_the_same_selection():
    toy, run, curve, lines = _start_rule(Away, None)
    checks = _strip(r for r in curve if "validation" in r)
    assert len(checks) > 3 and all(r["validation"] >= run.best.value for r in checks)
    assert run.best.iteration == 0 and float(toy.module.weight.detach()) == 0.0  # the whole schedule selects the start
    toy3, run3, curve3, lines3 = _start_rule(Away, 3)
    assert _strip(r for r in curve3 if "validation" in r) == checks[:3] and len(curve3) == 3 * PlateauCfg.select_every
    assert run3.best.iteration == 0 and float(toy3.module.weight.detach()) == 0.0  # the same selection, earlier
    assert any("none of 3 validation checks beat the start's" in line for line in lines3), lines3[-3:]
    assert "selected iteration 0 by validation" in lines3[-1]


def test_a_fit_that_beats_its_start_runs_its_whole_schedule_whatever_beat_start_within_says():
    _, run, curve, _ = _start_rule(Target, None)
    _, run1, curve1, lines1 = _start_rule(Target, 1)
    assert _strip(curve1) == _strip(curve) and run1.best.iteration == run.best.iteration > 0
    assert not any("beat the start" in line for line in lines1)


def test_the_start_rule_counts_checks_across_a_resume(tmp_path):
    _, _, straight, _ = _start_rule(Away, 3)
    _start_rule(Away, 3, tmp_path / "run", until=2 * PlateauCfg.select_every)
    toy, run, resumed, lines = _start_rule(Away, 3, tmp_path / "run")
    assert _strip(resumed) == _strip(straight) and run.best.iteration == 0
    assert any("none of 3 validation checks" in line for line in lines)


def test_a_clocked_log_marks_the_end_of_the_set_up_before_the_start_is_scored():
    rng = np.random.default_rng(0)
    order = []

    class Marked(Toy):
        def begin(self, run):
            order.append("begin")
            super().begin(run)

    def log(line):
        order.append(line)

    log.clock = True  # as ClockLog's with WRESDYN_LOG_CLOCK=1
    run_window_fit(Cfg(), Marked(rng), RunFolder(None, {}), rng, log=log)
    assert order[:2] == ["toy fit: set up; scoring the start", "begin"]
    plain = []
    run_window_fit(Cfg(), Toy(np.random.default_rng(0)), RunFolder(None, {}), np.random.default_rng(0),
                   log=plain.append)
    assert not any("set up" in line for line in plain)  # without the clock the log is unchanged
