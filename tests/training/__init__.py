"""Training the detector: labelled sets as CVAT and Label Studio export them (each layout built as the tool writes
it, Label Studio's through its own converter), their checks, the split by video, and the base model a run starts
from."""
