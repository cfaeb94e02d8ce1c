#!/bin/sh
# The project's one install script: docker/Dockerfile, docker/Dockerfile.gpu and CI (.ci/run)
# all run it, and nothing else installs anything.
#
#   sh docker/install.sh cpu   image: Mesa EGL + llvmpipe (headless GL on the CPU), the service
#                              user, quilting[server,gl,queue] into the venv $VENV
#   sh docker/install.sh gpu   image: glvnd's EGL/GL with NVIDIA's EGL vendor file (the NVIDIA
#                              container toolkit brings the driver at run time), the service
#                              user, the same Python install
#   sh docker/install.sh ci    tests: the cpu role's system packages, redis-server, Debian's
#                              chromium (checked to render headless), then the development
#                              install in .venv: -e '.[dev]' -e ./client
#
# VENV (default /opt/quilting) is where the cpu and gpu roles install the package.
# QUILTING_CHROMIUM names another Chromium binary for the ci role (default /usr/bin/chromium).
#
# Debian packages are installed with apt-get only when missing and only when we may (root,
# apt-get present); otherwise the script says what is missing and goes on, and the tests that
# need it skip (in CI, where QUILTING_REQUIRE_GL/_BROWSER/_REDIS are set, they fail instead).
# The image roles remove apt's package lists afterwards. Running the script again changes
# nothing.
set -eu

cd "$(dirname "$0")/.."

VENV="${VENV:-/opt/quilting}"
CHROMIUM="${QUILTING_CHROMIUM:-/usr/bin/chromium}"

# Mesa's EGL and its llvmpipe rasterizer, and glvnd's libGL.so.1 (moderngl's EGL context loads
# libGL as well as libEGL).
MESA_PACKAGES="libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"
# glvnd's dispatch libraries: the vendor library (libEGL_nvidia.so.0) comes from the driver,
# injected by the NVIDIA container toolkit when NVIDIA_DRIVER_CAPABILITIES has graphics.
# (Debian's libegl1 brings Mesa's EGL vendor too; docker/Dockerfile.gpu sets
# __EGL_VENDOR_LIBRARY_FILENAMES so that EGL loads NVIDIA's alone.)
GLVND_PACKAGES="libglvnd0 libegl1 libgl1"
NVIDIA_EGL_VENDOR=/usr/share/glvnd/egl_vendor.d/10_nvidia.json
SERVICE_USER=quilting
SERVICE_UID=10001

missing=""  # Debian packages to install, space-separated
apt_ran=""  # set once apt-get has fetched package lists

say() {
    echo "install.sh: $*" >&2
}

fail() {
    say "$*"
    exit 1
}

