"""The embedded simulator backend: vehicle kinematics, battery, GPS, and the camera's world."""
