"""Frames worth labelling (``aerodaas label frames``): camera frames out of recordings and videos, chosen within a
budget by how much the shipped detector is unsure of them and how different they look, written with the detector's
boxes as pre-labels a reviewer only corrects (Label Studio tasks, CVAT for images 1.1 XML, COCO JSON).

Modules: :mod:`~aerodaas.labelling.names` (frame file names), :mod:`~aerodaas.labelling.sources` (frames out of
MCAP recordings, videos and image lists), :mod:`~aerodaas.labelling.features` (near-duplicate hash and the
appearance embedding), :mod:`~aerodaas.labelling.scoring` (informativeness), :mod:`~aerodaas.labelling.select`
(the selection: :func:`~aerodaas.labelling.select.select_frames`), :mod:`~aerodaas.labelling.prelabels` (the
pre-label files) and :mod:`~aerodaas.labelling.frames` (the whole ``label frames`` run, written atomically); the Label Studio round
trip: :mod:`~aerodaas.labelling.label_studio` (its REST client), :mod:`~aerodaas.labelling.push`,
:mod:`~aerodaas.labelling.pull` and :mod:`~aerodaas.labelling.ml_backend` (``aerodaas label serve``).
"""
