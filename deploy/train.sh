#!/usr/bin/env bash
# The main job: train SAC-LSP on the MuJoCo Ant on this machine. Installs MuJoCo's library (once),
# builds in release, and runs `sac-lsp train` with a run file (default deploy/configs/ant-v5.toml).
# Usage: deploy/train.sh [RUN_FILE] [sac-lsp train flags: --epochs N --minutes M --seed S --out DIR]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
config=deploy/configs/ant-v5.toml
if [[ $# -gt 0 && $1 != -* ]]; then
    config=$1
    shift
fi
./deploy/setup.sh
cargo build --release -p sac-lsp-cli
exec target/release/sac-lsp train --config "$config" "$@"
