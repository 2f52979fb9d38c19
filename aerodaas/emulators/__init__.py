"""Protocol emulators for testing the real-vehicle backends on loopback, written from the protocols' public
specifications (MAVLink common message set and the autopilots' documented behaviour; the Tello SDK 2.0),
not from our backends' assumptions."""
