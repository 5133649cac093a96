#!/usr/bin/env bash
# Runs the seed records' studies, diagnoses and presses on the GPU machine inside one call's time limit, each
# resumed where an earlier call on the same machine stopped it, and packs each record (checkpoints left out: they
# are too large to bring back) into $OUT/NAME.tgz. Rerun the same line in the next call to go on.
#
#   bash docs/seeds/gpu_queue.sh SECONDS ENTRY ...
#
# SECONDS is the call's wall-time budget; the entries run one after another, each with what is left of it, less
# a margin for packing. One at a time: two processes on one GPU time-slice it, and on 2026-12-01 a 25,000-grain
# study beside a one-world press took 1,076 s where it had taken 516 s alone, and the press about 1,110 s against
# about 700 s (README, eighteenth stage).
#   NAME            warpdem study studies/NAME.toml
#   diagnose/NAME   warpdem diagnose studies/diagnose/NAME.toml
#   press, press80  seed 001's die press at the sixteenth stage's calibrated set (EDEM's standard rolling
#                   friction, X1 0.2752, X2 0.5904, X3 0.1052 J/m^2); press80 fills the die to 83.5 mm of loose
#                   height so that the bed settles near the seed's 80 mm
# Records go to ~/seeds/NAME on the machine (kept between calls while it stays warm).
set -uo pipefail
budget=$1
shift
start=$SECONDS
device=${GQ_DEVICE:-cuda:0}
press_set=(
  --set die_press.interaction.feed.feed.rolling_friction=0.2752
  --set die_press.interaction.feed.feed.static_friction=0.5904
  --set die_press.interaction.feed.feed.surface_energy=0.1052
  --set die_press.interaction.feed.feed.rolling_model=standard
  --set die_press.interaction.feed.steel.rolling_model=standard
)

left() { echo $((budget - (SECONDS - start) - 25)); }

run_entry() {
  local e=$1 s
  s=$(left)
  if ((s < 40)); then
    echo "gpu_queue: $e not started, ${s} s left" >&2
    return 0
  fi
  local name=${e#diagnose/} t0=$SECONDS rc
  echo "gpu_queue: $e with ${s} s" >&2
  case $e in
    diagnose/*) warpdem diagnose "studies/$e.toml" --device "$device" --out "$HOME/seeds/$name" --stop-after "$s" ;;
    press) python3 benchmarks/rigs_full.py --rig die_press --device "$device" --out "$HOME/seeds/$name" \
      --stop-after "$s" "${press_set[@]}" ;;
    press80) python3 benchmarks/rigs_full.py --rig die_press --device "$device" --out "$HOME/seeds/$name" \
      --stop-after "$s" "${press_set[@]}" --set die_press.fill_height=0.0835 ;;
    *) warpdem study "studies/$e.toml" --device "$device" --out "$HOME/seeds/$name" --stop-after "$s" ;;
  esac
  rc=$?
  echo "gpu_queue: $e exit $rc after $((SECONDS - t0)) s" >&2
}

for e in "$@"; do run_entry "$e"; done

for e in "$@"; do
  name=${e#diagnose/}
  [[ -d $HOME/seeds/$name ]] && tar -C "$HOME/seeds" --exclude='*.npz' -czf "$OUT/$name.tgz" "$name"
done
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
ls -la "$OUT"
