#!/usr/bin/env bash
# The live suite: `scanclean capture` through the real OpenNI2 API from the virtual sensor at
# sensor rate (pace=realtime, 30 fps), with --record and --accumulate 30, for LIVE_SECONDS
# (default 300) per source:
#   3dj      the bundled PrimeSense recording (12 frames 640x480), recorded to a folder, looped
#   pattern  the 640x480 test pattern, looped
# It prints one Markdown table: frames the driver delivered (read + index gaps), frames read,
# recorded (frames.csv of the recording), cleaned, windows cleaned and skipped, latency from a
# frame's arrival to its window's output (p50 / p95), and the peak resident memory (VmHWM) at
# 60 s and at the end of the run.
#
#   bench/live.sh [path/to/scanclean]          # default build/apps/scanclean
#   LIVE_SECONDS=60 bench/live.sh              # shorter runs (the 300 s column is then the end)
#   LIVE_WORK=out/live-bench LIVE_KEEP=1 ...   # work folder; keep outputs and recordings
#   LIVE_ARGS="--kernel-stride 2" ...          # extra capture options (e.g. filter settings)
set -euo pipefail
cd "$(dirname "$0")/.."
S=${1:-build/apps/scanclean}
RUN_S=${LIVE_SECONDS:-300}
WORK=${LIVE_WORK:-out/live-bench}
EXTRA=${LIVE_ARGS:-}
[ -x "$S" ] || { echo "live.sh: no scanclean program at $S (build it first)" >&2; exit 2; }
rm -rf "$WORK"
mkdir -p "$WORK"
ABS=$(cd "$WORK" && pwd)

"$S" record --source recordings/oni/3dj_test.oni "$ABS/3dj_rec" >"$WORK/record_3dj.txt" 2>&1

field() {  # field FILE KEY: the value of a summary line
  sed -n "s/^  $2: *//p" "$1" | head -1
}

run_one() {  # run_one NAME URI
  local name=$1 uri=$2 dir="$ABS/$1"
  mkdir -p "$dir"
  local t0=$SECONDS
  # shellcheck disable=SC2086
  "$S" capture --source "$uri" -o "$dir/window.ply" --record "$dir/rec" --accumulate 30 \
    --seconds "$RUN_S" --latest "$dir/latest.ply" $EXTRA >"$dir/summary.txt" 2>&1 &
  local pid=$! hwm60="" last="" v
  while kill -0 "$pid" 2>/dev/null; do
    v=$(awk '/^VmHWM/ {print $2}' "/proc/$pid/status" 2>/dev/null || true)
    [ -n "$v" ] && last=$v
    if [ -z "$hwm60" ] && [ $((SECONDS - t0)) -ge 60 ]; then hwm60=$last; fi
    sleep 1
  done
  local rc=0
  wait "$pid" || rc=$?
  local f="$dir/summary.txt"
  local read gaps recorded cleaned windows skipped lat
  read=$(field "$f" "frames delivered" | tr -d ,)
  gaps=$(field "$f" "dropped frames (index gaps)" | awk '{print $1}' | tr -d ,)
  recorded=$(($(wc -l <"$dir/rec/frames.csv") - 1))
  cleaned=$(field "$f" "frames cleaned" | tr -d ,)
  windows=$(field "$f" "windows" | tr -d ,)
  skipped=$(field "$f" "windows skipped" | awk '{print $1}' | tr -d ,:)
  lat=$(field "$f" "latency (frame -> window)" | sed 's/p50 \(.*\) s, p95 \(.*\) s/\1 \/ \2/')
  printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$name" "$RUN_S" \
    "$((read + gaps))" "$read" "$recorded" "$cleaned" "$windows" "$skipped" "$lat" \
    "$((${hwm60:-0} / 1024))" "$((${last:-0} / 1024))" "$rc"
  if [ -z "${LIVE_KEEP:-}" ]; then rm -rf "$dir/rec" "$dir"/window_*.ply "$dir/window.ply"; fi
}

echo "live suite: $S, ${RUN_S} s per source, $(nproc) hardware threads, load $(cut -d' ' -f1-3 /proc/loadavg), $(date -u +%FT%TZ)"
echo
echo "| source | s | delivered by the driver | read | recorded | cleaned | windows cleaned | windows skipped | latency p50 / p95 s | peak RSS 60 s MiB | peak RSS end MiB | exit |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
run_one 3dj "vsensor://$ABS/3dj_rec?pace=realtime&loop=1"
run_one pattern "vsensor://pattern?w=640&h=480&n=300&fps=30&pace=realtime&loop=1"
echo
echo "summaries: $WORK/*/summary.txt"
