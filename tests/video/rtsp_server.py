"""An RTSP server for the tests, as a drone's gimbal camera or a companion computer serves its video: GStreamer's
gst-rtsp-server (Debian packages gstreamer1.0-rtsp, gir1.2-gst-rtsp-server-1.0, python3-gi), run by the system's
/usr/bin/python3, which has PyGObject. It serves ``rtsp://127.0.0.1:PORT/cam``: H.264 relayed from MPEG-TS arriving
on UDP ``TS_PORT`` (from tests/video/video_rig.py's looping sender), RTP-packetised with SPS/PPS on every keyframe.

    /usr/bin/python3 tests/video/rtsp_server.py PORT TS_PORT

Prints ``ready`` once it listens."""
import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtspServer  # noqa: E402

Gst.init(None)
port, ts_port = sys.argv[1], int(sys.argv[2])
server = GstRtspServer.RTSPServer()
server.set_address("127.0.0.1")
server.set_service(port)
factory = GstRtspServer.RTSPMediaFactory()
factory.set_launch(f'( udpsrc port={ts_port} buffer-size=4194304 caps="video/mpegts,systemstream=(boolean)true" ! tsdemux ! '
                   f'h264parse ! rtph264pay name=pay0 pt=96 config-interval=1 )')
factory.set_shared(True)
server.get_mount_points().add_factory("/cam", factory)
if server.attach(None) == 0:
    sys.exit(f"rtsp_server: cannot listen on 127.0.0.1:{port}")
print("ready", flush=True)
GLib.MainLoop().run()
