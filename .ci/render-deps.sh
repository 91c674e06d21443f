#!/usr/bin/env bash
# Headless OpenGL for MuJoCo's offscreen renderer (rollout videos, foottof/eval/video.py):
# Mesa's EGL (llvmpipe on CPU machines) or OSMesa. A no-op where either is installed; otherwise
# installs the Debian packages below (root, or sudo).
set -euo pipefail
has() { ldconfig -p 2>/dev/null | grep -q "$1"; }
if has 'libEGL_mesa.so' || has 'libOSMesa.so'; then
  exit 0
fi
pkgs=(libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6)
if ! command -v apt-get >/dev/null 2>&1; then
  echo "render-deps: no apt-get here; install Mesa's EGL or OSMesa (Debian: ${pkgs[*]})" >&2
  exit 1
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
echo "render-deps: installing ${pkgs[*]}"
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${pkgs[@]}"
