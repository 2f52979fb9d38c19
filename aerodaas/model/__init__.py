"""The data model, the bottom layer (imports no other sub-package): waypoints, navigation, odometry, detections and
frame metadata (``types.py``), the IAeroData containers (``data.py``), WGS-84 <-> ENU geodesy (``geo.py``), the id
grammar (``ids.py``) and bounded JSON reading (``jsonfile.py``)."""
