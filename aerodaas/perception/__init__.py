"""Perception from a drone: bring-your-own ONNX detectors (:mod:`.decoders`), the detector options
checked before Ray (:mod:`.options`) and tiled (sliced) inference for small objects (:mod:`.tiling`)."""
