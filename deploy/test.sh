#!/usr/bin/env bash
# The test command: installs what the tests need (MuJoCo 3.17's library, once), then runs every test of
# the workspace on the real simulator. Extra arguments go to `cargo test` (e.g. `-p sim`).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
./deploy/setup.sh
# --no-fail-fast: one failing test binary must not hide how the others fare.
exec cargo test --workspace --no-fail-fast "$@"
