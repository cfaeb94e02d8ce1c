#!/bin/sh
# Headless Chromium for the web page's end-to-end tests (tests/service/test_web_page.py), driven
# by Playwright with Debian's own browser: Playwright's browser downloads are not used.
# Installs Debian's `chromium` with apt when it is missing and we may (root, apt-get); otherwise
# says what is missing. The browser tests skip without it, except in CI
# (QUILTING_REQUIRE_BROWSER=1), where a browser test that cannot run is a failure.
# QUILTING_CHROMIUM names another Chromium binary (default /usr/bin/chromium).
set -eu
chromium="${QUILTING_CHROMIUM:-/usr/bin/chromium}"
# The arguments the tests launch it with (tests/service/browser.py).
headless_args="--headless=new --no-sandbox --disable-gpu --disable-quic --no-first-run
 --disable-background-networking --disable-component-update --disable-sync"

runs_headless() {
    [ -x "$chromium" ] || return 1
    profile=$(mktemp -d)
    # shellcheck disable=SC2086 # one word per argument
    dom=$(timeout 120 "$chromium" $headless_args --user-data-dir="$profile" \
        --dump-dom 'data:text/html,<p>quilting-headless-ok</p>' 2>/dev/null) || true
    rm -rf "$profile"
    case "$dom" in
        *quilting-headless-ok*) return 0 ;;
        *) return 1 ;;
    esac
}

if runs_headless; then
    exit 0
fi
if [ -x "$chromium" ]; then
    echo "note: $chromium is there but does not render a page headless; the browser tests" \
        "will skip (or fail, with QUILTING_REQUIRE_BROWSER set)" >&2
    exit 0
fi
packages="chromium"
if [ "$chromium" = /usr/bin/chromium ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1
then
    echo "installing Debian's Chromium: $packages" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >/dev/null
    # Without the recommends (sandbox helper, desktop integration) it still runs headless with
    # --no-sandbox; fonts come with fontconfig, which chromium depends on.
    # shellcheck disable=SC2086 # one word per package
    apt-get install -y -q --no-install-recommends $packages >/dev/null
    runs_headless || {
        echo "$chromium still does not render a page headless after installing $packages" >&2
        exit 1
    }
else
    echo "note: Chromium not found at $chromium (Debian package: $packages); the browser tests" \
        "will skip" >&2
fi
