#!/usr/bin/env bash
# Adds what `make gpu-check` needs beyond the offline GPU kit (../shared/gpu-kit/build.sh, which
# writes .gpu/): the pure-Python wheels of pytest, pytest-xdist and their dependencies, into
# .gpu/wheels/, which `source .gpu/install.sh` installs on the node with the rest. Run here, where
# PyPI is reachable, after building the kit and before carrying .gpu to the GPU node. About 1.8 MB.
set -eu
cd "$(dirname "$0")/.."
[ -d .gpu/wheels ] || { echo "gpu_kit_extras: no .gpu/wheels: build the kit first (../shared/gpu-kit/build.sh)"; exit 2; }
py=${PYTHON:-python3}
"$py" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  -d .gpu/wheels pytest==8.4.2 pluggy==1.6.0 iniconfig==2.1.0 packaging==25.0 pytest-timeout==2.4.0 pygments==2.19.2 \
  pytest-xdist==3.8.0 execnet==2.1.1
ls .gpu/wheels | grep -E "^(pytest|pluggy|iniconfig|packaging|pygments|execnet)"
