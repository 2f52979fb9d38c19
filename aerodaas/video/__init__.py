"""Video streams as camera sources: RTSP, RTP on UDP (QGroundControl's 5600), MPEG-TS on UDP, V4L2 and video files,
decoded with PyAV into a newest-wins slot, each frame stamped at capture (see docs/video.md)."""
from aerodaas.video.clock import CaptureClock
from aerodaas.video.reader import StreamReader, VideoEvent, VideoFrame, VideoSourceError
from aerodaas.video.source import StreamSpec, is_stream_source, parse_stream_source

__all__ = ["CaptureClock", "StreamReader", "StreamSpec", "VideoEvent", "VideoFrame", "VideoSourceError",
           "is_stream_source", "parse_stream_source"]
