#!/usr/bin/env bash
# Build voxgi's C++ core with AddressSanitizer + UndefinedBehaviorSanitizer
# (CMake option VOXGI_SANITIZE=ON) into a separate virtual environment and run
# the test suite under it. See docs/sanitizers.md.
#
#   scripts/sanitize.sh                 # default tests
#   scripts/sanitize.sh -m "slow or not slow" tests/test_stress.py   # any pytest args
#
# Environment: VENV (default build/venv-asan), JOBS (default 2), PYTHON (python3).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=$(realpath -m "${VENV:-build/venv-asan}")
PYTHON=${PYTHON:-python3}
JOBS=${JOBS:-2}

if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" -m venv "$VENV"
fi
# The runtime and test dependencies as pyproject.toml lists them (read on
# every run, so the list cannot fall behind), and the build backend.
"$VENV/bin/python" -c 'import tomllib
p = tomllib.load(open("pyproject.toml", "rb"))["project"]
print("\n".join(p["dependencies"] + p["optional-dependencies"]["test"]))' > "$VENV/requirements.txt"
"$VENV/bin/pip" install -q -r "$VENV/requirements.txt" pybind11 scikit-build-core ninja cmake
# A normal (not editable) install, so nothing else's build dir is touched.
CMAKE_BUILD_PARALLEL_LEVEL=$JOBS "$VENV/bin/pip" install -q --no-deps --no-build-isolation \
    --force-reinstall -Cbuild-dir=build/asan -Ccmake.define.VOXGI_SANITIZE=ON \
    -Ccmake.build-type=RelWithDebInfo .

# The interpreter is not instrumented, so the ASan runtime must be loaded
# first (LD_PRELOAD); the UBSan runtime comes in as a dependency of _core.
CXX=${CXX:-c++}
# libstdc++ is preloaded too: the interpreter does not link it, and ASan's
# __cxa_throw interceptor must find it at start-up, else the first C++
# exception (pybind11's ValueError, OpenEXR's errors) aborts with
# 'CHECK failed: real___cxa_throw != 0'.
LIBASAN="$("$CXX" -print-file-name=libasan.so) $("$CXX" -print-file-name=libstdc++.so)"
# detect_leaks=0: CPython keeps its own objects alive at exit (not our leaks);
# PYTHONMALLOC=malloc: Python objects go through ASan's allocator too;
# halt_on_error: a UBSan report fails the run instead of scrolling by.
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=0:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export PYTHONMALLOC=malloc
# From the repository root src/ is not on sys.path: the sanitized installed
# copy is imported (printed here to make sure).
LD_PRELOAD="$LIBASAN" "$VENV/bin/python" -c "import voxgi._core as c; print('sanitized core:', c.__file__)"
LD_PRELOAD="$LIBASAN" "$VENV/bin/python" -m pytest -q -p no:cacheprovider "${@:-tests}"
