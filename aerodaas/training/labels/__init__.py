"""Reading what labelling tools export (CVAT, Label Studio): the export's layout recognised (:mod:`.layout`), YOLO
txt labels (:mod:`.yolo`), COCO JSON (:mod:`.coco`), the images and their video/sequence (:mod:`.images`), every
problem collected (:mod:`.check`). :func:`aerodaas.training.dataset.load_set` is the entry point."""
