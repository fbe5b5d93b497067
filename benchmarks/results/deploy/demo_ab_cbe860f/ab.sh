export OMP_NUM_THREADS=1
for r in 3; do for t in old new; do
  d=/tmp/old; [ $t = new ] && d=/work/main
  cd $d; s=$(date +%s.%N)
  PYTHONPATH=$d /work/main/.venv/bin/python -m wresdyn.cli fit data/dataset.npz --iterations 150 --identify.iterations 150 --out /tmp/ab_$t$r > /tmp/ab_$t$r.log 2>&1
  echo "$t round $r rc=$? $(python3 -c "import time;print(round(time.time()-$s,1))") s"
done; done
