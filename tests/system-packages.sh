#!/bin/sh
# The Debian packages linkevo's tests drive for real: Chromium and its driver (the explorer
# page's and the MLflow UI's browser tests) and PostgreSQL's server programs (the local
# cluster's test). linkevo itself needs none of them. Installed here when this user can
# (root, or password-less sudo); otherwise named, and the tests that need them fail saying
# the same. Nothing else is changed.
missing=""
command -v chromium >/dev/null 2>&1 || missing="$missing chromium"
command -v chromedriver >/dev/null 2>&1 || missing="$missing chromium-driver"
ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || command -v initdb >/dev/null 2>&1 \
    || missing="$missing postgresql"
[ -z "$missing" ] && exit 0
if [ "$(id -u)" = 0 ]; then
    sudo=""
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    sudo="sudo -n"
else
    echo "linkevo's tests need Debian packages this user cannot install:$missing" >&2
    echo "  install them with: sudo apt-get install -y$missing" >&2
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "linkevo's tests need:$missing (no apt-get here: install them as this system does)" >&2
    exit 0
fi
echo "installing the Debian packages linkevo's tests drive:$missing" >&2
$sudo apt-get update -q && $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -q $missing
