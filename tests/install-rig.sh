#!/bin/sh
# The test rig (Debian 12 / Ubuntu 22.04+), run by the README's test command and CI. Each step is skipped when
# already done.
# - Debian packages: GStreamer's RTSP server and PyGObject for the system python (tests/video/rtsp_server.py runs
#   under /usr/bin/python3), with the elements the relay uses (udpsrc, tsdemux, h264parse, rtph264pay), and FFmpeg's
#   decoders for GStreamer (gstreamer1.0-libav: avdec_h264, what the GStreamer appsink peer of `aerodaas bench video`
#   decodes with, as a user's pipeline would); node and npm when missing.
# - npm packages: Foxglove's WebSocket client from tests/js/package-lock.json (tests/liveview/test_liveview_npm_client.py)
#   and, into npm's cache, @mcap/core and fzstd (tests/liveview/test_live_and_foxglove.py installs them into a
#   temporary folder, --prefer-offline).
# - Label Studio 1.23.2 in a venv of its own (AERODAAS_LABEL_STUDIO_VENV, default
#   $HOME/.cache/aerodaas/label-studio-1.23.2; it pins NumPy and OpenCV versions that must not replace the project's):
#   the server the tests of `aerodaas label push/pull` start (tests/labelling/).
# The video, live-view and labelling tests fail, never skip, without them when CI is set (tests/conftest.py
# skip_or_fail).
set -e
PKGS="gstreamer1.0-rtsp gir1.2-gst-rtsp-server-1.0 python3-gi gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav"
NEED=""
if ! { /usr/bin/python3 -c "import gi; gi.require_version('GstRtspServer', '1.0'); from gi.repository import GstRtspServer" 2>/dev/null \
   && command -v gst-inspect-1.0 >/dev/null 2>&1 && gst-inspect-1.0 tsdemux >/dev/null 2>&1 \
   && gst-inspect-1.0 avdec_h264 >/dev/null 2>&1; }; then
  NEED="$PKGS gstreamer1.0-tools"
fi
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  NEED="$NEED nodejs npm"
fi
if [ -n "$NEED" ]; then
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq >/dev/null
  $SUDO apt-get install -y -qq --no-install-recommends $NEED >/dev/null
fi

JS="$(cd "$(dirname "$0")" && pwd)/js"
if [ ! -d "$JS/node_modules/@foxglove/ws-protocol" ]; then
  (cd "$JS" && npm ci --silent --no-audit --no-fund)
fi
npm cache add "@mcap/core@2" "fzstd@0.1" >/dev/null

LS_VERSION=1.23.2
LS_VENV="${AERODAAS_LABEL_STUDIO_VENV:-$HOME/.cache/aerodaas/label-studio-$LS_VERSION}"
if ! "$LS_VENV/bin/python" -c "import sys, label_studio; sys.exit(label_studio.__version__ != '$LS_VERSION')" 2>/dev/null \
   || [ ! -x "$LS_VENV/bin/label-studio" ]; then
  python3 -m venv "$LS_VENV"
  "$LS_VENV/bin/python" -m pip install -q --disable-pip-version-check "label-studio==$LS_VERSION"
fi
