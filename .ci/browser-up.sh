#!/usr/bin/env bash
# Install headless Chromium (Debian's package) for the HTML report's browser test, and
# poppler-utils (pdffonts) for the figures' font test, unless they are there already.
# Run as root; .ci/run and the README's test command call it.
set -euo pipefail
if command -v chromium >/dev/null && command -v pdffonts >/dev/null; then
    echo "[browser-up] $(chromium --version); $(pdffonts -v 2>&1 | head -n 1)"
    exit 0
fi
install() {
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends chromium \
        poppler-utils
}
install || { apt-get update -q && install; }
echo "[browser-up] $(chromium --version); $(pdffonts -v 2>&1 | head -n 1)"
