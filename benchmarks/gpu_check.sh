#!/usr/bin/env bash
# --device cuda end to end, on a machine with an NVIDIA GPU and torch already installed (pecli's own
# dependencies installed, or their wheels in .whl/): train with the BiMDN belief on the GPU, resume the run
# there with a larger budget (replay buffer and belief fitter restored), play the checkpoint on the CPU, export
# it to ONNX, self-play on the GPU (an alternating round, a simultaneous one, a league with exploiters and join
# games resumed to a second round, its pursuer played on the CPU), a two-trial Optuna study in two processes, and
# the speed of training on each device (bench_train.py device).
# Prints PASS, or FAIL and the failed command; writes its logs to ${OUT:-runs/gpu_check} (relative to the
# repository's root).
#   bash benchmarks/gpu_check.sh [steps timed per device, default 8000]
set -Eeuo pipefail
trap 'echo "FAIL: $BASH_COMMAND" >&2' ERR
cd "$(dirname "$0")/.."
out=${OUT:-runs/gpu_check}
mkdir -p "$out"
if [ -d .whl ]; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
    export PYTHONPATH=/tmp/site:$PWD
else
    export PYTHONPATH=$PWD
fi
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
zoo=$(mktemp -d)
pecli() { python3 -m pecli "$@"; }

python3 -c "import torch; print('torch', torch.__version__, 'on', torch.cuda.get_device_name(0))"
step() { echo "== $*"; "$@" 2>&1 | tee -a "$out/check.log" | tail -n 4; }
step pecli train pursuer -c quick --belief bimdn --steps 11000 --device cuda --zoo "$zoo" --name gpu -q
step pecli train pursuer --resume --steps 13000 --device cuda --zoo "$zoo" --name gpu -q
python3 - "$zoo/gpu/pursuer/final.zip" <<'EOF'
import json, sys
from pathlib import Path
meta = json.loads(Path(sys.argv[1]).with_suffix(".json").read_text())
assert meta["steps"] >= 13000, meta["steps"]
print("resumed on the GPU to", meta["steps"], "transitions")
EOF
step pecli play --pursuer "$zoo/gpu/pursuer/final.zip" --evader greedy -c quick --episodes 50 --seed 0
step pecli export onnx "$zoo/gpu/pursuer/final.zip" --out "$zoo/gpu.onnx"
step pecli selfplay -c quick --belief bimdn --rounds 1 --steps-per-round 3000 --device cuda --zoo "$zoo" --name sp -q
step pecli selfplay -c quick --belief bimdn --schedule simultaneous --rounds 1 --steps-per-round 3000 --device cuda \
    --zoo "$zoo" --name sim -q
league=(-c quick --belief bimdn --opponents league --steps-per-round 2000 --device cuda --zoo "$zoo" --name league -q
        --set selfplay.league_exploiter_every=1 --set selfplay.exploiter_join_games=20)
step pecli selfplay "${league[@]}" --rounds 1
step pecli selfplay "${league[@]}" --rounds 2 --resume
python3 - "$zoo/league/selfplay.json" <<'EOF'
import json, sys
from pathlib import Path
turns = json.loads(Path(sys.argv[1]).read_text())["turns"]
assert max(t["round"] for t in turns) == 2, "the league run did not resume to round 2"
exploiters = [t for t in turns if t["learner"] == "exploiter"]
assert len(exploiters) == 4 and all(t["join_rate"] is not None for t in exploiters), exploiters
print("league on the GPU: 2 rounds,", len(exploiters), "exploiter turns with join games")
EOF
step pecli play --pursuer "$zoo/league/pursuer/round-002.zip" --evader circler -c quick --episodes 50 --seed 0
step pecli tune pursuer -c quick --trials 2 --jobs 2 --cpu-minutes 0.2 --evaluations 2 --eval-episodes 20 --device cuda \
    --dir "$zoo/tune"
test -s "$zoo/tune/quick-pursuer/report.md"
python3 benchmarks/bench_train.py device --steps "${1:-8000}" | tee "$out/device.md"
echo PASS
