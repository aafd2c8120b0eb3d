#!/usr/bin/env bash
# The main job on bundled data: install, build, then a mesh-in/mesh-out deform of the Stanford bunny
# (stretch an ear, pin the body), with a JSON report of residuals, volumes and timings.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
./build/bin/voxwarp deform data/bunny.obj data/bunny_ear.json -o out/bunny_ear.obj --resolution 128 --report out/bunny_ear_report.json
./build/bin/voxwarp info out/bunny_ear.obj
echo "demo: wrote out/bunny_ear.obj and out/bunny_ear_report.json"
