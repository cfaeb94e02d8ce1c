#!/bin/sh
# Headless OpenGL for the gl backend's tests: Mesa's EGL and its llvmpipe rasterizer.
# Installs them with apt when they are missing and we may (root, Debian/Ubuntu); otherwise
# says what is missing. The GL tests skip without them, except in CI (QUILTING_REQUIRE_GL=1),
# where a skipped GL test is a failure.
set -eu
have_mesa() {
    ldconfig -p | grep -q 'libEGL_mesa\.so\.0' &&
        ldconfig -p | grep -q 'libEGL\.so\.1' &&
        ls /usr/lib/*/dri/swrast_dri.so /usr/lib/dri/swrast_dri.so 2>/dev/null | grep -q .
}
if have_mesa; then
    exit 0
fi
packages="libegl1 libegl-mesa0 libgl1-mesa-dri"
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing Mesa EGL + llvmpipe: $packages" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >/dev/null
    # shellcheck disable=SC2086 # one word per package
    apt-get install -y -q --no-install-recommends $packages >/dev/null
    have_mesa || { echo "Mesa EGL still not found after installing $packages" >&2; exit 1; }
else
    echo "note: Mesa EGL/llvmpipe not found (packages: $packages); the GL tests will skip" >&2
fi
