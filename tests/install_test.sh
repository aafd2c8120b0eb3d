#!/usr/bin/env bash
# cmake --install into a fresh prefix, then configure, build and run an outside project against it
# (find_package(voxwarp CONFIG REQUIRED), target_link_libraries(outside voxwarp::voxwarp)).
# Usage: install_test.sh BUILD_DIR SOURCE_DIR WORK_DIR
set -euo pipefail
build=$1 source=$2 work=$3
rm -rf "$work"
cmake --install "$build" --prefix "$work/prefix" > "$work.install.log" 2>&1 || { cat "$work.install.log"; exit 1; }
cmake -S "$source/tests/outside" -B "$work/outside" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$work/prefix" > "$work.configure.log" 2>&1 ||
  { cat "$work.configure.log"; exit 1; }
cmake --build "$work/outside" > "$work.build.log" 2>&1 || { cat "$work.build.log"; exit 1; }
"$work/outside/outside"
# The installed command line runs from the prefix alone.
"$work/prefix/bin/voxwarp" --version
