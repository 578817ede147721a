#!/bin/bash
# The fast learner's DQN timesteps/s with its gradient updates on CUDA and on one CPU core of the same machine,
# alternating (cpu, cuda, cpu, cuda; 2 rounds of 50,000 timesteps on m5 each), nothing else running. Made for the
# device machine, which starts bare with its own torch: run it from the repository root with gymnasium,
# stable-baselines3, farama-notifications, cloudpickle and tqdm wheels in .whl/ (pip download ... -d .whl), and
# OUT set to the folder that receives the JSON files (one per call of eval/bench_train.py).
#   OUT=/tmp/gpu bash eval/gpu_bench_train.sh
set -u
python3 -m pip install --no-deps --root-user-action=ignore -q .whl/*.whl 2>&1 | tail -2
# the wheel's package data (maps, models) without installing the package
ln -sfn ../maps garage_mj/maps; ln -sfn ../models garage_mj/models
export PYTHONPATH=$PWD
python3 -c "import torch; print(torch.__version__, torch.cuda.get_device_name(0))" || exit 3
for d in cpu cuda cpu cuda; do
  taskset -c 0 timeout 100 python3 eval/bench_train.py --maps m5_13x13_aligned --timesteps 50000 --learners fast \
    --rounds 2 --set "device=\"$d\"" --json "$OUT/bench_train_${d}_$(date +%s).json" 2>&1 | tail -3
done
