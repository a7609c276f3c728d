# Sourced by the browser tests: sets and exports CHROMIUM (the variable if set, else Debian's
# `chromium`, installed with apt-get when missing and running as root); calls the caller's
# `skip MESSAGE` when there is none.
chromium="${CHROMIUM:-$(command -v chromium || true)}"
if [ -z "$chromium" ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "installing Debian's chromium"
        "$(dirname "${BASH_SOURCE[0]}")/apt-install.sh" chromium >/dev/null 2>&1 || true
    fi
    chromium="$(command -v chromium || true)"
    [ -n "$chromium" ] || skip "chromium is not installed and apt-get could not install it"
fi
export CHROMIUM="$chromium"
