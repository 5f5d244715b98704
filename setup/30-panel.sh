#!/usr/bin/env bash
# The Robot Supervisor Panel: Debian's chromium (end-to-end tests, benchmark), the npm packages
# of panel/ and its built bundle in virtualstar/panel/static/. Each step runs only when needed.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ ! -x /usr/bin/chromium ]; then
  echo "panel: installing Debian's chromium"
  SUDO=""
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null || { echo "panel: error: chromium is missing and this user cannot apt-get install it" >&2; exit 1; }
    SUDO="sudo -n"
  fi
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends chromium
fi

command -v node >/dev/null && command -v npm >/dev/null || {
  echo "panel: error: node and npm are missing; install Node.js >= 20.19 (e.g. apt-get install nodejs npm)" >&2
  exit 1
}
node -e 'const [a, b] = process.versions.node.split(".").map(Number); process.exit(a > 20 || (a === 20 && b >= 19) ? 0 : 1)' || {
  echo "panel: error: Node.js $(node --version) is too old; Vite needs >= 20.19" >&2
  exit 1
}

cd panel
# npm writes node_modules/.package-lock.json on every install: older than the lock file = stale.
if [ ! -f node_modules/.package-lock.json ] || [ package-lock.json -nt node_modules/.package-lock.json ]; then
  echo "panel: npm ci"
  npm ci --no-audit --no-fund --prefer-offline --loglevel=error
fi

BUNDLE=../virtualstar/panel/static/index.html
if [ ! -f "$BUNDLE" ] || [ -n "$(find src public index.html vite.config.js package-lock.json -newer "$BUNDLE" -print -quit)" ]; then
  echo "panel: npm run build"
  npm run build --silent >/dev/null
fi
echo "panel: ready (bundle in virtualstar/panel/static/)"
