"""Tests: real-time video sources (RTSP, RTP/UDP, MPEG-TS) and missions flown on them."""
