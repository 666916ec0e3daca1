#!/usr/bin/env bash
# The GPU measurements of benchmarks/results, one stage per call, on a machine with JAX + CUDA.
#
#   bash benchmarks/gpu_suite.sh setup        # install the wheels in .whl/ (and Warp's) once
#   bash benchmarks/gpu_suite.sh throughput   # Touch env steps/s, Warp against JAX, one GPU
#   bash benchmarks/gpu_suite.sh solve        # time to 95% from a cold start, Reach and Touch
#   bash benchmarks/gpu_suite.sh gentle       # Touch (gentle) at a few action scales, long runs
#   bash benchmarks/gpu_suite.sh scaling      # Touch training steps/s on 1 GPU and on 2
#   bash benchmarks/gpu_suite.sh cold-touch   # Touch cold and warm to 0.95, warmup then a start
#   bash benchmarks/gpu_suite.sh cold-lift    # Lift (gripper arm) cold and warm to 0.9
#   bash benchmarks/gpu_suite.sh cold-arm     # a mesh-collision arm: cold, a second task, warm
#   bash benchmarks/gpu_suite.sh warp-kernels # Warp's kernel compiles by optimisation level
#   bash benchmarks/gpu_suite.sh parity       # C MuJoCo, MJX on Warp and MJX on JAX agree
#   bash benchmarks/gpu_suite.sh sweep        # Touch over a few seeds per candidate (CANDIDATES)
#   bash benchmarks/gpu_suite.sh seeds        # the fast preset as shipped, seeds 0-9, both tasks
#   bash benchmarks/gpu_suite.sh coldseed     # one Touch seed with every cache empty
#   bash benchmarks/gpu_suite.sh transfer     # MJX rows of the transfer matrix, seeds' policies
#   bash benchmarks/gpu_suite.sh arms         # published arms with no arm file, over seeds
#   bash benchmarks/gpu_suite.sh jobs         # one seeds run per ARM:TASK:SEED item of JOBS
#   bash benchmarks/gpu_suite.sh scaling-gpus # 1, 2, 4 GPUs: steps/s per GPU, Touch time to 0.95
#   bash benchmarks/gpu_suite.sh seeds-gpus   # Touch seeds one per GPU against one after another
#   bash benchmarks/gpu_suite.sh campaign     # one seeds benchmark per GPU at once (JOBS), bounded
#
# Results (JSON and markdown) go to $OUT (default: benchmarks/results/gpu); the runs, their logs
# and the exported policies (.npz) to $WORK (default: runs/gpu_suite), never under
# benchmarks/results (benchmarks/README.md). Single-GPU stages use GPU 0 only.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-benchmarks/results/gpu}"
WORK="${WORK:-runs/gpu_suite}"
SITE="${SITE:-/tmp/site}"
mkdir -p "$OUT" "$WORK"
OUT=$(cd "$OUT" && pwd)  # absolute: some stages write it from inside $WORK
export PYTHONPATH="$SITE:$PWD" PYTHONUNBUFFERED=1 MUJOCO_GL="${MUJOCO_GL:-}"
[ -z "$MUJOCO_GL" ] && unset MUJOCO_GL
one_gpu() { CUDA_VISIBLE_DEVICES=0 "$@"; }
# export_runs DIR PREFIX: each run under DIR (with a checkpoint) to $WORK/policies/PREFIX_RUN.npz
export_runs() {
  mkdir -p "$WORK/policies"
  for run in "$1"/*/; do
    [ -d "$run/checkpoints" ] || continue
    python3 -m mjx_arm.cli export "$run" -o "$WORK/policies/$2_$(basename "$run").npz" || true
  done
}

case "${1:?stage}" in
setup)
  wheels=(.whl/*.whl)
  [ -n "${WARP_WHEEL:-}" ] && wheels+=("$WARP_WHEEL")
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target "$SITE" "${wheels[@]}" || exit 1
  # Warp as the pieces of an xz tarball of its wheel's files (without warp-clang.so, Warp's
  # CPU compiler): WARP_PARTS holds them, gathered over several calls
  if compgen -G "${WARP_PARTS:-/tmp/wparts}/wpart_*" >/dev/null; then
    cat "${WARP_PARTS:-/tmp/wparts}"/wpart_* | xz -dc | tar x -C "$SITE" || exit 1
  fi
  nvidia-smi --query-gpu=name,memory.total --format=csv
  python3 -c "import jax, mujoco, warp; from mujoco import mjx; print(jax.devices(), mujoco.__version__, warp.__version__)"
  ;;
throughput)
  one_gpu python3 benchmarks/bench_mjx_throughput.py --impls jax warp --batches 32768 131072 \
    --steps 50 --results-dir "$OUT" --name mjx_throughput_touch_impls
  ;;
solve)
  # Each task from a cold start in its own process. Touch in the seed variant: the task whose
  # time to solve the README compares across impls. EXTRA_SETS: more --set items (SUFFIX names).
  for task in reach touch; do
    one_gpu python3 benchmarks/bench_train.py --tasks "$task" --preset fast --cold \
      --set "physics.impl=${IMPL:-warp}" task.variant=seed stop_at_success=0.99 num_evals=21 \
      ${EXTRA_SETS:-} --devices 1 --out "$WORK/runs" --results-dir "$OUT" \
      --name "train_fast_${IMPL:-warp}_cold_$task${SUFFIX:-}"
  done
  export_runs "$WORK/runs" "solve_${IMPL:-warp}"
  ;;
gentle)
  # Gentle Touch (the default variant) at the given action scales, each run capped in time.
  for scale in ${SCALES:-0.15 0.3}; do
    one_gpu timeout "${RUN_LIMIT:-280}" python3 benchmarks/bench_train.py --tasks touch \
      --preset fast --set "physics.impl=${IMPL:-warp}" "task.action_scale=$scale" \
      num_timesteps="${STEPS:-150000000}" num_evals=16 stop_at_success=0.98 --devices 1 \
      --out "$WORK/gentle_$scale" --results-dir "$OUT" --name "gentle_touch_scale_$scale"
    export_runs "$WORK/gentle_$scale" "gentle_$scale"
  done
  ;;
scaling)
  # Strong scaling: the same global batch (32768 envs) on 1 GPU, then split over 2.
  sets=(num_envs=32768 batch_size=4096 num_minibatches=16 num_timesteps=30000000
        num_evals=6 stop_at_success=0)
  for devices in 1 2; do
    python3 benchmarks/bench_train.py --tasks touch --preset fast --devices "$devices" \
      --set "physics.impl=${IMPL:-warp}" "${sets[@]}" --out "$WORK/runs" --results-dir "$OUT" \
      --name "scaling_touch_${IMPL:-warp}_${devices}gpu"
  done
  ;;
cold-touch)
  # Touch on the shipped arm, every cache empty, then warm, each trained to 0.95 in a new
  # process (times from the command's start); then mjx-arm warmup with empty caches and a new
  # process's start after it. About 4-5 minutes.
  one_gpu python3 benchmarks/bench_cold_start.py --preset fast --tasks touch --to-threshold \
    --threshold 0.95 --warmup-task touch --child-timeout 200 --results-dir "$OUT" \
    --name cold_start_fast_touch 2>&1 | tee "$WORK/log_cold_touch.txt"
  ;;
cold-lift)
  # Lift on the shipped gripper arm (the preset's), cold then warm, each to 0.9. At most 8 min.
  one_gpu python3 benchmarks/bench_cold_start.py --preset fast --tasks lift --to-threshold \
    --threshold 0.9 --child-timeout 230 --results-dir "$OUT" --name cold_start_fast_lift \
    2>&1 | tee "$WORK/log_cold_lift.txt"
  ;;
warp-kernels)
  # MuJoCo Warp's kernel compiles module by module at Warp's optimisation levels (LEVELS), and
  # the physics speed each gives: a mesh-collision arm (ARM under ROBOTS, Reach) with the level
  # on its convex-collision kernels, then the shipped arm's Touch with it on every module.
  export ROS_PACKAGE_PATH="${ROBOTS:?folder that holds example-robot-data}"
  one_gpu python3 benchmarks/bench_warp_kernels.py --task reach --scope ccd \
    --arm "$ROBOTS/${ARM:-ur_description/urdf/ur5_robot.urdf}" --levels ${LEVELS:-default 2 1} \
    --results-dir "$OUT" --name warp_kernels_arm_ccd
  one_gpu python3 benchmarks/bench_warp_kernels.py --task touch --scope all \
    --levels ${LEVELS:-default 2 1} --results-dir "$OUT" --name warp_kernels_touch_all
  ;;
cold-arm)
  # A published arm with mesh collisions (ARM, a URDF under ROBOTS): its first task with every
  # cache empty, a second task in a new process on those caches, the first again (warm); each
  # start stops after its first epoch (compile figures). About 3 minutes.
  export ROS_PACKAGE_PATH="${ROBOTS:?folder that holds example-robot-data}"
  one_gpu python3 benchmarks/bench_cold_start.py --preset fast --tasks \
    --arm "$ROBOTS/${ARM:-ur_description/urdf/ur5_robot.urdf}" --arm-tasks reach touch \
    --child-timeout 170 --results-dir "$OUT" --name cold_start_fast_arm \
    2>&1 | tee "$WORK/log_cold_arm.txt"
  ;;
campaign)
  # One `bench seeds` per JOBS line: "GPU|NAME|TASK|SEEDS|SETS[|ARGS]" (SETS: a --set list, "-"
  # for the preset as shipped; ARGS: more `bench seeds` arguments, such as --arm A --threshold
  # 0.9, or --server: each seed's command run by a warm trainer per GPU). The GPUs run at once;
  # the lines of one GPU run one after another (several runs on one
  # GPU at once make their times incomparable, and three SO-101 runs on one H200 ran out of
  # memory). GPU may name a lane, "0:b": each lane of a GPU runs at once beside the others
  # (success over seeds, not times). GPU may also list several, "0,1", for seeds trained on all
  # of them (ARGS "--gpus-per-seed 2"; with --server, one warm group of those GPUs trains each
  # seed: `mjx-arm serve --devices 2`). Where lanes share a GPU, each process takes 0.6 / lanes of
  # its memory unless XLA_PYTHON_CLIENT_MEM_FRACTION says otherwise (three Lift runs at 0.3 each
  # left Warp out of memory). Every line stops DEADLINE seconds (default 540) after the
  # campaign's start. The runs' metrics, configs and start-up reports, and every report, go
  # into $OUT/NAME.tar.gz; with EXPORT=1 each run's policy (its final checkpoint, the best
  # evaluated one) also goes to $OUT/policies/NAME_RUN.npz. Last, one line per seed run
  # (benchmarks/campaign_brief.py).
  start=$SECONDS
  run_line() {  # GPU NAME TASK SEEDS SETS ARGS
    local set_args=() more=() left=$(( ${DEADLINE:-540} - (SECONDS - start) ))
    [ "$left" -le 10 ] && { echo "no time left for $2" > "$WORK/$2.log"; return; }
    [ "$5" != "-" ] && read -r -a set_args <<< "--set $5"
    read -r -a more <<< "${6:-}"
    CUDA_VISIBLE_DEVICES=${1%%:*} timeout "$left" python3 -m mjx_arm.cli bench seeds \
      --task "$3" --preset "${PRESET:-fast}" --seeds "$4" "${set_args[@]}" "${more[@]}" \
      --name "$2" --runs "$WORK/$2" --out "$WORK/$2/report" ${EXTRA:-} > "$WORK/$2.log" 2>&1
  }
  jobs_text="${JOBS:?one GPU|NAME|TASK|SEEDS|SETS per line}"
  lanes=$(cut -d'|' -f1 <<< "$jobs_text" | grep -v '^$' | sort -u | cut -d: -f1 | uniq -c \
    | sort -rn | head -1 | awk '{print $1}')
  share="${XLA_PYTHON_CLIENT_MEM_FRACTION:-0.$(printf %02d $((60 / ${lanes:-1})))}"
  [ "${lanes:-1}" -gt 1 ] && export XLA_PYTHON_CLIENT_MEM_FRACTION="$share"
  for gpu in $(cut -d'|' -f1 <<< "$jobs_text" | grep -v '^$' | sort -u); do
    (while IFS='|' read -r g name task seeds sets args; do
      [ "$g" = "$gpu" ] && run_line "$g" "$name" "$task" "$seeds" "$sets" "$args"
    done <<< "$jobs_text") &
  done
  wait
  for dir in "$WORK"/*/; do
    name=$(basename "$dir")
    (cd "$WORK" && find "$name" "$name.log" \( -name metrics.csv -o -name config.json \
      -o -name compile.json -o -name '*.log' -o -path '*/report/*' \) -print0 2>/dev/null \
      | tar --null -czf "$OUT/$name.tar.gz" -T -)
    if [ "${EXPORT:-0}" = 1 ]; then
      mkdir -p "$OUT/policies"
      for run in "$dir"*/; do
        [ -d "$run/checkpoints" ] || continue
        python3 -m mjx_arm.cli export "$run" -o "$OUT/policies/${name}_$(basename "$run").npz" \
          > /dev/null 2>&1 || echo "export failed: $run" &
      done
    fi
  done
  wait
  python3 -m benchmarks.campaign_brief "$WORK" ${THRESHOLD:+--threshold "$THRESHOLD"}
  ;;
sweep)
  # Candidate changes to the fast preset, each trained on SWEEP_SEEDS (exploration: the
  # reports say "with ..."). CANDIDATES: one quoted --set list per line.
  n=0
  while IFS= read -r sets; do
    [ -z "$sets" ] && continue
    n=$((n + 1))
    # shellcheck disable=SC2086
    one_gpu python3 -m mjx_arm.cli bench seeds --task "${TASK:-touch}" --preset fast \
      --seeds "${SWEEP_SEEDS:-0-2}" --set $sets --name "sweep_${TASK:-touch}_$n" \
      --runs "$WORK/sweep_runs_$n" --out "$OUT"
  done <<< "${CANDIDATES:?one --set list per line}"
  ;;
