#!/usr/bin/env bash
# Set up dancesynth on a fresh Debian/Ubuntu machine: system tools, a virtual environment, the package.
#   bash scripts/setup.sh          # what `dancesynth dance`, `eval` and `bench` need
#   bash scripts/setup.sh --test   # plus what the tests use (pytest, three.js, Blender for import checks,
#                                  # Chromium + playwright-core for the web page, a PulseAudio server for
#                                  # `stream system`)
set -euo pipefail
cd "$(dirname "$0")/.."
want_tests=0
[ "${1:-}" = "--test" ] && want_tests=1

# command:package pairs; only missing commands are installed
# (fluidsynth renders the generated beat ground truth of `dancesynth bench`)
needs="ffmpeg:ffmpeg ffprobe:ffmpeg fluidsynth:fluidsynth"
[ $want_tests = 1 ] && needs="$needs blender:blender node:nodejs npm:npm chromium:chromium pulseaudio:pulseaudio"
missing=""
for pair in $needs; do
  command -v "${pair%%:*}" >/dev/null 2>&1 || missing="$missing ${pair##*:}"
done
soundfont=0  # any General MIDI soundfont will do
for sf in TimGM6mb.sf2 default-GM.sf2 FluidR3_GM.sf2; do [ -f "/usr/share/sounds/sf2/$sf" ] && soundfont=1; done
[ $soundfont = 1 ] || missing="$missing timgm6mb-soundfont"
# Blender's glTF importer runs on the system Python and needs its numpy (Debian's python3-numpy).
if [ $want_tests = 1 ] && command -v dpkg >/dev/null && ! dpkg -s python3-numpy >/dev/null 2>&1; then
  missing="$missing python3-numpy"
fi
missing=$(echo $missing | tr ' ' '\n' | sort -u | tr '\n' ' ')
if [ -n "${missing// /}" ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "please install: $missing(apt-get install -y $missing)" >&2; exit 1; fi
  echo "installing system packages: $missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

python3 -c 'import sys; assert sys.version_info[:2] == (3, 11), "dancesynth needs Python 3.11"'
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q --upgrade pip
if [ $want_tests = 1 ]; then
  .venv/bin/pip install -q -e '.[test]'
  (cd tests/clients && npm ci --silent --no-audit --no-fund)
else
  .venv/bin/pip install -q -e .
fi
echo "dancesynth is set up: .venv/bin/dancesynth --help"
