#!/usr/bin/env bash
# Runs the seed records' studies, diagnoses and presses on the GPU machine inside one call's time limit, each
# resumed where an earlier call on the same machine stopped it, and packs each record (checkpoints left out: they
# are too large to bring back) into $OUT/NAME.tgz. Rerun the same line in the next call to go on.
#
#   bash docs/seeds/gpu_queue.sh SECONDS ENTRY ... [-- ENTRY ...]
#
# SECONDS is the call's wall-time budget; each entry gets what is left of it, less a margin for packing. Entries
# before "--" run one after another; those after it run in a second lane at the same time, on the same GPU (a
# one-world press is bound by launch latency and leaves the GPU mostly idle, so it costs a batched study little;
# the two lanes' wall times are then not each one's alone).
#   NAME            warpdem study studies/NAME.toml
#   diagnose/NAME   warpdem diagnose studies/diagnose/NAME.toml
#   press, press80  seed 001's die press at the sixteenth stage's calibrated set (EDEM's standard rolling
#                   friction, X1 0.2752, X2 0.5904, X3 0.1052 J/m^2); press80 fills the die to 83.5 mm of loose
#                   height so that the bed settles near the seed's 80 mm
#   secant          seed 001's secant step at 25,000 grains (docs/seeds/001/secant_step.py), written from the
#                   record of wetfeed_verify_large_standard_scaled_step run before it, and run where it is due
# Records go to ~/seeds/NAME on the machine (kept between calls while it stays warm).
set -uo pipefail
budget=$1
shift
start=$SECONDS
device=${GQ_DEVICE:-cuda:0}
lane_a=()
lane_b=()
seen_sep=0
for e in "$@"; do
  if [[ $e == -- ]]; then seen_sep=1; elif ((seen_sep)); then lane_b+=("$e"); else lane_a+=("$e"); fi
done
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
    secant)
      python3 docs/seeds/001/secant_step.py "$HOME/seeds/wetfeed_verify_large_standard_scaled_step" --write \
        && [[ -f studies/wetfeed_verify_large_standard_scaled_secant.toml ]] \
        && warpdem study studies/wetfeed_verify_large_standard_scaled_secant.toml --device "$device" \
          --out "$HOME/seeds/$name" --stop-after "$s" ;;
    *) warpdem study "studies/$e.toml" --device "$device" --out "$HOME/seeds/$name" --stop-after "$s" ;;
  esac
  rc=$?
  echo "gpu_queue: $e exit $rc after $((SECONDS - t0)) s" >&2
}

lane() {
  local e
  for e in "$@"; do run_entry "$e"; done
}

if ((${#lane_b[@]})); then
  lane "${lane_b[@]}" > >(sed -u 's/^/[b] /') 2>&1 &
  pid_b=$!
fi
lane "${lane_a[@]}"
if ((${#lane_b[@]})); then wait "$pid_b"; fi

for e in "${lane_a[@]}" "${lane_b[@]}"; do
  name=${e#diagnose/}
  [[ -d $HOME/seeds/$name ]] && tar -C "$HOME/seeds" --exclude='*.npz' -czf "$OUT/$name.tgz" "$name"
done
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
ls -la "$OUT"
