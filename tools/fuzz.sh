#!/usr/bin/env bash
# Runs the fuzz targets (docs/hardening.md) for a given time each.
#
#   tools/fuzz.sh TARGET|all|cpp|python SECONDS [libFuzzer flags...]
#
# C++ targets (libFuzzer, ASan + UBSan, built by clang into build/fuzz with -DMMRL_FUZZ=ON):
#   bvh, database, runtime_file. Python targets (atheris, tests/fuzz/fuzz_python.py):
#   checkpoint, database_npz (they import mmrl: install it, or set PYTHONPATH=python with
#   the _core module built there).
# Each target starts from its checked-in seeds (tests/fuzz/corpus/TARGET, never written) and
# grows a working corpus in $FUZZ_WORK/corpus/TARGET (default build/fuzz/work); a crashing
# input goes to $FUZZ_WORK/artifacts/TARGET/ and the script exits non-zero. The log of each
# run is $FUZZ_WORK/TARGET.log; the last line of each ("DONE cov: ... ft: ... corp: ...")
# is printed as a summary. Targets run one after the other. FUZZ_NO_BUILD=1 skips the
# (incremental) build, for several runs started at once.
set -euo pipefail
cd "$(dirname "$0")/.."

CPP_TARGETS="bvh database runtime_file"
PY_TARGETS="checkpoint database_npz"
if [ $# -lt 2 ]; then
  sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
what=$1 seconds=$2
shift 2
case "$what" in
  all) targets="$CPP_TARGETS $PY_TARGETS" ;;
  cpp) targets=$CPP_TARGETS ;;
  python) targets=$PY_TARGETS ;;
  *) targets=$what ;;
esac
work=${FUZZ_WORK:-build/fuzz/work}
build=${FUZZ_BUILD:-build/fuzz}

needs_cpp=0
for t in $targets; do
  case " $CPP_TARGETS " in *" $t "*) needs_cpp=1 ;; esac
  case " $CPP_TARGETS $PY_TARGETS " in *" $t "*) ;; *) echo "unknown target '$t' (known: $CPP_TARGETS $PY_TARGETS)"; exit 2 ;; esac
done
if [ $needs_cpp = 1 ] && [ -z "${FUZZ_NO_BUILD:-}" ]; then
  if [ ! -f "$build/CMakeCache.txt" ]; then
    CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMMRL_FUZZ=ON \
      -DMMRL_PYTHON=OFF -DMMRL_BUILD_EXAMPLES=OFF >/dev/null
  fi
  cmake --build "$build" -j"${FUZZ_JOBS:-2}" >/dev/null
fi

# Leaks are findings too (LeakSanitizer runs at exit and, with -detect_leaks, per input).
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
status=0
for t in $targets; do
  mkdir -p "$work/corpus/$t" "$work/artifacts/$t"
  flags=(-max_total_time="$seconds" -rss_limit_mb=2048 -timeout=60 -print_final_stats=1
         -artifact_prefix="$work/artifacts/$t/")
  [ -f "tests/fuzz/$t.dict" ] && flags+=(-dict="tests/fuzz/$t.dict")
  case " $CPP_TARGETS " in
    *" $t "*) cmd=("$build/fuzz_$t") ;;
    *) cmd=(python tests/fuzz/fuzz_python.py "$t") ;;
  esac
  set +e
  "${cmd[@]}" "${flags[@]}" "$@" "$work/corpus/$t" "tests/fuzz/corpus/$t" >"$work/$t.log" 2>&1
  rc=$?
  set -e
  summary=$(grep -E "^#[0-9]+[[:space:]]+DONE" "$work/$t.log" | tail -1 || true)
  execs=$(grep -E "^stat::number_of_executed_units" "$work/$t.log" | tail -1 | awk '{print $2}' || true)
  if [ $rc -ne 0 ]; then
    status=1
    echo "fuzz $t: FAILED (exit $rc); log $work/$t.log, inputs in $work/artifacts/$t/"
    grep -E "ERROR|SUMMARY|Test unit written" "$work/$t.log" | head -5
  else
    echo "fuzz $t: ${seconds}s, ${execs:-?} executions, ${summary:-no summary}"
  fi
done
exit $status
