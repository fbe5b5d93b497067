"""The arguments `wresdyn collect` passes to data.real_robot.collect, with the code of the current directory."""
import dataclasses, json, os, sys, types
sys.path.insert(0, os.getcwd())
import wresdyn
assert wresdyn.__file__.startswith(os.getcwd())
import wresdyn.robot.description as description, wresdyn.data.real_robot as real_robot
from wresdyn.cli import main

class Captured(Exception):
    pass

class FakeRobot:
    source = types.SimpleNamespace(name="fake")
    def check_replay(self): pass

description.load_robot = lambda *a, **k: FakeRobot()
def capture(robot, mismatch, counts, duration=4.0, rate_hz=500.0, seed=0, excitation=None, store_tau=True, progress=None):
    raise Captured({"counts": counts, "duration": duration, "rate": rate_hz, "seed": seed,
                    "excitation": dataclasses.asdict(excitation), "store_tau": store_tau,
                    "mismatch": mismatch.to_dict()})
real_robot.collect = capture
O = ["--out", "/tmp/cli-check/collect_out", "--quiet"]
LINES = [[], ["--train", "16", "--validation", "4", "--heldout", "4", "--ood", "4", "--duration", "4", "--seed", "0",
              "--no-tau"], ["--mismatch", "data/mismatch_uneven.toml"], ["--excitation", "joint", "--max-velocity", "3"],
         ["--frames", "left_sole, right_sole"], ["--frames", "a,b", "--excitation", "foot", "--rate", "250"],
         ["--excitation", "auto", "--frames", "x"], ["--max-velocity", "20", "--duration", "2.5", "--ood", "0"],
         ["--mismatch", "none", "--seed", "7", "--train", "2", "--validation", "0", "--heldout", "1"]]
for argv in LINES:
    try:
        main(["collect", *argv, *O])
        raise SystemExit("no capture")
    except Captured as c:
        print(json.dumps({"argv": argv, **c.args[0]}, sort_keys=True))
