#!/usr/bin/env bash
# The test suite on a clean clone with no ../shared beside it, once idle and once beside two CPU-bound processes.
# usage: bash bench/ci_under_load.sh   (installs stress-ng with apt-get if missing; prints both wall times)
# The suite must pass both times: its tests wait on conditions and simulated clocks, never on wall time.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'kill "${stress_pid:-0}" 2>/dev/null || true; rm -rf "$work"' EXIT
git clone --quiet "$repo" "$work/clone"      # a clean clone: no ../shared beside it, nothing untracked
command -v stress-ng >/dev/null || { apt-get update -qq && apt-get install -y -qq stress-ng >/dev/null; }
run() {  # $1: label
    local start end
    start=$(date +%s)
    EYEHIL_CI_VENV="$work/venv-$1" bash "$work/clone/.ci/run" > "$work/$1.log" 2>&1 || { tail -30 "$work/$1.log"; exit 1; }
    end=$(date +%s)
    echo "$1: $((end - start)) s wall; $(grep -E '[0-9]+ passed' "$work/$1.log" | tail -1)"
}
run idle
stress-ng --cpu 2 --quiet & stress_pid=$!
run loaded
