#!/usr/bin/env bash
# The scaling benchmark (bench/README.md, "Scaling"): seeded scenes from scanclean_gencloud,
# filtered in memory, by tiles, and by MPI processes; wall time, points/s and peak resident memory
# (GNU time), and the comparison of outputs. Run from the repository root after a build with
# -DSCANCLEAN_WITH_MPI=ON. Generated clouds go to $SCALING_DIR (default out/scaling) and are
# deleted at the end (KEEP=1 keeps them, and the identity suite's outputs).
#
#   bench/scaling.sh [suite...]      suites: identity10m default20m ranks big200m (default: all)
#
# Sizes can be changed: N10=10000000 N1=2000000 N20=20000000 NRANKS=4000000 NBIG=200000000.
set -euo pipefail
B=${BUILD:-build}
S=$B/apps/scanclean
MPI=$B/apps/scanclean-mpi
G=$B/bench/scanclean_gencloud
D=${SCALING_DIR:-out/scaling}
mkdir -p "$D"
N10=${N10:-10000000}
N1=${N1:-2000000}
N20=${N20:-20000000}
NRANKS=${NRANKS:-4000000}
NBIG=${NBIG:-200000000}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
MPIRUN=(mpirun --mca btl_vader_single_copy_mechanism none)
suites=("$@")
[ ${#suites[@]} -eq 0 ] && suites=(identity10m default20m ranks big200m)

# Runs a command under GNU time; prints "wall_s peak_MiB" of it.
timed() {
  local log=$1
  shift
  /usr/bin/time -f "%e %M" -o "$log.time" "$@" >"$log" 2>&1
  awk '{printf "%.1f %.0f\n", $1, $2 / 1024}' "$log.time"
}
row() { printf '| %s |\n' "$(IFS='|'; echo "$*" | sed 's/|/ | /g')"; }
gen() { [ -f "$2" ] || "$G" scene "$2" --points "$1" --seed 14 >/dev/null 2>&1; }
# Whether two PLY outputs hold the same bytes after their headers (the headers differ in the
# provenance comment, which names the command and its output path).
header_bytes() { echo $(($(grep -abo -m1 'end_header' "$1" | head -1 | cut -d: -f1) + 11)); }
same_body() { cmp -s -i "$(header_bytes "$1"):$(header_bytes "$2")" "$1" "$2"; }

for suite in "${suites[@]}"; do
  case $suite in
    identity10m)
      gen "$N10" "$D/s10m.ply"
      read -r tm mm < <(timed "$D/mem.log" "$S" filter "$D/s10m.ply" -o "$D/mem.ply" --memory-budget off)
      read -r tt mt < <(timed "$D/tiled.log" "$S" filter "$D/s10m.ply" -o "$D/tiled.ply" --tiled \
        --memory-budget 1G)
      tiles=$(grep -o 'tiles: *[0-9]*' "$D/tiled.log" | grep -o '[0-9]*$')
      cmp=$("$G" compare "$D/mem.ply" "$D/tiled.ply" || true)
      # The same with kernels at every point (no stride subsample: the remaining differences), on
      # a smaller cloud ($N1 points) cut into as many tiles by a smaller budget.
      gen "$N1" "$D/s1.ply"
      read -r tm1 _ < <(timed "$D/mem1.log" "$S" filter "$D/s1.ply" -o "$D/mem1.ply" \
        --memory-budget off --kernel-stride 1)
      read -r tt1 _ < <(timed "$D/tiled1.log" "$S" filter "$D/s1.ply" -o "$D/tiled1.ply" --tiled \
        --memory-budget 400M --kernel-stride 1)
      cmp1=$("$G" compare "$D/mem1.ply" "$D/tiled1.ply" || true)
      echo "## $N10 points: in memory against tiled (budget 1G, $tiles tiles)"
      row run wall_s peak_MiB
      row "in memory" "$tm" "$mm"
      row "tiled" "$tt" "$mt"
      row "in memory, $N1 points, --kernel-stride 1" "$tm1" "-"
      row "tiled (budget 400M), $N1 points, --kernel-stride 1" "$tt1" "-"
      echo "tiling cost: $(awk -v a="$tt" -v b="$tm" 'BEGIN{printf "%+.1f %%", 100*(a-b)/b}')" \
        "(stride 1: $(awk -v a="$tt1" -v b="$tm1" 'BEGIN{printf "%+.1f %%", 100*(a-b)/b}'))"
      echo "compare (default options): $cmp"
      echo "compare (--kernel-stride 1): $cmp1"
      [ "${KEEP:-0}" = 1 ] || rm -f "$D"/mem*.ply "$D"/tiled*.ply
      ;;
    default20m)
      gen "$N20" "$D/s20m.ply"
      read -r t m < <(timed "$D/d20.log" "$S" filter "$D/s20m.ply" -o "$D/d20.ply")
      echo "## $N20 points, default options"
      row wall_s peak_MiB points_per_s
      row "$t" "$m" "$(awk -v n="$N20" -v t="$t" 'BEGIN{printf "%.0f", n/t}')"
      grep -E "tiles:|memory budget|first pass" "$D/d20.log" || true
      rm -f "$D/d20.ply"
      ;;
    ranks)
      gen "$NRANKS" "$D/sr.ply"
      echo "## $NRANKS points, scanclean-mpi, budget 512M per process"
      row processes wall_s points_per_s per_process_points_per_s peak_MiB_per_process identical
      ref=""
      for np in 1 2 4; do
        extra=()
        [ "$np" -gt 2 ] && extra=(--oversubscribe)
        read -r t m < <(timed "$D/r$np.log" "${MPIRUN[@]}" -np "$np" "${extra[@]}" "$MPI" "$D/sr.ply" \
          -o "$D/r$np.ply" --memory-budget 512M --threads 1)
        same="-"
        if [ -z "$ref" ]; then ref="$D/r$np.ply"; else same_body "$ref" "$D/r$np.ply" && same=yes || same=NO; fi
        row "$np" "$t" "$(awk -v n="$NRANKS" -v t="$t" 'BEGIN{printf "%.0f", n/t}')" \
          "$(awk -v n="$NRANKS" -v t="$t" -v p="$np" 'BEGIN{printf "%.0f", n/t/p}')" "$m" "$same"
      done
      rm -f "$D"/r?.ply
      ;;
    big200m)
      gen "$NBIG" "$D/sbig.ply"
      read -r t m < <(timed "$D/big1.log" "$S" filter "$D/sbig.ply" -o "$D/big1.ply" --memory-budget 2G)
      echo "## $NBIG points ($(du -h "$D/sbig.ply" | cut -f1) binary PLY), out of core"
      row run wall_s points_per_s peak_MiB budget
      row "1 process" "$t" "$(awk -v n="$NBIG" -v t="$t" 'BEGIN{printf "%.0f", n/t}')" "$m" 2G
      read -r t2 m2 < <(timed "$D/big2.log" "${MPIRUN[@]}" -np 2 "$MPI" "$D/sbig.ply" -o "$D/big2.ply" \
        --memory-budget 1G)
      row "2 MPI processes" "$t2" "$(awk -v n="$NBIG" -v t="$t2" 'BEGIN{printf "%.0f", n/t}')" \
        "$m2 (largest)" "1G each"
      # (Budgets differ, so do the tile plans: identity holds for equal budgets, see "ranks".)
      rm -f "$D/big1.ply" "$D/big2.ply"
      ;;
    *)
      echo "unknown suite $suite" >&2
      exit 2
      ;;
  esac
done
[ "${KEEP:-0}" = 1 ] || rm -f "$D"/s*.ply