seeds)
  # The fast preset exactly as shipped, seeds one after another in one process per task.
  for task in ${TASKS:-touch reach}; do
    one_gpu python3 -m mjx_arm.cli bench seeds --task "$task" --preset fast \
      --seeds "${SEEDS:-0-9}" --runs "$WORK/seeds_runs_$task" --out "$OUT"
    export_runs "$WORK/seeds_runs_$task" "seeds_$task"
  done
  ;;
coldseed)
  # One Touch seed (not among 0-9) from a cold start: JAX, Warp and CUDA driver caches empty.
  MJX_ARM_JAX_CACHE="$(mktemp -d)" WARP_CACHE_PATH="$(mktemp -d)" CUDA_CACHE_PATH="$(mktemp -d)" \
    one_gpu python3 -m mjx_arm.cli bench seeds --task "${TASK:-touch}" --preset fast \
    --seeds "${COLD_SEED:-10}" --name "seeds_${TASK:-touch}_fast_cold_seed${COLD_SEED:-10}" \
    --runs "$WORK/cold_runs" --out "$OUT"
  ;;
transfer)
  # MJX rows of the transfer matrix (both implementations) for the exported Touch policies of
  # TRANSFER_SEEDS (from the seeds stage); the CPU rows run where PyBullet is installed.
  for seed in ${TRANSFER_SEEDS:-0 1 2}; do
    for impl in warp jax; do
      one_gpu python3 -m mjx_arm.cli bench transfer \
        "$WORK/policies/seeds_touch_touch-fast-seed$seed.npz" --engines mjx --impl "$impl" \
        --trained-on "MJX on Warp, H200, fast preset, seed $seed" \
        --name "transfer_touch_fast_seed${seed}_mjx_$impl" --out "$OUT/transfer"
    done
  done
  ;;
