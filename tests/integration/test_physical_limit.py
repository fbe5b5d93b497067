"""``benchmarks/speed/physical_limit.py``'s count of a generated step kernel's FLOPs and bytes, on a kernel written by
hand whose counts are known: each ``+ - * /`` once (a helper's at each call, the friction block only with friction),
no index arithmetic, each per-world array element once, a constant-index (shared) element left out."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE = '''
@wp.func
def helper(x: S):
    return x * x + S(1.0)


@wp.kernel(enable_backward=False, **KERNEL)
def replay_step(world_start: int, dt: S, fric_m0: wp.array(dtype=S), ke: wp.array(dtype=S),
                body_com: wp.array(dtype=V3), body_inertia: wp.array(dtype=M33), joint_q_out: wp.array(dtype=S)):
    w = wp.tid() + world_start
    bd = w * 2
    a = ke[bd + 0] * ke[bd + 1] - fric_m0[3]
    c = body_com[w]
    i = body_inertia[w]
    b = helper(a) + wp.sin(helper(a))
    if fric_on:
        b = b / (a * dt)
    joint_q_out[bd + 0] = b
    joint_q_out[bd + 0] = b * c[0]
'''


def _script():
    spec = importlib.util.spec_from_file_location("physical_limit", ROOT / "benchmarks/speed/physical_limit.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_counts_of_a_hand_written_step():
    count = _script().count_code
    ops, touched = count(SOURCE, friction=False)
    # mul: ke * ke, helper twice, b * c[0]; add: helper twice, helper + sin; sub: - fric_m0
    assert ops == {"mul": 4, "add": 3, "sub": 1, "call sin": 1}
    assert touched == 2 * 4 + 12 + 36 + 4  # ke twice, one vec3, one mat33, joint_q_out[bd + 0] once; fric_m0 shared
    ops, touched = count(SOURCE, friction=True)
    assert ops == {"mul": 5, "add": 3, "sub": 1, "div": 1, "call sin": 1}
    assert touched == 60
