#!/usr/bin/env bash
# Installs what the independent checkers of the ground tests need (Foxglove, fleet bus); idempotent, silent on success.
#
#   ground/tests/foxglove/setup.sh
#
# * a Python venv at ${PPRZ_FOXGLOVE_VENV:-<repo>/target/foxglove-venv} with
#   requirements.txt (PyPI's mcap and jsonschema, for check_mcap.py; eclipse-zenoh, for
#   the fleet bus clients in ground/tests/zenoh/);
# * node_modules/ beside the scripts, from package-lock.json (npm ci), for ws_client.mjs.
#
# Each part is redone only when its pinned versions changed (or it is broken). Needs
# python3 (>= 3.11, with venv and ensurepip) and node (>= 18) with npm.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../../.." && pwd)"
venv="${PPRZ_FOXGLOVE_VENV:-$repo/target/foxglove-venv}"

die() {
    printf 'foxglove setup: %s\n' "$*" >&2
    exit 1
}

# Runs a command with its output kept aside, shown only if it fails.
quiet() {
    local log
    log="$(mktemp)"
    if ! "$@" >"$log" 2>&1; then
        printf 'foxglove setup: failed: %s\n' "$*" >&2
        cat "$log" >&2
        rm -f "$log"
        exit 1
    fi
    rm -f "$log"
}

digest() {
    sha256sum "$1" | cut -d' ' -f1
}

# --- tools ------------------------------------------------------------------------------
command -v python3 >/dev/null || die "python3 not found (Debian: apt-get install python3 python3-venv)"
python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
    || die "python3 >= 3.11 needed, found $(python3 --version 2>&1)"
command -v node >/dev/null || die "node not found (install Node.js >= 18 with npm)"
command -v npm >/dev/null || die "npm not found (Debian: apt-get install npm, or Node.js from nodejs.org)"
node -e 'process.exit(Number(process.versions.node.split(".")[0]) >= 18 ? 0 : 1)' \
    || die "node >= 18 needed, found $(node --version)"

mkdir -p "$(dirname "$venv")"
# One setup at a time (tests may run it in parallel).
if command -v flock >/dev/null; then
    exec 9>"$venv.lock"
    flock 9
fi

# --- Python venv ------------------------------------------------------------------------
want="$(digest "$here/requirements.txt")"
stamp="$venv/.pprz-requirements.sha256"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ] \
    || ! "$venv/bin/python" -c 'import mcap, jsonschema, zenoh' >/dev/null 2>&1; then
    if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -m pip --version >/dev/null 2>&1; then
        python3 -c 'import ensurepip, venv' >/dev/null 2>&1 \
            || die "python3 cannot create a venv with pip: install python3-venv (Debian 12: apt-get install python3-venv)"
        rm -rf "$venv"
        quiet python3 -m venv "$venv"
    fi
    rm -f "$stamp"
    quiet "$venv/bin/python" -m pip install --disable-pip-version-check --no-input \
        --require-virtualenv -r "$here/requirements.txt"
    "$venv/bin/python" -c 'import mcap, jsonschema, zenoh' \
        || die "the venv $venv cannot import mcap, jsonschema and zenoh after installing them"
    printf '%s\n' "$want" >"$stamp"
fi

# --- node_modules -----------------------------------------------------------------------
want="$(digest "$here/package-lock.json")"
stamp="$here/node_modules/.pprz-lock.sha256"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ] \
    || [ ! -f "$here/node_modules/@foxglove/ws-protocol/package.json" ] \
    || [ ! -f "$here/node_modules/ws/package.json" ]; then
    (cd "$here" && quiet npm ci --no-audit --no-fund)
    printf '%s\n' "$want" >"$stamp"
fi
