#!/bin/sh
# One mutant's tests with a numba cache of its own (tools/mutation.py).
#   mutation_pytest.sh PYTHON BASE "STEMS" PYTEST-ARGS...
# BASE: a numba cache warmed on the unmutated code; STEMS: the file stems of the mutated module
# and of every module importing it. numba keys a kernel's cache on its own file only: a caller
# in another module would run its cached copy of the unmutated callee (a false survivor), and
# a cache written while a mutant was on disk would outlive it. So each mutant gets a copy of
# BASE without the entries of those modules, recompiled against the mutant and thrown away.
python=$1; base=$2; drop=$3; shift 3
tmp=$(mktemp -d "${TMPDIR:-/tmp}/cdprctl-mutant.XXXXXX") || exit 3
trap 'rm -rf "$tmp"' EXIT INT TERM
cp -a "$base/." "$tmp/"
for stem in $drop; do find "$tmp" -name "$stem.*" -delete; done
NUMBA_CACHE_DIR=$tmp "$python" -m pytest "$@"