arms)
  # Published arm URDFs with no arm file and no --set: the fast preset as shipped over SEEDS,
  # for each of TASKS. ARMS: URDF paths under ROBOTS (a folder that holds example-robot-data).
  # PARALLEL: (arm, task) jobs at once on the one GPU (their compiles overlap; times measured
  # with jobs side by side say so in the file name).
  export ROS_PACKAGE_PATH="${ROBOTS:?folder that holds example-robot-data}"
  tag="${PARALLEL:-1}"; [ "$tag" = 1 ] && tag="" || tag="_x$tag"
  # JAX takes 75% of the GPU's memory per process unless told otherwise; Warp needs its own
  [ "${PARALLEL:-1}" -gt 1 ] && export XLA_PYTHON_CLIENT_MEM_FRACTION="0.$((60 / PARALLEL))"
  arm_task() {
    local urdf="$1" task="$2" name
    name=$(basename "$urdf" .urdf)
    one_gpu timeout "${RUN_LIMIT:-580}" python3 -m mjx_arm.cli bench seeds --task "$task" \
      --preset fast --seeds "${SEEDS:-0-1}" --arm "$ROBOTS/$urdf" \
      --name "seeds_${task}_fast_${name}$tag" --runs "$WORK/runs_${name}_$task" --out "$OUT" \
      > "$WORK/log_${name}_$task.txt" 2>&1
    export_runs "$WORK/runs_${name}_$task" "$name"
  }
  for urdf in ${ARMS:?URDF paths}; do
    for task in ${TASKS:-reach touch}; do
      while [ "$(jobs -rp | wc -l)" -ge "${PARALLEL:-1}" ]; do sleep 1; done
      arm_task "$urdf" "$task" &
    done
  done
  wait
  ;;
