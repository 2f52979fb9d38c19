-- Announces one video stream for camera instance 0 of a real ArduCopter SITL (tests/test_sitl_camera.py), as
-- ArduPilot's video-stream-information applet does for a Siyi or Herelink: the firmware then answers
-- MAV_CMD_REQUEST_MESSAGE for VIDEO_STREAM_INFORMATION with it. Needs CAM1_TYPE set (AP_Camera instance 0).
local function announce()
  local s = mavlink_video_stream_information_t()
  local name, uri = 'main', 'rtsp://127.0.0.1:8554/cam'
  s:stream_id(1) s:count(1) s:type(0) s:flags(1) s:framerate(10)  -- VIDEO_STREAM_TYPE_RTSP, RUNNING
  s:resolution_h(640) s:resolution_v(480) s:bitrate(2000) s:rotation(0) s:hfov(80) s:encoding(1)  -- H264
  for i = 0, #name do s:name(i, name:byte(i+1)) end
  for i = 0, #uri do s:uri(i, uri:byte(i+1)) end
  camera:set_stream_information(0, s)
  return announce, 5000
end
return announce()
