"""The kick successes of every ``floor_kick_gap.py`` output here, per policy and condition, summed over the runs
that played it: ``../kick55/kick_table.py``'s table of this folder's files, with this folder's calibrated variants
(``python kick_table.py PREFIX... > table.md``)."""

import importlib.util
from pathlib import Path

HERE = Path(__file__).parent
VARIANTS = (("cal_torso_hiproll", "torso+hip roll limits true"), ("cal_torso_effort", "torso+effort true"),
            ("cal_hiproll", "hip roll limits true"), ("cal_effort", "effort true"), ("cal_torso", "torso true"))
"""The calibrated folders of ``../kick55/variants.py`` and ``variants_hip.py`` and their labels, the longest name
first."""

if __name__ == "__main__":
    spec = importlib.util.spec_from_file_location("kick55_table", HERE.parent / "kick55" / "kick_table.py")
    table = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(table)
    table.main(HERE, VARIANTS)
