"""The cloud side of analytics scheduling: the cloud executor actors a dispatcher sends frames to."""
