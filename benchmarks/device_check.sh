#!/usr/bin/env bash
# The GPU check, as run through the project's lent device (README "On a GPU"): the numerics
# tests on the accelerator, then the scanning benchmark there. Wheels the device image lacks
# (h5netcdf, foamlib, meshio: pure Python) travel in .whl/ (ignored by git).
#   OUT=folder SUITE_S=seconds TESTS="files..." WORKERS=n BENCH=0|1 BENCH_ARGS=" " (full run)
#   bash benchmarks/device_check.sh
set -u
OUT=${OUT:-/tmp/device_out}; mkdir -p "$OUT"
export XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
export PYTHONPATH=$PWD
if [ -d .whl ] && ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl && export PYTHONPATH=$PWD:/tmp/site
fi
nvidia-smi -L 2>/dev/null
python3 -c "import jax, numpy; print('jax', jax.__version__, 'numpy', numpy.__version__, jax.devices())"
if [ "${BENCH:-1}" = 1 ]; then
  timeout "${BENCH_S:-200}" python3 benchmarks/scanning.py ${BENCH_ARGS:---quick} --out "$OUT" --name scanning_device
  echo "benchmark rc $?"
fi
TESTS=${TESTS:-"tests/core tests/scenes tests/io/test_openfoam_exact.py tests/io/test_snapshots.py tests/io/test_vtk.py tests/io/test_turbulence.py tests/io/test_tables.py tests/io/test_hpl.py"}
WORKERS=${WORKERS:-12}
# shellcheck disable=SC2086
timeout "${SUITE_S:-240}" python3 -m pytest -p no:cacheprovider -n "$WORKERS" --dist loadfile -v \
  -o addopts="" -p no:benchmark $TESTS > "$OUT/suite.log" 2>&1
echo "suite rc $?"
grep -cE " PASSED" "$OUT/suite.log" | sed 's/^/passed: /'
grep -E "(FAILED|ERROR)( |$)" "$OUT/suite.log" | grep -v "^\[gw" | head -40
grep -E "^\[gw[0-9]+\] .*(FAILED|ERROR)" "$OUT/suite.log" | head -40
tail -3 "$OUT/suite.log"
