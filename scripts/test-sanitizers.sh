#!/usr/bin/env bash
# The whole test suite again, built with AddressSanitizer + UndefinedBehaviorSanitizer (build-asan/).
set -euo pipefail
cd "$(dirname "$0")/.."
VOXWARP_BUILD_DIR=build-asan bash scripts/setup.sh -DVOXWARP_SANITIZE=ON -DVOXWARP_BUILD_BENCH=OFF -DVOXWARP_BUILD_PYTHON=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo
cd build-asan
# Leak checking stays on; UBSan stops at the first error.
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
ctest --output-on-failure --parallel "$(nproc)" --timeout 1200
