#!/usr/bin/env bash
# Install voxwarp's Blender add-on into Blender's user add-ons, with the compiled module shipped inside it, and
# enable it (saved in Blender's preferences). Builds first if there is no build yet (scripts/setup.sh installs
# the Debian packages, Blender among them). Blender's BLENDER_USER_SCRIPTS / BLENDER_USER_CONFIG choose where.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -f build/python/voxwarp/__init__.py ] || bash scripts/setup.sh
blender -b --python-exit-code 1 --python blender/install.py -- "$PWD" 2>&1 | grep "^voxwarp" || { echo "install: Blender failed" >&2; exit 1; }
