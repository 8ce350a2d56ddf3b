#!/usr/bin/env bash
# Fetch MuJoCo 3.17.0's shared library from PyPI's `mujoco==3.17.0` wheel into third_party/mujoco/
# (git-ignored). mujoco-rs links it through MUJOCO_DYNAMIC_LINK_DIR (.cargo/config.toml) and every
# binary finds it at run time through an rpath (build.rs), so nobody sets LD_LIBRARY_PATH.
# With --tests (deploy/test.sh), also ffmpeg, which `sac-lsp render` encodes .mp4 videos with (a .gif
# needs nothing) and without which their test skips: installed once with apt-get when run as root
# where there is one (CI), else a note. Training and the other scripts install nothing but MuJoCo.
# Idempotent: returns at once when the library (and with --tests, ffmpeg) is already there.
set -euo pipefail

# Quiet: one line while it installs, apt's output only when it fails; never fails the set-up.
if [[ ${1:-} == --tests ]] && ! command -v ffmpeg >/dev/null 2>&1; then
    if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing ffmpeg (apt-get) for sac-lsp render's .mp4 videos" >&2
        apt_log="$(mktemp)"
        started=$SECONDS
        export DEBIAN_FRONTEND=noninteractive
        install_ffmpeg() { apt-get install -y -q --no-install-recommends ffmpeg >>"$apt_log" 2>&1; }
        # A fresh machine may have no package lists yet, or stale ones: then update and try again.
        if install_ffmpeg || { apt-get update -q >>"$apt_log" 2>&1 && install_ffmpeg; }; then
            echo "setup: ffmpeg installed in $((SECONDS - started)) s" >&2
        else
            tail -n 20 "$apt_log" >&2
            echo "setup: could not install ffmpeg (above): .mp4 videos and their test are skipped" >&2
        fi
        rm -f "$apt_log"
    else
        echo "setup: no ffmpeg on PATH: sac-lsp render writes .gif only and its .mp4 test is skipped" \
            "(install it as root: apt-get install ffmpeg)" >&2
    fi
fi

MUJOCO_VERSION=3.17.0
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
dest="$root/third_party/mujoco"
lib="libmujoco.so.$MUJOCO_VERSION"

if [[ -f "$dest/$lib" && -L "$dest/libmujoco.so" ]]; then
    exit 0
fi

python=""
for candidate in python3 python; do
    if command -v "$candidate" >/dev/null 2>&1 && "$candidate" -m pip --version >/dev/null 2>&1; then
        python="$candidate"
        break
    fi
done
if [[ -z "$python" ]]; then
    echo "setup: MuJoCo $MUJOCO_VERSION comes from PyPI's mujoco==$MUJOCO_VERSION wheel, which needs" >&2
    echo "setup: python3 with pip; neither 'python3 -m pip' nor 'python -m pip' works here." >&2
    echo "setup: install pip (Debian: apt-get install python3-pip) and run deploy/setup.sh again." >&2
    exit 1
fi

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
echo "setup: downloading the mujoco==$MUJOCO_VERSION wheel from PyPI" >&2
# On a terminal pip draws its own progress bar; elsewhere (CI, logs) its output is kept for errors.
if [[ -t 2 ]]; then pip_log=/dev/stderr quiet=(); else pip_log="$work/pip.log" quiet=(--quiet); fi
if ! "$python" -m pip download "${quiet[@]}" --no-deps --only-binary=:all: --dest "$work" \
    "mujoco==$MUJOCO_VERSION" >"$pip_log" 2>&1; then
    [[ $pip_log == /dev/stderr ]] || cat "$pip_log" >&2
    echo "setup: could not download mujoco==$MUJOCO_VERSION from PyPI (is the package registry reachable?)." >&2
    exit 1
fi

mkdir -p "$dest"
"$python" - "$work" "$dest" "$lib" <<'PY'
import pathlib, sys, zipfile
work, dest, lib = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2]), sys.argv[3]
wheels = sorted(work.glob("mujoco-*.whl"))
if not wheels:
    sys.exit(f"setup: no mujoco wheel in {work}")
with zipfile.ZipFile(wheels[0]) as wheel:
    member = f"mujoco/{lib}"
    if member not in wheel.namelist():
        sys.exit(f"setup: {wheels[0].name} has no {member}")
    tmp = dest / (lib + ".partial")
    tmp.write_bytes(wheel.read(member))
    tmp.chmod(0o755)
    tmp.rename(dest / lib)
PY
ln -sfn "$lib" "$dest/libmujoco.so"
echo "setup: MuJoCo $MUJOCO_VERSION is in $dest" >&2