may_apt() {
    [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1
}

libraries() {
    # ldconfig lives in /sbin, which is not on a user's PATH on Debian.
    if command -v ldconfig >/dev/null 2>&1; then ldconfig -p; else /sbin/ldconfig -p; fi
}

have_libraries() {  # have_libraries SONAME...: all of them known to the dynamic linker
    found=$(libraries 2>/dev/null) || return 1
    for soname in "$@"; do
        printf '%s\n' "$found" | awk -v soname="$soname" '$1 == soname { found = 1 }
            END { exit !found }' || return 1
    done
}

have_mesa() {
    have_libraries libEGL.so.1 libGL.so.1 libEGL_mesa.so.0 || return 1
    for driver in /usr/lib/*/dri/swrast_dri.so /usr/lib/dri/swrast_dri.so; do
        [ -e "$driver" ] && return 0
    done
    return 1
}

have_glvnd() {
    have_libraries libEGL.so.1 libGL.so.1
}

have_redis() {
    command -v redis-server >/dev/null 2>&1 || [ -x /usr/bin/redis-server ]
}

have_venv_module() {
    command -v python3 >/dev/null 2>&1 && python3 -c 'import ensurepip, venv' 2>/dev/null
}

# The arguments the browser tests launch Chromium with (tests/service/browser.py).
HEADLESS_ARGS="--headless=new --no-sandbox --disable-gpu --disable-quic --no-first-run
 --disable-background-networking --disable-component-update --disable-sync"

chromium_renders() {
    [ -x "$CHROMIUM" ] || return 1
    profile=$(mktemp -d)
    # shellcheck disable=SC2086 # one word per argument
    dom=$(timeout 120 "$CHROMIUM" $HEADLESS_ARGS --user-data-dir="$profile" \
        --dump-dom 'data:text/html,<p>quilting-headless-ok</p>' 2>/dev/null) || true
    rm -rf "$profile"
    case "$dom" in
        *quilting-headless-ok*) return 0 ;;
        *) return 1 ;;
    esac
}

want() {  # want PACKAGE...: install these with the next install_missing
    missing="$missing $*"
}

# Install the wanted packages. Returns 1 (after saying what is missing and why it is left) when
# we may not, so that the caller checks the result only of what was installed.
install_missing() {
    [ -n "$missing" ] || return 0
    if ! may_apt; then
        say "note: missing Debian packages:$missing (not root, or no apt-get: not installed)"
        return 1
    fi
    say "installing:$missing"
    export DEBIAN_FRONTEND=noninteractive
    # Called as a condition, where `set -e` does not apply: every failure is checked here.
    apt_ran=1
    apt-get update -q >/dev/null || fail "apt-get update failed"
    # shellcheck disable=SC2086 # one word per package
    apt-get install -y -q --no-install-recommends $missing >/dev/null ||
        fail "apt-get install failed:$missing"
    missing=""
}

clean_apt_lists() {  # image roles only: the lists are tens of MB that an image does not need
    if [ -n "$apt_ran" ]; then
        rm -rf /var/lib/apt/lists/*
    fi
}

nvidia_egl_vendor() {
    vendor='{
    "file_format_version" : "1.0.0",
    "ICD" : {
        "library_path" : "libEGL_nvidia.so.0"
    }
}'
    if [ -f "$NVIDIA_EGL_VENDOR" ] && [ "$(cat "$NVIDIA_EGL_VENDOR")" = "$vendor" ]; then
        return 0
    fi
    if [ "$(id -u)" != 0 ]; then
        say "note: $NVIDIA_EGL_VENDOR is missing (not root: not written); EGL will not find" \
            "NVIDIA's driver"
        return 0
    fi
    mkdir -p "$(dirname "$NVIDIA_EGL_VENDOR")"
    printf '%s\n' "$vendor" >"$NVIDIA_EGL_VENDOR"
}

service_user() {  # the unprivileged user the images run as
    if id "$SERVICE_USER" >/dev/null 2>&1; then
        return 0
    fi
    if [ "$(id -u)" != 0 ]; then
        say "note: user $SERVICE_USER is missing (not root: not created)"
        return 0
    fi
    useradd --uid "$SERVICE_UID" --user-group --create-home --home-dir "/home/$SERVICE_USER" \
        --shell /usr/sbin/nologin "$SERVICE_USER"
}

python_package() {  # quilting with the service, GL and queue extras, into $VENV
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q --no-cache-dir --disable-pip-version-check ".[server,gl,queue]"
    "$VENV/bin/quilting" --help >/dev/null
    # The compiled kernels, compiled once here into NUMBA_CACHE_DIR (the images set it): numba
    # uses a cache directory only if it may write there, so it belongs to the service user.
    if [ -n "${NUMBA_CACHE_DIR:-}" ]; then
        mkdir -p "$NUMBA_CACHE_DIR"
    fi
    "$VENV/bin/python" -c "import quilting; quilting.warm_up()"
    if [ -n "${NUMBA_CACHE_DIR:-}" ] && [ "$(id -u)" = 0 ] && id "$SERVICE_USER" >/dev/null 2>&1
    then
        chown -R "$SERVICE_USER:$SERVICE_USER" "$NUMBA_CACHE_DIR"
    fi
}

role_cpu() {
    have_mesa || want "$MESA_PACKAGES"
    if install_missing; then
        have_mesa || fail "Mesa EGL/llvmpipe still not found after installing $MESA_PACKAGES"
    fi
    clean_apt_lists
    service_user
    python_package
}

role_gpu() {
    have_glvnd || want "$GLVND_PACKAGES"
    if install_missing; then
        have_glvnd || fail "glvnd's libEGL/libGL still not found after installing $GLVND_PACKAGES"
    fi
    clean_apt_lists
    nvidia_egl_vendor
    service_user
    python_package
}

role_ci() {
    # System packages first, all in one apt-get run.
    have_mesa || want "$MESA_PACKAGES"
    have_redis || want redis-server
    browser=""  # what to check once installed: "render" when chromium was installed here
    if ! chromium_renders; then
        if [ -x "$CHROMIUM" ]; then
            say "note: $CHROMIUM is there but does not render a page headless; the browser" \
                "tests will skip (or fail, with QUILTING_REQUIRE_BROWSER set)"
        elif [ "$CHROMIUM" = /usr/bin/chromium ]; then
            # Without the recommends (sandbox helper, desktop integration) it still runs
            # headless with --no-sandbox; fonts come with fontconfig, which chromium depends on.
            want chromium
            browser=render
        else
            say "note: Chromium not found at $CHROMIUM (Debian package: chromium); the browser" \
                "tests will skip"
        fi
    fi
    # `python3 -m venv` needs ensurepip: Debian's python3-venv (when python3 is Debian's).
    if ! have_venv_module; then
        if ! command -v python3 >/dev/null 2>&1; then
            want python3 python3-venv
        elif [ "$(command -v python3)" = /usr/bin/python3 ]; then
            want python3-venv
        else
            fail "$(command -v python3) cannot create a virtual environment (no ensurepip)"
        fi
    fi
    if install_missing; then
        have_mesa || fail "Mesa EGL/llvmpipe still not found after installing $MESA_PACKAGES"
        have_redis || fail "redis-server still not found after installing redis-server"
        if [ "$browser" = render ] && ! chromium_renders; then
            fail "$CHROMIUM still does not render a page headless after installing chromium"
        fi
        have_venv_module || fail "python3 still cannot create a virtual environment"
    fi
    # The development install, as the README's test command has always done it.
    python3 -m venv .venv
    .venv/bin/pip install -q -e '.[dev]' -e ./client
    # Compile the kernels once now, so that no test's worker process waits for a compilation.
    .venv/bin/python -c "import quilting; quilting.warm_up()"
}

case "${1:-}" in
    cpu) role_cpu ;;
    gpu) role_gpu ;;
    ci) role_ci ;;
    *)
        echo "usage: sh docker/install.sh cpu|gpu|ci" >&2
        exit 2
        ;;
esac
