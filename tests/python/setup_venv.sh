#!/usr/bin/env bash
# Creates the Python environment the integration tests use: target/py-venv with the pinned
# packages of tests/python/requirements.txt. Idempotent: when the stamp file holds the hash of
# the current requirements it only checks that the venv's python runs and exits.
# Prints the venv's python path as its last line.
set -euo pipefail
crate_dir="$(cd "$(dirname "$0")/../.." && pwd)"
requirements="$crate_dir/tests/python/requirements.txt"
venv="$crate_dir/target/py-venv"
stamp="$venv/.requirements.sha256"
python="$venv/bin/python"

wanted="$(sha256sum "$requirements" | cut -d' ' -f1)"
if [[ -x "$python" && -f "$stamp" && "$(cat "$stamp")" == "$wanted" ]] && "$python" -c '' 2>/dev/null; then
    echo "$python"
    exit 0
fi

# Another test binary may be setting up the same venv: one at a time.
mkdir -p "$crate_dir/target"
exec 9>"$crate_dir/target/py-venv.lock"
flock 9
# It may have finished while we waited.
if [[ -x "$python" && -f "$stamp" && "$(cat "$stamp")" == "$wanted" ]]; then
    echo "$python"
    exit 0
fi

echo "setting up $venv from $requirements" >&2
if [[ ! -x "$python" ]] || ! "$python" -c '' 2>/dev/null; then
    rm -rf "$venv"
    python3 -m venv "$venv"
fi
rm -f "$stamp"
"$python" -m pip install --quiet --disable-pip-version-check -r "$requirements" >&2
echo "$wanted" >"$stamp"
echo "$python"
