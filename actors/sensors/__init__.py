"""Sensors inside a drone's actor besides the drone's own odometry: the camera component and its built-in
frame sources, and the component that runs a plug-in sensor."""
