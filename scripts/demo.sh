#!/usr/bin/env bash
# The main job on bundled data: install, build, then mesh in -> voxmap -> mesh out on the Stanford bunny.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
./build/bin/voxwarp info data/bunny.obj
./build/bin/voxwarp voxelize data/bunny.obj -o out/bunny.vdb --resolution 128
./build/bin/voxwarp extract out/bunny.vdb -o out/bunny_roundtrip.obj
./build/bin/voxwarp info out/bunny_roundtrip.obj
echo "demo: wrote out/bunny.vdb and out/bunny_roundtrip.obj"