jobs)
  # The fast preset (or PRESET) as shipped, one process per item "ARM:TASK:SEED" of JOBS (ARM:
  # a URDF path under ROBOTS, or "shipped" for the task's shipped arm; SEED one seed or several
  # joined by "+", run one after another in the process), PARALLEL processes at once on the
  # one GPU, each stopped after RUN_LIMIT s. The file names carry _xPARALLEL. SETS: --set items for
  # every job (a variant of the preset; TAG names it in the file names). MEM_FRACTION: each
  # process's share of GPU memory (default 0.6 / PARALLEL; lower it where two suites share).
  export ROS_PACKAGE_PATH="${ROBOTS:-/tmp/robots}"
  tag="${TAG:-}_x${PARALLEL:-1}"
  export XLA_PYTHON_CLIENT_MEM_FRACTION="${MEM_FRACTION:-0.$(printf %02d $((60 / ${PARALLEL:-1})))}"
  read -r -a sets <<< "${SETS:-}"
  [ ${#sets[@]} -gt 0 ] && sets=(--set "${sets[@]}")
  seed_job() {
    local arm="${1%%:*}" rest="${1#*:}" task seed name args=()
    task="${rest%%:*}"; seed="${rest#*:}"
    name=$(basename "$arm" .urdf)
    [ "$arm" = shipped ] || args=(--arm "$ROBOTS/$arm")
    one_gpu timeout "${RUN_LIMIT:-580}" python3 -m mjx_arm.cli bench seeds --task "$task" \
      --preset "${PRESET:-fast}" --seeds "${seed//+/,}" "${args[@]}" "${sets[@]}" \
      --name "seeds_${task}_${PRESET:-fast}_${name}${tag}_seed${seed//+/_}" \
      --runs "$WORK/runs_${name}_${task}${TAG:-}_$seed" --out "$OUT" \
      > "$WORK/log_${name}_${task}${TAG:-}_seed$seed.txt" 2>&1
    export_runs "$WORK/runs_${name}_${task}${TAG:-}_$seed" "${name}_${task}${TAG:-}"
  }
  for item in ${JOBS:?ARM:TASK:SEED items}; do
    while [ "$(jobs -rp | wc -l)" -ge "${PARALLEL:-1}" ]; do sleep 1; done
    seed_job "$item" &
  done
  wait
  ;;
scaling-gpus)
  # Every GPU count of DEVICES on this host, one command each as a user types it (one process
  # per GPU, joined by jax.distributed): steady env steps/s at 8192 envs per GPU, then Touch's
  # time to 0.95 with the fast preset as shipped over SEEDS. Runs go to RUNS (not $OUT).
  # THROUGHPUT=0 skips the first part; SOLVE_DEVICES: the counts of the second (--append keeps
  # the others already in $OUT, so the counts can be measured over several calls).
  [ "${THROUGHPUT:-1}" = 1 ] && timeout "${RUN_LIMIT:-280}" python3 benchmarks/bench_scaling.py \
    throughput --devices ${DEVICES:-1 2 4} --out "$OUT" --runs "${RUNS:-/tmp/runs}" --limit 200 \
    --name scaling_throughput_touch
  timeout "${SOLVE_LIMIT:-600}" python3 benchmarks/bench_scaling.py solve --append \
    --devices ${SOLVE_DEVICES:-1 2 4} --seeds "${SEEDS:-0-2}" --out "$OUT" \
    --runs "${RUNS:-/tmp/runs}" --limit 200 --name "scaling_solve_touch${TAG:-}" ${SOLVE_ARGS:-}
  ;;
seeds-gpus)
  # Touch seeds (SEEDS) on one GPU, one process after another, then one per GPU at once.
  for n in ${GPU_COUNTS:-1 4}; do
    timeout "${RUN_LIMIT:-300}" python3 -m mjx_arm.cli bench seeds --task touch --preset fast \
      --seeds "${SEEDS:-0-3}" --devices "$n" --runs "${RUNS:-/tmp/runs}/seeds_${n}gpu" \
      --name "seeds_touch_fast_${n}gpu" --out "$OUT"
  done
  ;;
parity)
  one_gpu python3 -m mjx_arm.cli bench parity --engines mujoco mjx --impls warp jax \
    --out "$OUT/parity_gpu"
  ;;
*)
  echo "unknown stage $1" >&2
  exit 2
  ;;
esac
