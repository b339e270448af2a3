#!/usr/bin/env bash
# Install headless Chromium (Debian's package) for the HTML report's browser test,
# unless it is there already. Run as root; .ci/run and the README's test command call it.
set -euo pipefail
if command -v chromium >/dev/null; then
    echo "[browser-up] $(chromium --version)"
    exit 0
fi
install() { DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends chromium; }
install || { apt-get update -q && install; }
echo "[browser-up] $(chromium --version)"
