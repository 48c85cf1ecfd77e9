#!/usr/bin/env bash
# The hardening checks (docs/hardening.md): the C++ tests under AddressSanitizer +
# UndefinedBehaviorSanitizer with LeakSanitizer, Python tests against an ASan build of the
# extension, the threaded tests under ThreadSanitizer, and the fuzz targets.
#
#   tools/hardening.sh ci     what CI runs (.ci/run): all of it, the Python tests a subset
#                             that drives the extension, each fuzz target 30 s
#   tools/hardening.sh full   on demand: the whole Python suite under ASan, each fuzz target
#                             30 minutes (FUZZ_SECONDS overrides)
#   tools/hardening.sh STEP   one step: asan, asan-python, tsan or fuzz (ci settings)
#
# Needs gcc (the sanitizer builds) and, for the fuzz step, clang with libFuzzer (Debian:
# clang libclang-rt-14-dev) and atheris (PyPI), the ASan step pybind11 (PyPI); the Python steps need mmrl's Python
# dependencies (the fuzz step's Python targets import the installed mmrl, or PYTHONPATH).
# Builds go to build/hardening-*; each step prints its time.
set -euo pipefail
cd "$(dirname "$0")/.."
mode=${1:-ci}
jobs=${HARDENING_JOBS:-$(nproc)}
asan_build=${HARDENING_ASAN_BUILD:-build/hardening-asan}
tsan_build=${HARDENING_TSAN_BUILD:-build/hardening-tsan}

# The extension's tests that drive C++ code (parsing, the database, the search, both envs,
# the controller, the runtime loader, threads, the fuzz regressions) for the ci subset.
PY_SUBSET="test_bvh.py test_database.py test_core_envs.py test_search.py test_obstacles.py test_controller.py
           test_runtime_file.py test_threads.py test_fuzz_regressions.py test_import_axes_fps.py test_capi.py"

# Sanitizer settings. LeakSanitizer runs at the exit of every C++ test process; a UBSan
# finding aborts (the builds also pass -fno-sanitize-recover).
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
CPP_ASAN_OPTIONS=detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1

# Both sanitizer builds: -O1 -g1 takes a third less compile time than -O2 -g (the build is most
# of a sanitizer step's time) and keeps line numbers in the reports.
SANITIZER_FLAGS="-O1 -g1 -DNDEBUG"

timed() {
  local name=$1 t0=$SECONDS
  shift
  echo "hardening: $name ..."
  "$@"
  echo "hardening: $name passed in $((SECONDS - t0)) s"
}

step_asan() {
  local pybind11_dir
  pybind11_dir=$(python -m pybind11 --cmakedir 2>/dev/null) || {
    echo "hardening: the ASan step builds mmrl._core and needs pybind11 in this Python: pip install 'pybind11>=2.12'" >&2
    exit 2
  }
  cmake -S . -B "$asan_build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="$SANITIZER_FLAGS" \
    -DMMRL_SANITIZE=ON -DMMRL_PYTHON=ON \
    -DMMRL_BUILD_TESTS=ON -DMMRL_BUILD_EXAMPLES=OFF -Dpybind11_DIR="$pybind11_dir" >/dev/null
  cmake --build "$asan_build" -j"$jobs" >/dev/null
  ASAN_OPTIONS=$CPP_ASAN_OPTIONS ctest --test-dir "$asan_build" --output-on-failure -j1
}

# The Python tests against the ASan build of mmrl._core: the package's Python files with the
# ASan module beside them in build/hardening-asan/pkg, the ASan runtime preloaded into python.
# Leak checking is off here: CPython and torch keep memory until exit by design, and LSan
# would report those (the C++ tests above check leaks).
step_asan_python() {
  [ -f "$asan_build/CMakeCache.txt" ] || step_asan
  cmake --build "$asan_build" -j"$jobs" --target _core mmrl_runtime_c >/dev/null
  local pkg libasan files
  pkg=$(pwd)/$asan_build/pkg
  rm -rf "$pkg" && mkdir -p "$pkg"
  cp -r python/mmrl "$pkg/mmrl"
  rm -f "$pkg"/mmrl/_core*.so
  cp "$asan_build"/_core*.so "$pkg/mmrl/"
  # libstdc++ too: python itself is not linked with it, and ASan's exception interceptor
  # must find the real __cxa_throw when it starts (else the first C++ throw aborts).
  libasan="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libstdc++.so.6)"
  files=$PY_SUBSET
  [ "$mode" = full ] && files=.
  # test_capi.py loads the C interface's ASan build (every call and error path under ASan).
  (export PYTHONPATH=$pkg LD_PRELOAD="$libasan" MMRL_CAPI_LIB=$(pwd)/$asan_build/libmmrl_runtime_c.so
   export ASAN_OPTIONS=detect_leaks=0:alloc_dealloc_mismatch=0:detect_odr_violation=0
   cd tests
   python -c "import mmrl; assert mmrl.__file__.startswith('$pkg'), mmrl.__file__"
   # --capture=sys: an ASan report (written to file descriptor 2) reaches the log.
   python -m pytest -q -p no:cacheprovider --capture=sys $files)
}

step_tsan() {
  cmake -S . -B "$tsan_build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="$SANITIZER_FLAGS" \
    -DMMRL_TSAN=ON -DMMRL_PYTHON=OFF -DMMRL_BUILD_EXAMPLES=OFF >/dev/null
  cmake --build "$tsan_build" -j"$jobs" --target mmrl_tsan_tests >/dev/null  # the library and that file only
  ctest --test-dir "$tsan_build" --output-on-failure
}

step_fuzz() {
  local seconds=${FUZZ_SECONDS:-30}
  [ "$mode" = full ] && seconds=${FUZZ_SECONDS:-1800}
  FUZZ_JOBS=$jobs tools/fuzz.sh all "$seconds"
}

case "$mode" in
  ci | full)
    timed "ASan + UBSan + LSan: ctest" step_asan
    timed "ASan: Python tests" step_asan_python
    timed "TSan: threaded tests" step_tsan
    timed "fuzz" step_fuzz
    ;;
  asan) timed "ASan + UBSan + LSan: ctest" step_asan ;;
  asan-python) timed "ASan: Python tests" step_asan_python ;;
  tsan) timed "TSan: threaded tests" step_tsan ;;
  fuzz) timed "fuzz" step_fuzz ;;
  *) sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'; exit 2 ;;
esac
