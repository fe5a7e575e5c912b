#!/bin/sh
# Runs the Python tests: creates the virtual environment (python/.venv, or
# $HCC_PYTHON_VENV), installs the pinned packages of requirements.txt and
# the hcc package itself, and the franka-sim server's own environment
# (python/.venv-franka-sim, or $HCC_FRANKA_SIM_VENV, from
# requirements-franka-sim.txt), then runs pytest on python/tests. Arguments are
# passed to pytest. The process tests need the Rust binaries built first
# (cargo build --workspace --bins).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
venv=${HCC_PYTHON_VENV:-$here/.venv}
python=${PYTHON:-python3}

if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
pip="$venv/bin/python -m pip --disable-pip-version-check -q"
$pip install -r "$here/requirements.txt"
$pip install --no-deps --no-build-isolation --force-reinstall "$here"
# The installed package is tested, not the source tree.
rm -rf "$here/build" "$here"/*.egg-info
# The franka-sim test server and pylibfranka pin numpy 1.x, which the hcc
# package's numpy 2 excludes: they get an environment of their own
# (requirements-franka-sim.txt), which tests/test_franka.py runs them from.
fsim_venv=${HCC_FRANKA_SIM_VENV:-$here/.venv-franka-sim}
if [ ! -x "$fsim_venv/bin/python" ]; then
    "$python" -m venv "$fsim_venv"
fi
"$fsim_venv/bin/python" -m pip --disable-pip-version-check -q install -r "$here/requirements-franka-sim.txt"
export HCC_FRANKA_SIM_PYTHON="$fsim_venv/bin/python"

cd "$here/tests"
set +e
"$venv/bin/python" -m pytest -p no:cacheprovider "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "python/test.sh: pytest collected no tests" >&2
    exit 1
fi
exit "$rc"
