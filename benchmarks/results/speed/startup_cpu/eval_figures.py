"""The evaluation of a fit's run folder with its figures drawn in worker processes against drawn in this process.

    python eval_figures.py RUN DATA [--pairs 3]      (from the tree to time, PYTHONPATH naming it)

Each pair evaluates RUN on DATA's splits twice in this process (``evaluate_run``, on the CPU, into a temporary
folder): once as the tree does it (the figures in a :class:`~wresdyn.evaluation.figure_pool.FigurePool`), once with the
pool replaced by one that draws each figure here when it is submitted (what the tree before did), in alternating
order; prints the seconds of each and whether the two folders' files are the same bytes.
"""
import argparse
import filecmp
import tempfile
import time
from pathlib import Path


class Here:
    """A figure pool that draws each figure in this process as it is submitted."""

    def __init__(self, *a, **k):
        pass

    def submit(self, fn, *a, **k):
        fn(*a, **k)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("data")
    ap.add_argument("--pairs", type=int, default=3)
    args = ap.parse_args()
    # imported here, not at the top: a spawned figure worker runs this file's top level as it starts
    import wresdyn.evaluation.evaluate_run as er
    from wresdyn.data.loading import load_data

    ds, robot = load_data(args.data, None, None)
    pool = er.FigurePool
    er.evaluate_run(args.run, ds, robot, out=tempfile.mkdtemp())  # warm: kernels loaded, modules imported
    for i in range(args.pairs):
        outs = {}
        for name in (("workers", "here") if i % 2 == 0 else ("here", "workers")):
            er.FigurePool = pool if name == "workers" else Here
            outs[name] = Path(tempfile.mkdtemp())
            t = time.perf_counter()
            er.evaluate_run(args.run, ds, robot, out=str(outs[name]))
            print(f"pair {i + 1} {name}: {time.perf_counter() - t:.2f} s", flush=True)
        names = sorted(p.name for p in outs["here"].iterdir())
        same = all(filecmp.cmp(outs["here"] / n, outs["workers"] / n, shallow=False) for n in names
                   if n != "report.md")
        print(f"pair {i + 1}: {len(names)} files, the same bytes: {same}", flush=True)


if __name__ == "__main__":
    main()
