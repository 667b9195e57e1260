#!/usr/bin/env bash
# The wheels bench/accelerator.sh needs on the device machine (Python 3.12, its own JAX 0.11.2 and
# the common packages; no MuJoCo), downloaded here into .whl/ (ignored: add /.whl/ to
# .git/info/exclude), 22 MB; a `run` then names .whl in `carry` (docs/benchmarks.md).
set -euo pipefail
case "${1:-}" in  # no arguments
  "") ;;
  -h|--help) sed -n '2,/^set /p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
  *) echo "$(basename "$0"): error: unknown argument '$1'; allowed: -h, --help" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."
grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo '/.whl/' >> .git/info/exclude
python3 -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
  --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl \
  mujoco==4.0.0 mujoco-core==4.0.0 mujoco-mjx==3.17.0 trimesh==5.2.0 gymnasium==1.4.0 \
  farama-notifications glfw pyopengl optax==0.2.8 tensorboardX
ls .whl
du -sh .whl
