#!/usr/bin/env bash
# Fuzzes the inputs a role takes from outside with cargo fuzz (libFuzzer): every wire decoder
# (`wire`), the replay snapshot reader (`replay_snapshot`), the learner checkpoint loader with the
# param server's and an executor's weights checks (`checkpoint`), and every role's run-file parser
# (`run_file`); fuzz/fuzz_targets/ has one file each.
#
#   deploy/fuzz.sh [SECONDS] [TARGET...]        (default 60 s for each of the four)
#
# Needs the nightly toolchain (`rustup toolchain install nightly`); installs cargo-fuzz from
# crates.io if it is missing. The first build compiles every dependency again, instrumented, in
# fuzz/target/ (~10 minutes on 2 cores). Corpora grow in fuzz/corpus/<target>/; a crash stops the
# script non-zero and leaves its input in fuzz/artifacts/<target>/ (replay it with
# `cargo +nightly fuzz run <target> <file>`, then add a regression test beside the code).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

seconds=${1:-60}
[[ $seconds =~ ^[0-9]+$ && $seconds -ge 1 ]] || { echo "fuzz.sh: SECONDS must be a positive integer, got '$seconds'" >&2; exit 2; }
shift || true
targets=("$@")
[[ ${#targets[@]} -gt 0 ]] || targets=(wire replay_snapshot checkpoint run_file)

./deploy/setup.sh # the MuJoCo library the executor's config crate links
rustup toolchain list | grep -q '^nightly' || {
    echo "fuzz.sh: cargo fuzz needs the nightly toolchain: rustup toolchain install nightly" >&2
    exit 2
}
if ! command -v cargo-fuzz >/dev/null; then
    echo "fuzz.sh: installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked
fi
# The fuzz crate pins the workspace's versions: its lock starts from the workspace's.
[[ -f fuzz/Cargo.lock ]] || cp Cargo.lock fuzz/Cargo.lock

for target in "${targets[@]}"; do
    mkdir -p "fuzz/corpus/$target"
    echo "fuzz.sh: $target for $seconds s" >&2
    # No sanitizer: the code under test is safe Rust, so ASan would only slow it down; panics,
    # overflows (debug assertions are on) and runaway allocations (-rss_limit_mb) are what it finds.
    cargo +nightly fuzz run --sanitizer none "$target" "fuzz/corpus/$target" -- \
        -max_total_time="$seconds" -rss_limit_mb=4096 -malloc_limit_mb=2048 -print_final_stats=1
done
echo "fuzz.sh: no crash in ${targets[*]} (${seconds} s each)" >&2
